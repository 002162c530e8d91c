"""Every code block of the README and of the documentation pages runs as written, in order.

One mechanism for every page: the page's ```python blocks run in one namespace per page and its ```bash blocks
(``mincam-sim ...`` commands) in a shell, in the order the page shows them, in a fresh directory holding a copy of
the repository's ``scenes/`` (as a reader's checkout has it), with this checkout's ``mincam_sim`` first on the path.
A block that needs what an earlier block wrote finds it, as a reader does who follows the page.

A block is not run only when an HTML comment right above it says why (GitHub and the site both hide it):

* ``<!-- docs-test: skip: REASON -->``: never run here (``make test`` runs the suite itself, a cluster ...);
* ``<!-- docs-test: requires module NAME (HOW TO GET IT), command NAME (WHAT IT IS) -->``: run when the module
  imports and the command is on the PATH, else the page's test is skipped at its end, naming what is missing.

Other fences must name their language (``toml``, ``text``, ``{directive}`` ...): an unlabelled block is refused,
so that no shell command goes unrun by mistake. Pages that take more than 30 s are marked slow (:data:`SLOW`).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
RUN = ("python", "bash")
NOT_RUN = ("toml", "text", "console-output")  # shown only: a file's content, a formula, a tree

FENCE = re.compile(r"^(?P<fence>`{3,})(?P<info>[^`\n]*)\n(?P<body>.*?)^(?P=fence)[ \t]*$", re.M | re.S)
MARKER = re.compile(r"<!--\s*docs-test:\s*(?P<what>.*?)\s*-->", re.S)
REQUIREMENT = re.compile(r"(?P<kind>module|command)\s+(?P<name>[\w.-]+)(?:\s*\((?P<how>[^)]*)\))?")

#: Pages whose blocks take more than 30 s on 2 cores (seconds measured there): slow tests.
SLOW = {"studies.md": "five studies (one of 33 points x 2 replicates): 9.5 min on 2 cores shared at load ~11"}


@dataclass(frozen=True)
class Block:
    """One fenced block of a page: its language, code, line (1-based) and the docs-test marker above it."""

    language: str
    code: str
    line: int
    marker: str | None

    def where(self, page: Path, root: Path = ROOT) -> str:
        return f"{page.relative_to(root)}:{self.line} ({self.language})"


def blocks(page: Path) -> list[Block]:
    """The fenced blocks of ``page`` in order (MyST directives such as ```{image} included, language "{...}")."""
    text = page.read_text(encoding="utf-8")
    found = []
    for m in FENCE.finditer(text):
        before = text[:m.start()].rstrip().splitlines()
        last = before[-1].strip() if before else ""
        marker = MARKER.fullmatch(last)
        found.append(Block(m.group("info").strip().split(" ")[0] if m.group("info").strip() else "",
                           m.group("body"), text.count("\n", 0, m.start()) + 1,
                           marker.group("what") if marker else None))
    return found


def missing_requirements(marker: str) -> list[str]:
    """What a ``requires ...`` marker names that this machine lacks, each with how to get it."""
    missing = []
    for req in REQUIREMENT.finditer(marker.removeprefix("requires")):
        kind, name, how = req.group("kind"), req.group("name"), req.group("how")
        present = (importlib.util.find_spec(name) is not None if kind == "module" else shutil.which(name) is not None)
        if not present:
            missing.append(f"{kind} {name}" + (f" ({how})" if how else ""))
    return missing


def _shell_env(bin_dir: Path) -> dict[str, str]:
    """The environment of a bash block: ``mincam-sim`` is this checkout's command line, run by this Python."""
    shim = bin_dir / "mincam-sim"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m mincam_sim.cli "$@"\n')
    shim.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}", "PYTHONPATH": str(ROOT),
           "MPLBACKEND": "Agg", "COLUMNS": "200"}
    env.pop("MINCAM_DEBUG", None)
    return env


def run_page(page: Path, workdir: Path, root: Path = ROOT) -> tuple[list[str], list[str]]:
    """Run every block of ``page`` in order in ``workdir`` (with a copy of ``root/scenes``); return (what ran,
    what was not run and why).

    Raises
    ------
    AssertionError
        A block that failed (naming the page, the line and the error), an unlabelled block, or a marker without a
        reason.
    """
    shutil.copytree(root / "scenes", workdir / "scenes")
    bin_dir = workdir.parent / f"{workdir.name}_bin"
    bin_dir.mkdir()
    env = _shell_env(bin_dir)
    namespace: dict = {"__name__": "docs_page"}
    ran, not_run = [], []
    for block in blocks(page):
        where = block.where(page, root)
        assert block.language, f"{where}: a fenced block without a language; name it (bash, python, toml, text)"
        if block.language.startswith("{") or block.language in NOT_RUN:
            continue
        assert block.language in RUN, f"{where}: language {block.language!r}: use one of {RUN + NOT_RUN}"
        if block.marker is not None:
            if block.marker.startswith("skip:"):
                assert block.marker.removeprefix("skip:").strip(), f"{where}: 'docs-test: skip:' needs a reason"
                not_run.append(f"{where}: {block.marker}")
                continue
            assert block.marker.startswith("requires "), f"{where}: unknown docs-test marker {block.marker!r}"
            missing = missing_requirements(block.marker)
            if missing:
                not_run.append(f"{where}: needs {', '.join(missing)}")
                continue
        if block.language == "python":
            _run_python(block, where, namespace)
        else:
            _run_bash(block, where, workdir, env)
        ran.append(where)
    return ran, not_run


def _run_python(block: Block, where: str, namespace: dict) -> None:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a page shows what it warns; the blocks check what they expect
            exec(compile(block.code, where, "exec"), namespace)
    except Exception as err:  # noqa: BLE001 - name the block that failed
        pytest.fail(f"{where} raised {type(err).__name__}: {err}\n{block.code}")


def _run_bash(block: Block, where: str, workdir: Path, env: dict[str, str]) -> None:
    proc = subprocess.run(["bash", "-euo", "pipefail", "-c", block.code], cwd=workdir, env=env, capture_output=True,
                          text=True, check=False, timeout=900)
    assert proc.returncode == 0, f"{where} exited {proc.returncode}:\n{block.code}\nstderr:\n{proc.stderr[-3000:]}"


# ---------------------------------------------------------------------------------- what some pages print


def _readme_prints_the_sweep(out: str) -> None:
    lines = [line for line in out.splitlines() if line.startswith("square at")]
    assert len(lines) == 9 and all(line.count("W/m²") == 2 for line in lines), out


def _python_api_prints_its_refusals(out: str) -> None:
    # the errors block prints each refusal: three InputErrors and one ConfigError, each naming the fix
    assert out.count("InputError:") >= 4 and "ConfigError:" in out, out
    assert "'toy_car' has 'toy_car.vertex_positions'" in out, out


CHECKS: dict[str, Callable[[str], None]] = {"README.md": _readme_prints_the_sweep,
                                           "python_api.md": _python_api_prints_its_refusals}


def _page_param(page: Path):
    marks = [pytest.mark.slow] if page.name in SLOW else []
    return pytest.param(page, id=page.name, marks=marks)


@pytest.mark.parametrize("page", [_page_param(p) for p in PAGES])
def test_every_block_of_the_page_runs_in_order(page, tmp_path, capsys, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    workdir = tmp_path / "reader"
    workdir.mkdir()
    monkeypatch.chdir(workdir)
    monkeypatch.syspath_prepend(str(ROOT))
    ran, not_run = run_page(page, workdir)
    out = capsys.readouterr().out
    if page.name in CHECKS:
        CHECKS[page.name](out)
    missing = [n for n in not_run if ": needs " in n]
    if missing:
        pytest.skip(f"ran {len(ran)} block(s); not run: {'; '.join(missing)}")


def test_every_page_with_shell_commands_runs_them_or_says_why():
    """The README's and the pages' bash blocks all run or carry a reason; some pages have code that runs."""
    reasons, runnable = [], 0
    for page in PAGES:
        for block in blocks(page):
            if block.language == "bash" and block.marker is not None:
                reasons.append(block.marker)
            runnable += block.language in RUN and block.marker is None
    assert runnable >= 15 and all(r.startswith(("skip:", "requires ")) for r in reasons), reasons


def test_the_mechanism_refuses_unlabelled_blocks_and_reasonless_skips(tmp_path):
    (tmp_path / "scenes").mkdir()
    page = tmp_path / "page.md"

    def run(text: str, name: str):
        page.write_text(text)
        (tmp_path / name).mkdir()
        return run_page(page, tmp_path / name, root=tmp_path)

    with pytest.raises(AssertionError, match="without a language"):
        run("text\n\n```\nmincam-sim render x.toml\n```\n", "a")
    with pytest.raises(AssertionError, match="needs a reason"):
        run("<!-- docs-test: skip: -->\n```bash\nfalse\n```\n", "b")
    ran, not_run = run("<!-- docs-test: requires module no_such_module_xyz (pip install it) -->\n```python\nimport "
                       "no_such_module_xyz\n```\n\n```bash\ntest -d scenes\n```\n", "c")
    assert ran == ["page.md:6 (bash)"]
    assert not_run == ["page.md:2 (python): needs module no_such_module_xyz (pip install it)"]
    with pytest.raises(AssertionError, match="exited 3"):
        run("```bash\nexit 3\n```\n", "d")
    with pytest.raises(pytest.fail.Exception, match="page.md:1 \\(python\\) raised NameError"):
        run("```python\nx = y\n```\n", "e")


def _resolves(dotted: str) -> bool:
    """``mincam_sim.a.b.C`` names a module, or an attribute of the longest module prefix that imports."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        try:
            for part in parts[k:]:
                obj = getattr(obj, part)
        except AttributeError:
            return False
        return True
    return False


def test_every_module_path_named_in_the_docs_exists():
    """A package that moves leaves no stale ``mincam_sim.x`` behind in the README, the pages or the examples (the
    docstrings' cross references are checked by the nitpicky docs build)."""
    named: dict[str, str] = {}
    for path in [*PAGES, *sorted((ROOT / "docs" / "examples").glob("*.py"))]:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            for m in re.finditer(r"(?<![\w/.])mincam_sim(?:\.[A-Za-z_]\w*)+", line):
                named.setdefault(m.group(0), f"{path.relative_to(ROOT)}:{number}")
    assert len(named) > 50
    stale = {name: where for name, where in named.items() if not _resolves(name)}
    assert not stale, f"names that do not exist: {stale}"
