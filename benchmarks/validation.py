"""Measured agreement of the renderer with closed forms and invariants (value +/- sigma), for the README and
the issue notes: ``python benchmarks/validation.py`` writes ``benchmarks/validation.json``.
The pass/fail versions of these checks are ``tests/test_physics.py``; this script reports the numbers at
higher sample counts."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parent / "tests"))


def main() -> int:
    from test_physics import _sinusoid_frequency, closed_form

    from mincam_sim import Mincam, Mixel, Pose, Screen, masks, single
    from mincam_sim.render.screen_engine import ScreenRenderer, response_maps
    from mincam_sim.screen import vertical_line, white_square

    out: dict = {}
    screen = Screen()
    frame = np.full(screen.shape, 2.0)
    for label, offset in (("on_axis", (0.0, 0.0)), ("clipped", (0.3, 0.12))):
        cam = single(masks.constant(1.0), pose=Pose((*offset, 0.0), (0, 0, -1)))
        expected = closed_form(screen, cam[0], 2.0)
        rows = {"closed_form_w_m2": expected}
        for form in ("reference", "fast", "response_map"):
            if form == "response_map":
                m = response_maps(cam, screen, 64, seed=1).measure(frame)
            else:
                m = ScreenRenderer(cam, screen, form, replicates=16).render(frame, spp=1 << 22, seed=1)
            v, s = float(m.irradiance_w_m2[0, 0]), float(m.stderr_w_m2[0, 0])
            rows[form] = {"value_w_m2": v, "sigma_w_m2": s, "deviation_sigma": (v - expected) / s,
                          "relative_deviation": v / expected - 1}
        out[f"open_aperture_{label}"] = rows

    gx, gy = screen.texel_centers_m()
    image = 1.0 + 0.8 * np.sin(6 * gx) * np.cos(4 * gy)
    ramp = masks.ramp("x", 64)
    res = {}
    for name, mask in {"x": ramp, "1-x": ramp.complement(), "1": masks.constant(1.0), "0.3x": ramp.scaled(0.3)}.items():
        m = ScreenRenderer(single(mask), screen, "fast", replicates=16).render(image, spp=1 << 22, seed=len(name))
        res[name] = (float(m.irradiance_w_m2[0, 0]), float(m.stderr_w_m2[0, 0]))
    diff = res["x"][0] + res["1-x"][0] - res["1"][0]
    sig = float(np.sqrt(res["x"][1] ** 2 + res["1-x"][1] ** 2 + res["1"][1] ** 2))
    out["complementary_masks"] = {"P(x)+P(1-x)-P(1)_w_m2": diff, "sigma_w_m2": sig, "P(1)_w_m2": res["1"][0]}
    diff = res["0.3x"][0] - 0.3 * res["x"][0]
    sig = float(np.hypot(res["0.3x"][1], 0.3 * res["x"][1]))
    out["scaled_mask"] = {"P(0.3x)-0.3P(x)_w_m2": diff, "sigma_w_m2": sig}

    renderer = ScreenRenderer(single(ramp), screen, "fast", replicates=16)
    a = white_square(screen, (-0.1, 0.05), 0.08, 3.0)
    b = white_square(screen, (0.12, -0.08), 0.12, 1.5)
    pa, pb, pab = (renderer.render(f, spp=1 << 22, seed=s) for f, s in ((a, 11), (b, 12), (a + b, 13)))
    diff = float(pab.irradiance_w_m2[0, 0] - pa.irradiance_w_m2[0, 0] - pb.irradiance_w_m2[0, 0])
    sig = float(np.sqrt(pab.stderr_w_m2[0, 0] ** 2 + pa.stderr_w_m2[0, 0] ** 2 + pb.stderr_w_m2[0, 0] ** 2))
    out["superposition"] = {"P(A+B)-P(A)-P(B)_w_m2": diff, "sigma_w_m2": sig,
                            "P(A+B)_w_m2": float(pab.irradiance_w_m2[0, 0])}

    omega_df, d_f = 2 * np.pi / 0.4e-3, 2e-3
    for depth in (0.5, 1.0):
        scr = Screen(width_m=1.2, height_m=1.2, resolution=(480, 8), pose=Pose((0, 0, -depth), (0, 0, 1)))
        cam = Mincam((Mixel(masks.sinusoid(omega_df, resolution=512), d_f, name="sin"),
                      Mixel(masks.constant(1.0), d_f, name="open")))
        maps = response_maps(cam, scr, 64, seed=5)
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
    maps = response_maps(cam, scr, 64, seed=7)
    curves = maps.weights_sr.sum(axis=1)
    x = scr.texel_centers_m()[0][0]
    c = (curves * x).sum(axis=1) / curves.sum(axis=1)
    out["fov_offset"] = {"baseline_m": baseline, "centroid_shift_m": float(c[1] - c[0]),
                         "relative_deviation": float((c[1] - c[0]) / baseline - 1)}
    (HERE / "validation.json").write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
