"""Generate the documentation's reference fragments from the code, the schema and the benchmark JSON.

``python docs/gen_pages.py`` (also run by ``docs/conf.py`` at the start of every build) writes, under
``docs/generated/`` (git-ignored):

* ``validation_tables.md``: the physics-validation tables, from ``benchmarks/validation.json``;
* ``performance_tables.md``: the performance figures and the machine, from ``benchmarks/results.json``;
* ``cli_reference.md``: every ``mincam-sim`` command, its usage, arguments and options, from the Typer app;
* ``config_reference.md``: the render schema (``mincam_sim.configuration.config.EXAMPLE_TOML``), the reproduce set-up
and
  experiment parameters (their dataclasses, full and quick defaults), the world schema
  (``mincam_sim.configuration.world_config.world_example_toml()``), the study file
  (``mincam_sim.studies.spec.study_example_toml()``) and the study targets' parameters;
* ``reference_toc.md``: the reference section's table of contents (the changelog page only when the
  repository has a ``CHANGELOG.md``, so the site never carries an empty page).

Nothing here is typed in by hand: a number on those pages is the number in the JSON or the code.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Any

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
OUT = DOCS / "generated"


# ------------------------------------------------------------------------------------------------ helpers
def _write(name: str, text: str) -> Path:
    """Write ``text`` to ``generated/name`` only when it changed (Sphinx then rebuilds only what changed)."""
    OUT.mkdir(exist_ok=True)
    path = OUT / name
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")
    return path


def _table(header: list[str], rows: list[list[str]]) -> str:
    def clean(cell: str) -> str:
        return str(cell).replace("|", "\\|").replace("\n", " ")

    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(clean(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _g(value: float, digits: int = 6) -> str:
    """``value`` with ``digits`` significant digits, positional for ordinary magnitudes (no exponent)."""
    import numpy as np

    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if value == 0:
        return "0"
    if 1e-4 <= abs(value) < 1e6:
        return np.format_float_positional(value, precision=digits, fractional=False, unique=False, trim="k")
    return f"{value:.{max(digits - 1, 1)}e}"


def _pm(value: float, sigma: float, digits: int = 6) -> str:
    return f"{_g(value, digits)} ± {_g(sigma, 2)}"


def _pct(rel: float, digits: int = 2) -> str:
    """A relative deviation as a signed percentage with ``digits`` significant digits."""
    text = _g(100 * rel, digits)
    return f"{'+' if rel >= 0 else ''}{text} %"


# ------------------------------------------------------------------------------------------------ validation
FORMS = ("reference", "fast", "response_map")  # the keys of benchmarks/validation.json
SOLVER_OF_FORM = {"reference": "reference", "fast": "aperture", "aperture": "aperture", "response_map": "response_map"}

OPEN_APERTURE = {
    "open_aperture_on_axis": "open aperture, uniform screen L = 2 W m⁻² sr⁻¹, mixel on axis",
    "open_aperture_clipped": "same, mixel 0.3 m / 0.12 m off axis: the screen edge clips its view",
}
INVARIANTS = {
    "complementary_masks": ("P(x)+P(1-x)-P(1)_w_m2", "complementary masks: P(x) + P(1 − x) − P(1)", "P(1)_w_m2"),
    "scaled_mask": ("P(0.3x)-0.3P(x)_w_m2", "scaled mask: P(0.3 x) − 0.3 P(x)", None),
    "superposition": ("P(A+B)-P(A)-P(B)_w_m2", "superposition: P(A + B) − P(A) − P(B)", "P(A+B)_w_m2"),
}
ORACLE_ROWS = {
    "response_map_tilted_sinusoid30": "tilted mixel, screen rotated 25°, sinusoid at 30° (response map)",
    "response_map_tilted_ramp": "same geometry, ramp mask (response map)",
    "shadow_fast": "a second mixel's body hides part of the view (aperture solver)",
    "shadow_response_map": "same, response map",
    "shadow_reference": "same, reference solver",
    "speed_sinusoid_trough": "0.2 mm-period sinusoid, region at a trough of its projection (response map)",
}


def validation_tables(data: dict[str, Any]) -> str:
    """Markdown tables of ``benchmarks/validation.json`` (every entry; unknown ones in a generic table)."""
    used: set[str] = set()
    parts = []

    rows = []
    for key, label in OPEN_APERTURE.items():
        if key not in data:
            continue
        used.add(key)
        entry = data[key]
        for form in (*FORMS, "aperture"):
            if form in entry:
                e = entry[form]
                rows.append([label if form == FORMS[0] else "", f"`{SOLVER_OF_FORM[form]}`",
                             _pm(e["value_w_m2"], e["sigma_w_m2"]),
                             _g(entry["closed_form_w_m2"]), f"{e['deviation_sigma']:+.2f}",
                             _pct(e["relative_deviation"])])
    if rows:
        parts.append("## Open aperture against the closed form E = π L F\n\n"
                     "F is the view factor from each detector point to the part of the screen seen through the "
                     "aperture (Howell's catalogue, case B-3), averaged over the detector by Gauss-Legendre "
                     "quadrature (`mincam_sim.oracles.closed_forms.open_aperture_irradiance`).\n\n"
                     + _table(["check", "solver", "rendered [W/m²]", "closed form [W/m²]", "deviation [σ]",
                               "relative"], rows))

    rows = []
    for key, (value_key, label, scale_key) in INVARIANTS.items():
        if key not in data:
            continue
        used.add(key)
        e = data[key]
        z = e[value_key] / e["sigma_w_m2"] if e["sigma_w_m2"] > 0 else float("nan")
        scale = f"{_g(e[scale_key], 4)}" if scale_key else "-"
        rows.append([label, _pm(e[value_key], e["sigma_w_m2"], 3), f"{z:+.2f}", scale])
    if rows:
        parts.append("## Linearity invariants (expected 0)\n\n"
                     "A measurement is linear in the mask's transmission; these combinations of renders must "
                     "vanish within their Monte Carlo error.\n\n"
                     + _table(["invariant", "value [W/m²]", "value / σ", "scale of the terms [W/m²]"], rows))

    rows = []
    for key in sorted(k for k in data if k.startswith("depth_scaling_")):
        used.add(key)
        e = data[key]
        depth = key.removeprefix("depth_scaling_").replace("m", " m")
        rows.append([depth, _pm(e["fitted_omega_rad_per_m"], e["fit_sigma"]), _g(e["expected_omega_rad_per_m"]),
                     _pct(e["relative_deviation"])])
    if "fov_offset" in data:
        used.add("fov_offset")
    if rows:
        text = ("## Geometry: depth-scaled mask frequency and field-of-view offset\n\n"
                "A sinusoid of ω on the mask appears on a screen at depth d with frequency ω d_f / d (fitted to "
                "a vertical line swept across the screen).\n\n"
                + _table(["screen depth", "fitted ω [rad/m]", "expected ω d_f / d [rad/m]", "relative"], rows))
        if "fov_offset" in data:
            e = data["fov_offset"]
            text += (f"\nTwo mixels {_g(100 * e['baseline_m'], 3)} cm apart: their response curves are shifted "
                     f"by {_g(100 * e['centroid_shift_m'], 5)} cm (relative {_pct(e['relative_deviation'])}).\n")
        parts.append(text)

    coupled = data.get("coupled_geometry_and_shadows")
    if isinstance(coupled, dict):
        used.add("coupled_geometry_and_shadows")
        rows = []
        for key, e in coupled.items():
            if not isinstance(e, dict):
                continue
            label = ORACLE_ROWS.get(key, key.replace("_", " "))
            rows.append([label, _pm(e["value_w_m2"], e["sigma_w_m2"]), _g(e["oracle_w_m2"]),
                         f"{e['deviation_sigma']:+.2f}", _pct(e["relative_deviation"])])
        note = ""
        if "shadow_unshadowed_oracle_w_m2" in coupled:
            unshadowed = coupled["shadow_unshadowed_oracle_w_m2"]
            shadowed = coupled.get("shadow_fast", {}).get("oracle_w_m2")
            if shadowed:
                note = (f"\nWithout the other mixel's body the same view gives {_g(unshadowed)} W/m²: the body "
                        f"hides {100 * (1 - shadowed / unshadowed):.1f} % of it.\n")
        parts.append("## Tilted geometry, analytic masks and other mixels' shadows against independent "
                     "quadrature\n\n"
                     "Oracles: `mincam_sim.oracles.quadrature` (float64 Gauss-Legendre over the detector and the "
                     "visible screen polygon, masks read from their analytic profiles; exact polygon view factors, "
                     "Lambert's contour formula, for the shadows). They share no code with the renderer.\n\n"
                     + _table(["check", "rendered [W/m²]", "oracle [W/m²]", "deviation [σ]", "relative"], rows)
                     + note)

    rest = {k: v for k, v in data.items() if k not in used}
    if rest:
        rows = [[f"`{k}`", f"`{json.dumps(v, sort_keys=True)[:300]}`"] for k, v in rest.items()]
        parts.append("## Other entries\n\n" + _table(["entry", "values"], rows))
    return ("<!-- generated by docs/gen_pages.py from benchmarks/validation.json: do not edit -->\n\n"
            + "\n".join(parts))


# ------------------------------------------------------------------------------------------------ performance
def performance_tables(data: dict[str, Any]) -> str:
    """Markdown tables of ``benchmarks/results.json``: the headline figures, their goals, and the machine."""
    rows = []
    sweep = data.get("sweep", {})
    if sweep:
        rows.append(["`sweep_seconds`",
                     f"{sweep['positions']:,} square positions × {sweep['mixels']} mixels, every measurement "
                     f"≤ 0.1 % relative standard error, maps included",
                     f"**{sweep['sweep_seconds']:.2f} s** (worst {100 * sweep['worst_rel_stderr']:.3f} %, median "
                     f"{100 * sweep['median_rel_stderr']:.4f} %, {sweep['samples_per_texel']} samples per texel)",
                     f"≤ {sweep['goal_seconds']:g} s"])
    if "sweep_speedup_vs_bruteforce" in data:
        brute = data.get("bruteforce", {})
        rows.append(["`sweep_speedup_vs_bruteforce`",
                     "the same sweep at equal noise with the literal irradiance-meter scene (timed on "
                     f"{brute.get('subset_positions', '?')} positions, scaled by (σ / 0.1 %)²)",
                     f"**{data['sweep_speedup_vs_bruteforce']:.2g} ×**", "≥ 1,000 ×"])
    mo = data.get("moving_object", {})
    if mo:
        rows.append(["`moving_object_variance_reduction`",
                     "ΔP of a box on a table, 4 mixels: correlated against independent seeds, same samples",
                     f"**{mo['moving_object_variance_reduction']:.0f} ×**", "≥ 10 ×"])
        rows.append(["`frames_per_second`",
                     f"that scene, ΔP at ≤ 1 % relative error for all mixels, {mo.get('fps_estimator', '')} "
                     "estimator",
                     f"**{mo['frames_per_second']:.1f} frames/s** (worst {100 * mo['fps_worst_rel_stderr_dP']:.2f} %, "
                     f"{mo['fps_rays_per_mixel_per_frame'] / 1e3:.1f} k rays per mixel per frame); plain estimator "
                     f"{mo['plain_frames_per_second']:.2f} frames/s: {mo['fps_speedup_vs_plain_same_run']:.0f} ×",
                     "≥ 125, ≤ 12 k rays"])
        if "fps_traced_full_background_same_run" in mo:
            same = "the same numbers bit for bit" if mo.get("fps_frozen_paired_equals_traced_bit_for_bit") else \
                "NOT the same numbers"
            rows.append(["`fps_speedup_frozen_paired_vs_traced`",
                         "those runs traced per frame with full background passes, timed in the same run",
                         f"**{mo['fps_speedup_frozen_paired_vs_traced']:.2f} ×** ("
                         f"{mo['fps_traced_full_background_same_run']:.1f} frames/s traced, "
                         f"{mo['fps_traced_rays_per_mixel_per_frame'] / 1e3:.1f} k rays; background rays traced "
                         f"{100 * mo['fps_background_rays_share']:.0f} %; {same})", "report"])
        rows.append(["`fast_vs_plain_max_abs_z`",
                     f"stratified against plain on {mo['fast_vs_plain_comparisons']} values",
                     f"{mo['fast_vs_plain_max_abs_z']:.2f}", "≤ 4.5"])
    sp = data.get("sliding_plane", {})
    if sp:
        rows.append(["`sliding_plane.speedup_per_frame`",
                     f"the vehicle's road, {sp['rays_per_frame']:,} rays a frame: replayed (`PlaneReplay`) against "
                     "traced frame by frame, same seed, same run",
                     f"**{sp['speedup_per_frame']:.1f} ×** ({sp['traced_ms_per_frame']:.1f} → "
                     f"{sp['replayed_ms_per_frame']:.2f} ms a frame; built in {sp['replay_build_s']:.2f} s; largest "
                     f"relative difference {sp['max_rel_difference']:.1e})", "report"])
    rep = data.get("reproduce_all", {})
    if rep:
        frames = ", ".join(f"{v} {k}" for k, v in rep.get("frames_per_run", {}).items())
        rows.append(["`reproduce_all_seconds`", f"the paper's experiments in full mode ({frames} frames)",
                     f"{rep['reproduce_all_seconds']:.0f} s", "≤ 30 s"])
    for key, what in (("memory_sweep_1080p", "positions on a 1920 × 1080 display"),
                      ("memory_10k_frames", "frames at 256 × 144")):
        m = data.get(key)
        if m:
            rows.append([f"`{key}`", f"{m['frames']:,} {what} (the frame stack alone: "
                         f"{m.get('frame_stack_gib_if_held', m['frames'] * 256 * 144 * 8 / 2**30):.1f} GiB)",
                         f"**{m['peak_memory_mib'] / 1024:.2f} GiB** peak", f"≤ {m['goal_peak_gib']:g} GiB"])
    st = data.get("study_scaling", {})
    if st:
        rows.append(["`study_scaling`", f"the spacing study ({st['points']} points), 1 → 2 dask workers",
                     f"efficiency {st['scaling_efficiency_1_to_2_workers']:.2f} ({st['seconds_1_worker']:.1f} s → "
                     f"{st['seconds_2_workers']:.1f} s)", "report"])
    base = data.get("baseline", {})
    if base:
        ref, fast = base["reference"], base["fast"]
        rows.append(["baseline", f"a white square through a ramp mask, {ref['spp']:,} samples",
                     f"reference {ref['samples_per_s'] / 1e6:.1f} M samples/s at {100 * ref['rel_stderr']:.1f} % "
                     f"noise; fast {fast['samples_per_s'] / 1e6:.1f} M samples/s at {100 * fast['rel_stderr']:.1f} % "
                     f"({base['fast_over_reference_time_to_equal_noise']:.1f} × less time to equal noise)", "-"])
    text = ("<!-- generated by docs/gen_pages.py from benchmarks/results.json: do not edit -->\n\n"
            + _table(["figure", "what is measured", "value", "goal"], rows))

    machine = data.get("machine", {})
    if machine:
        text += ("\n**Machine of this run**: "
                 + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in machine.items()) + ".\n")
    goals = data.get("goals", {})
    if goals:
        text += "\n## The performance targets in this run\n\n" + _table(
            ["target", "measured", "met"],
            [[name, f"{g['value']:,}" if isinstance(g["value"], int) else _g(g["value"], 3),
              "yes" if g["met"] else "**no**"] for name, g in goals.items()])
    peaks = data.get("memory_peak_mib", {})
    if peaks:
        text += "\n## Peak memory of each benchmark (its own process)\n\n" + _table(
            ["benchmark", "peak RSS [MiB]", "wall time [s]", "1-min load before / after"],
            [[f"`{k}`", f"{v:.0f}", _g(data.get(k, {}).get("wall_seconds"), 3),
              " / ".join(f"{x:.2f}" for x in data.get(k, {}).get("load_average_1min", []))]
             for k, v in peaks.items()])
    return text


# ------------------------------------------------------------------------------------------------ CLI
def _help_text(path: list[str]) -> str:
    """What ``mincam-sim PATH --help`` prints (the Typer app's own help, 100 columns)."""
    import contextlib
    import io
    import os

    from mincam_sim.cli import main as cli_main

    buffer = io.StringIO()
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    try:
        with contextlib.redirect_stdout(buffer), contextlib.redirect_stderr(buffer):
            try:
                cli_main([*path, "--help"])
            except SystemExit as exit_:
                if exit_.code not in (0, None):
                    raise RuntimeError(f"mincam-sim {' '.join(path)} --help exited with {exit_.code}") from None
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return buffer.getvalue().rstrip()


def _commands(group: Any, path: list[str]) -> list[list[str]]:
    """Every command path under ``group`` (groups first, then their commands), in the app's order."""
    out = []
    for name, cmd in getattr(group, "commands", {}).items():
        if getattr(cmd, "hidden", False):
            continue
        out.append([*path, name])
        out.extend(_commands(cmd, [*path, name]))
    return out


def cli_reference() -> str:
    """Every command of ``mincam-sim``, with the help the Typer app prints for it."""
    import typer.main

    from mincam_sim.cli import app

    root = typer.main.get_command(app)
    parts = ["<!-- generated by docs/gen_pages.py from mincam_sim.cli.app: do not edit -->\n",
             "## `mincam-sim`\n\nGlobal options go before the command "
             "(`mincam-sim -v --variant llvm_ad_mono render ...`).\n\n```text\n" + _help_text([]) + "\n```\n"]
    for path in _commands(root, []):
        level = "#" * min(2 + len(path) - 1, 4)
        parts.append(f"{level} `mincam-sim {' '.join(path)}`\n\n```text\n{_help_text(path)}\n```\n")
    return "\n".join(parts)


# ------------------------------------------------------------------------------------------------ config
def _first_doc_line(doc: str | None) -> str:
    return (doc or "").strip().split("\n\n")[0].replace("\n", " ")


def _field_docs(cls: type) -> dict[str, str]:
    """``name -> description`` from a numpydoc ``Attributes`` section (the comments the example files show)."""
    from mincam_sim.configuration.schema import attribute_docs

    return attribute_docs(cls)


def _dataclass_table(full: Any, quick: Any) -> str:
    docs = _field_docs(type(full))
    rows = []
    for f in dataclasses.fields(full):
        a, b = getattr(full, f.name), getattr(quick, f.name)
        rows.append([f"`{f.name}`", f"`{a!r}`", "" if a == b else f"`{b!r}`", docs.get(f.name, "")])
    return _table(["key", "default", "`--quick`", "meaning"], rows)


def solver_table() -> str:
    """``[run] solver``: each name, its class, the files that take it (from mincam_sim.configuration.config.SOLVERS)."""
    from mincam_sim.configuration.config import SOLVERS, solvers_for

    rows = []
    for name, cls in SOLVERS.items():
        files = [kind for kind in ("display", "world") if name in solvers_for(kind)]
        rows.append([f"`{name}`", f"{{class}}`~mincam_sim.render.solvers.{cls.__name__}`",
                     ", ".join(files) or "Python only (`Simulation.measure`)",
                     " ".join(_first_doc_line(cls.__doc__).split()).split("; ")[0].split(". ")[0].rstrip(".") + "."])
    return ("## The solver: `[run] solver`\n\n"
            "Render and world files name the solver the same way: the Python class in snake case. The typed "
            "config holds the solver object (`cfg.run.solver`) and its {class}`~mincam_sim.budget.Budget` "
            "(`cfg.run.budget`), whose checks (e.g. `replicates` at most `samples_per_texel`) are the ones "
            "Python callers get. The keys of earlier releases are refused with the new one: `[run] form = "
            "\"fast\"` -> `[run] solver = \"aperture\"`, `form = \"response_map\"` / `\"reference\"` -> the "
            "same name, `[run] estimator = \"stratified\"` / `\"plain\"` -> `\"stratified_change\"` / "
            "`\"plain_change\"`.\n\n" + _table(["solver", "class", "files", "what it does"], rows)
            + "\nA render is refused before it starts when its estimated time exceeds the limit (4 h; "
            "`--time-limit-s` raises it; `--check` shows the estimate), for display and world files alike; a "
            "world file's keyframes are counted before any frame is made (at most 1,000,000 frames).\n")


def config_reference() -> str:
    """The render schema (EXAMPLE_TOML), the reproduce sections and the study experiments, from the code."""
    from mincam_sim.configuration.config import EXAMPLE_TOML
    from mincam_sim.configuration.world_config import world_example_toml
    from mincam_sim.experiments import REGISTRY, Setup
    from mincam_sim.studies import study_target, target_names
    from mincam_sim.studies.spec import study_example_toml

    text = ["<!-- generated by docs/gen_pages.py from mincam_sim.configuration.config, "
            "mincam_sim.configuration.world_config, mincam_sim.experiments and mincam_sim.studies: do not edit -->\n"]
    text.append(solver_table())
    text.append("## Render configuration (`mincam-sim render CONFIG.toml`)\n\n"
                "Every key with its default, as `mincam-sim config-example` prints it "
                "(`mincam_sim.configuration.config.EXAMPLE_TOML`):\n\n```toml\n" + EXAMPLE_TOML.rstrip() + "\n```\n")
    text.append("## Reproduce configuration (`mincam-sim reproduce --config FILE.toml`)\n\n"
                "A `[setup]` section (shared by every experiment) and one section per experiment; each key "
                "of a section is a field of its dataclass, validated like the render schema (unknown keys, "
                "wrong types and out-of-range values are one-line errors naming the field). The `--quick` "
                "column lists the values quick mode uses where they differ. `mincam-sim config-example "
                "--reproduce` writes the same as a file (`scenes/experiments/reproduce.toml`, below).\n\n"
                f"### `[setup]`: {_first_doc_line(Setup.__doc__)}\n\n" + _dataclass_table(Setup(), Setup(quick=True)))
    for name, experiment in REGISTRY.items():
        full, quick = experiment.params(False), experiment.params(True)
        doc = _first_doc_line(type(full).__doc__)
        text.append(f"### `[{name}]`: {doc}\n\n" + _dataclass_table(full, quick))
    from mincam_sim.cli import design_schema

    text.append("## Design configuration (`mincam-sim design tracking --config FILE.toml`)\n\n"
                "One `[tracking]` section of `mincam_sim.design.tracking.TrackingTask` fields, checked "
                "like the others; options on the command line win. Every key with its default:\n\n```toml\n"
                + design_schema().example(commented_keys=True).rstrip() + "\n```\n")
    text.append("## World render configuration (`mincam-sim render WORLD.toml`)\n\n"
                "A config with a `[world]` section renders a world scene (a Mitsuba XML file, meshes, lights "
                "and movers) instead of a display; every key with its default, as "
                "`mincam-sim config-example --world` prints it "
                "(`mincam_sim.configuration.world_config.world_example_toml()`). "
                "`scenes/world/room.toml` is the shipped example:\n\n```toml\n"
                + world_example_toml().rstrip() + "\n```\n")
    rows = []
    for name in (n for n in target_names() if n != "render"):  # render needs a config: described below
        exp = study_target({"name": name})
        params = ", ".join(f"`{k} = {v!r}`" for k, v in exp.parameters.items())
        rows.append([f"`{name}`", exp.description, params, ", ".join(f"`{m}`" for m in exp.metrics)])
    rows.append(["`render`", "a render config (`[study] config = \"file.toml\"`) per point",
                 "every numeric key of the config as `section.key` (`mincam.d_f_m`, `screen.distance_m`, ...)",
                 "per mixel: `<mixel>.mean_irradiance_w_m2`, `<mixel>.peak_irradiance_w_m2`"])
    text.append("## Study configuration (`mincam-sim study run STUDY.toml`)\n\n"
                "Sections `[study]`, `[fixed]`, one of `[grid]` / `[points]` / `[random]`, `[quick]` and "
                "`[metrics]`; every `[study]` key with its default, as `mincam-sim config-example --study` prints "
                "it (`mincam_sim.studies.spec.study_example_toml()`):\n\n```toml\n"
                + study_example_toml().rstrip() + "\n```\n\n"
                "The experiments a study can sweep, their parameters with defaults and the metrics they return "
                "(`mincam_sim.studies.study_target`):\n\n"
                + _table(["experiment", "what a point computes", "parameters (defaults)", "metrics"], rows))
    return "\n".join(text)


# ------------------------------------------------------------------------------------------------ toc
def reference_toc() -> str:
    """The reference section's toctree; the changelog only when the repository has a CHANGELOG.md."""
    entries = ["cli", "config", "api"]
    if (ROOT / "CHANGELOG.md").is_file():
        entries.append("changelog")
    return ("```{toctree}\n:maxdepth: 1\n:caption: Reference\n\n" + "\n".join(entries) + "\n```\n")


def main() -> list[Path]:
    """Write every generated fragment; return their paths."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    validation = json.loads((ROOT / "benchmarks" / "validation.json").read_text(encoding="utf-8"))
    results = json.loads((ROOT / "benchmarks" / "results.json").read_text(encoding="utf-8"))
    return [
        _write("validation_tables.md", validation_tables(validation)),
        _write("performance_tables.md", performance_tables(results)),
        _write("cli_reference.md", cli_reference()),
        _write("config_reference.md", config_reference()),
        _write("reference_toc.md", reference_toc()),
    ]


if __name__ == "__main__":
    for written in main():
        print(written)
