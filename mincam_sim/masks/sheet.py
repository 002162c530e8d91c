"""Print sheets: every mask of a mincam on one page at its place and spacing, at the printer's dots, with crop and
registration marks, the side that faces the detectors marked, and the film mapping and dpi printed on the sheet
and in a text file beside it (:func:`write_print_sheet`). Pure numpy + Pillow (+ matplotlib for PDF).

Sheet geometry: the page is what the detectors see looking out through the film (the convention of every mask
array and of :func:`~mincam_sim.masks.export_print_png`): mask centre ``(x, y)`` [m] (x right, y up, from the
mincam's centre) lands ``x`` right and ``y`` up of the page's reference centre (the registration marks' centre).
Each mask is its own printer-dot grid (``round(size * dpi / 0.0254)`` dots a side, as
:meth:`~mincam_sim.masks.PrintedFilm.print` models it), placed on the nearest dot: a centre is off by at most half
a dot (21 um at 600 dpi).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from mincam_sim.errors import InputError
from mincam_sim.masks.mask import MAX_TEXELS, Mask, resample
from mincam_sim.masks.printing import PrintedFilm, _dot_grid, few_print_dots, png_bit_depth, warn_few_print_dots
from mincam_sim.storage import imageio
from mincam_sim.storage.atomic import atomic_path, atomic_write_text

MM = 1e-3
MARGIN_M = 8 * MM  # [m] blank border around the masks: crop marks and registration marks live in it
CROP_GAP_M = 1.0 * MM  # [m] gap between a mask's edge and its crop marks
CROP_LEN_M = 3.0 * MM  # [m] length of a crop mark
REG_RADIUS_M = 2.0 * MM  # [m] registration mark (circle and cross) radius
SCALE_BAR_M = 10 * MM  # [m] scale bar to check the print was not scaled
TEXT_PT = 7.0  # text size [pt]


@dataclass(frozen=True)
class SheetPlacement:
    """Where one mask lies on the sheet (pixel rows/cols from the top left; metres from the reference centre)."""

    name: str
    centre_m: tuple[float, float]
    top_left_px: tuple[int, int]
    shape_px: tuple[int, int]


def _line_px(dpi: float, width_m: float = 0.15 * MM) -> int:
    return max(1, round(width_m * dpi / 0.0254))


def _px(length_m: float, dpi: float) -> int:
    return int(round(length_m * dpi / 0.0254))


def _film_text(film: PrintedFilm | None, dpi: float) -> str:
    if film is None:
        return (f"{dpi:g} dpi; grey value v in [0, 1] (PNG value / 255) is the wanted transmission "
                "(no film model: measure your film)")
    tone = "ordered 8x8 halftone" if film.halftone else (f"{film.levels} grey levels" if film.levels else
                                                        "continuous grey")
    return (f"{dpi:g} dpi, {tone}; film: transmission = {film.t_min:g} + ({film.t_max:g} - {film.t_min:g}) "
            f"* v^{film.gamma:g}, v = printer grey in [0, 1] (0 = full ink)")


def write_print_sheet(masks: Sequence[Mask], positions_m: Sequence[Sequence[float]], dpi: float,
                      film: PrintedFilm | None, path: str | Path, names: Sequence[str] | None = None,
                      title: str = "") -> tuple[Path, Path]:
    """Write a print sheet (PNG at ``dpi`` or a PDF of that page) of every mask at its place, and its notes.

    Parameters
    ----------
    masks : sequence of Mask
        The masks, as seen from the detector looking out (row 0 at the top).
    positions_m : sequence of (x, y)
        Each mask's centre [m] in the mincam's plane: x right, y up, as seen from the detectors looking out (the
        in-plane offsets of :func:`mincam_sim.model.optics.layout`).
    dpi : float
        Printer resolution [dots per inch]; the PNG records it so that printing at 100 % keeps every size.
    film : PrintedFilm or None
        With a film, each mask's dots are the film's printer input (quantised or halftoned) and the mapping from
        grey to transmission is printed; None: the masks' transmission is printed as grey.
    path : str or Path
        ``.png`` or ``.pdf``. A text file ``<name>.txt`` beside it repeats the notes (film mapping, dpi, each
        mask's place and size). Both are written atomically.
    names : sequence of str, optional
        Labels (default: the mask names).
    title : str
        First line of the notes.

    Returns
    -------
    (Path, Path)
        The sheet and its text file.

    Raises
    ------
    InputError
        No masks, a position per mask missing, masks that overlap on the sheet, a sheet too large at ``dpi``, or a
        file name that is neither ``.png`` nor ``.pdf``.

    Warns
    -----
    PrintWarning
        A mask that prints as fewer than :data:`~mincam_sim.masks.printing.MIN_PRINT_DOTS` dots a side; the
        sheet is written all the same (:func:`check_print_sheet` refuses it instead).
    """
    path, kind = _checked_path(path)
    film, masks, pos, labels, notes, layout = _checked_sheet(masks, positions_m, dpi, film, names, title)
    for m, label in zip(masks, labels, strict=True):
        warn_few_print_dots(m.width_m, m.height_m, dpi, f"mask {label!r}")
    bit_depth = png_bit_depth(film)
    sheet, placements = _draw_sheet(layout, notes, labels, pos, masks, film, dpi)
    _write_sheet(sheet, kind, path, bit_depth, dpi)
    notes_path = atomic_write_text(path.with_suffix(".txt"), _notes_text(notes, placements, layout, dpi))
    return path, notes_path


def check_print_sheet(masks: Sequence[Mask], positions_m: Sequence[Sequence[float]], dpi: float,
                      film: PrintedFilm | None = None, names: Sequence[str] | None = None, title: str = "") -> None:
    """Refuse, before anything is written, what :func:`write_print_sheet` would refuse for these masks.

    Parameters are those of :func:`write_print_sheet` (without the file).

    Raises
    ------
    InputError
        No masks, a position or label per mask missing, a dpi out of 50..4800, masks that overlap on the sheet, a
        mask of fewer than :data:`~mincam_sim.masks.printing.MIN_PRINT_DOTS` dots a side, or a sheet of more than
        ``MAX_TEXELS`` dots.
    """
    _, masks, _, labels, _, _ = _checked_sheet(masks, positions_m, dpi, film, names, title)
    for m, label in zip(masks, labels, strict=True):
        problem = few_print_dots(m.width_m, m.height_m, dpi, f"mask {label!r}")
        if problem is not None:
            raise InputError(problem)


def _checked_path(path: str | Path) -> tuple[Path, str]:
    """The sheet's path and its kind (``".png"`` / ``".pdf"``); anything else is refused (InputError)."""
    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".png", ".pdf"):
        raise InputError(f"print sheet {str(path)!r}: give a name ending in .png (at the printer's dpi) or .pdf")
    return path, kind


def _checked_sheet(masks: Sequence[Mask], positions_m: Sequence[Sequence[float]], dpi: float,
                   film: PrintedFilm | None, names: Sequence[str] | None, title: str
                   ) -> tuple[PrintedFilm | None, list[Mask], np.ndarray, list[str], list[str], _Layout]:
    """The film at ``dpi``, the masks, their centres [m], labels, the notes and the sheet's layout, all checked."""
    masks, pos, labels = _checked_inputs(masks, positions_m, dpi, names)
    film = film if film is None or film.dpi == dpi else replace(film, dpi=float(dpi))
    png_bit_depth(film)
    _check_overlaps(masks, pos, labels)
    notes = _sheet_notes(title, film, dpi, labels, pos, masks)
    return film, masks, pos, labels, notes, _layout(notes, masks, pos, dpi)


def _checked_inputs(masks: Sequence[Mask], positions_m: Sequence[Sequence[float]], dpi: float,
                    names: Sequence[str] | None) -> tuple[list[Mask], np.ndarray, list[str]]:
    """The masks, their centres [m] and labels, checked.

    Raises
    ------
    InputError
        No masks, a position per mask missing, a dpi out of range, or a label per mask missing.
    """
    masks = list(masks)
    if not masks:
        raise InputError("a print sheet needs at least one mask")
    pos = np.asarray(positions_m, dtype=np.float64)
    if pos.shape != (len(masks), 2) or not np.isfinite(pos).all():
        raise InputError(f"positions_m must be one finite (x, y) in metres per mask ({len(masks)}), got shape "
                         f"{pos.shape}")
    if not (np.isfinite(dpi) and 50 <= dpi <= 4800):
        raise InputError(f"dpi must be a printer resolution of 50 to 4800 dots per inch, got {dpi!r}")
    labels = [m.name for m in masks] if names is None else [str(n) for n in names]
    if len(labels) != len(masks):
        raise InputError(f"{len(labels)} names for {len(masks)} masks")
    return masks, pos, labels


def _mask_boxes(masks: Sequence[Mask], pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each mask's half size and its lower-left and upper-right corners [m] around its centre ``pos`` [m]."""
    half = np.array([[m.width_m / 2, m.height_m / 2] for m in masks])
    return half, pos - half, pos + half


def _check_overlaps(masks: Sequence[Mask], pos: np.ndarray, labels: Sequence[str]) -> None:
    """Refuse (InputError) two masks whose areas overlap on the sheet (touching edges are allowed)."""
    half, lo, hi = _mask_boxes(masks, pos)
    for i in range(len(masks)):
        for j in range(i + 1, len(masks)):
            if np.all(lo[i] < hi[j] - 1e-12) and np.all(lo[j] < hi[i] - 1e-12):
                raise InputError(f"masks {labels[i]!r} and {labels[j]!r} overlap on the sheet (centres "
                                 f"{pos[i].tolist()} and {pos[j].tolist()} m, sizes {2e3 * half[i]} and "
                                 f"{2e3 * half[j]} mm): space the mixels at least a mask width apart")


def _sheet_notes(title: str, film: PrintedFilm | None, dpi: float, labels: Sequence[str], pos: np.ndarray,
                 masks: Sequence[Mask]) -> list[str]:
    """The lines printed under the masks (and first in the text file): title, film mapping, how to print, places."""
    notes = [title or "mincam mask print sheet",
             _film_text(film, dpi),
             "PRINT AT 100 % (no fit to page). This face towards the detectors: the text reads correctly from the "
             "detector side.",
             f"scale bar {SCALE_BAR_M * 1e3:g} mm; registration marks' centre = mincam centre; crop marks "
             f"{CROP_GAP_M * 1e3:g} mm outside each mask"]
    for name, (x, y), m in zip(labels, pos, masks, strict=True):
        notes.append(f"{name}: centre ({1e3 * x:+.2f}, {1e3 * y:+.2f}) mm, {1e3 * m.width_m:g} x "
                     f"{1e3 * m.height_m:g} mm")
    return notes


@dataclass(frozen=True)
class _Layout:
    """The sheet's size [dots], the masks' area (``inner_h`` rows, then the notes), margin, text line and font."""

    width: int
    height: int
    inner_h: int
    margin: int
    line_h: int
    font: Any


def _layout(notes: Sequence[str], masks: Sequence[Mask], pos: np.ndarray, dpi: float) -> _Layout:
    """Size the sheet: the masks around the page's reference centre, the margins, then the notes below.

    Raises
    ------
    InputError
        A sheet of more than ``MAX_TEXELS`` dots at ``dpi``.
    """
    layout, half_span = _layout_unchecked(notes, masks, pos, dpi)
    width, height = layout.width, layout.height
    if width * height > MAX_TEXELS:
        span_cm = 100 * 2 * half_span
        raise InputError(f"print sheet of {width} x {height} dots at {dpi:g} dpi is too large (max {MAX_TEXELS}): "
                         f"it holds the masks at their places, {span_cm[0]:.3g} x {span_cm[1]:.3g} cm apart at the "
                         "edges; lower the dpi, bring the mixels closer (their spacing) or print the masks on "
                         "separate sheets")
    return layout


def _layout_unchecked(notes: Sequence[str], masks: Sequence[Mask], pos: np.ndarray, dpi: float
                      ) -> tuple[_Layout, np.ndarray]:
    """The sheet's layout at ``dpi`` whatever its size, and the masks' half span [m] around the reference centre."""
    from PIL import ImageFont

    font = ImageFont.load_default(size=max(6, round(TEXT_PT / 72 * dpi)))
    line_h = int(font.getbbox("Ag")[3] * 1.35) + 1
    text_w = max(int(font.getlength(t)) for t in notes)

    margin = _px(MARGIN_M, dpi)
    _, lo, hi = _mask_boxes(masks, pos)
    span_lo, span_hi = lo.min(axis=0), hi.max(axis=0)
    half_span = np.maximum(np.abs(span_lo), np.abs(span_hi))  # the reference centre is the page's centre
    inner_w = 2 * _px(half_span[0], dpi) + 2 * margin
    inner_h = 2 * _px(half_span[1], dpi) + 2 * margin
    width = max(inner_w, text_w + 2 * margin)
    height = inner_h + line_h * (len(notes) + 1) + margin
    return _Layout(width, height, inner_h, margin, line_h, font), half_span


def print_sheet_dots(masks: Sequence[Mask], positions_m: Sequence[Sequence[float]], dpi: float,
                     film: PrintedFilm | None = None, names: Sequence[str] | None = None,
                     title: str = "") -> tuple[int, int]:
    """The size (width, height) [dots] of the sheet :func:`write_print_sheet` would draw, whether or not it fits.

    Parameters are those of :func:`write_print_sheet` (without the file). A sheet is written only when
    ``width * height`` is at most ``MAX_TEXELS`` (8192 x 8192 dots).

    Raises
    ------
    InputError
        No masks, a position or label per mask missing, a dpi out of 50..4800, or masks that overlap on the sheet.
    """
    masks, pos, labels = _checked_inputs(masks, positions_m, dpi, names)
    film = film if film is None or film.dpi == dpi else replace(film, dpi=float(dpi))
    _check_overlaps(masks, pos, labels)
    layout, _ = _layout_unchecked(_sheet_notes(title, film, dpi, labels, pos, masks), masks, pos, dpi)
    return layout.width, layout.height


def _mask_dots(m: Mask, shape: tuple[int, int], film: PrintedFilm | None) -> np.ndarray:
    """A mask's printer dots: the film's printer input, or (no film) its transmission on the ``shape`` grid."""
    return film.printer_input(m) if film is not None else resample(m, shape)


def _draw_sheet(layout: _Layout, notes: Sequence[str], labels: Sequence[str], pos: np.ndarray,
                masks: Sequence[Mask], film: PrintedFilm | None, dpi: float
                ) -> tuple[np.ndarray, list[SheetPlacement]]:
    """The sheet's grey values in [0, 1] (masks, crop marks, marks and text) and where each mask lies."""
    cx, cy = layout.width / 2, layout.inner_h / 2
    sheet = np.ones((layout.height, layout.width))
    placements = []
    for name, (x, y), m in zip(labels, pos, masks, strict=True):
        shape = _dot_grid(m.width_m, m.height_m, dpi)
        r0 = int(round(cy - _px_f(y, dpi) - shape[0] / 2))
        c0 = int(round(cx + _px_f(x, dpi) - shape[1] / 2))
        sheet[r0:r0 + shape[0], c0:c0 + shape[1]] = _mask_dots(m, shape, film)
        placements.append(SheetPlacement(name, (float(x), float(y)), (r0, c0), shape))
        _crop_marks(sheet, r0, c0, shape, dpi)
    sheet = np.minimum(sheet, _marks_and_text(layout, notes, placements, dpi))
    for p, m in zip(placements, masks, strict=True):  # the masks' own dots win over any mark or text
        (r0, c0), (h, w) = p.top_left_px, p.shape_px
        sheet[r0:r0 + h, c0:c0 + w] = _mask_dots(m, (h, w), film)
    return sheet, placements


def _marks_and_text(layout: _Layout, notes: Sequence[str], placements: Sequence[SheetPlacement],
                    dpi: float) -> np.ndarray:
    """Registration marks, scale bar, notes and mask labels drawn black on white, as grey values in [0, 1]."""
    from PIL import Image, ImageDraw

    width, inner_h, margin, line_h, font = layout.width, layout.inner_h, layout.margin, layout.line_h, layout.font
    img = Image.fromarray(np.zeros((layout.height, width), dtype=np.uint8) + 255, mode="L")
    draw = ImageDraw.Draw(img)
    lw = _line_px(dpi)
    reg = _px(REG_RADIUS_M, dpi)
    off = margin // 2
    for rx, ry in ((off, off), (width - off, off), (off, inner_h - off), (width - off, inner_h - off)):
        draw.ellipse((rx - reg, ry - reg, rx + reg, ry + reg), outline=0, width=lw)
        draw.line((rx - reg - lw, ry, rx + reg + lw, ry), fill=0, width=lw)
        draw.line((rx, ry - reg - lw, rx, ry + reg + lw), fill=0, width=lw)
    bar = _px(SCALE_BAR_M, dpi)
    text_top = inner_h
    y_bar = text_top + line_h // 4
    draw.line((margin, y_bar, margin + bar, y_bar), fill=0, width=2 * lw)
    for k, text in enumerate(notes):
        draw.text((margin, text_top + line_h * (k + 1) - line_h // 2), text, fill=0, font=font)
    for p in placements:  # each mask's label just above its crop marks, outside the aperture
        r0, c0 = p.top_left_px
        draw.text((c0, max(0, r0 - _px(CROP_GAP_M + CROP_LEN_M, dpi) - line_h)), p.name, fill=0, font=font)
    return np.asarray(img, dtype=np.float64) / 255.0


def _write_sheet(sheet: np.ndarray, kind: str, path: Path, bit_depth: int, dpi: float) -> None:
    """Write the sheet atomically: a PNG of ``bit_depth`` bits recording ``dpi``, or a one-page PDF."""
    if kind == ".png":
        with atomic_path(path) as tmp:
            imageio.write_png(tmp, sheet, bit_depth=bit_depth, dpi=dpi)
    else:
        _write_pdf(sheet, dpi, path)


def _notes_text(notes: Sequence[str], placements: Sequence[SheetPlacement], layout: _Layout, dpi: float) -> str:
    """The text file beside the sheet: the notes, each mask's dots on the sheet, the sheet's size."""
    width, height = layout.width, layout.height
    return "\n".join(notes) + "\n" + "\n".join(
        f"{p.name}: {p.shape_px[1]} x {p.shape_px[0]} dots at column {p.top_left_px[1]}, row {p.top_left_px[0]} "
        "(top left) of the sheet" for p in placements) + (
        f"\nsheet: {width} x {height} dots = {width / dpi * 25.4:.2f} x {height / dpi * 25.4:.2f} mm at {dpi:g} "
        "dpi; each mask centre within half a dot of its place\n")


def _px_f(length_m: float, dpi: float) -> float:
    return length_m * dpi / 0.0254


def _crop_marks(sheet: np.ndarray, r0: int, c0: int, shape: tuple[int, int], dpi: float) -> None:
    """Short black lines along each edge line of a mask, starting ``CROP_GAP_M`` outside its corners."""
    gap, length, lw = _px(CROP_GAP_M, dpi), _px(CROP_LEN_M, dpi), _line_px(dpi)
    h, w = shape
    rows, cols = sheet.shape

    def fill(ra: int, rb: int, ca: int, cb: int) -> None:
        sheet[max(0, ra):max(0, min(rows, rb)), max(0, ca):max(0, min(cols, cb))] = 0.0

    for r in (r0, r0 + h):  # horizontal marks on the top and bottom edge lines, left and right of the mask
        fill(r - lw // 2, r - lw // 2 + lw, c0 - gap - length, c0 - gap)
        fill(r - lw // 2, r - lw // 2 + lw, c0 + w + gap, c0 + w + gap + length)
    for c in (c0, c0 + w):  # vertical marks on the left and right edge lines, above and below the mask
        fill(r0 - gap - length, r0 - gap, c - lw // 2, c - lw // 2 + lw)
        fill(r0 + h + gap, r0 + h + gap + length, c - lw // 2, c - lw // 2 + lw)


def _write_pdf(sheet: np.ndarray, dpi: float, path: Path) -> None:
    """One PDF page of exactly the sheet's size, the sheet embedded at ``dpi`` without resampling."""
    from matplotlib.figure import Figure

    h, w = sheet.shape
    fig = Figure(figsize=(w / dpi, h / dpi), dpi=dpi)
    fig.figimage(sheet, cmap="gray", vmin=0.0, vmax=1.0, origin="upper", resize=False)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="pdf", dpi=dpi)


__all__ = ["SheetPlacement", "check_print_sheet", "print_sheet_dots", "write_print_sheet"]
