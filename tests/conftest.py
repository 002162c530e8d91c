"""Shared fixtures. Monte Carlo comparisons use Z = 4.5 standard errors: with estimated standard errors from
16 replicates (t-distribution, 15 degrees of freedom) a true-null comparison fails with probability ~4e-4, and
seeds are fixed, so a run is repeatable."""

from __future__ import annotations

import signal

import numpy as np
import pytest

Z = 4.5

# A runner that starts the tests in the background (``cmd &`` in a script) hands them SIGINT ignored, and every
# process they start inherits that. The Ctrl-C tests need what a terminal gives: Python's own handler here, the
# default disposition in the processes started from here.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def assert_close_mc(value, expected, sigma, z: float = Z, what: str = "") -> None:
    """|value - expected| <= z * sigma, elementwise, with a message giving the deviation in sigmas."""
    value, expected, sigma = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (value, expected, sigma)))
    dev = np.abs(value - expected) / sigma
    assert np.all(sigma > 0), f"{what}: standard error must be > 0"
    assert np.all(dev <= z), f"{what}: deviation {dev.max():.2f} sigma > {z} (value {value}, expected {expected})"


@pytest.fixture(scope="session")
def mi_variant():
    from mincam_sim.render import backend

    return backend.variant()
