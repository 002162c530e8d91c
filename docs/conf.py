"""Sphinx configuration of the mincam_sim documentation (built by ``make docs``: warnings are errors, nitpicky
cross references, offline: no intersphinx, no remote images)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS))

import gen_pages  # noqa: E402  (docs/gen_pages.py: pages generated from the code, the schema and the JSON)

gen_pages.main()

import mincam_sim  # noqa: E402

project = "mincam_sim"
author = "mincam_sim contributors"
copyright = "mincam_sim contributors"  # noqa: A001
release = mincam_sim.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
# generated/ holds fragments that pages include, not pages of their own.
exclude_patterns = ["_build", "build", "generated", "examples/*.txt", "examples/*.rst", "gallery/*.py"]
if not (ROOT / "CHANGELOG.md").is_file():  # the changelog page exists only where the repository has one
    exclude_patterns.append("changelog.md")
root_doc = "index"

# ---------------------------------------------------------------------------------------------- cross references
nitpicky = True
# External types that the offline build cannot resolve (no intersphinx: it would fetch inventories).
nitpick_ignore_regex = [
    (r"py:.*", r"(np|numpy|mi|mitsuba|dr|drjit|xr|xarray|dask|zarr|scipy|matplotlib|typer|click|trimesh|PIL)(\..*)?"),
    (r"py:.*", r"(pathlib|typing|collections|collections\.abc|dataclasses|os|io|enum|abc|contextlib|concurrent)\..*"),
    (r"py:class", r"(Path|Any|Callable|Iterator|Iterable|Sequence|Mapping|ArrayLike|NDArray|Literal|Self)"),
    (r"py:class", r"(float|int|str|bool|dict|list|tuple|object|bytes|None|complex|type|slice)"),
    (r"py:class", r"optional|array_like|array-like|callable|default.*|shape.*|sequence|iterable|mapping"),
    (r"py:class", r"(BaseException|Exception|ValueError|RuntimeError|OSError|UserWarning|Warning|TypeError)"),
]

# ---------------------------------------------------------------------------------------------- autodoc, numpydoc
autodoc_typehints = "none"          # the numpydoc sections carry the types and units
autodoc_member_order = "bysource"
autodoc_default_options: dict[str, object] = {}  # api.md says :members: where it wants them
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# ---------------------------------------------------------------------------------------------- MyST
# No dollarmath / mathjax: MathJax would be fetched from a CDN, and the site is read offline too.
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# ---------------------------------------------------------------------------------------------- gallery
# MINCAM_DOCS_GALLERY_PATTERN="plot_masks" builds one example (what to use while writing one).
sphinx_gallery_conf = {
    "examples_dirs": ["examples"],
    "gallery_dirs": ["gallery"],
    "filename_pattern": os.environ.get("MINCAM_DOCS_GALLERY_PATTERN", r"/plot_"),
    "ignore_pattern": r"__init__\.py|_helpers\.py",
    "abort_on_example_error": True,   # a failing example fails the build
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "min_reported_time": 1,
    "show_memory": False,
    "show_signature": False,
    "capture_repr": (),  # no stray reprs (a colorbar object) under the figures
    "write_computation_times": False,  # its page loads scripts from a CDN: the site stays offline
}

# ---------------------------------------------------------------------------------------------- HTML
html_theme = "furo"
html_title = f"mincam_sim {release}"
html_static_path: list[str] = []
html_show_sourcelink = False
pygments_style = "sphinx"


# ---------------------------------------------------------------------------------------------- viewcode back links
# viewcode links each object in a module's highlighted source back to ``<module>.<name>`` on the page that
# documents it, with ONE <module> per source file: the name under which the first object of that file was
# documented. An object of the same file documented under another name (a package that re-exports it, or the file
# itself) then gets a link to an anchor that does not exist. The first handler gives such an object that anchor too;
# the second reads every back link of the built source pages and warns (an error under -W) about any that is broken.
def _add_viewcode_anchors(app, doctree) -> None:
    from sphinx import addnodes
    from sphinx.ext.viewcode import _get_full_modname

    entries = getattr(app.env, "_viewcode_modules", {})
    taken = {i for node in doctree.findall() if hasattr(node, "get") for i in (node.get("ids") or [])}
    for sig in doctree.findall(addnodes.desc_signature):
        modname, fullname = sig.get("module"), sig.get("fullname")
        entry = entries.get(_get_full_modname(modname, fullname) or "") if modname and fullname else None
        if not entry or entry[3] == modname or fullname not in entry[2]:
            continue
        anchor = f"{entry[3]}.{fullname}"
        if anchor not in taken:
            sig["ids"].append(anchor)
            taken.add(anchor)


def _check_viewcode_back_links(app, exception) -> None:
    import re

    from sphinx.util import logging

    if exception is not None or app.builder.format != "html":
        return
    out = Path(app.outdir)
    ids: dict[Path, set[str]] = {}
    for page in sorted((out / "_modules").rglob("*.html")):
        for href in re.findall(r'class="viewcode-back" href="([^"]+)"', page.read_text(encoding="utf-8")):
            target, _, anchor = href.partition("#")
            path = (page.parent / target).resolve()
            if path not in ids:
                text = path.read_text(encoding="utf-8") if path.is_file() else ""
                ids[path] = set(re.findall(r'id="([^"]+)"', text))
            if anchor not in ids[path]:
                logging.getLogger(__name__).warning(f"broken link in the highlighted source "
                                                    f"{page.relative_to(out)}: {href}")


def setup(app) -> None:
    app.connect("doctree-read", _add_viewcode_anchors, priority=600)  # after viewcode's own (500)
    app.connect("build-finished", _check_viewcode_back_links)
