"""Frozen functions (``dr.freeze``) kept per scene: a launch traced once per shape, then replayed.

Each (scene, function) pair has a frozen function of its own, kept while the scene is among the
:data:`FROZEN_SCENES` last used, so that a recording is never replayed on another scene. The scene is an input,
so its geometry and parameters as updated before the call (acceleration structure rebuilt outside) are what a
replay traces; callers key the call on where the moved objects' arrays live (:func:`.stratified.buffers_key`),
since Dr.Jit 1.5 replays with the addresses a recording read.
"""

from __future__ import annotations

import gc
from collections import OrderedDict
from collections.abc import Callable
from contextlib import contextmanager

FROZEN_SCENES = 4  # scenes whose frozen functions are kept (each holds its recordings)
FROZEN_RECORDINGS = 16  # recordings kept per (scene, function) (launch shapes x buffer addresses), LRU dropped
FREEZE_ALLOWANCE = 6  # recordings of a frozen function before it must replay (then: one more per 4 calls)
FROZEN_WARN_AFTER = 1 << 30  # recordings before Dr.Jit warns: never (keeps_recording is the guard)

_FROZEN: OrderedDict[int, tuple] = OrderedDict()  # id(scene) -> (scene, {function: frozen function})


@contextmanager
def no_cyclic_gc():
    """Python's cyclic garbage collector paused: collecting another scene (its Embree structure, its arrays)
    while a frozen function is being recorded aborts Dr.Jit."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def frozen(scene, function: Callable) -> Callable:
    """``function`` frozen (``dr.freeze``) for ``scene``: one frozen function per (scene object, function)."""
    import drjit as dr

    key = id(scene)
    if key in _FROZEN and _FROZEN[key][0] is scene:
        _FROZEN.move_to_end(key)
    else:
        _FROZEN[key] = (scene, {})
        while len(_FROZEN) > FROZEN_SCENES:
            _FROZEN.popitem(last=False)
    kept = _FROZEN[key][1]
    if function not in kept:
        # when recording stops paying is decided by keeps_recording (per run); Dr.Jit's own warning at a fixed count
        # printed a line per launch once ~15 mixed runs on one Simulation had recorded 64 times (numbers unaffected)
        kept[function] = dr.freeze(function, limit=FROZEN_RECORDINGS, warn_after=FROZEN_WARN_AFTER)
    return kept[function]


def release_with(owner, scene) -> None:
    """Drop ``scene``'s frozen functions (their recordings, and the reference that keeps the scene alive) when
    ``owner`` (the Python object that holds the scene: a simulation's scene, a static split) is collected.
    Without it a dropped simulation's scene stayed alive while it was among the :data:`FROZEN_SCENES` last used:
    a loop over seven simulations of a 500 k triangle table grew from 310 to 557 MiB."""
    import weakref

    weakref.finalize(owner, _release, id(scene))


def _release(key: int) -> None:
    _FROZEN.pop(key, None)


def recordings(scene, function: Callable) -> int:
    """How many times ``function`` was recorded frozen for ``scene`` (0 if it never ran frozen there)."""
    entry = _FROZEN.get(id(scene))
    if entry is None or entry[0] is not scene or function not in entry[1]:
        return 0
    return int(entry[1][function].n_recordings)


def keeps_recording(recorded: int, calls: int) -> bool:
    """True once a frozen function recorded ``recorded`` times over ``calls`` calls, more than
    :data:`FREEZE_ALLOWANCE` plus one per 4 calls: its inputs land at new addresses or values every call, so
    recording (which costs what tracing does, and more) never pays off in replays; trace instead."""
    return recorded > FREEZE_ALLOWANCE + calls // 4
