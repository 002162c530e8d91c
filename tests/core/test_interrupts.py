"""A Ctrl-C held while native code runs that a ``KeyboardInterrupt`` must not cross (Dr.Jit's start-up)."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from mincam_sim import interrupts


def test_a_ctrl_c_inside_a_held_block_is_raised_after_it_and_counted():
    interrupts.reset()
    before = signal.getsignal(signal.SIGINT)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts.held():
            os.kill(os.getpid(), signal.SIGINT)
            done.append("the block ran to its end")
    assert done and interrupts.arrived()
    assert signal.getsignal(signal.SIGINT) is before  # the handler is given back
    interrupts.reset()


def test_a_held_block_without_a_ctrl_c_raises_nothing_and_off_the_main_thread_runs_as_it_is():
    with interrupts.held():
        pass
    errors = []

    def worker():
        try:
            with interrupts.held():
                pass
        except Exception as err:  # signal.signal outside the main thread would raise ValueError
            errors.append(err)

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert not errors
