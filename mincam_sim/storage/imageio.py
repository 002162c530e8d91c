"""Image file input/output for masks and rendered measurements: OpenEXR (float) and PNG (8/16-bit).

Arrays follow the package convention: row 0 is the *top* of the image, column 0 the *left*; single-channel
images are (H, W), multi-channel images (H, W, C).

OpenEXR files are written with the OpenEXR 3.x Python bindings (``OpenEXR.File``). EXR stores 32-bit floats
(float64 input is rounded to float32). Metadata is stored in the header as one JSON string attribute
(``mincam_metadata``) so that numbers, lists and nested dicts survive a round trip; string attributes that
other tools put in the header are returned as well.

PNG files are read and written with Pillow as grayscale (8 or 16 bit); reading also accepts RGB/RGBA,
palette and 1-bit images. PNG values are normalised to [0, 1] (value / 255 or value / 65535).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

EXR_MAGIC = b"\x76\x2f\x31\x01"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
METADATA_KEY = "mincam_metadata"
CHANNEL_ORDER_KEY = "mincam_channel_order"
_INCH_M = 0.0254  # [m]


# ----------------------------------------------------------------------------------------------- helpers
def _existing_file(path: str | Path, what: str = "image file") -> Path:
    """Check that ``path`` is a non-empty regular file and return it as a Path."""
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{what} {str(p)!r} does not exist; check the path")
    if not p.is_file():
        raise ValueError(f"{what} {str(p)!r} is not a regular file (is it a directory?)")
    if p.stat().st_size == 0:
        raise ValueError(f"{what} {str(p)!r} is empty (0 bytes); give a PNG or OpenEXR image")
    return p


def sniff_format(path: str | Path, what: str = "image file") -> str:
    """Image format of a file from its first bytes.

    Parameters
    ----------
    path : str or Path
        File to inspect.
    what : str
        Noun used in error messages (e.g. ``"mask file"``).

    Returns
    -------
    str
        ``"exr"`` or ``"png"``.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is empty or neither a PNG nor an OpenEXR image.
    """
    p = _existing_file(path, what)
    with p.open("rb") as fh:
        head = fh.read(8)
    if head.startswith(EXR_MAGIC):
        return "exr"
    if head.startswith(PNG_MAGIC):
        return "png"
    raise ValueError(
        f"{what} {str(p)!r} is not an image this package reads (first bytes {head[:8]!r});"
        " give a PNG (8/16-bit) or an OpenEXR (.exr) file"
    )


def _jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays, tuples and Paths to JSON-serialisable builtins."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float | int | str | bool) or value is None:
        return value
    return repr(value)


def _default_channels(c: int) -> tuple[str, ...]:
    if c == 1:
        return ("Y",)
    if c == 3:
        return ("R", "G", "B")
    if c == 4:
        return ("R", "G", "B", "A")
    return tuple(f"C{k}" for k in range(c))


# ----------------------------------------------------------------------------------------------- OpenEXR
def write_exr(
    path: str | Path,
    array: np.ndarray,
    channels: Sequence[str] | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> Path:
    """Write a float image to an OpenEXR file (32-bit float, ZIP compression, scanline).

    Parameters
    ----------
    path : str or Path
        Output file; parent directories are created.
    array : (H, W) or (H, W, C) array_like of float
        Pixel values, row 0 at the top. Stored as float32.
    channels : sequence of str, optional
        Channel names, one per channel. Default: ``("Y",)`` for one channel, ``("R", "G", "B")`` for three,
        ``("R", "G", "B", "A")`` for four, otherwise ``C0, C1, ...``. The order is recorded in the header
        so :func:`read_exr` restores it (EXR itself stores channels alphabetically).
    metadata : mapping, optional
        Extra information (e.g. ``{"width_m": 2e-3, "units": "m"}``), stored as JSON in the header
        attribute ``mincam_metadata``. Values must be JSON-serialisable (numpy values are converted).

    Returns
    -------
    Path
        The written file.
    """
    import OpenEXR

    a = np.asarray(array)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3:
        raise ValueError(f"write_exr: array must be (H, W) or (H, W, C), got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"write_exr: array of shape {a.shape} is empty; nothing to write")
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"write_exr: array must hold real numbers, got dtype {a.dtype}")
    c = a.shape[2]
    names = _default_channels(c) if channels is None else tuple(channels)
    if len(names) != c:
        raise ValueError(f"write_exr: {len(names)} channel name(s) {names} for an array with {c} channel(s)")
    if len(set(names)) != c or any(not n for n in names):
        raise ValueError(f"write_exr: channel names must be distinct and non-empty, got {names}")
    meta = {} if metadata is None else _jsonable(dict(metadata))
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        METADATA_KEY: json.dumps(meta, sort_keys=True),
        CHANNEL_ORDER_KEY: json.dumps(list(names)),
    }
    pixels = {n: np.ascontiguousarray(a[..., k], dtype=np.float32) for k, n in enumerate(names)}
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    with OpenEXR.File(header, pixels) as f:
        f.write(str(p))
    return p


def read_exr(path: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """Read an OpenEXR image.

    Parameters
    ----------
    path : str or Path
        EXR file (single part, scanline or tiled).

    Returns
    -------
    array : ndarray
        (H, W) for one channel, (H, W, C) otherwise; float32 (half and uint channels are converted), row 0 at
        the top.
    metadata : dict
        The JSON metadata written by :func:`write_exr` plus any other string header attributes, and
        ``"channels"``: the channel names in array order.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If it is empty, not an OpenEXR file, or cannot be decoded.
    """
    import OpenEXR

    p = _existing_file(path, "EXR file")
    if sniff_format(p, "EXR file") != "exr":
        raise ValueError(f"EXR file {str(p)!r} is not an OpenEXR image (it looks like a PNG); use read_png")
    try:
        with OpenEXR.File(str(p), separate_channels=True) as f:
            header = dict(f.header())
            chans = {name: np.array(ch.pixels) for name, ch in f.channels().items()}
    except Exception as exc:  # the bindings raise RuntimeError for truncated/corrupt files
        raise ValueError(
            f"EXR file {str(p)!r} could not be decoded ({exc}); is it truncated or corrupt?"
        ) from exc
    if not chans:
        raise ValueError(f"EXR file {str(p)!r} has no channels; give an image with at least one channel")

    meta: dict[str, Any] = {}
    for k, v in header.items():
        if isinstance(v, str) and k not in (METADATA_KEY, CHANNEL_ORDER_KEY):
            meta[k] = v
    if METADATA_KEY in header:
        try:
            meta.update(json.loads(header[METADATA_KEY]))
        except (TypeError, json.JSONDecodeError):
            meta[METADATA_KEY] = header[METADATA_KEY]
    order: list[str] = []
    if CHANNEL_ORDER_KEY in header:
        try:
            order = [n for n in json.loads(header[CHANNEL_ORDER_KEY]) if n in chans]
        except (TypeError, json.JSONDecodeError):
            order = []
    if sorted(order) != sorted(chans):
        rgba = [n for n in ("R", "G", "B", "A") if n in chans]
        order = rgba + sorted(n for n in chans if n not in rgba)
    shapes = {chans[n].shape for n in order}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(
            f"EXR file {str(p)!r} has channels of different shapes {sorted(shapes)} (subsampled channels);"
            " give an image whose channels are all full resolution"
        )
    arrays = [chans[n].astype(np.float32, copy=False) for n in order]
    out = arrays[0] if len(arrays) == 1 else np.stack(arrays, axis=-1)
    meta["channels"] = order
    return out, meta


# ----------------------------------------------------------------------------------------------- PNG
def write_png(
    path: str | Path,
    array: np.ndarray,
    bit_depth: int = 16,
    dpi: float | None = None,
) -> Path:
    """Write a grayscale PNG from values in [0, 1].

    Parameters
    ----------
    path : str or Path
        Output file; parent directories are created.
    array : (H, W) array_like of float
        Values in [0, 1] (0 = black, 1 = white), row 0 at the top; stored as
        ``round(v * (2**bit_depth - 1))``.
    bit_depth : {8, 16}
        Bits per pixel.
    dpi : float, optional
        Resolution [dots per inch] stored in the PNG ``pHYs`` chunk (needed by printers to get the physical
        size right).

    Returns
    -------
    Path
        The written file.
    """
    from PIL import Image

    a = np.asarray(array, dtype=np.float64)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim != 2:
        raise ValueError(f"write_png: a grayscale (H, W) array is required, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"write_png: array of shape {a.shape} is empty; nothing to write")
    if not np.isfinite(a).all():
        raise ValueError("write_png: array contains NaN or infinite values")
    lo, hi = float(a.min()), float(a.max())
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"write_png: values must lie in [0, 1], got [{lo:.4g}, {hi:.4g}]")
    if bit_depth not in (8, 16):
        raise ValueError(f"write_png: bit_depth must be 8 or 16, got {bit_depth!r}")
    top = 2**bit_depth - 1
    q = np.rint(a * top)
    im = Image.fromarray(q.astype(np.uint8 if bit_depth == 8 else np.uint16))
    kwargs: dict[str, Any] = {}
    if dpi is not None:
        if not (np.isfinite(dpi) and dpi > 0):
            raise ValueError(f"write_png: dpi must be a positive number, got {dpi!r}")
        kwargs["dpi"] = (float(dpi), float(dpi))
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    im.save(p, format="PNG", **kwargs)
    return p


def read_png(path: str | Path) -> tuple[np.ndarray, dict[str, Any]]:
    """Read a PNG image as floats in [0, 1].

    Parameters
    ----------
    path : str or Path
        PNG file: grayscale (8/16-bit), gray+alpha, RGB(A) or palette.

    Returns
    -------
    array : ndarray of float64
        (H, W) for grayscale, (H, W, C) with C in {2, 3, 4} for gray+alpha / RGB / RGBA; values divided by
        255 (8-bit) or 65535 (16-bit). Row 0 at the top.
    info : dict
        ``"bit_depth"`` (8 or 16), ``"mode"`` (Pillow mode), ``"channels"`` (names, e.g. ``["L"]`` or
        ``["R", "G", "B"]``) and ``"dpi"`` (x, y) [dots per inch] when the file records it.

    Notes
    -----
    Pillow reduces 16-bit RGB PNGs to 8 bits per channel; 16-bit precision is kept for grayscale only.
    """
    from PIL import Image, UnidentifiedImageError

    p = _existing_file(path, "PNG file")
    if sniff_format(p, "PNG file") != "png":
        raise ValueError(f"PNG file {str(p)!r} is not a PNG image (it looks like OpenEXR); use read_exr")
    try:
        with Image.open(p) as im:
            im.load()
            mode = im.mode
            info = dict(im.info)
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in info else "RGB")
            elif mode == "1":
                im = im.convert("L")
            a = np.array(im)
            out_mode = im.mode
    except (UnidentifiedImageError, OSError, SyntaxError) as exc:
        raise ValueError(
            f"PNG file {str(p)!r} could not be decoded ({exc}); is it truncated or corrupt?"
        ) from exc
    if out_mode in ("I;16", "I;16B", "I;16L", "I"):
        bit_depth, scale = 16, 65535.0
    elif a.dtype == np.uint8:
        bit_depth, scale = 8, 255.0
    else:
        raise ValueError(
            f"PNG file {str(p)!r} has unsupported pixel mode {mode!r}; give 8/16-bit gray or RGB"
        )
    arr = a.astype(np.float64) / scale
    if arr.size == 0:
        raise ValueError(f"PNG file {str(p)!r} has no pixels; give a non-empty image")
    chans = {"LA": ["L", "A"], "RGB": ["R", "G", "B"], "RGBA": ["R", "G", "B", "A"]}.get(out_mode, ["L"])
    meta: dict[str, Any] = {"bit_depth": bit_depth, "mode": mode, "channels": chans}
    if "dpi" in info:
        meta["dpi"] = tuple(float(round(d, 2)) for d in info["dpi"])  # pHYs is integer px/m
    return arr, meta


def dpi_to_dots_per_m(dpi: float) -> float:
    """Convert dots per inch to dots per metre (1 inch = 0.0254 m)."""
    return float(dpi) / _INCH_M
