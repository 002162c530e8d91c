"""``python -m mincam_sim.render.check``: load the chosen Mitsuba variant and render a tiny scene whose answer is
known (an irradiance meter under a constant sky of radiance 1 reads pi W/m^2)."""

from __future__ import annotations

import argparse

from mincam_sim.render import backend
from mincam_sim.render.scene.scene_dicts import irradiancemeter


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Check that a Mitsuba variant loads and renders.")
    parser.parse_args(argv)
    mi = backend.mitsuba()
    scene = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "path"},
            "emitter": {"type": "constant", "radiance": {"type": "spectrum", "value": 1.0}},
            "shape": {"type": "rectangle", "sensor": irradiancemeter(1024)},
        }
    )
    value = float(mi.TensorXf(mi.render(scene)).numpy().mean())
    print(f"mincam_sim backend OK: variant={backend.variant()} E(constant sky, L=1)={value:.4f} W/m^2 (pi expected)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
