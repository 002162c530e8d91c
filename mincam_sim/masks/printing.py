"""What a printer makes of a mask on transparency film (:class:`PrintedFilm`: dot grid, grey levels or
ordered halftone, film transmission range) and print-ready PNG export at the mask's physical size."""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.masks.mask import MAX_TEXELS, Mask, resample
from mincam_sim.storage import imageio
from mincam_sim.storage.atomic import atomic_path

#: Fewest printer dots a side a print file may give a mask: fewer cannot show a ramp or a sinusoid (and an 8 x 8
#: ordered halftone cell needs 8).
MIN_PRINT_DOTS = 8
METRES_PER_INCH = 0.0254

_BAYER8 = np.array(
    [
        [0, 32, 8, 40, 2, 34, 10, 42],
        [48, 16, 56, 24, 50, 18, 58, 26],
        [12, 44, 4, 36, 14, 46, 6, 38],
        [60, 28, 52, 20, 62, 30, 54, 22],
        [3, 35, 11, 43, 1, 33, 9, 41],
        [51, 19, 59, 27, 49, 17, 57, 25],
        [15, 47, 7, 39, 13, 45, 5, 37],
        [63, 31, 55, 23, 61, 29, 53, 21],
    ]
)


@dataclass(frozen=True)
class PrintedFilm:
    """What a printer really makes of a mask on transparency film.

    Parameters
    ----------
    t_min : float
        Transmission of fully inked film (printer value 0, black). Typical printed black on transparency film
        passes ~1-5 % of visible light; default 0.02. Measure your own film for quantitative work.
    t_max : float
        Transmission of the unprinted film (printer value 1, white). Clear transparency film typically
        transmits ~85-92 %; default 0.9.
    dpi : float
        Printer addressable resolution [dots per inch]; default 600. Note that a 2 mm mask is only ~47 dots
        across at 600 dpi.
    levels : int or None
        Grey levels the printer reproduces per dot (256 = 8-bit); ``None`` = continuous. Ignored when
        halftoning.
    halftone : {None, "ordered"}
        ``"ordered"``: each dot is either fully inked or clear, grey produced by an 8x8 Bayer ordered dither
        (65 effective levels over 8x8 dots), as laser and many inkjet printers do. Deterministic.
    gamma : float
        Tone response: transmission = t_min + (t_max - t_min) * value**gamma (1 = linear; fit it to a printed
        step wedge if needed).

    Notes
    -----
    The printed transmission spans [t_min, t_max], not [0, 1]: a complementary pair M, 1 - M sums to
    t_min + t_max instead of 1, and the dark parts of a mask still leak light. These defaults are typical
    values only; set them from measurements of your film and printer.
    """

    t_min: float = 0.02
    t_max: float = 0.9
    dpi: float = 600.0
    levels: int | None = 256
    halftone: str | None = None
    gamma: float = 1.0

    def __post_init__(self) -> None:
        if not (is_finite_real(self.t_min) and is_finite_real(self.t_max) and 0.0 <= self.t_min < self.t_max <= 1.0):
            raise InputError(
                f"PrintedFilm: need 0 <= t_min < t_max <= 1, got t_min={self.t_min!r}, t_max={self.t_max!r}"
            )
        if not (is_finite_real(self.dpi) and self.dpi > 0):
            raise InputError(f"PrintedFilm: dpi must be a positive number of dots per inch, got {self.dpi!r}")
        if self.levels is not None and (not is_finite_real(self.levels) or int(self.levels) != self.levels
                                        or self.levels < 2):
            raise InputError(f"PrintedFilm: levels must be an integer >= 2 or None, got {self.levels!r}")
        if self.halftone not in (None, "ordered"):
            raise InputError(f"PrintedFilm: halftone must be None or 'ordered', got {self.halftone!r}")
        if not (is_finite_real(self.gamma) and self.gamma > 0):
            raise InputError(f"PrintedFilm: gamma must be positive, got {self.gamma!r}")

    @property
    def dots_per_m(self) -> float:
        """Printer resolution [dots/m]."""
        return self.dpi / 0.0254

    def grid_shape(self, width_m: float, height_m: float) -> tuple[int, int]:
        """(H, W) printer dots covering a ``width_m`` x ``height_m`` [m] mask (rounded, at least 1)."""
        return _dot_grid(width_m, height_m, self.dpi)

    def printer_input(self, mask: Mask) -> np.ndarray:
        """Printer grey values in [0, 1] (0 = full ink) on the dot grid: resampled, quantised or halftoned."""
        v = resample(mask, self.grid_shape(mask.width_m, mask.height_m))
        if self.halftone == "ordered":
            h, w = v.shape
            thr = (np.tile(_BAYER8, (h // 8 + 1, w // 8 + 1))[:h, :w] + 0.5) / 64.0
            return (v >= thr).astype(np.float64)
        if self.levels is not None:
            v = np.rint(v * (self.levels - 1)) / (self.levels - 1)
        return v

    def print(self, mask: Mask) -> Mask:
        """The mask as printed on this film.

        The mask is area-averaged onto the printer's dot grid for its physical size (``round(size * dpi)``
        dots per side; the dot pitch is adjusted by less than half a dot so the print covers exactly the mask
        size), quantised to ``levels`` (or halftoned) and mapped to [t_min, t_max].

        Returns
        -------
        Mask
            Same physical size, one texel per printer dot; ``meta["film"]`` records this film and
            ``meta["printed_from"]`` the source mask name.
        """
        v = self.printer_input(mask)
        t = self.t_min + (self.t_max - self.t_min) * v**self.gamma
        meta = dict(mask.meta)
        meta.update({"film": asdict(self), "printed_from": mask.name})
        return Mask(np.clip(t, 0.0, 1.0), mask.width_m, mask.height_m, f"{mask.name}@film", meta,
                    interpolation="nearest")


def _dot_grid(width_m: float, height_m: float, dpi: float) -> tuple[int, int]:
    if not (np.isfinite(dpi) and dpi > 0):
        raise InputError(f"dpi must be a positive number of dots per inch, got {dpi!r}")
    per_m = dpi / METRES_PER_INCH
    h, w = max(1, round(height_m * per_m)), max(1, round(width_m * per_m))
    if h * w > MAX_TEXELS:
        raise InputError(
            f"print grid {h}x{w} dots is too large (max {MAX_TEXELS}); lower the dpi or the mask size"
        )
    return h, w


class PrintWarning(UserWarning):
    """A print file was written that cannot show its mask as meant (too few printer dots a side)."""


def few_print_dots(width_m: float, height_m: float, dpi: float, name: str = "mask") -> str | None:
    """Why a ``width_m`` x ``height_m`` [m] mask at ``dpi`` [dots per inch] prints as too few dots to show it, or
    None when it gets at least :data:`MIN_PRINT_DOTS` dots a side.

    The message names the size, the dpi, the dots it gives and the smallest dpi (or, where no dpi up to 4800 does,
    the smallest mask) that gives ``MIN_PRINT_DOTS`` dots a side.
    """
    rows, cols = _dot_grid(width_m, height_m, dpi)
    if min(rows, cols) >= MIN_PRINT_DOTS:
        return None
    need_dpi = int(np.ceil(MIN_PRINT_DOTS * METRES_PER_INCH / min(width_m, height_m)))
    need_side_mm = 1e3 * MIN_PRINT_DOTS * METRES_PER_INCH / dpi
    larger = f"make the mask at least {need_side_mm:.3g} mm a side at {dpi:g} dpi"
    fix = f"give dpi >= {need_dpi}, or {larger}" if need_dpi <= 4800 else f"no dpi up to 4800 does: {larger}"
    return (f"{name} of {1e3 * width_m:.4g} x {1e3 * height_m:.4g} mm prints as {cols} x {rows} dots at {dpi:g} dpi, "
            f"too few to show it (at least {MIN_PRINT_DOTS} dots a side): {fix}")


def check_print_dots(width_m: float, height_m: float, dpi: float, name: str = "mask") -> None:
    """Refuse a mask that a print file would hold as fewer than :data:`MIN_PRINT_DOTS` dots a side.

    Parameters
    ----------
    width_m, height_m : float
        The mask's size [m].
    dpi : float
        Printer resolution [dots per inch].
    name : str
        Named in the message.

    Raises
    ------
    InputError
        With :func:`few_print_dots`'s message: the size, the dpi, the dots it gives and the smallest dpi (or
        mask) that gives ``MIN_PRINT_DOTS`` dots a side.
    """
    problem = few_print_dots(width_m, height_m, dpi, name)
    if problem is not None:
        raise InputError(problem)


def warn_few_print_dots(width_m: float, height_m: float, dpi: float, name: str = "mask") -> None:
    """One :class:`PrintWarning` when the mask prints as fewer than :data:`MIN_PRINT_DOTS` dots a side."""
    problem = few_print_dots(width_m, height_m, dpi, name)
    if problem is not None:
        warnings.warn(problem, PrintWarning, stacklevel=3)


def export_print_png(
    mask: Mask,
    path: str | Path,
    dpi: float | None = None,
    film: PrintedFilm | None = None,
    bit_depth: int | None = None,
) -> Path:
    """Write a print-ready grayscale PNG of a mask at its physical size.

    Parameters
    ----------
    mask : Mask
        Mask to print; white (1) = no ink = clear, black (0) = full ink.
    path : str or Path
        Output PNG.
    dpi : float, optional
        Printer resolution [dots per inch]; default ``film.dpi`` if a film is given, else 600. The image has
        ``round(width_m * dpi / 0.0254)`` x ``round(height_m * dpi / 0.0254)`` pixels and the PNG records
        the dpi so that printing at 100 % scale reproduces the physical size.
    film : PrintedFilm, optional
        If given, the pixels are the film's printer input (quantised to its levels, or halftoned), i.e.
        exactly what :meth:`PrintedFilm.print` assumes is printed.
    bit_depth : {8, 16}, optional
        PNG bit depth. Default: 8 (what printer drivers generally use), or 16 when the film reproduces more
        than 256 grey levels. A film with more than 65536 levels, or 8 bits for more than 256 levels, is
        refused: the file could not hold what the film model assumes is printed.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InputError
        A file name that does not end in ``.png`` (the bytes are PNG whatever the name), or levels the bit depth
        cannot hold.

    Warns
    -----
    PrintWarning
        A mask that prints as fewer than :data:`~mincam_sim.masks.printing.MIN_PRINT_DOTS` dots a side
        (:func:`~mincam_sim.masks.printing.few_print_dots`); the file is written all the same
        (:func:`~mincam_sim.masks.printing.check_print_dots` refuses it instead).

    Notes
    -----
    The file is written atomically. The image is the mask as seen from the detector looking out; mount the film
    so the print reads the same way from the detector side (printing on the far side of the film mirrors it as
    seen from the scene).
    """
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError(f"print file {str(path)!r}: masks are written as PNG; give a name ending in .png "
                         f"(not {path.suffix or 'no suffix'!r})")
    bit_depth = png_bit_depth(film, bit_depth)
    if dpi is None:
        dpi = film.dpi if film is not None else 600.0
    warn_few_print_dots(mask.width_m, mask.height_m, dpi, f"mask {mask.name!r}")
    if film is not None:
        if dpi != film.dpi:
            film = replace(film, dpi=float(dpi))
        values = film.printer_input(mask)
    else:
        values = resample(mask, _dot_grid(mask.width_m, mask.height_m, dpi))
    with atomic_path(path) as tmp:
        imageio.write_png(tmp, values, bit_depth=bit_depth, dpi=dpi)
    return path


def png_bit_depth(film: PrintedFilm | None, bit_depth: int | None = None) -> int:
    """The PNG bit depth that holds ``film``'s grey levels (8 up to 256 levels, 16 up to 65536).

    Raises
    ------
    InputError
        More than 65536 levels (no PNG holds them), or ``bit_depth = 8`` for more than 256 levels.
    """
    levels = None if film is None or film.halftone is not None else film.levels
    if levels is not None and levels > 65536:
        raise InputError(f"levels = {levels}: a PNG holds at most 65536 grey levels (16 bits); give levels <= 65536 "
                         "(256 for an 8-bit printer)")
    need = 16 if levels is not None and levels > 256 else 8
    if bit_depth is None:
        return need
    if bit_depth not in (8, 16):
        raise InputError(f"bit_depth must be 8 or 16, got {bit_depth!r}")
    if bit_depth < need:
        raise InputError(f"levels = {levels} need a 16-bit PNG; an 8-bit file holds 256 grey levels")
    return bit_depth
