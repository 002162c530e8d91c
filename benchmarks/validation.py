"""Measured agreement of the renderer with closed forms and invariants (value +/- sigma), for the README and
the changelog: ``python benchmarks/validation.py`` writes ``benchmarks/validation.json``.
The pass/fail versions of these checks are ``tests/oracles/test_physics.py``; this script reports the numbers at
higher sample counts."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE.parent / "tests" / "oracles"))  # test_physics
sys.path.insert(0, str(HERE.parent / "tests" / "render"))  # test_render_core


def main() -> int:
    from test_physics import _sinusoid_frequency, closed_form

    from mincam_sim import Mincam, Mixel, Pose, Screen, masks, single
    from mincam_sim.scene.display import vertical_line, white_square

    out: dict = {}
    screen = Screen()
    frame = np.full(screen.shape, 2.0)
    for label, offset in (("on_axis", (0.0, 0.0)), ("clipped", (0.3, 0.12))):
        cam = single(masks.constant(1.0), pose=Pose((*offset, 0.0), (0, 0, -1)))
        expected = closed_form(screen, cam[0], 2.0)
        rows = {"closed_form_w_m2": expected}
        for form in ("reference", "fast", "response_map"):
            if form == "response_map":
                m = _maps(cam, screen, 64, seed=1).measure(frame)
            else:
                m = _rays(cam, screen, form, 1 << 22, seed=1, frame=frame)
            v, s = float(m.irradiance_w_m2[0, 0]), float(m.stderr_w_m2[0, 0])
            rows[form] = {"value_w_m2": v, "sigma_w_m2": s, "deviation_sigma": (v - expected) / s,
                          "relative_deviation": v / expected - 1}
        out[f"open_aperture_{label}"] = rows

    gx, gy = screen.texel_centers_m()
    image = 1.0 + 0.8 * np.sin(6 * gx) * np.cos(4 * gy)
    ramp = masks.ramp("x", 64)
    res = {}
    for name, mask in {"x": ramp, "1-x": ramp.complement(), "1": masks.constant(1.0), "0.3x": ramp.scaled(0.3)}.items():
        m = _rays(single(mask), screen, "fast", 1 << 22, seed=len(name), frame=image)
        res[name] = (float(m.irradiance_w_m2[0, 0]), float(m.stderr_w_m2[0, 0]))
    diff = res["x"][0] + res["1-x"][0] - res["1"][0]
    sig = float(np.sqrt(res["x"][1] ** 2 + res["1-x"][1] ** 2 + res["1"][1] ** 2))
    out["complementary_masks"] = {"P(x)+P(1-x)-P(1)_w_m2": diff, "sigma_w_m2": sig, "P(1)_w_m2": res["1"][0]}
    diff = res["0.3x"][0] - 0.3 * res["x"][0]
    sig = float(np.hypot(res["0.3x"][1], 0.3 * res["x"][1]))
    out["scaled_mask"] = {"P(0.3x)-0.3P(x)_w_m2": diff, "sigma_w_m2": sig}

    a = white_square(screen, (-0.1, 0.05), 0.08, 3.0)
    b = white_square(screen, (0.12, -0.08), 0.12, 1.5)
    pa, pb, pab = (_rays(single(ramp), screen, "fast", 1 << 22, seed=s, frame=f) for f, s in ((a, 11), (b, 12),
                                                                                               (a + b, 13)))
    diff = float(pab.irradiance_w_m2[0, 0] - pa.irradiance_w_m2[0, 0] - pb.irradiance_w_m2[0, 0])
    sig = float(np.sqrt(pab.stderr_w_m2[0, 0] ** 2 + pa.stderr_w_m2[0, 0] ** 2 + pb.stderr_w_m2[0, 0] ** 2))
    out["superposition"] = {"P(A+B)-P(A)-P(B)_w_m2": diff, "sigma_w_m2": sig,
                            "P(A+B)_w_m2": float(pab.irradiance_w_m2[0, 0])}

    omega_df, d_f = 2 * np.pi / 0.4e-3, 2e-3
    for depth in (0.5, 1.0):
        scr = Screen(width_m=1.2, height_m=1.2, resolution=(480, 8), pose=Pose((0, 0, -depth), (0, 0, 1)))
        cam = Mincam((Mixel(masks.sinusoid(omega_df, resolution=512), d_f, name="sin"),
                      Mixel(masks.constant(1.0), d_f, name="open")), allow_overlap=True)
        maps = _maps(cam, scr, 64, seed=5)
        x = scr.texel_centers_m()[0][0]
        p = maps.measure(np.stack([vertical_line(scr, xc, scr.texel_size_m[0]) for xc in x])).irradiance_w_m2
        keep = (np.abs(x) < 0.8 * 1e-3 * depth / d_f) & (p[:, 1] > 0)
        omega, sigma = _sinusoid_frequency(x[keep], p[keep, 0] / p[keep, 1], omega_df * d_f / depth)
        out[f"depth_scaling_{depth}m"] = {"fitted_omega_rad_per_m": float(omega), "fit_sigma": float(sigma),
                                          "expected_omega_rad_per_m": omega_df * d_f / depth,
                                          "relative_deviation": float(omega / (omega_df * d_f / depth) - 1)}

    scr = Screen(width_m=1.2, height_m=0.6, resolution=(240, 6))
    baseline = 10 * scr.texel_size_m[0]
    cam = Mincam((Mixel(ramp, pose=Pose((-baseline / 2, 0, 0), (0, 0, -1)), name="l"),
                  Mixel(ramp, pose=Pose((baseline / 2, 0, 0), (0, 0, -1)), name="r")))
    maps = _maps(cam, scr, 64, seed=7)
    curves = maps.weights_sr.sum(axis=1)
    x = scr.texel_centers_m()[0][0]
    c = (curves * x).sum(axis=1) / curves.sum(axis=1)
    out["fov_offset"] = {"baseline_m": baseline, "centroid_shift_m": float(c[1] - c[0]),
                         "relative_deviation": float((c[1] - c[0]) / baseline - 1)}
    out["coupled_geometry_and_shadows"] = coupled_geometry_and_shadows()
    (HERE / "validation.json").write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))
    return 0


def _maps(cam, screen, samples_per_texel: int, seed: int, replicates: int | None = None):
    """The response maps of ``cam`` over ``screen`` (the ResponseMap solver's maps, through the front door)."""
    from mincam_sim import Budget, Simulation

    budget = Budget(samples_per_texel=samples_per_texel, seed=seed, replicates=replicates)
    return Simulation(cam, screen=screen).response_maps(budget)


def _rays(cam, screen, form: str, spp: int, seed: int, frame: np.ndarray):
    """``frame`` measured by the reference or the aperture ("fast") solver, 16 replicates."""
    from mincam_sim import Aperture, Budget, Reference, Simulation

    solver = Reference() if form == "reference" else Aperture()
    return Simulation(cam, screen=screen).measure(frame, solver, Budget(spp=spp, replicates=16, seed=seed))


def _row(value: float, sigma: float, expected: float) -> dict:
    return {"value_w_m2": float(value), "sigma_w_m2": float(sigma), "oracle_w_m2": float(expected),
            "relative_deviation": float(value / expected - 1), "deviation_sigma": float((value - expected) / sigma)}


def coupled_geometry_and_shadows() -> dict:
    """The render-core checks against the independent float64 oracles (:mod:`mincam_sim.oracles.quadrature`), at the
    sample counts of ``tests/render/test_render_core.py``: tilted mixel and rotated screen, mixels that shadow each
    other (occluder 1 cm away), the 0.2 mm-period sinusoid at a trough."""
    from test_render_core import SINUSOID_30, SQUARE_M, TILT_SCREEN, _shadow_oracle, _shadowing_pair, _tilted_mixel

    from mincam_sim import Mincam, Mixel, Screen, masks
    from mincam_sim.oracles.quadrature import mixel_irradiance_gl
    from mincam_sim.scene.display import coverage

    out: dict = {}
    for name, mask in (("sinusoid30", SINUSOID_30), ("ramp", masks.ramp("1-x"))):
        mixel = _tilted_mixel(mask)
        expected = mixel_irradiance_gl(mixel, TILT_SCREEN, SQUARE_M, 1.0, n_detector=8, n_screen=24)
        m = _maps(Mincam((mixel,)), TILT_SCREEN, 1024, seed=4, replicates=16).measure(
            coverage(TILT_SCREEN, *SQUARE_M))
        out[f"response_map_tilted_{name}"] = _row(m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0], expected)
    cam = _shadowing_pair()
    expected, alone = _shadow_oracle(cam, 2.0)
    frame = np.full(Screen().shape, 2.0)
    out["shadow_unshadowed_oracle_w_m2"] = alone
    for form in ("fast", "response_map", "reference"):
        if form == "response_map":
            m = _maps(cam, Screen(), 16, seed=3).measure(frame)
        else:
            m = _rays(cam, Screen(), form, 1 << 20 if form == "fast" else 1 << 23, seed=3, frame=frame)
        out[f"shadow_{form}"] = _row(m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0], expected)
    screen = Screen(width_m=0.24, height_m=0.12, resolution=(96, 48))
    exact = masks.sinusoid(2 * np.pi / 0.2e-3, 0.5, 0.5)
    region = (0.0125, 0.0375, -0.025, 0.025)
    expected = mixel_irradiance_gl(Mixel(exact), screen, region, 1.0, n_detector=12, n_screen=24)
    m = _maps(Mincam((Mixel(exact),)), screen, 1024, seed=2, replicates=16).measure(coverage(screen, *region))
    out["speed_sinusoid_trough"] = _row(m.irradiance_w_m2[0, 0], m.stderr_w_m2[0, 0], expected)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
