"""Mask files: PNG / OpenEXR / NumPy ``.npy`` in (grayscale or RGB -> luma, alpha refused), OpenEXR out with
metadata."""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.masks.freeform import is_npy, load_npy
from mincam_sim.masks.mask import Mask
from mincam_sim.storage import imageio
from mincam_sim.storage.atomic import atomic_path

_LUMA_709 = np.array([0.2126, 0.7152, 0.0722])


def _to_transmission(arr: np.ndarray, channels: list[str], src: str) -> np.ndarray:
    """Reduce an image (H, W) or (H, W, C) to one transmission channel."""
    if arr.ndim == 2:
        return arr
    names = list(channels)
    if "A" in names:
        alpha = arr[..., names.index("A")]
        if np.any(alpha < 1.0 - 1e-6):
            raise InputError(
                f"mask file {src!r} has a transparent alpha channel; transmission would be ambiguous:"
                " flatten the image onto white or black and save it without alpha"
            )
        keep = [k for k, n in enumerate(names) if n != "A"]
        arr, names = arr[..., keep], [names[k] for k in keep]
        if arr.shape[-1] == 1:
            return arr[..., 0]
    if "Y" in names:
        return arr[..., names.index("Y")]
    if all(c in names for c in ("R", "G", "B")) and len(names) == 3:
        rgb = np.stack([arr[..., names.index(c)] for c in ("R", "G", "B")], axis=-1)
        return rgb @ _LUMA_709
    raise InputError(
        f"mask file {src!r} has {arr.shape[-1]} channels ({', '.join(names)}); give a single-channel"
        " grayscale (PNG 'L' / EXR 'Y') or an RGB image"
    )


def load(path: str | Path, width_m: float | None = None, height_m: float | None = None, invert: bool = False,
         name: str | None = None, encoding: str = "linear") -> Mask:
    """Load a mask from a PNG (8/16-bit), OpenEXR or NumPy ``.npy`` file (a 2D float array in [0, 1]: a freeform
    mask; ``width_m`` required).

    Parameters
    ----------
    path : str or Path
        Image file; the format is detected from its content. Image row 0 (top) is mask row 0 (top as seen from
        the detector looking out), i.e. the picture overlays the scene as the mixel sees it.
    width_m : float, optional
        Physical mask width [m]. Required for PNG; for EXR files written by :func:`save_exr` it defaults to
        the stored size.
    height_m : float, optional
        Physical mask height [m]; defaults to the stored size (EXR) or ``width_m * H / W`` (square texels).
    invert : bool
        Use ``1 - value`` (for files where black means clear).
    name : str, optional
        Mask name; defaults to the stored name (EXR) or the file stem.
    encoding : {"linear", "srgb"}
        Transfer function of PNG values: ``"linear"`` (default: the value / 255 or / 65535 *is* the
        transmission) or ``"srgb"`` (the values are sRGB-encoded, as most image editors write them, and are
        decoded with the IEC 61966-2-1 curve before anything else). OpenEXR files are linear by definition; asking
        ``"srgb"`` for one is refused.

    Returns
    -------
    Mask
        ``meta`` records the source file and format (and, for EXR, the stored metadata).

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    InputError
        For an empty, unreadable or non-image file, an unsupported channel layout, NaN/infinite values, values
        outside [0, 1] (EXR) or a missing/invalid physical size.

    Notes
    -----
    PNG values are divided by 255 (8-bit) or 65535 (16-bit). With ``encoding = "linear"`` that value is the
    transmission (no gamma decoding: a mid-grey 128 passes 50.2 %); with ``"srgb"`` it is decoded first (128
    passes 21.6 %). RGB images are reduced to luminance with the Rec. 709 weights 0.2126 R + 0.7152 G + 0.0722 B
    applied to the (decoded) values. An alpha channel is accepted only if fully opaque.
    """
    if is_npy(path):
        return _npy_mask(Path(path), width_m, height_m, invert, name, encoding)
    p, fmt = _source(path, encoding)
    t, info, stored = _read_exr(p) if fmt == "exr" else _read_png(p, encoding)
    width_m, height_m = _physical_size(p, t.shape, width_m, height_m, stored, info)
    t = 1.0 - t if invert else t
    label = name if name is not None else str(stored.get("name") or p.stem)
    return Mask(t, width_m, height_m, label, _file_meta(p, fmt, invert, encoding, stored, info))


def _npy_mask(p: Path, width_m: float | None, height_m: float | None, invert: bool, name: str | None,
              encoding: str) -> Mask:
    """A freeform mask from a ``.npy`` array (linear transmission in [0, 1]; its size must be given)."""
    if width_m is None:
        raise InputError(f"mask file {str(p)!r} (a NumPy array) has no physical size: give width_m in metres")
    if encoding != "linear":
        raise InputError(f"mask file {str(p)!r} is a NumPy array of linear transmissions; the sRGB encoding applies "
                         "to PNG files only (use mask_encoding = \"linear\")")
    mask = load_npy(p, width_m, height_m, name)
    if invert:
        mask = Mask(1.0 - mask.transmission, mask.width_m, mask.height_m, mask.name, {**mask.meta, "invert": True})
    return mask


def _source(path: str | Path, encoding: str) -> tuple[Path, str]:
    """The file and its format (``"png"`` / ``"exr"``, from its content), checked against ``encoding``."""
    if encoding not in ("linear", "srgb"):
        raise InputError(f"encoding must be 'linear' or 'srgb', got {encoding!r}")
    p = Path(path)
    with _unreadable_file_is_input_error():
        fmt = imageio.sniff_format(p, "mask file")
    if fmt == "exr" and encoding == "srgb":
        raise InputError(f"mask file {str(p)!r} is OpenEXR, whose values are linear transmission; the sRGB "
                         "encoding applies to PNG files only (use mask_encoding = \"linear\")")
    return p, fmt


@contextlib.contextmanager
def _unreadable_file_is_input_error() -> Iterator[None]:
    """The image reader's ``ValueError`` (a directory, an empty, damaged or non-image file) as the
    :class:`~mincam_sim.errors.InputError` that :func:`load` promises, with the reader's message."""
    try:
        yield
    except InputError:
        raise
    except ValueError as err:
        refused = InputError(str(err))
        for note in getattr(err, "__notes__", ()):  # what the image library said (see _library_output_held)
            refused.add_note(note)
        raise refused from None


_C_OUTPUT_LOCK = threading.Lock()


def _flush_c_streams() -> None:
    """Flush the C library's buffered streams (``std::cout`` writes through C's ``stdout`` buffer)."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def _library_output_held() -> Iterator[None]:
    """Hold what a native library prints to the standard output and error inside the block.

    OpenEXR prints its own lines about a damaged file before it raises: ``t.exr: (EXR_ERR_BAD_CHUNK_LEADER) ...``
    from C straight to file descriptor 2, ``Warning: Exception raised reading pixel data ...`` through Python's
    ``sys.stdout``; the caller's one ``error:`` line says what is wrong. Both levels are held: the descriptors 1
    and 2 (where they can be redirected) and ``sys.stdout`` / ``sys.stderr``. When the block ends without an
    exception, what was held is written where it was going (nothing is lost); when it raises, it is added to the
    exception as a note instead (shown with its traceback, e.g. under ``--debug``)."""
    with _C_OUTPUT_LOCK, tempfile.TemporaryFile() as out_sink, tempfile.TemporaryFile() as err_sink:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        _flush_c_streams()
        saved: dict[int, tuple[int, Any]] = {}
        with contextlib.suppress(OSError):  # a closed descriptor: only Python's streams are held
            for fd, sink in ((1, out_sink), (2, err_sink)):
                copy = os.dup(fd)
                saved[fd] = (copy, sink)
                os.dup2(sink.fileno(), fd)
        python = {1: io.StringIO(), 2: io.StringIO()}
        native: dict[int, bytes] = {}
        try:
            with contextlib.redirect_stdout(python[1]), contextlib.redirect_stderr(python[2]):
                yield
        except BaseException as err:
            _restore(saved, native)
            text = "\n".join(part for part in (
                *(python[fd].getvalue().strip() for fd in (1, 2)),
                *(native.get(fd, b"").decode("utf-8", errors="replace").strip() for fd in (1, 2))) if part)
            if text:
                err.add_note(f"OpenEXR said:\n{text}")
            raise
        _restore(saved, native)
        for fd, stream in ((1, sys.stdout), (2, sys.stderr)):
            with contextlib.suppress(Exception):
                if python[fd].getvalue():
                    stream.write(python[fd].getvalue())
                    stream.flush()
                if native.get(fd):
                    os.write(fd, native[fd])


def _restore(saved: dict[int, tuple[int, Any]], native: dict[int, bytes]) -> None:
    """Put the descriptors back and keep in ``native`` what was written to each meanwhile."""
    _flush_c_streams()
    for fd, (copy, sink) in saved.items():
        os.dup2(copy, fd)
        os.close(copy)
        sink.seek(0)
        if data := sink.read():
            native[fd] = data
    saved.clear()


def _read_exr(p: Path) -> tuple[np.ndarray, dict, dict]:
    """An OpenEXR mask's transmission (finite, in [0, 1]), its header and the stored metadata (the same dict).

    OpenEXR's own lines about a damaged file are held back (:func:`_library_output_held`): a truncated file is
    one ``ValueError`` saying so, nothing more."""
    with _unreadable_file_is_input_error(), _library_output_held():
        arr, info = imageio.read_exr(p)
    arr = np.asarray(arr, dtype=np.float64)
    t = _to_transmission(arr, info["channels"], str(p))
    bad = ~np.isfinite(t)
    if bad.any():
        raise InputError(
            f"mask file {str(p)!r}: {int(bad.sum())} pixel(s) are NaN or infinite;"
            " transmission must be finite numbers in [0, 1]"
        )
    lo, hi = float(t.min()), float(t.max())
    if lo < 0.0 or hi > 1.0:
        raise InputError(
            f"mask file {str(p)!r}: values span [{lo:.4g}, {hi:.4g}] but transmission must lie in [0, 1];"
            " rescale the image (e.g. divide by its maximum) or clip it before loading"
        )
    return t, info, info


def _read_png(p: Path, encoding: str) -> tuple[np.ndarray, dict, dict]:
    """A PNG mask's transmission (value / 255 or / 65535, sRGB-decoded if asked), its info and no stored metadata."""
    with _unreadable_file_is_input_error():
        arr, info = imageio.read_png(p)
    if encoding == "srgb":
        arr = np.asarray(arr, dtype=np.float64).copy()
        colour = [k for k, c in enumerate(info["channels"]) if c != "A"] if arr.ndim == 3 else None
        if colour is None:
            arr = srgb_to_linear(arr)
        else:
            arr[..., colour] = srgb_to_linear(arr[..., colour])
    return _to_transmission(arr, info["channels"], str(p)), info, {}


def _physical_size(p: Path, shape: tuple[int, int], width_m: float | None, height_m: float | None, stored: dict,
                   info: dict) -> tuple[float, float]:
    """The mask's width and height [m]: given, else stored (EXR), else (height) square texels.

    Raises
    ------
    InputError
        No width given or stored (naming the width the file's dpi implies, if it records one).
    """
    h, w = shape
    if width_m is None:
        width_m = stored.get("width_m")
    if width_m is None:
        hint = ""
        if "dpi" in info and info["dpi"][0] > 0:
            dpi_x = info["dpi"][0]
            hint = f" (the file says {dpi_x:g} dpi, i.e. width_m={w / dpi_x * 0.0254:.6g} m)"
        raise InputError(f"mask file {str(p)!r} has no physical size: give width_m in metres{hint}")
    if height_m is None:
        same_width = "width_m" in stored and width_m == stored.get("width_m")
        height_m = stored.get("height_m") if same_width else None
    if height_m is None:
        height_m = float(width_m) * h / w
    return width_m, height_m


def _file_meta(p: Path, fmt: str, invert: bool, encoding: str, stored: dict, info: dict) -> dict:
    """The mask's ``meta``: the stored one (EXR), then the source file, format, invert (encoding, PNG bit depth)."""
    meta = dict(stored.get("meta", {})) if isinstance(stored.get("meta"), dict) else {}
    meta.update({"source": str(p), "format": fmt, "invert": bool(invert)})
    if encoding != "linear":  # recorded only when not the default (older records stay the same)
        meta["encoding"] = encoding
    if fmt == "png":
        meta["bit_depth"] = info["bit_depth"]
    return meta


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """Decode sRGB-encoded values in [0, 1] to linear (IEC 61966-2-1: v / 12.92 below 0.04045, else
    ((v + 0.055) / 1.055) ** 2.4)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def save_exr(mask: Mask, path: str | Path) -> Path:
    """Write a mask to OpenEXR (one float32 channel ``Y`` = transmission) with its physical size.

    The header records ``width_m``, ``height_m``, ``units`` ("m"), ``name``, the array convention and the
    mask's ``meta``; :func:`load` reads them back (values exact to float32, ~6e-8).

    The file is written atomically (a temporary file beside it, moved into place when complete).

    Returns
    -------
    Path
        The written file.
    """
    metadata = {
        "width_m": mask.width_m,
        "height_m": mask.height_m,
        "units": "m",
        "name": mask.name,
        "quantity": "transmission",
        "convention": "row 0 = top, column 0 = left, as seen from the detector looking out",
        "meta": mask.meta,
    }
    path = Path(path)
    with atomic_path(path) as tmp:  # a full disk or a kill leaves the old file or none, never a torn one
        imageio.write_exr(tmp, mask.transmission, ("Y",), metadata)
    return path
