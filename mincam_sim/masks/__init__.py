"""Transmission masks: the :class:`Mask` type and its generators (:mod:`.mask`), curved ramps (:mod:`.curves`),
files (:mod:`.files`), printing on film (:mod:`.printing`) and the standard library (:mod:`.library`)."""

from .curves import circular_ramp, curved_ramp
from .files import load, save_exr
from .library import LIBRARY_SINUSOID_PERIOD_M, generate_library, standard_library
from .mask import (
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
from .printing import PrintedFilm, export_print_png

__all__ = [
    "DEFAULT_MASK_SIZE_M", "DEFAULT_RESOLUTION", "LIBRARY_SINUSOID_PERIOD_M", "MAX_TEXELS", "Mask", "PrintedFilm",
    "circular_ramp", "constant", "curved_ramp", "export_print_png", "from_function", "from_profile",
    "generate_library", "load", "ramp", "resample", "save_exr", "sinusoid", "standard_library",
]
