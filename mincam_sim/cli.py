"""Command line: ``mincam-sim render CONFIG.toml``, ``mincam-sim masks ...``, ``mincam-sim demo`` ...

Every user error (config, option, file, output location, a backend this machine lacks) is one line
``error: ...`` on stderr with exit code 2, caught in one place (:class:`_MincamGroup`); ``--debug`` (or
``MINCAM_DEBUG=1``) shows the traceback instead. Warnings are one line ``warning: ...`` each. Progress bars go
to stderr unless ``--quiet`` (periodic lines when stderr is not a terminal).
"""

from __future__ import annotations

import os
import re
import signal
import sys
import traceback
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from typer.core import TyperGroup

from mincam_sim import interrupts, paper
from mincam_sim.configuration.config import EXAMPLE_TOML, load_config, parse_mask
from mincam_sim.errors import BackendUnavailableError, ConfigError, InputError, MincamError
from mincam_sim.masks import PrintedFilm, export_print_png, generate_library, save_exr
from mincam_sim.storage.store import lock_out_dir

try:  # typer >= 0.2x vendors click
    from typer._click.exceptions import BadParameter, ClickException
except ImportError:  # pragma: no cover - older typer on the real click
    from click.exceptions import BadParameter, ClickException

ENV_DEBUG = "MINCAM_DEBUG"
_PACKAGE_DIR = Path(__file__).resolve().parent
_BACKEND_FILE = _PACKAGE_DIR / "render" / "backend.py"

_state: dict[str, Any] = {"verbose": False, "quiet": False, "debug": False, "variant": None, "invoked": False,
                          "command": None}


# ------------------------------------------------------------------------------------------- error handling


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _is_backend_error(err: BaseException) -> bool:
    """True if ``err`` was raised by mincam_sim.render.backend (a variant that cannot be loaded)."""
    innermost = None
    for frame, _ in traceback.walk_tb(err.__traceback__):
        filename = Path(frame.f_code.co_filename).resolve()
        if _PACKAGE_DIR in filename.parents:
            innermost = filename
    return innermost == _BACKEND_FILE


def _is_user_error(err: BaseException) -> bool:
    """The project's own errors, and what the machine refuses (a full disk, a missing permission, memory): one
    line. Anything else (a ValueError or KeyError from inside the package) is a bug and shows its traceback."""
    if isinstance(err, MincamError | MemoryError):
        return True
    if isinstance(err, OSError) and err.errno is not None:
        return True
    return isinstance(err, RuntimeError | ImportError) and _is_backend_error(err)


def user_error_message(err: BaseException) -> str:
    """The one-line message shown for a user error (without the ``error: `` prefix)."""
    if isinstance(err, MemoryError):
        return "out of memory; use fewer frames, a lower resolution or fewer samples"
    if isinstance(err, EOFError):
        return f"unexpected end of file ({err or 'no data left'}); the file is empty or truncated"
    if isinstance(err, OSError) and not isinstance(err, MincamError) and err.strerror:
        import errno

        target = f": {err.filename}" if err.filename else ""
        other = f" -> {err.filename2}" if getattr(err, "filename2", None) else ""
        fix = ""
        if err.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
            fix = " (nothing half-written is left there); free some space or choose another output location"
        elif err.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            fix = "; choose an output location you can write to"
        return _one_line(f"{err.strerror}{target}{other}{fix}")
    text = _one_line(str(err))
    if not text:
        text = type(err).__name__
    if isinstance(err, MincamError | ValueError):
        return text
    return f"{text} ({type(err).__name__})"


def _show_warning(message: Any, category: type[Warning], filename: str, lineno: int, file: Any = None,
                  line: str | None = None) -> None:
    """A warning as one line ``warning: <message> (<Category>)`` on stderr, without the source line."""
    stream = sys.stderr if file is None else file
    try:
        stream.write(f"warning: {_one_line(str(message))} ({category.__name__})\n")
    except (OSError, ValueError):  # a closed stream: nothing to tell
        pass


# library warnings that say nothing about the user's run
QUIET_WARNINGS = (
    r"Port \d+ is already in use",  # dask's dashboard moved to another port: no dashboard is used
)


def install_warning_format() -> None:
    """Print warnings as one line each (:func:`_show_warning`) and drop the :data:`QUIET_WARNINGS`."""
    import warnings

    warnings.showwarning = _show_warning
    for pattern in QUIET_WARNINGS:
        warnings.filterwarnings("ignore", message=pattern)


def _fail_line(message: str, code: int = 2) -> typer.Exit:
    typer.echo(f"error: {_one_line(message)}", err=True)
    return typer.Exit(code)


class _CarriedBug(Exception):
    """A bug's error carried past click's ``main``, which would answer an ``EOFError`` with "aborted" (meant for an
    input prompt at the end of stdin; no command here prompts) and drop its traceback; raised again as it was."""

    def __init__(self, error: BaseException) -> None:
        super().__init__(repr(error))
        self.error = error


def _is_path_parameter(param: Any) -> bool:
    """True if the command-line parameter ``param`` takes a file or folder path."""
    descriptor = getattr(param, "type_descriptor", None)
    if descriptor is not None:
        return bool(getattr(descriptor, "is_path", False))
    return type(getattr(param, "type", None)).__name__ == "Path"  # pragma: no cover - older typer on click


def _refuse_empty_paths(command: Any) -> None:
    """Make every path option and argument of ``command`` (and of its subcommands) refuse an empty value: the
    command line's own parsing would take ``--out ""`` for ``.``, the working directory. The refusal is one
    usage error naming the parameter (exit code 2)."""
    for sub in getattr(command, "commands", {}).values():
        _refuse_empty_paths(sub)
    for param in getattr(command, "params", ()):
        if not _is_path_parameter(param) or getattr(param, "_refuses_empty", False):
            continue
        original = param.process_value

        def process_value(ctx: Any, value: Any, _original: Any = original, _param: Any = param) -> Any:
            if isinstance(value, str) and not value.strip():
                raise BadParameter(f"{value!r} is {'an empty' if not value else 'a blank'} path; give a file or "
                                   "folder name (the working directory is '.')", ctx=ctx, param=_param)
            return _original(ctx, value)

        param.process_value = process_value
        param._refuses_empty = True


class _MincamGroup(TyperGroup):
    """Top-level command group: turns user errors into one line on stderr and exit code 2, in one place."""

    def invoke(self, ctx: Any) -> Any:
        try:
            return super().invoke(ctx)
        except typer.Exit:
            raise
        except BaseException as err:
            if interrupts.arrived() and not isinstance(err, KeyboardInterrupt | SystemExit) and not _state["debug"]:
                # a Ctrl-C that landed in an import can come out as another error (a module left half-imported)
                raise KeyboardInterrupt from None
            if isinstance(err, KeyboardInterrupt):  # a folder made for a run stopped before it wrote anything
                _remove_created_if_empty()
            if isinstance(err, KeyboardInterrupt | SystemExit) or _state["debug"] or not _is_user_error(err):
                if isinstance(err, EOFError):  # a reader that let a file's end through: a bug, with its traceback
                    raise _CarriedBug(err) from None
                raise
            _remove_created_if_empty()
            raise _fail_line(user_error_message(err)) from None

    def main(self, args: Any = None, prog_name: Any = None, complete_var: Any = None,
             standalone_mode: bool = True, **extra: Any) -> Any:
        _created.clear()
        _refuse_empty_paths(self)
        _state.update(verbose=False, quiet=False, debug=os.environ.get(ENV_DEBUG, "") not in ("", "0"),
                      variant=None, invoked=False, command=None)
        install_warning_format()
        interrupts.reset()
        recording = signal.getsignal(signal.SIGINT) is signal.default_int_handler
        if recording:  # SIGINT left as Python's (not ignored, not the caller's own handler): counted as well
            signal.signal(signal.SIGINT, interrupts.recording_handler)
        bug: BaseException | None = None
        try:
            rv = super().main(args=args, prog_name=prog_name, complete_var=complete_var, standalone_mode=False,
                              **extra)
            code = rv if isinstance(rv, int) else 0
        except _CarriedBug as carried:
            bug = carried.error
        except ClickException as err:
            ctx = getattr(err, "ctx", None)
            if type(err).__name__ == "NoArgsIsHelpError":  # a bare command group: its help, as usual
                typer.echo(ctx.get_help() if ctx is not None else err.format_message(), err=True)
                code = 0
            else:
                hint = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
                typer.echo(f"error: {_one_line(err.format_message())}{hint}", err=True)
                code = err.exit_code
        except typer.Abort:
            typer.echo("error: aborted", err=True)
            code = 1
        finally:
            if recording:
                signal.signal(signal.SIGINT, signal.default_int_handler)
        if bug is not None:
            raise bug  # outside the handler: its traceback and its own cause as they were
        if code == 130 and not _state["invoked"]:  # Ctrl-C before a command began (:func:`_marked_started`)
            typer.echo(INTERRUPTED_WHILE_STARTING, err=True)
        elif code == 130 and _state.get("command") in RESTARTING_COMMANDS:
            typer.echo(INTERRUPTED_RESTARTS, err=True)
        elif code == 130:  # Ctrl-C (typer turns KeyboardInterrupt into exit code 130)
            typer.echo("error: interrupted; results written so far are kept, and the same command resumes", err=True)
        if standalone_mode:
            sys.exit(code)
        return code


HELP = ("Simulate minimalist cameras (mixels: photodetectors behind grayscale masks) with Mitsuba 3. Errors are one "
        "line on stderr with exit code 2 (--debug shows the traceback); progress bars go to stderr (--quiet "
        "silences them).")

# rich_markup_mode=None: plain help, so units such as [m] in option help are shown, not taken for markup.
app = typer.Typer(cls=_MincamGroup, add_completion=False, no_args_is_help=True, help=HELP, rich_markup_mode=None,
                  pretty_exceptions_show_locals=False)
masks_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None,
                        help="Generate the mask library or export print-ready masks.")
app.add_typer(masks_app, name="masks")
study_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None,
                        help="Parameter studies: `run STUDY.toml` on dask (xarray/Zarr results).")
app.add_typer(study_app, name="study")


@app.callback()
def _global(
    variant: Annotated[str | None, typer.Option(help="Mitsuba variant: cuda_ad_mono, llvm_ad_mono or scalar_rgb "
                                                     "(default: automatic; env MINCAM_VARIANT)")] = None,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="print the Mitsuba variant in use")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="no progress bars on stderr")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="show the traceback of an error (env MINCAM_DEBUG=1)")]
    = False,
) -> None:
    from mincam_sim import progress
    from mincam_sim.render import backend

    _state.update(verbose=verbose, quiet=quiet, debug=debug or _state["debug"], variant=variant)
    progress.set_enabled(not quiet)
    if variant is not None and variant not in backend.SUPPORTED_VARIANTS:
        raise ConfigError(f"--variant {variant!r} is not a Mitsuba variant mincam_sim supports: choose one of "
                          f"{', '.join(backend.SUPPORTED_VARIANTS)}")
    backend.request_variant(variant)


@contextmanager
def _warnings_once_valid() -> Iterator[None]:
    """Hold the warnings raised while a config is read and checked; show them once it passes. A refused config
    shows its one ``error:`` line alone (its warnings come back when it is fixed)."""
    import warnings

    with warnings.catch_warnings(record=True) as held:
        yield
    for w in held:
        warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _ignored(message: str) -> None:
    """One warning line for an option that does not apply (:class:`IgnoredSettingWarning`)."""
    import warnings

    from mincam_sim.configuration.schema import IgnoredSettingWarning

    warnings.warn(message, IgnoredSettingWarning, stacklevel=2)


def _say(msg: str) -> None:
    typer.echo(msg, err=True)


def _show_progress() -> bool:
    return not _state["quiet"]


def _announce_variant() -> None:
    if _state["verbose"]:
        from mincam_sim.render import backend

        _say(f"mincam-sim: Mitsuba variant {backend.variant()} ({backend.describe()['mitsuba']})")


# --------------------------------------------------------------------------------------- checks before work


def variant_problem(variant: str) -> str | None:
    """Why ``variant`` cannot run on this machine, or None if it can. Renders nothing.

    Asks the backend to load the variant (only the render layer imports Mitsuba / Dr.Jit) and reports its
    refusal.
    """
    from mincam_sim.render import backend

    backend.request_variant(variant)
    try:
        loaded = backend.variant()
    except (ImportError, RuntimeError, AttributeError, OSError) as err:
        why = _one_line(str(err))[:160]
        if variant.startswith("cuda"):
            return f"Mitsuba variant {variant!r} needs a working CUDA GPU and driver, and none was found ({why})"
        return f"Mitsuba variant {variant!r} cannot be loaded on this machine ({why})"
    if loaded != variant:
        return f"Mitsuba variant {loaded!r} is already in use in this process, not {variant!r}"
    return None


def check_variant(config_variant: str | None = None) -> str | None:
    """Validate the variant asked for (``--variant`` > the config's ``[run] variant`` > ``MINCAM_VARIANT``)
    before anything renders, request it, and return it (None: automatic).

    Raises
    ------
    ConfigError
        Unknown variant name.
    BackendUnavailableError
        The variant cannot run here (e.g. ``cuda_ad_mono`` without a GPU).
    """
    from mincam_sim.render import backend

    if _state["variant"] is not None:
        wanted, source = _state["variant"], "--variant"
    elif config_variant:
        wanted, source = config_variant, "[run] variant"
    elif os.environ.get(backend.ENV_VARIANT):
        wanted, source = os.environ[backend.ENV_VARIANT], backend.ENV_VARIANT
    else:
        return None
    if wanted not in backend.SUPPORTED_VARIANTS:
        raise ConfigError(f"{source} = {wanted!r} is not a supported Mitsuba variant: choose one of "
                          f"{', '.join(backend.SUPPORTED_VARIANTS)}")
    problem = variant_problem(wanted)
    if problem is not None:
        raise BackendUnavailableError(f"{source}: {problem}; use another variant or leave it unset (automatic)")
    return wanted


#: (directory, the topmost folder created for it) of each output directory this command created: removed again
#: when the command is refused and they hold nothing (:func:`_remove_created_if_empty`)
_created: list[tuple[Path, Path]] = []


def _remove_created_if_empty() -> None:
    """Remove the output directories this command created (and the folders made for them) that hold nothing but
    their lock file: a refused run leaves no empty folder behind. A lock another process holds is left alone."""
    from mincam_sim.storage.store import remove_if_only_lock

    while _created:
        remove_if_only_lock(*_created.pop())


def check_out_dir(path: Path, what: str = "output directory", create: bool = True) -> Path:
    """Make sure ``path`` can be a writable directory (create it unless ``create`` is False); ConfigError if not.
    A directory created here is removed again if the command is refused before writing anything into it."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{what} {path} is an existing file, not a directory; choose a directory path")
    ancestor = path
    while not ancestor.exists():
        if ancestor.parent == ancestor:
            break
        ancestor = ancestor.parent
    if ancestor.exists() and not ancestor.is_dir():
        raise ConfigError(f"{what} {path} cannot be created: {ancestor} is a file")
    if ancestor.exists() and not os.access(ancestor, os.W_OK | os.X_OK):
        raise ConfigError(f"{what} {path} cannot be written: no permission in {ancestor}")
    if create:
        from mincam_sim.storage.store import topmost_missing

        top = topmost_missing(path)
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ConfigError(f"cannot create {what} {path}: {err.strerror or err}") from None
        if top is not None:
            _created.append((path, top))
    return path


def check_out_file(path: Path, what: str = "output file") -> Path:
    """Make sure ``path`` can be written as a file (its directory is created); ConfigError if not."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{what} {path} is an existing directory; give a file name")
    check_out_dir(path.parent if str(path.parent) else Path("."), f"directory of the {what}")
    return path


# ------------------------------------------------------------------------------------------------- render
def _echo_table(m) -> None:
    """One line per frame: each mixel's value +/- standard error."""
    typer.echo("frame  " + "  ".join(f"{n:>24}" for n in m.mixel_names))
    for i in range(m.n_frames):
        cells = "  ".join(f"{v:12.5e} +/- {e:8.1e}" for v, e in zip(m.irradiance_w_m2[i], m.stderr_w_m2[i],
                                                                     strict=True))
        typer.echo(f"{i:5d}  {cells}")


def _render_world(config: Path, out_dir: Path | None, check: bool, overwrite: bool, time_limit_s: float) -> None:
    from mincam_sim.configuration.world_config import load_world_config
    from mincam_sim.runs.jobs import check_budget, run_world_config, world_summary

    with _warnings_once_valid():
        cfg = load_world_config(config)
        if out_dir is not None:
            cfg.run.out_dir = out_dir
        variant = check_variant(cfg.run.variant)
        check_out_dir(cfg.run.out_dir, create=False)
        if not check:
            check_budget(cfg, variant, time_limit_s)
    if check:
        for line in world_summary(cfg, variant, time_limit_s):
            typer.echo(line)
        return
    check_out_dir(cfg.run.out_dir)
    _announce_variant()
    ch = run_world_config(cfg, show_progress=_show_progress(), overwrite=overwrite, say=_say,
                          time_limit_s=time_limit_s)
    reached = ch.info.reached_rel_stderr
    typer.echo(f"# {ch.n_frames} frames x {len(ch.mixel_names)} mixels, dP [W/m^2] +/- stderr ({ch.info.solver}, "
               f"{ch.info.rays_per_mixel_per_frame} rays per mixel per frame, worst relative stderr "
               f"{'n/a' if reached is None else f'{reached:.2e}'}); outputs in {cfg.run.out_dir}")
    _echo_table(ch.dp)



@app.command()
def render(
    config: Annotated[Path, typer.Argument(help="TOML configuration (see `mincam-sim config-example`)")],
    out_dir: Annotated[Path | None, typer.Option("--out", help="override [run] out_dir")] = None,
    check: Annotated[bool, typer.Option("--check", help="validate the config and print a summary; render "
                                                        "nothing")] = False,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="replace the results of a different run in the "
                                                                "output directory")] = False,
    time_limit_s: Annotated[float, typer.Option(help="refuse a render estimated to take longer than this [s] "
                                                     "(the estimate is in --check)")] = 4 * 3600.0,
) -> None:
    """Render the measurements a config describes; write measurements.npz/.csv (with each frame's position),
    measurements.png (each mixel against position or frame, 2 sigma) and the response maps (EXR + PNG).

    A config with a [world] section renders your own scene (a Mitsuba XML file, meshes, lights, movers): dP and P
    per frame, a plot and the CSV (see `mincam-sim config-example --world`)."""
    from mincam_sim.configuration.config import solver_name
    from mincam_sim.configuration.toml_files import read_document
    from mincam_sim.plotting.plots import plot_render, plot_response_maps
    from mincam_sim.render.solvers import Reference
    from mincam_sim.runs.jobs import MAP_SOLVERS, check_budget, config_summary, run_render_config

    if not (np.isfinite(time_limit_s) and time_limit_s > 0):
        raise ConfigError(f"--time-limit-s must be a positive number of seconds, got {time_limit_s}")
    if check and overwrite:
        _ignored("--overwrite is ignored: --check renders nothing and writes nothing")
    raw, _, _ = read_document(config, None)
    if not raw:
        typer.echo(f"warning: {config} sets nothing: rendering the default job (every key at its default, "
                   "`mincam-sim config-example` shows them)", err=True)
    if "world" in raw:
        _render_world(config, out_dir, check, overwrite, time_limit_s)
        return
    with _warnings_once_valid():
        cfg = load_config(config)
        if out_dir is not None:
            cfg.run.out_dir = out_dir
        variant = check_variant(cfg.run.variant)
        cfg.run.variant = variant
        if variant == "scalar_rgb" and not isinstance(cfg.run.solver, Reference):
            raise ConfigError(f"[run] solver = {solver_name(cfg.run.solver)!r} needs a vectorised Mitsuba variant "
                              "(llvm_ad_mono or cuda_ad_mono); scalar_rgb renders only solver = \"reference\"")
        check_out_dir(cfg.run.out_dir, create=False)
        if not check:
            check_budget(cfg, variant, time_limit_s)
    if check:
        for line in config_summary(cfg, variant, time_limit_s):
            typer.echo(line)
        return
    check_out_dir(cfg.run.out_dir)
    _announce_variant()
    m, maps = run_render_config(cfg, show_progress=_show_progress(), overwrite=overwrite, say=_say,
                                time_limit_s=time_limit_s)
    out = Path(cfg.run.out_dir)
    figures = [plot_render(m, out / "measurements.png", cfg.frame_positions_m, cfg.frames_kind)]
    if maps is not None:
        figures.append(plot_response_maps(maps, cfg.screen, out / "response_maps.png"))
    elif isinstance(cfg.run.solver, MAP_SOLVERS) and (out / "response_maps.png").is_file():
        # a finished run shown again: its maps' figure is still there (run_render_config returns the maps when
        # one of their outputs is missing; --overwrite deletes the figure of the run it replaces)
        figures.append(out / "response_maps.png")
    np.set_printoptions(precision=6, suppress=False, linewidth=120)
    typer.echo(f"# {m.n_frames} frames x {len(m.mixel_names)} mixels, irradiance [W/m^2] +/- stderr, "
               f"variant {m.meta.get('variant')}, worst relative stderr {m.meta['reached_rel_stderr']:.2e}")
    _echo_table(m)
    typer.echo(f"# written to {cfg.run.out_dir} (figures: {', '.join(p.name for p in figures)})")


#: The ``[run]`` keys of a display file's budget, in the order a warning names them.
_RUN_BUDGET_KEYS = ("spp", "samples_per_texel", "target_rel_stderr", "replicates", "seed")


def _without_solver_warnings(read, *args: Any) -> Any:
    """``read(*args)`` (a display config's reader) without its warnings about the ``[run]`` budget keys and the
    ``[run.dot_product]`` options: they judge the keys by a solver, and ``export-maps`` says itself which of them
    the solver it exports reads (:func:`_export_budget`). Every other warning is shown as it came."""
    import warnings

    from mincam_sim.errors import IgnoredSettingWarning

    solver_keys = (*(f"[run] {key}" for key in _RUN_BUDGET_KEYS), "[run.dot_product] ")
    with warnings.catch_warnings(record=True) as held:
        result = read(*args)
    for w in held:
        if not (issubclass(w.category, IgnoredSettingWarning) and str(w.message).startswith(solver_keys)):
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return result


def _as_exported(raw: dict, ideal: bool) -> dict:
    """The display document ``raw`` with ``[run] solver`` set to the solver ``export-maps`` uses
    (``"dot_product"`` with ``--ideal``, else ``"response_map"``), so that the file is checked as the export
    reads it: a key that only the file's own solver reads is neither refused nor taken for used. ``raw`` itself
    is left as it is (its ``[run] solver`` is still checked, by :func:`_export_budget`)."""
    run = raw.get("run", {})
    if not isinstance(run, dict):  # not a table: the reader names it
        return raw
    return {**raw, "run": {**run, "solver": "dot_product" if ideal else "response_map"}}


def _export_budget(raw: dict, solver: Any) -> Any:
    """The :class:`~mincam_sim.budget.Budget` that ``export-maps`` traces with: the file's ``[run]`` keys that
    ``solver`` (the export's, whatever the file's ``[run] solver``) reads, checked as the file's reader checks
    them; one warning naming the keys the file wrote that the export ignores, as the file writes them
    (``[run] spp``), not as the Python API names them (``Budget.spp``), and one naming the ``[run.dot_product]``
    options when the export traces response maps (``--ideal`` uses them, whatever the file's solver)."""
    from mincam_sim.configuration.config import RENDER_SCHEMA, DotProductTable, RunSection, make_budget
    from mincam_sim.configuration.schema import warn_ignored

    tables = RENDER_SCHEMA.tables(raw)
    given = tables["run"]
    run = RENDER_SCHEMA.read("run", given)
    reads = solver.budget_fields("display")
    why = ("--ideal exports the idealised dot-product model: deterministic quadrature (no samples)"
           if not reads else 'export-maps traces response maps at samples_per_texel (spp is for the "aperture" '
                             'and "reference" solvers of render)')
    warn_ignored("run", given, [key for key in _RUN_BUDGET_KEYS if key not in reads], why, RunSection)
    if reads:  # response maps: the idealised model's options are for --ideal
        options = tables["run.dot_product"]
        warn_ignored("run.dot_product", options, list(options), "they are the options of the idealised model, "
                     "which export-maps writes with --ideal; without it, it traces response maps", DotProductTable)
    return make_budget(solver, "display", run.spp, run.samples_per_texel, run.target_rel_stderr, run.replicates,
                       run.seed)


@app.command("export-maps")
def export_maps_command(
    config: Annotated[Path, typer.Argument(help="TOML display configuration (see `mincam-sim config-example`)")],
    out_dir: Annotated[Path, typer.Option("--out", help="directory for maps/*.npy, forward_matrix.npy, maps.json")],
    psf_grid: Annotated[tuple[int, int] | None, typer.Option(help="also write psfs.npy: responses to point sources "
                                                                  "on an NX x NY grid over the screen")] = None,
    ideal: Annotated[bool, typer.Option("--ideal", help="the idealised dot-product model (DotProduct, with the "
                                                        "file's [run.dot_product] options) instead of the physics "
                                                        "(response maps)")] = False,
) -> None:
    """Write each mixel's response map (W/m^2 per W m^-2 sr^-1 of each screen texel) as NumPy arrays with a JSON
    sidecar (units, screen, geometry), at the config's [run] samples_per_texel, for other tools.

    The folder holds one export: files of an earlier export there that this one does not write (maps of mixels
    no longer there, psfs.npy without --psf-grid) are removed, saying so; other files are kept. A second export
    into the folder while one runs is refused."""
    from mincam_sim.configuration.config import RENDER_SCHEMA, display_solver
    from mincam_sim.configuration.toml_files import read_document
    from mincam_sim.render.simulation import Simulation
    from mincam_sim.render.solvers import ResponseMap

    raw, _, _ = read_document(config, None)
    if "world" in raw:
        raise ConfigError(f"{config} has a [world] section; response maps are maps over a display's texels: give a "
                          "display config ([screen] and [frames])")
    if psf_grid is not None and min(psf_grid) < 1:
        raise ConfigError(f"--psf-grid needs two positive integers NX NY, got {psf_grid[0]} {psf_grid[1]}")
    with _warnings_once_valid():
        cfg = _without_solver_warnings(load_config, _as_exported(raw, ideal), Path(config).parent)
        solver = (display_solver("dot_product", RENDER_SCHEMA.tables(raw)["run.dot_product"]) if ideal
                  else ResponseMap())
        budget = _export_budget(raw, solver)
    check_out_dir(out_dir)
    if not ideal:
        cfg.run.variant = check_variant(cfg.run.variant)
        _announce_variant()
    sim = Simulation(cfg.mincam, screen=cfg.screen)
    with lock_out_dir(out_dir, "export folder"):  # one export at a time in a folder
        sidecar = sim.export_maps(out_dir, budget, solver=solver, psf_grid=psf_grid, show_progress=_show_progress(),
                                  say=lambda msg: _say(f"mincam-sim: {msg}"))
    if not ideal:  # the count traced, where it is not the one asked (as render says it)
        from mincam_sim.configuration.config import traced_samples

        _, rounding = traced_samples(cfg.run)
        if rounding:
            _say(f"mincam-sim: {rounding}")
    typer.echo(f"# {len(cfg.mincam)} response maps ({'dot_product' if ideal else 'response_map'}) of "
               f"{cfg.screen.shape[0]} x {cfg.screen.shape[1]} texels written to {out_dir} (sidecar {sidecar.name})")


@app.command("config-example")
def config_example(
    world: Annotated[bool, typer.Option("--world", help="the world-scene config (your own scene from a file)")] = False,
    reproduce: Annotated[bool, typer.Option("--reproduce", help="the reproduce config (reproduce --config FILE): "
                                                                 "[setup] and every experiment's parameters")] = False,
    study: Annotated[bool, typer.Option("--study", help="a study file (study run FILE)")] = False,
) -> None:
    """Print a documented TOML file with every key and its default (a render config unless an option says
    which file)."""
    if world + reproduce + study > 1:
        raise ConfigError("config-example prints one file: give at most one of --world, --reproduce, --study")
    if world:
        from mincam_sim.configuration.world_config import world_example_toml

        text = world_example_toml()
    elif reproduce:
        from mincam_sim.experiments.reproduce_file import reproduce_example_toml

        text = reproduce_example_toml()
    elif study:
        from mincam_sim.studies.spec import study_example_toml

        text = study_example_toml()
    else:
        text = EXAMPLE_TOML
    typer.echo(text, nl=False)


@masks_app.command("generate")
def masks_generate(
    out_dir: Annotated[Path, typer.Option("--out", help="directory for the EXR files and previews")] = Path("masks"),
    resolution: Annotated[int, typer.Option(help="texels per side")] = 256,
    size_m: Annotated[float, typer.Option(help="mask side [m]")] = paper.MASK_SIZE_M,
) -> None:
    """Write the standard mask library (ramps, constant, sinusoid, circular ramp) as OpenEXR + PNG previews."""

    if not 1 <= resolution <= 8192:
        raise ConfigError(f"--resolution must be 1 to 8192 texels per side, got {resolution}")
    if not (np.isfinite(size_m) and size_m > 0):
        raise ConfigError(f"--size-m must be a positive mask side in metres, got {size_m}")
    check_out_dir(out_dir)
    for p in generate_library(out_dir, resolution=resolution, size_m=size_m):
        typer.echo(str(p))


@masks_app.command("export")
def masks_export(
    spec: Annotated[str, typer.Argument(help="'ramp:x', 'constant:0.5', 'file:path.png' ...")],
    out: Annotated[Path, typer.Option("--out", help="PNG to send to the printer (name ending in .png)")],
    size_m: Annotated[float | None, typer.Option(help="physical mask side [m]; default: the size an OpenEXR mask "
                                                      "file records, else 0.002")] = None,
    dpi: Annotated[int, typer.Option(help="printer resolution [dots per inch], 50 to 4800")] = 600,
    levels: Annotated[int | None, typer.Option(help="grey levels the printer reproduces per dot, 2 to 65536 (above "
                                                    "256 the PNG has 16 bits); default 256; not with --halftone")
                      ] = None,
    halftone: Annotated[bool, typer.Option(help="print with an ordered (Bayer) halftone")] = False,
    film_t_min: Annotated[float, typer.Option(help="transmission of fully inked film")] = 0.02,
    film_t_max: Annotated[float, typer.Option(help="transmission of clear film")] = 0.9,
    srgb: Annotated[bool, typer.Option("--srgb", help="a file: mask's PNG values are sRGB-encoded (decoded to "
                                                      "linear transmission); default: values are transmission")
                    ] = False,
    sheet: Annotated[Path | None, typer.Option(help="print sheet (.png at --dpi or .pdf) with crop and "
                                                    "registration marks, the detector side and the film mapping; "
                                                    "default: <out>_sheet.png, notes in <sheet>.txt")] = None,
    no_sheet: Annotated[bool, typer.Option("--no-sheet", help="write the mask's PNG alone, without a print sheet")
                        ] = False,
    preview: Annotated[Path | None, typer.Option(help="also write what the film will transmit (OpenEXR)")] = None,
) -> None:
    """Export a mask as a print-ready PNG at DPI and physical size, and a print sheet with its notes; optionally
    preview the printed film."""
    from mincam_sim.masks.sheet import write_print_sheet

    if size_m is not None and not (np.isfinite(size_m) and size_m > 0):
        raise ConfigError(f"--size-m must be a positive mask side in metres, got {size_m}")
    if not 50 <= dpi <= 4800:
        raise ConfigError(f"--dpi must be a printer resolution of 50 to 4800 dots per inch, got {dpi}")
    if levels is not None and not 2 <= levels <= 65536:
        raise ConfigError(f"--levels must be 2 to 65536 grey levels (256 for an 8-bit printer; a PNG holds at most "
                          f"16 bits), got {levels}")
    if out.suffix.lower() != ".png":
        raise ConfigError(f"--out {out}: the print file is a PNG; give a name ending in .png")
    if no_sheet and sheet is not None:
        raise ConfigError(f"--sheet {sheet} and --no-sheet: give one of them")
    sheet = out.with_name(f"{out.stem}_sheet.png") if sheet is None else sheet
    if sheet.suffix.lower() not in (".png", ".pdf"):
        raise ConfigError(f"--sheet {sheet}: give a name ending in .png (at --dpi) or .pdf")
    if sheet.resolve() == out.resolve():
        raise ConfigError(f"--sheet {sheet} is the --out file; give the sheet another name")
    check_out_file(out, "--out file")
    if not no_sheet:
        check_out_file(sheet, "--sheet file")
    if preview is not None:
        check_out_file(preview, "--preview file")
        if preview.suffix.lower() != ".exr":
            raise ConfigError(f"--preview {preview}: the preview is OpenEXR; give a name ending in .exr")
    _warn_unused_print_options(spec, srgb, levels, halftone)
    mask = _mask_to_print(spec, size_m, srgb)
    _check_print_grid(mask, dpi)
    try:
        film = PrintedFilm(t_min=film_t_min, t_max=film_t_max, dpi=dpi, levels=256 if levels is None else levels,
                           halftone="ordered" if halftone else None)
    except ValueError as err:
        raise ConfigError(str(err).replace("t_min", "--film-t-min").replace("t_max", "--film-t-max")) from None
    title = f"mask {spec}"
    if not no_sheet:
        _check_sheet(mask, dpi, film, title)
    path = export_print_png(mask, out, dpi=dpi, film=film)
    if not no_sheet:
        sheet_path, notes = write_print_sheet([mask], [(0.0, 0.0)], dpi, film, sheet, title=title)
    if preview is not None:
        printed = film.print(mask)
        save_exr(printed, preview)
        typer.echo(f"{preview}: printed film transmits {printed.transmission.min():.3f}.."
                   f"{printed.transmission.max():.3f} on a {printed.shape[1]}x{printed.shape[0]} dot grid")
    typer.echo(str(path))
    if not no_sheet:
        typer.echo(f"{sheet_path} (notes: {notes})")


def _check_sheet(mask, dpi: int, film: PrintedFilm, title: str) -> None:
    """Refuse, before anything is written, a print sheet that cannot be made at ``--dpi``, naming the largest dpi
    that makes it (the sheet's notes are text of a fixed size in points: their dots grow as dpi squared)."""
    from mincam_sim.masks.printing import METRES_PER_INCH, MIN_PRINT_DOTS
    from mincam_sim.masks.sheet import check_print_sheet

    def fits(at_dpi: int) -> bool:
        try:
            check_print_sheet([mask], [(0.0, 0.0)], at_dpi, film, title=title)
        except InputError:
            return False
        return True

    if fits(dpi):
        return
    # the smallest dpi that still gives the mask its dots; the search keeps fits(low) and not fits(high)
    low = max(50, int(np.ceil(MIN_PRINT_DOTS * METRES_PER_INCH / min(mask.width_m, mask.height_m))))
    high = dpi
    if low >= high or not fits(low):
        raise ConfigError(f"--size-m {mask.width_m:g}: no print sheet can be made at any --dpi; give --no-sheet "
                          "to write the mask alone")
    while high - low > 1:
        mid = (low + high) // 2
        low, high = (mid, high) if fits(mid) else (low, mid)
    raise ConfigError(f"--size-m {mask.width_m:g} at --dpi {dpi}: the print sheet (the mask, its marks and notes) "
                      f"would hold more dots than a print file does; give --dpi <= {low}, or --no-sheet to write "
                      "the mask alone")


def _warn_unused_print_options(spec: str, srgb: bool, levels: int | None, halftone: bool) -> None:
    """One warning line for each ``masks export`` option that does not apply to this mask or film."""
    if srgb and not spec.startswith("file:"):
        _say(f"warning: --srgb does not apply to {spec!r}: it decodes the values of a file: mask's PNG; a generated "
             "mask is transmission already (--srgb ignored)")
    if halftone and levels is not None:
        _say(f"warning: --levels {levels} does not apply with --halftone: an ordered halftone prints each dot fully "
             "inked or clear (65 effective levels over 8 x 8 dots); --levels ignored")


def _mask_to_print(spec: str, size_m: float | None, srgb: bool):
    """The mask of ``spec`` at ``--size-m`` [m]; without it, at the size an OpenEXR file records (else 2 mm).

    A file that records another size than ``--size-m`` is printed at ``--size-m``, with one warning line."""
    stored = _recorded_size_m(spec)
    height_m = None
    if size_m is None:
        size_m, height_m = stored if stored is not None else (paper.MASK_SIZE_M, None)
    elif stored is not None and not np.isclose(stored[0], size_m, rtol=1e-9, atol=0.0):
        _say(f"warning: {spec[5:]} records a {1e3 * stored[0]:.4g} x {1e3 * stored[1]:.4g} mm mask; printing it "
             f"{1e3 * size_m:.4g} mm wide as --size-m asks (leave --size-m out to print it at its own size)")
    return parse_mask(spec, size_m, 512, "mask", encoding="srgb" if srgb else "linear", height_m=height_m)


def _recorded_size_m(spec: str) -> tuple[float, float] | None:
    """(width, height) [m] that the OpenEXR mask file of a ``file:`` spec records; None for anything else."""
    from mincam_sim.masks import load

    if not spec.startswith("file:"):
        return None
    try:
        recorded = load(spec[5:])  # only an OpenEXR file written with its size loads without a width
    except Exception:  # noqa: BLE001 - not such a file: parse_mask reads it and names any problem
        return None
    return recorded.width_m, recorded.height_m


def _check_print_grid(mask, dpi: int) -> None:
    """Refuse a mask that prints as more dots than a print file holds, or as too few to show it (naming --size-m
    and --dpi)."""
    from mincam_sim.masks.mask import MAX_TEXELS
    from mincam_sim.masks.printing import check_print_dots

    per_m = dpi / 0.0254
    rows, cols = max(1, round(mask.height_m * per_m)), max(1, round(mask.width_m * per_m))
    size = f"--size-m {mask.width_m:g}"
    if rows * cols > MAX_TEXELS:
        largest = np.sqrt(MAX_TEXELS * mask.width_m / mask.height_m) / per_m
        raise ConfigError(f"{size} at --dpi {dpi} prints {cols} x {rows} dots, more than a print file "
                          f"holds ({MAX_TEXELS} dots): lower --dpi, or --size-m to at most {largest:.4g} m at "
                          f"{dpi} dpi")
    try:
        check_print_dots(mask.width_m, mask.height_m, dpi)
    except InputError as err:
        raise ConfigError(f"{size} at --dpi {dpi}: {err}".replace("give dpi", "give --dpi")) from None


def _render_demo(out_dir: Path) -> None:
    from mincam_sim.plotting.plots import plot_response_maps, plot_sweep
    from mincam_sim.runs.jobs import run_render_config

    cfg = load_config({"run": {"out_dir": str(out_dir), "target_rel_stderr": 1e-3}})
    # The demo is a fixed job: it starts afresh in its own output directory every time.
    m, maps = run_render_config(cfg, show_progress=_show_progress(), overwrite=True)
    plot_sweep(np.asarray(cfg.frame_positions_m)[:, 0], m, out_dir / "sweep.png")
    if maps is not None:
        plot_response_maps(maps, cfg.screen, out_dir / "response_maps.png")
    typer.echo(f"render: {m.n_frames} sweep positions x {len(m.mixel_names)} mixels (variant {m.meta.get('variant')}, "
               f"worst relative stderr {m.meta['reached_rel_stderr']:.1e}) -> {out_dir}")


def _pct(value, width: int, align: str = ">") -> str:
    """A percentage for the tables, or '-' when nothing was scored (None)."""
    return f"{'-' if value is None else f'{value:.2f}':{align}{width}}"


def _print_table(results: dict) -> None:
    from mincam_sim.experiments import EXPERIMENTS

    typer.echo("experiment   simulated max / avg error [%]   paper max / avg error [%]   n")
    for name in EXPERIMENTS:
        if name in results:
            r = results[name]
            p = r["paper"]
            typer.echo(f"{name:<12} {_pct(r['max_error_pct'], 10)} / {_pct(r['avg_error_pct'], 10, '<')}        "
                       f"{_pct(p['max_error_pct'], 8)} / {_pct(p['avg_error_pct'], 8, '<')}        {r['n']}")
    if "speed" in results and "vehicle" in results["speed"]:
        v = results["speed"]["vehicle"]
        typer.echo(f"{'(vehicle)':<12} {_pct(v['max_error_pct'], 10)} / {_pct(v['avg_error_pct'], 10, '<')}        "
                   f"{'-':>8} / {'-':<8}        {v['n']}")
    if "speed" in results and "display_timing" in results["speed"]:
        v = results["speed"]["display_timing"]
        p = results["speed"]["paper"]
        typer.echo(f"{'(display)':<12} {_pct(v['max_error_pct'], 10)} / {_pct(v['avg_error_pct'], 10, '<')}        "
                   f"{_pct(p['max_error_pct'], 8)} / {_pct(p['avg_error_pct'], 8, '<')}        {v['n']}"
                   f"   ({v['timing']}"
                   + (f"; median of {v['draws']['count']} draws {v['draws']['median_max_error_pct']:.2f} / "
                      f"{v['draws']['median_avg_error_pct']:.2f}" if "draws" in v else "") + ")")
    _print_details(results)


def _print_details(results: dict) -> None:
    """Per toy / car: maximum, 95th percentile, mean, the maximum without extrapolated frames, the per-axis
    mean, and the frames left unscored (missed or without a position) beside the scored ones."""
    rows = [(name, results[name]) for name in ("intrusion", "tracking")
            if name in results and "by_group" in results[name]]
    if not rows:
        return
    typer.echo("# position errors [% of the field]: Euclidean (the table's); per-axis avg beside; ground truth "
               "named per experiment")
    typer.echo(f"{'experiment':<12} {'group':<8} {'max':>7} {'p95':>7} {'avg':>7} {'max*':>7} {'axis avg':>8}"
               f" {'n':>5} {'unscored':>9} {'share':>7}")
    for name, r in rows:
        paper_s = " (the paper's)" if r.get("ground_truth") == "object" else ""
        typer.echo(f"{name:<12} ground truth: {r.get('ground_truth', '?')} centroid{paper_s}")
        for group, g in {"all": r, **r["by_group"]}.items():
            clean = g.get("without_extrapolated") or {}
            axis = g.get("per_axis") or {}
            share = g.get("unscored_frames_pct")
            typer.echo(f"{'':<12} {group:<8} {_pct(g.get('max_error_pct'), 7)} {_pct(g.get('p95_error_pct'), 7)} "
                       f"{_pct(g.get('avg_error_pct'), 7)} {_pct(clean.get('max_error_pct'), 7)} "
                       f"{_pct(axis.get('avg_error_pct'), 8)} {g.get('n', 0):>5} {g.get('unscored_frames', 0):>9} "
                       f"{_pct(share, 6)}{'' if share is None else '%'}")
    typer.echo("# max*: the maximum without the frames read outside the calibrated range (extrapolated)")


def _print_reused(results: dict, out_dir: Path) -> None:
    reused = results.get("meta", {}).get("reused") or []
    if reused:
        typer.echo(f"# reused from an earlier run in {out_dir} (same set-up, parameters and versions): "
                   f"{', '.join(reused)}; --overwrite recomputes")


def _reproduce_config(config: Path | None, quick: bool, names: Collection[str] | None = None,
                      **flags: Any) -> tuple[Any, dict]:
    """Set-up and parameters from an optional reproduce config, then the command-line flags given; checked for
    the experiments ``names`` (default all)."""
    from mincam_sim.experiments import load_reproduce_config

    given = {key: value for key, value in flags.items() if value is not None}
    for key in ("spacing_m", "depth_m"):
        if key in given and not np.isfinite(given[key]):
            raise ConfigError(f"--{key.replace('_', '-')} must be a finite number of metres, got {given[key]}")
    if given.get("seed", 0) < 0:
        raise ConfigError(f"--seed must be an integer >= 0, got {given['seed']}")
    try:
        setup, params = load_reproduce_config(config, quick=quick, **given)
    except ConfigError as err:
        text = str(err)
        if not text.startswith("[command line]"):
            raise
        flag = re.sub(r"Setup\.(\w+)", lambda m: "--" + m.group(1).replace("_", "-"), text)
        flag = re.sub(r"^\[command line\] (\w+)", lambda m: "--" + m.group(1).replace("_", "-"), flag)
        raise ConfigError(flag.replace("[command line]: ", "")) from None
    from mincam_sim.experiments.input_checks import check_reproduce

    # what the experiments to run would refuse only deep inside, refused here
    check_reproduce(setup, {name: p for name, p in params.items() if names is None or name in names})
    return setup, params


@app.command()
def reproduce(
    experiment: Annotated[str, typer.Argument(help="intrusion, tracking, speed or all")] = "all",
    out_dir: Annotated[Path, typer.Option("--out", help="output folder (results.json + plots)")] = Path("out/repro"),
    config: Annotated[Path | None, typer.Option(
        "--config", help="reproduce TOML: [setup] and one section per experiment (scenes/experiments/reproduce.toml)"
    )] = None,
    quick: Annotated[bool, typer.Option("--quick", help="fewer frames and samples (minutes)")] = False,
    seed: Annotated[int | None, typer.Option(help="seed of every random choice [default 0]")] = None,
    spacing_m: Annotated[float | None, typer.Option(
        help=f"mixel spacing [m] [default {paper.SPACING_M:g}, the paper's]")] = None,
    depth_m: Annotated[float | None, typer.Option(
        help=f"mincam to table/screen distance [m] [default {paper.CALIBRATION_DEPTH_M:g}]")] = None,
    bit_depth: Annotated[int | None, typer.Option(help=f"ADC bits [default {paper.ADC_BITS}, the paper's]")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="recompute everything, replacing what --out holds "
                                                                "(without it: another set-up there is refused, "
                                                                "finished experiments of this one are reused)")
                         ] = False,
) -> None:
    """Reproduce the paper's experiments in simulation; print the error table beside the paper's."""
    from mincam_sim.experiments import EXPERIMENTS
    from mincam_sim.experiments import reproduce as run

    if experiment != "all" and experiment not in EXPERIMENTS:
        raise ConfigError(f"unknown experiment {experiment!r}: choose {', '.join(EXPERIMENTS)} or all")
    names = list(EXPERIMENTS) if experiment == "all" else [experiment]
    setup, params = _reproduce_config(config, quick, names, seed=seed, spacing_m=spacing_m, depth_m=depth_m,
                                      bit_depth=bit_depth)
    check_variant()
    check_out_dir(out_dir)
    _announce_variant()
    with lock_out_dir(out_dir):
        results = run(names, setup, out_dir, show_progress=_show_progress(), params=params, overwrite=overwrite,
                      say=lambda msg: _say(f"mincam-sim: {msg}"))
    _print_table(results)
    _print_reused(results, out_dir)
    typer.echo(f"# results.json and plots in {out_dir}")


@study_app.command("run")
def study_run(
    study_file: Annotated[Path, typer.Argument(help="study TOML (see scenes/studies/*.toml)")],
    workers: Annotated[int | None, typer.Option(help="workers: 1 = in this process, >= 2 = process workers of "
                                                     "an embedded dask cluster (default min(2, cores))")] = None,
    scheduler: Annotated[str | None, typer.Option(help="address of an existing dask scheduler, e.g. "
                                                       "tcp://host:8786 (a dask-jobqueue cluster)")] = None,
    out_dir: Annotated[Path | None, typer.Option("--out", help="output folder (default: [study] out_dir)")] = None,
    quick: Annotated[bool, typer.Option("--quick", help="the study's [quick] lists, fast points (~1 min)")] = False,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="replace a different study's results")] = False,
    max_points: Annotated[int | None, typer.Option("--max-points", help="refuse studies with more points than "
                                                                         "this (default 10000)")] = None,
    time_limit_s: Annotated[float | None, typer.Option(help="refuse a study estimated to take longer than this [s]: "
                                                            "points x replicates x the target's typical seconds "
                                                            "per point / workers (default 86400)")] = None,
) -> None:
    """Run a parameter study on dask.distributed: results.zarr (xarray), summary.json and study.png in --out.

    Ctrl-C stops it within seconds (exit code 130), keeping every completed point; the same command resumes."""
    try:  # the study's modules take a second or two to import: nothing is written meanwhile
        from mincam_sim.studies.cli import run_study_command

        check_variant()
    except Exception as err:
        if not interrupts.arrived():
            raise
        # a Ctrl-C that landed in an import can come out as another error (a module left half-imported)
        typer.echo(f"error: {interrupts.STUDY_NOT_STARTED}", err=True)
        raise SystemExit(130) from err
    except KeyboardInterrupt:
        typer.echo(f"error: {interrupts.STUDY_NOT_STARTED}", err=True)
        raise SystemExit(130) from None
    run_study_command(study_file, workers, scheduler, out_dir, quick, overwrite, quiet=not _show_progress(),
                      max_points=max_points, time_limit_s=time_limit_s)


@app.command()
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="output directory")] = Path("out/demo"),
) -> None:
    """Built-in default job: a 2-mixel (x | 1-x) mincam 0.5 m from a 50" screen with a white square swept along
    the boundary (measurements, response maps as EXR, plots), then every registered experiment in quick mode
    (the paper's three and the spacing study)."""
    from mincam_sim.experiments import EXPERIMENTS, REGISTRY
    from mincam_sim.experiments import reproduce as run

    check_variant()
    check_out_dir(out_dir)
    _announce_variant()
    _render_demo(out_dir / "render")
    setup, params = _reproduce_config(None, quick=True)
    with lock_out_dir(out_dir / "repro"):
        # the demo's folder is the demo's own: it is recomputed every time (a run of older code is replaced)
        results = run(list(EXPERIMENTS), setup, out_dir / "repro", show_progress=_show_progress(), params=params,
                      overwrite=True)
    _print_table(results)
    studies = [name for name in REGISTRY if name not in EXPERIMENTS]
    with lock_out_dir(out_dir / "study"):
        run(studies, setup, out_dir / "study", show_progress=_show_progress(), params=params, overwrite=True)
    typer.echo(f"demo: wrote {out_dir}/render, {out_dir}/repro (results.json, plots), {out_dir}/study")


def _pair(text: str | None, option: str, scale: float = 1.0) -> tuple[float, float] | None:
    """``"a,b"`` -> (a * scale, b * scale), or a ConfigError naming the option."""
    if text is None:
        return None
    try:
        lo, hi = (float(v) * scale for v in text.split(","))
    except ValueError:
        raise ConfigError(f"{option} must be two numbers MIN,MAX (e.g. {option} 1,15), got {text!r}") from None
    return lo, hi


def design_schema():
    """The design command's ``--config`` file: one ``[tracking]`` section of TrackingTask fields."""
    from mincam_sim.configuration.schema import Part, Schema
    from mincam_sim.design.tracking import TrackingTask

    return Schema("mincam-sim design tracking --config FILE: fields of the design task (options on the command "
                  "line win).", (Part("tracking", TrackingTask),))


#: The design command's options that set a field of the task's record, by field (the value of
#: ``--object-size-cm`` is in centimetres, the field's in metres).
_DESIGN_OPTIONS = {"seed": "--seed", "dpi": "--dpi", "object_size_range_m": "--object-size-cm (object_size_range_m, in "
                   "metres)", "background_radiances": "--backgrounds", "depth_range_m": "--depth-range-m",
                   "spacing_m": "--spacing-m", "d_f_m": "--d-f-m", "film_t_min": "--film-t-min",
                   "film_t_max": "--film-t-max"}


def _design_overrides(config: Path | None, **options) -> tuple[dict, set[str]]:
    """Task fields from a ``[tracking]`` section of a TOML file, each checked for its type by
    :func:`design_schema` (the ranges are the task's own checks), and the command line (which wins), with the
    names of the fields the file gave."""
    from dataclasses import fields

    from mincam_sim.configuration.schema import field_check, refuse_unknown
    from mincam_sim.configuration.toml_files import read_document

    overrides: dict = {}
    from_file: set[str] = set()
    if config is not None:
        raw, _, _ = read_document(Path(config), None, kind="--config")
        schema = design_schema()
        known = {f.name: f for f in fields(schema.part("tracking").cls)}
        loose = sorted(k for k in raw if k in known)
        if loose:
            raise ConfigError(f"--config {config}: put {', '.join(loose)} in a [tracking] section (the design "
                              "task's fields)")
        given = schema.tables(raw)["tracking"]
        refuse_unknown("tracking", given, list(known))
        overrides.update({key: field_check(known[key])("tracking", key, value) for key, value in given.items()})
        from_file = set(given)
    overrides.update({k: v for k, v in options.items() if v is not None})
    return overrides, from_file


@contextmanager
def _design_fields_named(options: dict, from_file: Collection[str] = ()) -> Iterator[None]:
    """A bad field of the design task's record (:class:`~mincam_sim.design.checks.FieldError`) as one line naming
    it as the user gave it: its option when given on the command line (``options``: field -> value or None),
    ``[tracking] key`` when given in the ``--config`` file, else the field and "(default)"."""
    from mincam_sim.design.checks import FieldError

    def name_of(field: str) -> str:
        if options.get(field) is not None:
            return _DESIGN_OPTIONS.get(field, field)
        return f"[tracking] {field}" if field in from_file else f"{field} (default)"

    try:
        yield
    except FieldError as err:
        raise ConfigError(err.named(name_of)) from None


def _design_scene_task(task: str, out_dir: Path, quick: bool, seed: int | None, overwrite: bool,
                       tracking_only: dict, **options) -> None:
    """``mincam-sim design counting|depth``: the scene tasks (:mod:`mincam_sim.design.scene_run`)."""
    from mincam_sim.design.scene_run import make_sizes
    from mincam_sim.design.tasks import get_task
    from mincam_sim.storage.store import lock_out_dir

    given = [k for k, v in tracking_only.items() if v is not None]
    if given:
        raise ConfigError(f"{', '.join(given)} only apply to the tracking task; design {task} takes --quick, "
                          "--seed, --dpi, --spacing-m, --d-f-m, --film-t-min, --film-t-max")
    spec_task = get_task(task)
    overrides = {k: v for k, v in options.items() if v is not None}
    named = {**options, "seed": seed}
    seed = 0 if seed is None else seed
    with _design_fields_named(named):  # one clear error for a bad field before anything runs
        make_sizes(spec_task.spec, quick, seed, **overrides)
    check_variant()
    check_out_dir(out_dir)
    _announce_variant()
    with lock_out_dir(out_dir):
        r = spec_task.run(out_dir, quick=quick, seed=seed, show_progress=_show_progress(), overwrite=overwrite,
                          **overrides)
    sm = r["suite"]["summary"]
    typer.echo(f"gradient check of the {task} decoder's loss: relative error {r['gradient_check']['max_rel_error']:.2e}"
               f" over {r['gradient_check']['n_checked']} logits")
    typer.echo(f"held-out suite: {sm['metric']} per case ({'lower' if sm['lower_is_better'] else 'higher'} is better)")
    labels = list(r["suite"]["cases"][0][sm["metric"]])
    typer.echo(f"{'case':<18}" + "".join(f"{lab:>22}" for lab in labels))
    for c in r["suite"]["cases"]:
        typer.echo(f"{c['name']:<18}" + "".join(f"{c[sm['metric']][lab]:>22.1f}" for lab in labels))
    typer.echo(f"# suite mean {sm['metric']}: designed {sm['designed']:.1f}; "
               + ", ".join(f"{k} {v:.1f} (designed better in {sm['n_cases_designed_better'][k]}/{sm['n_cases']}, "
                           f"worse in {sm['n_cases_designed_worse'][k]})" for k, v in sm["baselines"].items())
               + f"; design.json, masks, suite.png, training.zarr in {out_dir}")


@app.command()
def design(
    task: Annotated[str, typer.Argument(help="design task: tracking, counting or depth")],
    out_dir: Annotated[Path, typer.Option("--out", help="output folder (design.json, PNG masks, plots)")] = Path(
        "out/design"),
    quick: Annotated[bool, typer.Option("--quick", help="smaller training and held-out sets (minutes)")] = False,
    seed: Annotated[int | None, typer.Option(help="seed of the training and held-out draws and of the noise "
                                                  "[default 0; tracking: the --config file's seed]")] = None,
    dpi: Annotated[float | None, typer.Option(help="printer resolution of the film and the PNG masks "
                                                   "[dots/inch]; default 600")] = None,
    config: Annotated[Path | None, typer.Option("--config", help="TOML of TrackingTask fields ([tracking] "
                                                                  "table); options below win")] = None,
    object_size_cm: Annotated[str | None, typer.Option("--object-size-cm", help="training object sizes MIN,MAX "
                                                                            "[cm]; default 1,15")] = None,
    backgrounds: Annotated[str | None, typer.Option("--backgrounds", help="training background radiances, "
                                                     "comma-separated (0 = black); default 0,0,0.1,0.2,0.3,0.45")]
    = None,
    depth_range_m: Annotated[str | None, typer.Option("--depth-range-m", help="working depths MIN,MAX [m]; "
                                                                            "default 0.35,0.7")] = None,
    spacing_m: Annotated[float | None, typer.Option("--spacing-m", help="mixel distance from the centre [m]; "
                                                                       f"default {paper.SPACING_M:g}")] = None,
    d_f_m: Annotated[float | None, typer.Option("--d-f-m", help="mask-to-detector distance [m]; default "
                                                                 f"{paper.D_F_M:g}")] = None,
    film_t_min: Annotated[float | None, typer.Option("--film-t-min", help="film's darkest transmission; "
                                                                         "default 0.02")] = None,
    film_t_max: Annotated[float | None, typer.Option("--film-t-max", help="film's clearest transmission; "
                                                                         "default 0.9")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="replace a finished design of another set-up in "
                                                                "the output folder")] = False,
) -> None:
    """Design masks by differentiable rendering through the real geometry for a registered task (tracking,
    counting, depth); compare with the baselines (hand where one exists, random, PCA, ideal-trained) on the
    task's held-out suite."""
    from mincam_sim.design import TASKS, run_design
    from mincam_sim.design.suite import table
    from mincam_sim.storage.store import lock_out_dir

    if task not in TASKS:
        raise ConfigError(f"unknown design task {task!r}: choose one of {', '.join(TASKS)}")
    bg = None
    if backgrounds is not None:
        try:
            bg = tuple(float(v) for v in backgrounds.split(","))
        except ValueError:
            raise ConfigError(f"--backgrounds must be comma-separated radiances (e.g. 0,0.2), got {backgrounds!r}") \
                from None
    if task != "tracking":
        _design_scene_task(task, out_dir, quick, seed, overwrite, dpi=dpi, spacing_m=spacing_m, d_f_m=d_f_m,
                           film_t_min=film_t_min, film_t_max=film_t_max,
                           tracking_only={"--config": config, "--object-size-cm": object_size_cm,
                                          "--backgrounds": backgrounds, "--depth-range-m": depth_range_m})
        return
    options = dict(object_size_range_m=_pair(object_size_cm, "--object-size-cm", 0.01), background_radiances=bg,
                   depth_range_m=_pair(depth_range_m, "--depth-range-m"), spacing_m=spacing_m, d_f_m=d_f_m,
                   film_t_min=film_t_min, film_t_max=film_t_max, dpi=dpi, seed=seed)
    overrides, from_file = _design_overrides(config, **options)
    seed = overrides.pop("seed", 0)  # an explicit --seed wins over the file's, as every option does
    from mincam_sim.design.run import check_printable, make_task

    with _design_fields_named(options, from_file):  # one clear error for a bad field before anything runs
        check_printable(make_task(quick, seed, **dict(overrides)))
    check_variant()
    check_out_dir(out_dir)
    _announce_variant()
    with lock_out_dir(out_dir):
        r = run_design(task, out_dir, quick=quick, seed=seed, show_progress=_show_progress(), overwrite=overwrite,
                       **overrides)
    typer.echo(f"gradient check: max relative error {r['gradient_check']['max_rel_error']:.2e} "
               f"over {r['gradient_check']['n_checked']} parameters")
    typer.echo("old held-out draw (squares 2-5 cm, black plane): avg / max error [% of field]   n")
    for key, label in (("baseline", "current ramps"), ("designed", "designed")):
        typer.echo(f"{label:<14} {_pct(r[key]['avg_error_pct'], 6)} / {_pct(r[key]['max_error_pct'], 8, '<')}"
                   f"              {r[key]['n']}")
    typer.echo("held-out suite: avg (designed / baseline) / max error [% of field]")
    typer.echo(table(r["suite"]))
    su = r["suite"]
    typer.echo(f"# designed beat the current ramps in {su['n_better']} of {su['n_cases']} suite cases "
               f"(<= half in {su['n_at_most_half']}, worse in {su['n_worse']}); old draw ratio "
               f"{r['goal']['designed_over_baseline_avg']:.2f}; design.json, masks, plots in {out_dir}")
    sm = su["summary"]
    typer.echo("# suite mean of avg error [% of field], lower is better: designed " + _pct(sm["designed"], 0) + "; "
               + ", ".join(f"{k} {_pct(v, 0)} (designed better in {sm['n_cases_designed_better'][k]}/{sm['n_cases']})"
                           for k, v in sm["baselines"].items()))


@app.command()
def figures(
    out_dir: Annotated[Path, typer.Option("--out", help="output folder")] = Path("scenes/figures"),
    wave_figure: Annotated[bool, typer.Option("--wave", help="also the wave-vs-geometric optics figure "
                                                             "(2-3 minutes of CPU)")] = False,
) -> None:
    """Write the README's figures (mixel geometry, masks, response maps; --wave: wave optics)."""
    from mincam_sim.plotting.figures import make_figures, make_wave_figure

    check_variant()
    check_out_dir(out_dir)
    for path in make_figures(out_dir):
        typer.echo(str(path))
    if wave_figure:
        typer.echo(str(make_wave_figure(out_dir / "wave_vs_geometric.png")))


INTERRUPTED_WHILE_STARTING = "error: interrupted while starting; nothing was run"
#: The commands that keep nothing of an interrupted run to resume from (each file they write appears whole or
#: not at all): a Ctrl-C says that the same command starts again, not that it resumes.
RESTARTING_COMMANDS = frozenset({"export_maps_command", "masks_generate", "masks_export", "figures", "demo"})
INTERRUPTED_RESTARTS = ("error: interrupted; no file is left half-written, and the same command starts again from "
                        "the beginning")


def _marked_started(callback: Any) -> Any:
    """``callback`` (a command's function), noting that a command began: a Ctrl-C before it (typer still parsing
    the command line, which imports pydantic the first time) ran nothing, and is answered so."""
    import functools

    @functools.wraps(callback)
    def started(*args: Any, **kwargs: Any) -> Any:
        _state["invoked"] = True
        _state["command"] = callback.__name__
        return callback(*args, **kwargs)

    return started


def _mark_commands(typer_app: typer.Typer) -> None:
    for info in typer_app.registered_commands:
        info.callback = _marked_started(info.callback)
    for group in typer_app.registered_groups:
        if group.typer_instance is not None:
            _mark_commands(group.typer_instance)


_mark_commands(app)


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point. A Ctrl-C while typer builds the commands (before any runs; inside one, the
    group's own handling answers it) is one line and exit code 130, as during the package's imports."""
    try:
        app(args=argv if argv is not None else sys.argv[1:], prog_name="mincam-sim")
    except KeyboardInterrupt:
        typer.echo(INTERRUPTED_WHILE_STARTING, err=True)
        raise SystemExit(130) from None


if __name__ == "__main__":
    main()
