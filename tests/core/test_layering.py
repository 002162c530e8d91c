"""Architecture: the import graph of the package, read from the code (every import, module-level or local).

Floors, bottom to top: the pure core (numpy physics, sensor, estimators, calibration, masks, scene
descriptions, stores, budgets and typed results) -> ``render`` (the only Mitsuba / Dr.Jit user: the
simulation and its solvers, which hand their rows to a sink of ``mincam_sim.frames`` and never open a store or
take a lock) -> ``config`` and ``world_config`` (typed configuration; they name the solver classes) -> ``run``
(output directories: lock, identity, stores, resume; the solvers never import it) -> ``jobs`` (the config
services) -> ``experiments`` and ``design`` -> ``studies`` ->
``cli``. ``plots`` draws results and sits beside the core. The package root is the public facade: it exposes
upper floors lazily and nothing inside the package imports it. Lower floors never import upper ones, and no
modules import each other in a loop.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "mincam_sim"
UPPER = ("render", "config", "world_config", "run", "jobs", "experiments", "design", "studies", "cli", "plots",
         "figures")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}


def _resolve(module: str, level: int, current: str, is_package: bool) -> str:
    if level == 0:
        return module
    base = current.split(".") if is_package else current.split(".")[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join([*base, module] if module else base)


def _imports(name: str, path: Path) -> set[str]:
    """Modules of this package (and top-level third-party names) that ``name`` imports."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    is_package = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(node.module or "", node.level, name, is_package)
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in MODULES else target)
    return found


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _floor(module: str) -> str:
    parts = module.split(".")
    if module == "mincam_sim":
        return "facade"
    return parts[1] if len(parts) > 1 and parts[1] in UPPER else "core"


def _offenders(source_floors: set[str], forbidden: set[str]) -> list[str]:
    return sorted(f"{a} -> {b}" for a, targets in GRAPH.items() if _floor(a) in source_floors
                  for b in targets if b.startswith("mincam_sim.") and _floor(b) in forbidden)


def test_only_the_render_layer_imports_mitsuba_or_drjit():
    offenders = [f"{name} -> {t}" for name, targets in GRAPH.items() if _floor(name) != "render"
                 for t in targets if t.split(".")[0] in ("mitsuba", "drjit")]
    assert offenders == []


@pytest.mark.parametrize("source, forbidden", [
    ({"core"}, set(UPPER)),
    ({"render"}, {"config", "world_config", "run", "jobs", "experiments", "design", "studies", "cli", "plots",
                  "figures"}),
    ({"config", "world_config"}, {"run", "jobs", "experiments", "design", "studies", "cli", "plots", "figures"}),
    ({"run"}, {"config", "world_config", "jobs", "experiments", "design", "studies", "cli", "plots", "figures"}),
    ({"jobs"}, {"experiments", "design", "studies", "cli", "plots", "figures"}),
    ({"plots"}, {"experiments", "design", "studies", "cli", "render"}),
    ({"experiments", "design"}, {"studies", "cli"}),
    ({"studies"}, {"cli"}),
])
def test_lower_floors_never_import_upper_ones(source, forbidden):
    assert _offenders(source, forbidden) == []


#: What opens a store, takes a lock or writes an identity record: the run layer's business, never the solvers'.
STORE_OPENERS = frozenset({"ResultStore", "StoreSink", "DirLock", "lock_out_dir", "check_identity", "clear_store"})
#: What render/ may take from mincam_sim.store: content-addressed caches (no lock, no run identity).
RENDER_FROM_STORE = frozenset({"ContentCache"})


def _store_uses(name: str, path: Path) -> list[str]:
    """How module ``name`` reaches store-opening code: imports from mincam_sim.store beyond
    :data:`RENDER_FROM_STORE`, the store module itself, or any name of :data:`STORE_OPENERS`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(node.module or "", node.level, name, path.name == "__init__.py")
            for alias in node.names:
                if (target == "mincam_sim.store" and alias.name not in RENDER_FROM_STORE) or \
                        (target == "mincam_sim" and alias.name == "store"):
                    found.append(f"from {target} import {alias.name}")
        elif isinstance(node, ast.Import):
            found += [f"import {a.name}" for a in node.names if a.name.startswith("mincam_sim.store")]
        elif isinstance(node, ast.Name) and node.id in STORE_OPENERS:
            found.append(node.id)
        elif isinstance(node, ast.Attribute) and node.attr in STORE_OPENERS:
            found.append(f".{node.attr}")
    return found


def test_render_never_opens_a_store_or_takes_a_lock():
    """The solvers write rows to the sink they are given (``mincam_sim.frames``); from ``mincam_sim.store`` they
    take content caches only. (The deprecated ``out_dir=`` of the old entry points reaches a store through
    ``mincam_sim.frames.resolve_sink``, the one store-opening helper outside the run layer.)"""
    offenders = sorted(f"{name}: {use}" for name, path in MODULES.items() if _floor(name) == "render"
                       for use in _store_uses(name, path))
    assert offenders == []


def test_the_sink_protocol_loads_without_the_store():
    tree = ast.parse(MODULES["mincam_sim.frames"].read_text())
    top = {_resolve(n.module or "", n.level, "mincam_sim.frames", False) for n in tree.body
           if isinstance(n, ast.ImportFrom)}
    assert "mincam_sim.store" not in top and "mincam_sim.store" not in GRAPH["mincam_sim.frames"]


def test_nothing_inside_the_package_imports_its_facade():
    offenders = sorted(a for a, targets in GRAPH.items() if a != "mincam_sim" and "mincam_sim" in targets)
    assert offenders == []


def test_the_facade_imports_upper_floors_only_lazily():
    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    eager = [node for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))]
    names = {_resolve(n.module or "", n.level, "mincam_sim", True) for n in eager if isinstance(n, ast.ImportFrom)}
    assert all(_floor(n) == "core" for n in names), names


def test_no_import_cycles():
    internal = {a: {b for b in targets if b in MODULES and b != a} for a, targets in GRAPH.items()}
    # A package's __init__ only re-exports its modules; edges into it stand for its submodules.
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in internal[node]:
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, [*stack, nxt])
        state[node] = 2

    for module in sorted(internal):
        if module not in state:
            visit(module, [module])
    assert cycles == []


def test_pure_modules_import_without_a_renderer():
    code = (
        "import sys\n"
        "import mincam_sim.estimators, mincam_sim.calibration, mincam_sim.sensor, mincam_sim.masks\n"
        "import mincam_sim.optics, mincam_sim.scene.display, mincam_sim.objects, mincam_sim.config\n"
        "import mincam_sim.readout, mincam_sim.metrics, mincam_sim.forward_model, mincam_sim.plots\n"
        "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules, sorted(sys.modules)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


#: What modules outside ``render/`` may import from it: the front door, scene building, and named exceptions.
RENDER_DOOR = ("mincam_sim.render.simulation", "mincam_sim.render.solvers", "mincam_sim.render.scene_dicts",
               "mincam_sim.render.elements", "mincam_sim.render.scene_files", "mincam_sim.render.world_input",
               "mincam_sim.render.updates")
RENDER_ALLOWED = {
    # the variant in use and the set-up check: what the CLI, registry and runners print and record
    "mincam_sim.render.backend": "the Mitsuba variant is described and checked, nothing rendered",
    # the design floor optimises masks through Dr.Jit's automatic differentiation (a solver of gradients)
    "mincam_sim.render.differentiable": "the design floor's differentiable square scenes",
    "mincam_sim.render.autodiff": "the design floor's optimiser steps in Dr.Jit",
    # a parameter converted as the loaded scene holds it (a turned scene file in a world config)
    "mincam_sim.render.mincam_scene": "jobs.py turns a loaded scene file in place (to move into scene building)",
}


def test_outside_render_only_the_front_door_and_scene_building_are_imported():
    offenders = sorted(f"{a} -> {b}" for a, targets in GRAPH.items() if _floor(a) != "render"
                       for b in targets if b.startswith("mincam_sim.render.") and b != "mincam_sim.render"
                       and not b.startswith(RENDER_DOOR) and b not in RENDER_ALLOWED)
    assert offenders == []
