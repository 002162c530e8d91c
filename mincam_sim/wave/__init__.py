"""Scalar wave optics of a mixel: the detector-averaged power behind a mask, as a function of incidence.

A plane wave arrives from the direction a ray of the geometric model would leave in, with direction tangents
``t = (tan_x, tan_y)`` in physical mask coordinates (+x right, +y up, seen from the detector looking out: the
ray model's mask point is ``x_d + d_f t``). The mask multiplies the field by its amplitude transmission
``sqrt(T)`` (a real, thin, phase-free absorber: printed film, grey ink), the housing blocks everything outside
the aperture, and the field is propagated over ``d_f`` to the detector plane by the band-limited angular
spectrum method. :func:`angular_response` returns the detector average of ``|U|^2`` relative to the incident
intensity: 1 for an infinite open aperture, and in the limit lambda -> 0 the ray model's answer
(``optics="geometric"``: the detector average of ``T(x_d + d_f t)``, zero outside the aperture).

Numerical method (:class:`Sampling`):

* the mask plane is sampled on cells of ``dx`` aligned with the aperture's edges; the amplitude of a raster
  mask with ``"nearest"`` interpolation (printer dots) is area-averaged over each cell;
* the carrier of the tilted wave is never sampled: propagating ``A(x) exp(i 2 pi f0 x)`` is
  ``exp(i 2 pi f0 x) IFFT[ FFT[A](f) H(f + f0) ]`` with ``H(f) = exp(i 2 pi d_f sqrt(1/lambda^2 - |f|^2))``
  (the phase is taken relative to ``H(f0)``, in a cancellation-free form);
* band limit: directions that cannot reach the detector from the aperture, ``|tan| > (w/2 + a)/d_f`` per axis
  (rays), are dropped beyond a margin (:data:`BAND_MARGIN` = 1.5 times that: a hard cut right at the ray limit
  loses up to 1.5 % at the rim, because a plane-wave component is not a ray), and so are evanescent ones; the
  periodic domain (:data:`DOMAIN_FACTOR` x (w + 2 a)) is wide enough that nothing kept wraps onto the
  detector (checked by convergence in domain and cell size: 2e-5 at the rim);
* the detector average weighs each output cell by its overlap with the detector.

Masks whose transmission varies along one axis only (ramps, axis-aligned sinusoids, constants, 1D rasters) are
computed as a product of two exact 1D problems (``method="separable"``): the field factorises, up to the
fourth-order cross term ``lambda^3 d_f f_x^2 f_y^2`` of the propagation phase, which is < 1e-3 rad for every
mask feature and the aperture rim here (checked against the 2D solver in the tests). Other masks (printed
films, halftones, circular ramps) are solved in 2D.

The silicon quantum-efficiency curve for spectral weighting is a model, documented in :func:`silicon_qe`.
Files:

* ``geometric.py``: the ray model's answer for the same mixel: detector averages of T(x_d + d_f t), exact
  quadrature.
* ``propagation.py``: band-limited angular-spectrum propagation of tilted plane waves through the aperture to the
  detector.
* ``report.py``: numbers of the README's wave-optics section (pure numpy): the default sinusoid's contrast, the
  Talbot curve, the aperture rim, printed films against their geometric model.
* ``response.py``: the detector-averaged power behind the mask for plane waves from given directions (the public
  entry).
* ``sampling.py``: the computational grid of the wave solver and the mask's amplitude on it (one-axis masks, print
  dots).
* ``spectrum.py``: spectral weighting of the wave response: a silicon quantum-efficiency model and band weights.
* ``table.py``: a mixel's response tabulated over its field of view, for the renderer.
* ``validity.py``: how far the ray model is from the wave response for a mixel, and why (u, dot pitch, rim).
"""

from __future__ import annotations

from mincam_sim.wave.geometric import geometric_response, open_fraction
from mincam_sim.wave.propagation import axis_wavelength
from mincam_sim.wave.response import (
    MAX_CELLS_2D,
    MIN_FRESNEL_NUMBER,
    OPTICS,
    WaveInfo,
    angular_response,
    fresnel_number,
)
from mincam_sim.wave.sampling import (
    BAND_MARGIN,
    DOMAIN_FACTOR,
    Sampling,
    choose_sampling,
    dot_pitch_m,
    separable_axis,
    transmission_on_cells,
)
from mincam_sim.wave.spectrum import (
    DEFAULT_WAVELENGTHS_M,
    QE_RANGE_M,
    SI_COLLECTION_DEPTH_M,
    SI_DEAD_LAYER_M,
    SI_SURFACE_LOSS,
    silicon_qe,
    spectral_weights,
)
from mincam_sim.wave.table import TABLE_MEMORY_LIMIT_BYTES, ResponseTable, response_table
from mincam_sim.wave.validity import (
    U_ONE_PERCENT,
    VALIDITY_TOLERANCE,
    quick_check,
    rim_onset_deg,
    talbot_parameter,
    validity,
)

__all__ = [
    "BAND_MARGIN",
    "DEFAULT_WAVELENGTHS_M",
    "DOMAIN_FACTOR",
    "MAX_CELLS_2D",
    "MIN_FRESNEL_NUMBER",
    "OPTICS",
    "QE_RANGE_M",
    "ResponseTable",
    "SI_COLLECTION_DEPTH_M",
    "SI_DEAD_LAYER_M",
    "SI_SURFACE_LOSS",
    "TABLE_MEMORY_LIMIT_BYTES",
    "U_ONE_PERCENT",
    "Sampling",
    "VALIDITY_TOLERANCE",
    "WaveInfo",
    "angular_response",
    "axis_wavelength",
    "choose_sampling",
    "dot_pitch_m",
    "fresnel_number",
    "geometric_response",
    "open_fraction",
    "quick_check",
    "response_table",
    "rim_onset_deg",
    "separable_axis",
    "silicon_qe",
    "spectral_weights",
    "talbot_parameter",
    "transmission_on_cells",
    "validity",
]
