"""Where Dr.Jit finds libLLVM: the ``karellen-llvm-core`` wheel's, set before Dr.Jit is first imported.

Dr.Jit's LLVM backend loads a ``libLLVM`` at run time, the first time ``drjit`` is imported, and needs version
>= 16 (Debian 12's LLVM 15 loads, then aborts the process on the first kernel). ``import mincam_sim`` points
``DRJIT_LIBLLVM_PATH`` at the libLLVM shipped inside the environment, so that a user who imports ``drjit`` or
``mitsuba`` after ``mincam_sim`` gets it too; a variable the user set is left as it is. Pure standard library:
the package's facade imports it eagerly.
"""

from __future__ import annotations

import importlib.metadata
import os
import sys
from pathlib import Path


def bundled_libllvm() -> Path | None:
    """Path of the libLLVM shipped by the ``karellen-llvm-core`` wheel, or None if it is not installed."""
    try:
        files = importlib.metadata.files("karellen-llvm-core") or []
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in files:
        if f.name.startswith("libLLVM.so."):
            path = Path(f.locate()).resolve()
            if path.exists():
                return path
    return None


def configure_libllvm() -> str | None:
    """Set ``DRJIT_LIBLLVM_PATH`` to the bundled libLLVM if the user did not set it; return the path used."""
    if "drjit" in sys.modules and "DRJIT_LIBLLVM_PATH" not in os.environ:
        # Too late to steer Dr.Jit: it has already looked for libLLVM.
        return None
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = bundled_libllvm()
        if lib is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = str(lib)
    return os.environ.get("DRJIT_LIBLLVM_PATH")


__all__ = ["bundled_libllvm", "configure_libllvm"]
