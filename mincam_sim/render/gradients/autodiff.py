"""Dr.Jit automatic differentiation for the floors above the render layer.

The mask optimiser (:mod:`mincam_sim.design.optimiser`) is design logic written against an array namespace:
:func:`namespace` hands it the Dr.Jit arrays, operations and optimiser it uses, so that no module outside
``mincam_sim.render`` imports Dr.Jit. :func:`single_threaded` fixes the order of the reverse passes' sums.
"""

from __future__ import annotations

from contextlib import contextmanager
from types import SimpleNamespace

from mincam_sim.render import backend


def _mi():
    backend.require_jit("Differentiable mixel measurements (Dr.Jit AD)")
    return backend.mitsuba()


@contextmanager
def single_threaded():
    """Run Dr.Jit kernels on one thread inside the block (then restore the pool).

    The reverse pass of a ``gather`` is an atomic scatter-add, whose float32 sum depends on the order in
    which threads reach it: with several threads the same seed gave gradients differing by ~1e-5 relative,
    and optimisations that drifted apart. On one thread the order is fixed: same seed, same numbers.
    """
    import drjit as dr

    threads = dr.thread_count()
    dr.set_thread_count(1)
    try:
        yield
    finally:
        dr.set_thread_count(threads)


def namespace() -> SimpleNamespace:
    """The Dr.Jit arrays and operations of the mask optimiser (JIT variants only).

    Attributes: ``Float``, ``UInt32`` (array types, built from NumPy arrays or numbers), ``Adam`` (Mitsuba's
    optimiser: ``Adam(lr=...)``, parameters by key), ``xp`` (the Dr.Jit module, the array namespace of the
    decoders' ``features(dn, xp)``), the operations ``arange, backward, block_sum, detach, exp, gather,
    isfinite, mean, minimum, power, round, select, square`` (Dr.Jit's own) and :func:`single_threaded`.
    """
    mi = _mi()
    import drjit as dr

    ops = ("arange", "backward", "block_sum", "detach", "exp", "gather", "isfinite", "mean", "minimum", "power",
           "round", "select", "square")
    return SimpleNamespace(Float=mi.Float, UInt32=mi.UInt32, Adam=mi.ad.Adam, xp=dr,
                           single_threaded=single_threaded, **{name: getattr(dr, name) for name in ops})


__all__ = ["namespace", "single_threaded"]
