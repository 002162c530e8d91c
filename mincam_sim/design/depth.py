"""Task ``depth``: the distance (0.3-1.0 m) to a 5 cm square of unknown radiance anywhere in the field, from
the four mixels of the paper's cross.

The decoder is a cubic polynomial of the four changes normalised by their sum (gain-free, so the object's
unknown radiance cancels) that regresses ``ln(depth)``: an error in the log is the relative error the metric
counts (``|d' - d| / d`` in %). The physics to exploit: the parallax between mixels 6.6 cm apart (an object at
depth ``d`` is seen by the left and right mixels at directions that differ by ``0.066 / d`` rad) and the
object's apparent size (``5 cm / d``), which a mask with structure reads as a frequency that scales with depth
(the paper's Eq. 10). A textured plane is in the held-out suite, not in training: with an unknown texture there
is no single apparent size, and the suite says how far the object-trained decoders carry.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mincam_sim.design.scene_tasks import Case, Distribution, TaskSpec

TRAIN_DEPTHS_M = tuple(float(d) for d in np.round(np.geomspace(0.3, 1.0, 8), 4))
HELD_OUT_DEPTHS_M = tuple(float(d) for d in np.round(np.sqrt(np.array(TRAIN_DEPTHS_M[:-1])
                                                             * np.array(TRAIN_DEPTHS_M[1:])), 4))
_TRAIN = Distribution(depths_m=TRAIN_DEPTHS_M, counts=(1,), size_range_m=(0.05, 0.05), contrast_range=(0.4, 1.0),
                      radius=0.35)


def _case(name: str, description: str, **changes) -> Case:
    return Case(name, description, replace(_TRAIN, **{"depths_m": HELD_OUT_DEPTHS_M, **changes}))


DEPTH = TaskSpec(
    name="depth",
    description="distance 0.3-1.0 m to a 5 cm square (radiance 0.4-1) within |q| <= 0.35 of the field, black plane",
    train=_TRAIN,
    suite=(
        _case("between_planes", "the training objects at depths between the training planes"),
        _case("object_4cm", "a 4 cm object (training: 5 cm)", size_range_m=(0.04, 0.04)),
        _case("object_6cm", "a 6 cm object (training: 5 cm)", size_range_m=(0.06, 0.06)),
        _case("off_axis", "objects out to |q| <= 0.45 (training 0.35)", radius=0.45),
        _case("dim_0.1-0.3", "dim objects, radiance 0.1-0.3 (training 0.4-1)", contrast_range=(0.1, 0.3)),
        _case("textured_plane", "a plane of 5 cm patches of random radiance 0.2-1 filling the field",
              shape="texture", contrast_range=(0.2, 1.0)),
    ),
    target="log_depth",
    features="normalised",
    degree=3,
    output="exp",
    metric="abs_rel_error_pct",
    error_cap=0.5,
    starts=("ramps", "random"),
    decoder_family="cubic polynomial of the four changes normalised by their sum (gain-free), regressing "
                   "ln(depth); depth = exp(.)",
    learning_rate=0.02,
)

__all__ = ["DEPTH", "HELD_OUT_DEPTHS_M", "TRAIN_DEPTHS_M"]
