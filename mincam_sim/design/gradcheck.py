"""Gradient check of the differentiable forward model, the way Mitsuba checks its integrators
(``test_ad_integrators``): forward-mode AD derivatives against central finite differences with the same seed.

Checked parameters: mask texels (bilinear 8 x 8 grid, random values; texels through which the objects are
seen, i.e. with at least 10 % of the largest influence), ``d_f`` and the three coordinates of a mixel's
position, for square objects well inside every mixel's field of view (no aperture-edge term). The error of one
parameter is ``||AD - FD|| / ||FD||`` over the frames' irradiances; both use the same samples.
"""

from __future__ import annotations

import numpy as np

from mincam_sim.design import tracking as tr
from mincam_sim.masks import Mask

STEPS = {"texel": 5e-2, "d_f_m": 2e-5, "position_m": 2e-5}  # central-difference steps [1, m, m]


def check_gradients(seed: int = 0, strata: int = 48, n_texels: int = 3) -> dict:
    """Return ``{"max_rel_error", "n_checked", "checks": [{parameter, rel_error, ad, fd}, ...]}``."""
    from mincam_sim.render.gradients import differentiable as dz

    rng = np.random.default_rng([seed, 3])
    texels0 = rng.uniform(0.1, 0.9, (8, 8))
    cam = tr.mincam([Mask(texels0, tr.MASK_SIZE_M, tr.MASK_SIZE_M, f"random{i}") for i in range(4)])
    depth = 0.5
    q = np.array([[0.1, 0.04], [-0.2, 0.16], [0.0, -0.24], [0.22, 0.2]])
    scenes = dz.SquareScenes(depth, tr.to_metres(q, depth) * 0.8, 0.04, 1.0)
    inside = dz.check_inside_fov(cam, scenes)
    if not inside.all():
        raise RuntimeError(f"gradient-check objects must lie inside every field of view, got {inside}")
    probe = dz.GradientProbe(cam, 0, scenes, texels0, strata=strata, seed=seed)
    influence = probe.influence()
    seen = np.flatnonzero(influence >= 0.1 * influence.max())
    texel_ids = rng.choice(seen, min(n_texels, len(seen)), replace=False)
    checks = []
    for name, index in ([("texel", int(t)) for t in texel_ids] + [("d_f_m", 0)]
                        + [("position_m", a) for a in range(3)]):
        ad = probe.forward(name, index)
        fd = probe.central_difference(name, index, STEPS[name])
        rel = float(np.linalg.norm(ad - fd) / np.linalg.norm(fd))
        if name == "texel":
            label = f"texel[{index}]"
        else:
            label = name if name == "d_f_m" else f"position_m[{'xyz'[index]}]"
        checks.append({"parameter": label, "rel_error": rel, "ad": ad.tolist(), "fd": fd.tolist()})
    return {"max_rel_error": max(c["rel_error"] for c in checks), "n_checked": len(checks), "checks": checks}


__all__ = ["STEPS", "check_gradients"]
