"""Transmission masks: the :class:`Mask` type and its generators (:mod:`.mask`), curved ramps (:mod:`.curves`),
files (:mod:`.files`), printing on film (:mod:`.printing`) and the standard library (:mod:`.library`).

Files:

* ``curves.py``: curved and circular ramps (the paper's Sec. 4.1 extension to curved boundaries).
* ``files.py``: mask files: PNG / OpenEXR / NumPy ``.npy`` in (grayscale or RGB -> luma, alpha refused), OpenEXR
  out with metadata.
* ``freeform.py``: freeform masks: any 2D array (or ``.npy`` file) with its physical size, and the transmission at
  mask points in numpy with the renderer's reconstruction.
* ``library.py``: the standard mask library (four ramps, open aperture, a sinusoid, a circular ramp) and its files.
* ``mask.py``: transmission masks: a 2D grayscale transmission texture in [0, 1] with a physical size.
* ``printing.py``: what a printer makes of a mask on transparency film (:class:`PrintedFilm`: dot grid, grey levels
  or ordered halftone, film transmission range) and print-ready PNG export at the mask's physical size.
* ``profiles.py``: analytic mask profiles: the exact transmission of generated masks, evaluated by numpy or by the
  renderer.
* ``sheet.py``: print sheets: every mask of a mincam on one page at its place and spacing, at the printer's dots,
  with crop and registration marks, the side that faces the detectors marked, and the film mapping and dpi printed
  on the sheet and in a text file beside it (:func:`~mincam_sim.masks.sheet.write_print_sheet`).
"""

from mincam_sim.masks.curves import circular_ramp, curved_ramp
from mincam_sim.masks.files import load, save_exr
from mincam_sim.masks.freeform import from_array, load_npy, transmission_at
from mincam_sim.masks.library import LIBRARY_SINUSOID_PERIOD_M, generate_library, standard_library
from mincam_sim.masks.mask import (
    DEFAULT_MASK_SIZE_M,
    DEFAULT_RESOLUTION,
    MAX_TEXELS,
    Mask,
    constant,
    from_function,
    from_profile,
    ramp,
    resample,
    sinusoid,
)
from mincam_sim.masks.printing import PrintedFilm, export_print_png

__all__ = [
    "DEFAULT_MASK_SIZE_M", "DEFAULT_RESOLUTION", "LIBRARY_SINUSOID_PERIOD_M", "MAX_TEXELS", "Mask", "PrintedFilm",
    "circular_ramp", "constant", "curved_ramp", "export_print_png", "from_array", "from_function", "from_profile",
    "generate_library", "load", "load_npy", "ramp", "resample", "save_exr", "sinusoid", "standard_library",
    "transmission_at",
]
