"""Choice of the Mitsuba / Dr.Jit variant, in one place.

Order of preference: ``cuda_ad_mono`` when a CUDA device works, else ``llvm_ad_mono`` (vectorised CPU), else
``scalar_rgb`` with a one-line warning. The environment variable ``MINCAM_VARIANT`` (or the CLI flag
``--variant``) overrides the choice.

Dr.Jit's LLVM backend loads a system ``libLLVM`` at run time and needs version >= 16 (Debian 12's LLVM 15
loads, then aborts the process while compiling). The ``karellen-llvm-core`` wheel, a dependency of this
package on Linux x86_64, ships ``libLLVM.so.23.1`` inside the environment;
``mincam_sim.llvm_path.configure_libllvm`` points ``DRJIT_LIBLLVM_PATH`` at it before Dr.Jit is imported
(``import mincam_sim`` does), unless the user already set that variable.
"""

from __future__ import annotations

import os
import warnings
from functools import cache
from types import ModuleType

from mincam_sim import interrupts
from mincam_sim.errors import BackendUnavailableError
from mincam_sim.llvm_path import bundled_libllvm, configure_libllvm

ENV_VARIANT = "MINCAM_VARIANT"
SUPPORTED_VARIANTS = ("cuda_ad_mono", "llvm_ad_mono", "scalar_rgb")
JIT_VARIANTS = ("cuda_ad_mono", "llvm_ad_mono")

_requested: str | None = None


def request_variant(variant: str | None) -> None:
    """Ask for a variant before the first render (the CLI's ``--variant``). ``None`` means automatic."""
    global _requested
    if variant is not None and variant not in SUPPORTED_VARIANTS:
        raise ValueError(f"unknown Mitsuba variant {variant!r}: choose one of {', '.join(SUPPORTED_VARIANTS)}")
    if _requested != variant and _loaded_variant.cache_info().currsize:
        current = _loaded_variant()
        if variant is not None and current != variant:
            raise RuntimeError(
                f"Mitsuba variant is already {current!r} in this process; request {variant!r} before rendering"
            )
    _requested = variant


def _wanted_variant() -> str | None:
    wanted = _requested or os.environ.get(ENV_VARIANT) or None
    if wanted is not None and wanted not in SUPPORTED_VARIANTS:
        raise ValueError(
            f"{ENV_VARIANT}={wanted!r} is not a supported variant: choose one of {', '.join(SUPPORTED_VARIANTS)}"
        )
    return wanted


@cache
def _loaded_variant() -> str:
    with interrupts.held():  # a Ctrl-C inside Dr.Jit's native start-up aborted the process
        return _load_variant()


def _load_variant() -> str:
    configure_libllvm()
    import drjit as dr
    import mitsuba as mi

    wanted = _wanted_variant()
    if wanted is not None:
        if wanted.startswith("llvm"):
            check_libllvm(dr)
        mi.set_variant(wanted)
        return wanted
    if dr.has_backend(dr.JitBackend.CUDA):
        mi.set_variant("cuda_ad_mono")
        return "cuda_ad_mono"
    if dr.has_backend(dr.JitBackend.LLVM):
        check_libllvm(dr)
        mi.set_variant("llvm_ad_mono")
        return "llvm_ad_mono"
    warnings.warn(
        "mincam_sim: no CUDA device and no usable libLLVM (>= 16) found; falling back to the slow 'scalar_rgb' "
        "variant (fast forms and response maps need llvm_ad_mono: pip install karellen-llvm-core)",
        RuntimeWarning,
        stacklevel=3,
    )
    mi.set_variant("scalar_rgb")
    return "scalar_rgb"


MIN_LLVM = 16  # Dr.Jit's LLVM backend aborts the process on LLVM 15 ("LLVM ERROR: Cannot select")


def check_libllvm(dr) -> None:
    """Refuse, with the fix, a libLLVM older than :data:`MIN_LLVM` that Dr.Jit picked by itself (it does when
    ``mitsuba`` or ``drjit`` is imported before this package): compiling a kernel would abort the process."""
    try:
        version = tuple(dr.detail.llvm_version())
    except (AttributeError, RuntimeError, TypeError):  # no LLVM loaded, or a Dr.Jit without the query
        return
    if version and version[0] < MIN_LLVM:
        bundled = bundled_libllvm()
        fix = (f"import mincam_sim before mitsuba / drjit, or start Python with DRJIT_LIBLLVM_PATH={bundled}"
               if bundled else "install karellen-llvm-core (or a system libLLVM >= 16) and import mincam_sim first")
        raise BackendUnavailableError(
            f"Dr.Jit loaded libLLVM {'.'.join(map(str, version))} (it was imported before mincam_sim could point it "
            f"at a libLLVM >= {MIN_LLVM}); that version aborts the process on the first kernel: {fix}")


def mitsuba() -> ModuleType:
    """The ``mitsuba`` module with this package's variant set (chosen on first call)."""
    _loaded_variant()
    import mitsuba as mi

    return mi


def variant() -> str:
    """Name of the Mitsuba variant in use (chosen on first call)."""
    return _loaded_variant()


def is_jit() -> bool:
    """True for vectorised (LLVM/CUDA) variants, which Python plugins and response maps need."""
    return variant() in JIT_VARIANTS


def require_jit(what: str) -> None:
    """Raise a clear error when ``what`` needs a vectorised variant and the scalar fallback is active."""
    if not is_jit():
        raise RuntimeError(
            f"{what} needs a vectorised Mitsuba variant (llvm_ad_mono or cuda_ad_mono), but the active one is "
            f"{variant()!r}; install karellen-llvm-core (or a system libLLVM >= 16) or set {ENV_VARIANT}"
        )


def cap_threads(threads: int) -> None:
    """Limit Dr.Jit's thread pool in this process (several worker processes share the cores)."""
    configure_libllvm()
    import drjit as dr

    if dr.thread_count() != int(threads):
        dr.set_thread_count(int(threads))


def describe() -> dict[str, str]:
    """Metadata recorded with every output: variant and library versions."""
    import drjit as dr
    import mitsuba as mi

    return {
        "variant": variant(),
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH", ""),
    }
