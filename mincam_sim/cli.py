"""Command line: ``mincam-sim render CONFIG.toml``, ``mincam-sim masks ...``, ``mincam-sim demo`` ..."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

app = typer.Typer(add_completion=False, no_args_is_help=True, help=__doc__)
masks_app = typer.Typer(no_args_is_help=True, help="Generate the mask library or export print-ready masks.")
app.add_typer(masks_app, name="masks")

_state = {"verbose": False}


@app.callback()
def _global(
    variant: Annotated[str | None, typer.Option(help="Mitsuba variant: cuda_ad_mono, llvm_ad_mono or scalar_rgb "
                                                     "(default: automatic; env MINCAM_VARIANT)")] = None,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="print the variant and progress bars")] = False,
) -> None:
    from .render import backend

    backend.request_variant(variant)
    _state["verbose"] = verbose


def _say(msg: str) -> None:
    typer.echo(msg, err=True)


def _announce_variant() -> None:
    if _state["verbose"]:
        from .render import backend

        _say(f"mincam-sim: Mitsuba variant {backend.variant()} ({backend.describe()['mitsuba']})")


def _fail(err: Exception) -> None:
    typer.echo(f"error: {err}", err=True)
    raise typer.Exit(2)


def run_render_config(cfg, show_progress: bool = False):
    """Render a validated :class:`~mincam_sim.config.RenderConfig`; write outputs; return (measurements, maps)."""
    from .render.screen_engine import render_frames

    out = cfg.run.out_dir
    m, maps = render_frames(
        cfg.mincam, cfg.screen, cfg.frames, cfg.run.form, cfg.run.spp, cfg.run.samples_per_texel,
        cfg.run.target_rel_stderr, cfg.run.seed, cfg.run.replicates, out_dir=out / "run", show_progress=show_progress,
    )
    m.meta["config"] = cfg.raw
    if cfg.frame_positions_m is not None:
        m.meta["frame_positions_m"] = cfg.frame_positions_m.tolist()
    m.save_npz(out / "measurements.npz")
    m.save_csv(out / "measurements.csv")
    if maps is not None:
        maps.save_exr(out / "response_maps")
    return m, maps


@app.command()
def render(
    config: Annotated[Path, typer.Argument(help="TOML configuration (see `mincam-sim config-example`)")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="override [run] out_dir")] = None,
) -> None:
    """Render the measurements a config describes; write measurements.npz/.csv (+ response maps as EXR)."""
    from .config import ConfigError, load_config
    from .render import backend

    try:
        cfg = load_config(config)
        if cfg.run.variant:
            backend.request_variant(cfg.run.variant)
        if out_dir is not None:
            cfg.run.out_dir = out_dir
        _announce_variant()
        m, _ = run_render_config(cfg, show_progress=_state["verbose"])
    except (ConfigError, ValueError, FileNotFoundError) as err:
        _fail(err)
    np.set_printoptions(precision=6, suppress=False, linewidth=120)
    typer.echo(f"# {m.n_frames} frames x {len(m.mixel_names)} mixels, irradiance [W/m^2] +/- stderr, "
               f"variant {m.meta.get('variant')}, worst relative stderr {m.meta['reached_rel_stderr']:.2e}")
    typer.echo("frame  " + "  ".join(f"{n:>24}" for n in m.mixel_names))
    for i in range(m.n_frames):
        cells = "  ".join(f"{v:12.5e} +/- {e:8.1e}" for v, e in zip(m.irradiance_w_m2[i], m.stderr_w_m2[i],
                                                                     strict=True))
        typer.echo(f"{i:5d}  {cells}")
    typer.echo(f"# written to {cfg.run.out_dir}")


@app.command("config-example")
def config_example() -> None:
    """Print the documented TOML schema with every default."""
    from .config import EXAMPLE_TOML

    typer.echo(EXAMPLE_TOML)


@masks_app.command("generate")
def masks_generate(
    out_dir: Annotated[Path, typer.Option("--out", help="directory for the EXR files and previews")] = Path("masks"),
    resolution: Annotated[int, typer.Option(help="texels per side")] = 256,
    size_m: Annotated[float, typer.Option(help="mask side [m]")] = 2e-3,
) -> None:
    """Write the standard mask library (ramps, constant, sinusoid, circular ramp) as OpenEXR + PNG previews."""
    from .masks import generate_library

    try:
        paths = generate_library(out_dir, resolution=resolution, size_m=size_m)
    except ValueError as err:
        _fail(err)
    for p in paths:
        typer.echo(str(p))


@masks_app.command("export")
def masks_export(
    spec: Annotated[str, typer.Argument(help="'ramp:x', 'constant:0.5', 'file:path.png' ...")],
    out: Annotated[Path, typer.Option("--out", help="PNG to send to the printer")],
    size_m: Annotated[float, typer.Option(help="physical mask side [m]")] = 2e-3,
    dpi: Annotated[int, typer.Option(help="printer resolution [dots per inch]")] = 600,
    levels: Annotated[int, typer.Option(help="grey levels the printer reproduces per dot")] = 256,
    halftone: Annotated[bool, typer.Option(help="print with an ordered (Bayer) halftone")] = False,
    film_t_min: Annotated[float, typer.Option(help="transmission of fully inked film")] = 0.02,
    film_t_max: Annotated[float, typer.Option(help="transmission of clear film")] = 0.9,
    preview: Annotated[Path | None, typer.Option(help="also write what the film will transmit (OpenEXR)")] = None,
) -> None:
    """Export a mask as a print-ready PNG at DPI and physical size; optionally preview the printed film."""
    from .config import ConfigError, parse_mask
    from .masks import PrintedFilm, export_print_png, save_exr

    try:
        mask = parse_mask(spec, size_m, 512, "mask")
        film = PrintedFilm(t_min=film_t_min, t_max=film_t_max, dpi=dpi, levels=levels,
                           halftone="ordered" if halftone else None)
        path = export_print_png(mask, out, dpi=dpi, film=film)
        if preview is not None:
            printed = film.print(mask)
            save_exr(printed, preview)
            typer.echo(f"{preview}: printed film transmits {printed.transmission.min():.3f}.."
                       f"{printed.transmission.max():.3f} on a {printed.shape[1]}x{printed.shape[0]} dot grid")
    except (ConfigError, ValueError, OSError) as err:
        _fail(err)
    typer.echo(str(path))


def _render_demo(out_dir: Path) -> None:
    from .config import load_config
    from .plots import plot_response_maps, plot_sweep

    cfg = load_config({"run": {"out_dir": str(out_dir), "target_rel_stderr": 1e-3}})
    m, maps = run_render_config(cfg, show_progress=_state["verbose"])
    plot_sweep(np.asarray(cfg.frame_positions_m)[:, 0], m, out_dir / "sweep.png")
    if maps is not None:
        plot_response_maps(maps, cfg.screen, out_dir / "response_maps.png")
    typer.echo(f"render: {m.n_frames} sweep positions x {len(m.mixel_names)} mixels (variant {m.meta.get('variant')}, "
               f"worst relative stderr {m.meta['reached_rel_stderr']:.1e}) -> {out_dir}")


def _print_table(results: dict) -> None:
    typer.echo("experiment   simulated max / avg error [%]   paper max / avg error [%]   n")
    for name in ("intrusion", "tracking", "speed"):
        if name in results:
            r = results[name]
            p = r["paper"]
            typer.echo(f"{name:<12} {r['max_error_pct']:>10.2f} / {r['avg_error_pct']:<10.2f}        "
                       f"{p['max_error_pct']:>8.2f} / {p['avg_error_pct']:<8.2f}        {r['n']}")
    if "speed" in results and "vehicle" in results["speed"]:
        v = results["speed"]["vehicle"]
        typer.echo(f"{'(vehicle)':<12} {v['max_error_pct']:>10.2f} / {v['avg_error_pct']:<10.2f}        "
                   f"{'-':>8} / {'-':<8}        {v['n']}")


@app.command()
def reproduce(
    experiment: Annotated[str, typer.Argument(help="intrusion, tracking, speed or all")] = "all",
    out_dir: Annotated[Path, typer.Option("--out", help="output folder (results.json + plots)")] = Path("out/repro"),
    quick: Annotated[bool, typer.Option("--quick", help="fewer frames and samples (minutes)")] = False,
    seed: Annotated[int, typer.Option(help="seed of every random choice")] = 0,
    spacing_m: Annotated[float, typer.Option(help="mixel spacing [m] (paper: 0.033)")] = 0.033,
    depth_m: Annotated[float, typer.Option(help="mincam to table/screen distance [m]")] = 0.5,
    bit_depth: Annotated[int, typer.Option(help="ADC bits (paper: 12)")] = 12,
) -> None:
    """Reproduce the paper's experiments in simulation; print the error table beside the paper's."""
    from .experiments import EXPERIMENTS, Setup
    from .experiments import reproduce as run

    names = list(EXPERIMENTS) if experiment == "all" else [experiment]
    try:
        setup = Setup(quick=quick, seed=seed, spacing_m=spacing_m, depth_m=depth_m, bit_depth=bit_depth)
        _announce_variant()
        results = run(names, setup, out_dir, show_progress=_state["verbose"])
    except ValueError as err:
        _fail(err)
    _print_table(results)
    typer.echo(f"# results.json and plots in {out_dir}")


@app.command()
def study(
    what: Annotated[str, typer.Argument(help="spacing")] = "spacing",
    out_dir: Annotated[Path, typer.Option("--out", help="output folder")] = Path("out/study"),
    quick: Annotated[bool, typer.Option("--quick", help="fewer spacings and depths")] = False,
) -> None:
    """Studies: `spacing` = intrusion error against mixel spacing (0-10 cm) and depth, before/after calibration."""
    from .experiments import Setup
    from .experiments import spacing as spacing_study

    if what != "spacing":
        _fail(ValueError(f"unknown study {what!r}: the available study is 'spacing'"))
    _announce_variant()
    result = spacing_study.run(Setup(quick=quick), out_dir, show_progress=_state["verbose"])
    typer.echo("spacing [cm]  " + "  ".join(f"{100 * s:6.1f}" for s in result["spacing_m"]))
    for depth, rows in result["by_depth"].items():
        typer.echo(f"d={depth} m avg error before [%] " + " ".join(f"{v:6.2f}" for v in rows["avg_before_pct"]))
        typer.echo(f"d={depth} m avg error after  [%] " + " ".join(f"{v:6.2f}" for v in rows["avg_after_pct"]))
    typer.echo(f"# spacing_study.json and spacing_study.png in {out_dir}")


@app.command()
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="output directory")] = Path("out/demo"),
) -> None:
    """Built-in default job: a 2-mixel (x | 1-x) mincam 0.5 m from a 50" screen with a white square swept along
    the boundary (measurements, response maps as EXR, plots), then `reproduce all --quick` and the spacing study."""
    from .experiments import EXPERIMENTS, Setup
    from .experiments import reproduce as run
    from .experiments import spacing as spacing_study

    _announce_variant()
    _render_demo(out_dir / "render")
    results = run(list(EXPERIMENTS), Setup(quick=True), out_dir / "repro", show_progress=_state["verbose"])
    _print_table(results)
    spacing_study.run(Setup(quick=True), out_dir / "study")
    typer.echo(f"demo: wrote {out_dir}/render, {out_dir}/repro (results.json, plots), {out_dir}/study")


@app.command()
def figures(
    out_dir: Annotated[Path, typer.Option("--out", help="output folder")] = Path("scenes/figures"),
) -> None:
    """Write the README's figures (mixel geometry, masks, response maps)."""
    from .figures import make_figures

    for path in make_figures(out_dir):
        typer.echo(str(path))


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point."""
    app(args=argv if argv is not None else sys.argv[1:], prog_name="mincam-sim")


if __name__ == "__main__":
    main()
