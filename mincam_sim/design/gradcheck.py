"""Gradient check of the differentiable forward model, the way Mitsuba checks its integrators
(``test_ad_integrators``): forward-mode AD derivatives against central finite differences with the same seed.

Checked parameters: mask texels (bilinear 8 x 8 grid, random values; texels through which the objects are
seen, i.e. with at least 10 % of the largest influence), ``d_f`` and the three coordinates of a
mixel's position, for square objects well inside every mixel's field of view (no aperture-edge term). The
error of one parameter is ``||AD - FD|| / ||FD||`` over the frames' irradiances; both use the same samples.
"""

from __future__ import annotations

import numpy as np

from ..masks import Mask
from . import tracking as tr

STEPS = {"texel": 5e-2, "d_f_m": 2e-5, "position_m": 2e-5}  # central-difference steps [1, m, m]


def check_gradients(seed: int = 0, strata: int = 48, n_texels: int = 3) -> dict:
    """Return ``{"max_rel_error", "n_checked", "checks": [{parameter, rel_error}, ...]}``."""
    from ..render import backend
    from ..render import differentiable as dz

    mi = backend.mitsuba()
    import drjit as dr

    rng = np.random.default_rng([seed, 3])
    shape = (8, 8)
    texels0 = rng.uniform(0.1, 0.9, shape)
    cam = tr.mincam([Mask(texels0, tr.MASK_SIZE_M, tr.MASK_SIZE_M, f"random{i}") for i in range(4)])
    depth = 0.5
    q = np.array([[0.1, 0.04], [-0.2, 0.16], [0.0, -0.24], [0.22, 0.2]])
    scenes = dz.SquareScenes(depth, tr.to_metres(q, depth) * 0.8, 0.04, 1.0)
    inside = dz.check_inside_fov(cam, scenes)
    if not inside.all():
        raise RuntimeError(f"gradient-check objects must lie inside every field of view, got {inside}")
    k = 0
    bodies = dz._bodies_scene(cam)
    pos0 = np.asarray(cam[k].pose.position_m, dtype=np.float64)

    def point(p):
        return mi.Point3f(*(float(c) for c in p))

    def measure(texels, d_f, position):
        smp = dz.mixel_samples(cam, k, scenes, strata=strata, seed=seed, d_f=d_f, position=position, bodies=bodies)
        return dz.irradiance(smp, texels, shape)

    def values(texels=None, d_f=cam[k].d_f_m, position=pos0):
        texels = texels0.ravel() if texels is None else texels
        return np.asarray(measure(mi.Float(texels), mi.Float(d_f), point(position)), dtype=np.float64)

    # texels that the objects are seen through: reverse-mode influence of each texel on the summed irradiance
    probe = mi.Float(texels0.ravel())
    dr.enable_grad(probe)
    dr.backward(dr.sum(measure(probe, mi.Float(cam[k].d_f_m), point(pos0))))
    influence = np.asarray(dr.grad(probe), dtype=np.float64)
    seen = np.flatnonzero(influence >= 0.1 * influence.max())
    texel_ids = rng.choice(seen, min(n_texels, len(seen)), replace=False)
    checks = []
    for which in [("texel", int(t)) for t in texel_ids] + [("d_f_m", 0)] + [("position_m", a) for a in range(3)]:
        name, index = which
        texels, d_f, position = mi.Float(texels0.ravel()), mi.Float(cam[k].d_f_m), point(pos0)
        if name == "texel":
            dr.enable_grad(texels)
            e = measure(texels, d_f, position)
            tangent = np.zeros(texels0.size, dtype=np.float32)
            tangent[index] = 1.0
            dr.set_grad(texels, mi.Float(tangent))
        elif name == "d_f_m":
            dr.enable_grad(d_f)
            e = measure(texels, d_f, position)
            dr.set_grad(d_f, 1.0)
        else:
            dr.enable_grad(position)
            e = measure(texels, d_f, position)
            unit = [0.0, 0.0, 0.0]
            unit[index] = 1.0
            dr.set_grad(position, mi.Vector3f(*unit))
        dr.forward_to(e)
        ad = np.asarray(dr.grad(e), dtype=np.float64)
        h = STEPS[name]
        if name == "texel":
            plus, minus = texels0.ravel().copy(), texels0.ravel().copy()
            plus[index] += h
            minus[index] -= h
            fd = (values(texels=plus) - values(texels=minus)) / (2 * h)
        elif name == "d_f_m":
            fd = (values(d_f=cam[k].d_f_m + h) - values(d_f=cam[k].d_f_m - h)) / (2 * h)
        else:
            plus, minus = pos0.copy(), pos0.copy()
            plus[index] += h
            minus[index] -= h
            fd = (values(position=plus) - values(position=minus)) / (2 * h)
        rel = float(np.linalg.norm(ad - fd) / np.linalg.norm(fd))
        label = f"texel[{index}]" if name == "texel" else (name if name == "d_f_m" else f"position_m[{'xyz'[index]}]")
        checks.append({"parameter": label, "rel_error": rel, "ad": ad.tolist(), "fd": fd.tolist()})
    return {"max_rel_error": max(c["rel_error"] for c in checks), "n_checked": len(checks), "checks": checks}


__all__ = ["STEPS", "check_gradients"]
