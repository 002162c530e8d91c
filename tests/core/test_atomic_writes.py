"""Every file the package writes goes through :mod:`mincam_sim.storage.atomic`: a full disk, an error or a kill
mid-write leaves the old file or none, never a torn one that a rerun would read (a reproduce on a full disk left
``intrusion_data.npz`` at 0 or 4,096 bytes)."""

from __future__ import annotations

import ast
from pathlib import Path

import mincam_sim

WRITERS = {"savefig", "savez", "savez_compressed", "save", "write_text", "write_bytes", "tofile", "to_csv",
           "write_png", "write_exr"}
#: the image writers themselves: they write the path they are given; their callers must give a temporary one
WRITER_MODULES = {"atomic.py", "imageio.py"}
#: ``with`` blocks whose writes are safe: the atomic helpers' temporary files, or a private temporary folder
SAFE_BLOCKS = {"atomic_path", "atomic_open", "TemporaryDirectory"}
PACKAGE = Path(mincam_sim.__file__).parent


def _call_name(node: ast.expr) -> str:
    func = node.func if isinstance(node, ast.Call) else node
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""


def _unsafe_writes(tree: ast.AST) -> list[int]:
    found: list[int] = []

    def visit(node: ast.AST, safe: bool) -> None:
        if isinstance(node, ast.With | ast.AsyncWith):
            safe = safe or any(isinstance(item.context_expr, ast.Call) and _call_name(item.context_expr) in SAFE_BLOCKS
                               for item in node.items)
        if isinstance(node, ast.Call) and _call_name(node) in WRITERS and not safe:
            found.append(node.lineno)
        for child in ast.iter_child_nodes(node):
            visit(child, safe)

    visit(tree, False)
    return found


def test_every_file_is_written_atomically():
    unsafe = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name in WRITER_MODULES:
            continue
        unsafe += [f"{path.relative_to(PACKAGE)}:{line}" for line in _unsafe_writes(ast.parse(path.read_text()))]
    assert not unsafe, f"writes outside mincam_sim.storage.atomic: {unsafe}"


def test_the_check_sees_a_plain_write():
    assert _unsafe_writes(ast.parse("import numpy as np\nnp.savez('a.npz', x=1)\nfig.savefig(p)")) == [2, 3]
    assert _unsafe_writes(ast.parse("with atomic_path(p) as tmp:\n    fig.savefig(tmp)")) == []
