"""Task ``counting``: how many objects (0-3) lie on a tabletop plane 0.5 m in front of the four-mixel cross.

Objects are squares of 4-6 cm with a radiance of 0.6-1 above a black plane, anywhere in the working disc. The
decoder is a quadratic polynomial of the four changes at the task's fixed exposure, rounded to the nearest count
and clipped to 0-3: a count is ordinal and grows with the light the objects send, so a regression with rounding
is the natural small decoder, and as a least-squares fit it is solved exactly inside every optimiser step (the
gradient of the calibrated loss with the fit held fixed, as for tracking), where a classifier would need an
inner iterative fit. Four mixels (the brief allows up to eight): the cross of the paper, so that every baseline
(the idealised model's dot maps included) runs on the same geometry.

What physics there is to exploit: the reading of an object falls off with its angle from each mixel's axis
(cosines, distance, the aperture's field of view), so open or random masks read an object at the field's edge
as less than one at the centre; masks that flatten the response over the disc separate the counts.
"""

from __future__ import annotations

from mincam_sim.design.scene_tasks import Case, Distribution, TaskSpec

_TRAIN = Distribution(depths_m=(0.47, 0.5, 0.53), counts=(0, 1, 2, 3), size_range_m=(0.04, 0.06),
                      contrast_range=(0.6, 1.0), radius=0.4)


def _case(name: str, description: str, **changes) -> Case:
    from dataclasses import replace

    return Case(name, description, replace(_TRAIN, **{"depths_m": (0.5,), **changes}))


COUNTING = TaskSpec(
    name="counting",
    description="count 0-3 objects (squares 4-6 cm, radiance 0.6-1) on a black tabletop at 0.47-0.53 m",
    train=_TRAIN,
    suite=(
        _case("in_distribution", "the training distribution, at 0.5 m"),
        _case("table_0.42m", "the table 16 % nearer (0.42 m): brighter objects", depths_m=(0.42,)),
        _case("table_0.60m", "the table 20 % farther (0.60 m): dimmer objects", depths_m=(0.6,)),
        _case("small_3-4cm", "smaller objects, 3-4 cm", size_range_m=(0.03, 0.04)),
        _case("dim_0.4-0.7", "dimmer objects, radiance 0.4-0.7", contrast_range=(0.4, 0.7)),
        _case("whole_disc", "objects over the whole working disc (|q| <= 0.5, training 0.4)", radius=0.5),
        _case("bars", "bars 1 cm wide, 8-15 cm long (same area range as the squares)", shape="bar",
              size_range_m=(0.08, 0.15)),
    ),
    target="count",
    features="raw",
    degree=2,
    output="count",
    metric="accuracy_pct",
    error_cap=1.0,
    starts=("grey", "random"),
    decoder_family="quadratic polynomial of the four changes (12-bit range units, fixed exposure), rounded "
                   "to the nearest count and clipped to 0-3",
    frames_per_depth=(256, 512),
    grid=4,
)

__all__ = ["COUNTING"]
