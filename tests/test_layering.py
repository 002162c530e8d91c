"""Architecture: only the render layer imports mitsuba / drjit (estimators and calibration must run on
measurements recorded from real hardware, without a renderer)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "mincam_sim"
RENDER_LAYER = PACKAGE / "render"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_only_the_render_layer_imports_mitsuba_or_drjit():
    offenders = [
        str(p.relative_to(PACKAGE))
        for p in PACKAGE.rglob("*.py")
        if RENDER_LAYER not in p.parents and _imports(p) & {"mitsuba", "drjit"}
    ]
    assert offenders == []


def test_pure_modules_import_without_a_renderer():
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import mincam_sim.estimators, mincam_sim.calibration, mincam_sim.sensor, mincam_sim.masks\n"
        "import mincam_sim.optics, mincam_sim.screen, mincam_sim.objects, mincam_sim.config\n"
        "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules, sorted(sys.modules)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
