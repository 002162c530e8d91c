"""Architecture: the import graph of the package, read from the code (every import, module-level or local).

Floors, bottom to top, each a place in the tree: the pure core (``model``, ``masks``, ``scene``, ``estimation``,
``oracles``, ``storage``, ``wave`` and the typed results at the top: numpy physics, sensor, estimators,
calibration, masks, scene descriptions, stores, budgets) -> ``render`` (the only Mitsuba / Dr.Jit user: the
simulation and its solvers, which hand their rows to a sink of ``mincam_sim.frames`` and never open a store or
take a lock) -> ``configuration`` (typed configuration; it names the solver classes) -> ``runs.run`` (output
directories: lock, identity, stores, resume; the solvers never import it) -> ``runs.jobs`` (the config
services) -> ``experiments`` and ``design`` -> ``studies`` -> ``cli``. ``plotting.plots`` draws results and
sits beside the core; ``plotting.figures`` renders the README's figures. The package root is the public
facade: it exposes upper floors lazily and nothing inside the package imports it. Lower floors never import
upper ones, and no modules import each other in a loop.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "mincam_sim"
#: Each upper floor and the place in the tree that holds it (a subpackage, or one module of one).
FLOOR_OF = {
    "mincam_sim.render": "render",
    "mincam_sim.configuration": "config",
    "mincam_sim.runs.run": "run",
    "mincam_sim.runs.jobs": "jobs",
    "mincam_sim.experiments": "experiments",
    "mincam_sim.design": "design",
    "mincam_sim.studies": "studies",
    "mincam_sim.cli": "cli",
    "mincam_sim.plotting.plots": "plots",
    "mincam_sim.plotting.figures": "figures",
}
UPPER = tuple(FLOOR_OF.values())
#: The subpackages of the pure core (numpy, no renderer), and the modules at the package's top.
CORE_PACKAGES = ("model", "masks", "scene", "estimation", "oracles", "storage", "wave")
TOP_MODULES = ("__init__", "errors", "paper", "budget", "changes", "measurements", "frames", "progress", "interrupts",
               "llvm_path", "cli")


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
    if module == "mincam_sim":
        return "facade"
    for place, floor in FLOOR_OF.items():
        if module == place or module.startswith(place + "."):
            return floor
    return "core"


def _offenders(source_floors: set[str], forbidden: set[str]) -> list[str]:
    return sorted(f"{a} -> {b}" for a, targets in GRAPH.items() if _floor(a) in source_floors
                  for b in targets if b.startswith("mincam_sim.") and _floor(b) in forbidden)


def test_only_the_render_layer_imports_mitsuba_or_drjit():
    offenders = [f"{name} -> {t}" for name, targets in GRAPH.items() if _floor(name) != "render"
                 for t in targets if t.split(".")[0] in ("mitsuba", "drjit")]
    assert offenders == []


@pytest.mark.parametrize("source, forbidden", [
    ({"core"}, set(UPPER)),
    ({"render"}, {"config", "run", "jobs", "experiments", "design", "studies", "cli", "plots",
                  "figures"}),
    ({"config"}, {"run", "jobs", "experiments", "design", "studies", "cli", "plots", "figures"}),
    ({"run"}, {"config", "jobs", "experiments", "design", "studies", "cli", "plots", "figures"}),
    ({"jobs"}, {"experiments", "design", "studies", "cli", "plots", "figures"}),
    ({"plots"}, {"experiments", "design", "studies", "cli", "render"}),
    ({"experiments", "design"}, {"studies", "cli"}),
    ({"studies"}, {"cli"}),
])
def test_lower_floors_never_import_upper_ones(source, forbidden):
    assert _offenders(source, forbidden) == []


#: What opens a store, takes a lock or writes an identity record: the run layer's business, never the solvers'.
STORE_OPENERS = frozenset({"ResultStore", "StoreSink", "DirLock", "lock_out_dir", "check_identity", "clear_store"})
#: What render/ may take from mincam_sim.storage.store: content-addressed caches (no lock, no run identity).
RENDER_FROM_STORE = frozenset({"ContentCache"})


def _store_uses(name: str, path: Path) -> list[str]:
    """How module ``name`` reaches store-opening code: imports from mincam_sim.storage.store beyond
    :data:`RENDER_FROM_STORE`, the store module itself, or any name of :data:`STORE_OPENERS`."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(node.module or "", node.level, name, path.name == "__init__.py")
            for alias in node.names:
                if (target == "mincam_sim.storage.store" and alias.name not in RENDER_FROM_STORE) or \
                        (target == "mincam_sim" and alias.name == "store"):
                    found.append(f"from {target} import {alias.name}")
        elif isinstance(node, ast.Import):
            found += [f"import {a.name}" for a in node.names if a.name.startswith("mincam_sim.storage.store")]
        elif isinstance(node, ast.Name) and node.id in STORE_OPENERS:
            found.append(node.id)
        elif isinstance(node, ast.Attribute) and node.attr in STORE_OPENERS:
            found.append(f".{node.attr}")
    return found


def test_render_never_opens_a_store_or_takes_a_lock():
    """The solvers write rows to the sink they are given (``mincam_sim.frames``); from
    ``mincam_sim.storage.store`` they take content caches only: stores and locks are the run layer's."""
    offenders = sorted(f"{name}: {use}" for name, path in MODULES.items() if _floor(name) == "render"
                       for use in _store_uses(name, path))
    assert offenders == []


def test_the_sink_protocol_loads_without_the_store():
    tree = ast.parse(MODULES["mincam_sim.frames"].read_text())
    top = {_resolve(n.module or "", n.level, "mincam_sim.frames", False) for n in tree.body
           if isinstance(n, ast.ImportFrom)}
    assert "mincam_sim.storage.store" not in top and "mincam_sim.storage.store" not in GRAPH["mincam_sim.frames"]


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
        "import mincam_sim.estimation.estimators, mincam_sim.estimation.calibration, mincam_sim.model.sensor\n"
        "import mincam_sim.masks, mincam_sim.model.optics, mincam_sim.scene.display, mincam_sim.scene.objects\n"
        "import mincam_sim.configuration.config, mincam_sim.model.readout, mincam_sim.estimation.metrics\n"
        "import mincam_sim.model.forward_model, mincam_sim.plotting.plots, mincam_sim.oracles.quadrature\n"
        "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules, sorted(sys.modules)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_tree_shows_the_floors():
    """At most 12 modules at the package's top; every subpackage is a core floor or an upper floor's place, and
    says in its docstring which files it holds."""
    top = sorted(p.stem for p in PACKAGE.glob("*.py"))
    assert len(top) <= 12 and set(top) <= set(TOP_MODULES), top
    places = {place.split(".")[1] for place in FLOOR_OF}
    for sub in sorted(p for p in PACKAGE.iterdir() if (p / "__init__.py").exists()):
        assert sub.name in CORE_PACKAGES or sub.name in places, f"{sub.name}: neither a core floor nor an upper one"
        doc = ast.get_docstring(ast.parse((sub / "__init__.py").read_text())) or ""
        missing = [p.name for p in sorted(sub.glob("*.py")) if p.name != "__init__.py" and p.name not in doc]
        assert not missing, f"{sub.name}/__init__.py's docstring does not name {missing}"


#: What modules outside ``render/`` may import from it: the front door and scene building, and named exceptions.
RENDER_DOOR = ("mincam_sim.render.simulation", "mincam_sim.render.solvers", "mincam_sim.render.scene")
RENDER_ALLOWED = {
    # the variant in use and the set-up check: what the CLI, registry and runners print and record
    "mincam_sim.render.backend": "the Mitsuba variant is described and checked, nothing rendered",
    # the design floor optimises masks through Dr.Jit's automatic differentiation (a solver of gradients)
    "mincam_sim.render.gradients.differentiable": "the design floor's differentiable square scenes",
    "mincam_sim.render.gradients.autodiff": "the design floor's optimiser steps in Dr.Jit",
}


def test_outside_render_only_the_front_door_and_scene_building_are_imported():
    offenders = sorted(f"{a} -> {b}" for a, targets in GRAPH.items() if _floor(a) != "render"
                       for b in targets if b.startswith("mincam_sim.render.") and b != "mincam_sim.render"
                       and not b.startswith(RENDER_DOOR) and b not in RENDER_ALLOWED)
    assert offenders == []


def test_outside_render_nothing_calls_mitsuba_itself():
    """Upper floors reach Mitsuba only through the front door and scene building, never ``backend.mitsuba()``."""
    offenders = []
    for name, path in MODULES.items():
        if _floor(name) == "render":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Attribute) and node.attr in ("mitsuba", "drjit") and \
                    isinstance(node.value, ast.Name) and node.value.id == "backend":
                offenders.append(f"{name}: backend.{node.attr}")
    assert offenders == []


def test_hashing_and_toml_each_live_in_one_module():
    """Every content digest is made in ``storage/identity.py``; every TOML file is read in
    ``configuration/toml_files.py``."""
    def users(module: str) -> list[str]:
        return sorted(name for name, targets in GRAPH.items() if module in targets)

    assert users("hashlib") == ["mincam_sim.storage.identity"]
    assert users("tomllib") == ["mincam_sim.configuration.toml_files"]


def _parameter_count(func) -> int:
    import inspect

    try:
        params = inspect.signature(func).parameters
    except (TypeError, ValueError):
        return 0
    return len([p for p in params.values() if p.name not in ("self", "cls")
                and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)])


#: Exported types that users read but never build, whose constructor is a record of many fields.
RESULT_RECORDS = {"RunInfo": "what a change run did, built by the solver; a user reads its fields"}


def test_public_signatures_take_at_most_eight_parameters():
    """Every name the package exports (``mincam_sim.__all__``), and every public method of an exported class,
    takes at most 8 parameters: more options travel as one typed value (a Budget, an options dataclass)."""
    import inspect

    import mincam_sim as ms

    offenders = []
    for name in sorted(set(ms.__all__) - set(RESULT_RECORDS)):
        obj = getattr(ms, name)
        members = [(name, obj)]
        if inspect.isclass(obj):
            members = [(f"{name}.{m}", f) for m, f in vars(obj).items()
                       if (not m.startswith("_") or m == "__init__") and callable(f)]
            members.append((name, obj))
        offenders += [f"{qual}: {_parameter_count(f)}" for qual, f in members if _parameter_count(f) > 8]
    assert offenders == []
