"""Photodetector and readout model: irradiance on a mixel's detector -> digital numbers (DN). Pure numpy.

Pipeline of :meth:`SensorModel.measure`, per pixel and per exposure::

    irradiance [W/m^2] x pixel area [m^2] x exposure [s]      -> energy [J]
    energy / (h c / wavelength)                                 -> photons        (monochromatic assumption)
    photons x quantum efficiency + dark current x exposure      -> mean electrons
    Poisson(mean electrons)                                     -> shot + dark-current noise
    min(., full well)                                           -> saturation
    + Normal(0, read noise)                                     -> read noise
    / gain [e-/DN], round, clip to [0, 2^bit_depth - 1]         -> ADC

and, when ``pixels_averaged = N > 1``, the detector is split into N pixels of area ``detector_area_m2 / N``
whose digital values are averaged (the paper's prototype averaged a 48 x 48-pixel region of interest into one
12-bit value, Sec. 3.1).

Monochromatic assumption: all light is taken to be at ``wavelength_m`` (550 nm, the peak of photopic
sensitivity and close to the peak QE of silicon CMOS sensors). A broadband simulation should pass the
irradiance-weighted mean of QE / photon energy instead, i.e. choose ``quantum_efficiency`` and
``wavelength_m`` so that ``quantum_efficiency * wavelength_m`` equals the spectral average of
``QE(lambda) * lambda``.

The model is deliberately generic (no fixed-pattern noise, no PRNU, no black-level offset, no non-linearity);
its defaults are those of a typical small (~2 um) CMOS pixel, not values measured on the paper's hardware.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from mincam_sim import paper
from mincam_sim.errors import InputError, is_finite_real

PLANCK_J_S = 6.62607015e-34  # [J s] exact (SI 2019)
SPEED_OF_LIGHT_M_S = 299_792_458.0  # [m/s] exact

PAPER_PIXELS_AVERAGED = paper.PIXELS_AVERAGED  # the prototype's 48 x 48-pixel region of interest (Sec. 3.1)
PAPER_REGION_SIDE_M = paper.DETECTOR_SIZE_M  # [m] "approximately 0.1 mm x 0.1 mm" for those pixels (Sec. 3.1)
DEFAULT_PIXEL_PITCH_M = paper.PIXEL_PITCH_M  # [m] 48 x 2.2 um = 0.106 mm, consistent with the ~0.1 mm region

MeasureMethod = Literal["aggregate", "per_pixel"]


MAX_PIXELS_AVERAGED = 1 << 24  # a 4096 x 4096 region of interest: more pixels than any sensor averages into one
POISSON_MEAN_CAP_E = 1e18  # [e-] numpy's Poisson sampler refuses means near 9.2e18; far above every full well


def _check_positive_finite(name: str, value: float, hint: str) -> None:
    if not is_finite_real(value) or value <= 0:
        raise InputError(f"SensorModel.{name} must be a finite number > 0, got {value!r}; {hint}")


def _check_non_negative_finite(name: str, value: float, hint: str) -> None:
    if not is_finite_real(value) or value < 0:
        raise InputError(f"SensorModel.{name} must be a finite number >= 0, got {value!r}; {hint}")


@dataclass(frozen=True)
class SensorModel:
    """Photodetector + ADC model of one mixel.

    Parameters
    ----------
    exposure_s : float
        Exposure (integration) time [s]. Default 10 ms (a usual video-rate exposure; arbitrary). For
        simulations whose irradiance scale is arbitrary, use :meth:`exposure_for` / :meth:`auto_exposed`.
    quantum_efficiency : float
        Photoelectrons per incident photon, in (0, 1]. Default 0.6: typical peak QE of monochrome CMOS sensors
        near 550 nm (EMVA 1288 datasheets of small-pixel sensors report roughly 0.5-0.8).
    wavelength_m : float
        Wavelength [m] at which all light is assumed to arrive (monochromatic assumption, module docstring).
        Default 550e-9 m.
    read_noise_e : float
        Temporal read noise per pixel [e- rms]. Default 2.5 e-: typical of small CMOS pixels (about 2-3 e-).
    dark_current_e_per_s : float
        Mean dark current per pixel [e-/s]. Default 5 e-/s: order of magnitude for small CMOS pixels at room
        temperature (1-50 e-/s).
    full_well_e : float
        Full-well capacity per pixel [e-]. Default 10 000 e-: typical of ~2 um CMOS pixels (about 5-10 ke-).
    gain_e_per_dn : float or None
        Conversion gain [e-/DN]. ``None`` (default) maps the full well onto the ADC range:
        ``full_well_e / (2**bit_depth - 1)`` (2.44 e-/DN with the defaults), see :attr:`gain`.
    bit_depth : int
        ADC resolution [bits], 1-32. Default 12, as in the paper's prototype (Sec. 3.1).
    pixels_averaged : int
        Number N of pixels whose digital values are averaged into one mixel value (>= 1). Default 1;
        :meth:`paper_prototype` uses 48 x 48 = 2304.
    detector_area_m2 : float
        Total light-collecting area of the mixel [m^2], shared equally by its N pixels (fill factor 1).
        Default (2.2 um)^2, one pixel of the pitch implied by the paper (48 px ~ 0.1 mm).
    """

    exposure_s: float = 10e-3
    quantum_efficiency: float = 0.6
    wavelength_m: float = 550e-9
    read_noise_e: float = 2.5
    dark_current_e_per_s: float = 5.0
    full_well_e: float = 10_000.0
    gain_e_per_dn: float | None = None
    bit_depth: int = paper.ADC_BITS
    pixels_averaged: int = 1
    detector_area_m2: float = DEFAULT_PIXEL_PITCH_M**2

    def __post_init__(self) -> None:
        _check_positive_finite("exposure_s", self.exposure_s, "use an exposure time in seconds, e.g. 10e-3")
        if not is_finite_real(self.quantum_efficiency) or not 0 < self.quantum_efficiency <= 1:
            raise InputError(
                f"SensorModel.quantum_efficiency must be in (0, 1], got {self.quantum_efficiency!r}; "
                "give a fraction (0.6), not a percentage"
            )
        _check_positive_finite("wavelength_m", self.wavelength_m, "give metres, e.g. 550e-9 for 550 nm")
        _check_non_negative_finite("read_noise_e", self.read_noise_e, "give electrons rms per pixel")
        _check_non_negative_finite("dark_current_e_per_s", self.dark_current_e_per_s, "give e-/s per pixel")
        _check_positive_finite("full_well_e", self.full_well_e, "give the full-well capacity in electrons")
        if self.gain_e_per_dn is not None:
            _check_positive_finite(
                "gain_e_per_dn", self.gain_e_per_dn, "give electrons per DN, or None to map the full well"
            )
        if isinstance(self.bit_depth, bool) or not isinstance(self.bit_depth, int | np.integer):
            raise InputError(f"SensorModel.bit_depth must be an integer, got {self.bit_depth!r}")
        if not 1 <= self.bit_depth <= 32:
            raise InputError(
                f"SensorModel.bit_depth must be in 1..32, got {self.bit_depth} (the paper: {paper.ADC_BITS})"
            )
        if isinstance(self.pixels_averaged, bool) or not isinstance(self.pixels_averaged, int | np.integer):
            raise InputError(f"SensorModel.pixels_averaged must be an integer, got {self.pixels_averaged!r}")
        if not 1 <= self.pixels_averaged <= MAX_PIXELS_AVERAGED:
            raise InputError(
                f"SensorModel.pixels_averaged must be from 1 (a single pixel) to {MAX_PIXELS_AVERAGED} (4096 x 4096), "
                f"got {self.pixels_averaged}"
            )
        object.__setattr__(self, "bit_depth", int(self.bit_depth))  # numpy's int8(12) made 2**12 overflow to 0
        object.__setattr__(self, "pixels_averaged", int(self.pixels_averaged))
        _check_positive_finite("detector_area_m2", self.detector_area_m2, "give the area in m^2, e.g. 1e-8")

    @classmethod
    def paper_prototype(cls, **overrides: float | int | None) -> SensorModel:
        """The paper's mixel (Sec. 3.1): 48 x 48 pixels over ~0.1 mm x 0.1 mm averaged into one 12-bit value.

        Per-pixel parameters keep the generic defaults of :class:`SensorModel`; ``overrides`` replace fields.
        """
        params: dict = {
            "pixels_averaged": PAPER_PIXELS_AVERAGED,
            "detector_area_m2": PAPER_REGION_SIDE_M**2,
            "bit_depth": paper.ADC_BITS,
        }
        params.update(overrides)
        return cls(**params)

    # ----------------------------------------------------------------------------------------------- derived
    @property
    def gain(self) -> float:
        """Conversion gain in use [e-/DN]: ``gain_e_per_dn`` or, when None, ``full_well_e / max_dn``."""
        return self.full_well_e / self.max_dn if self.gain_e_per_dn is None else float(self.gain_e_per_dn)

    def _to_dn(self, electrons: np.ndarray) -> np.ndarray:
        """Electrons -> DN; with the default gain, exactly ``max_dn`` at full well (no rounding residue)."""
        if self.gain_e_per_dn is None:
            return electrons / self.full_well_e * self.max_dn
        return electrons / float(self.gain_e_per_dn)

    @property
    def max_dn(self) -> float:
        """Largest ADC output [DN]: ``2**bit_depth - 1``."""
        return float(2**self.bit_depth - 1)

    @property
    def pixel_area_m2(self) -> float:
        """Light-collecting area of one of the averaged pixels [m^2]."""
        return self.detector_area_m2 / self.pixels_averaged

    @property
    def photon_energy_j(self) -> float:
        """Energy of one photon at ``wavelength_m`` [J]: h c / lambda."""
        return PLANCK_J_S * SPEED_OF_LIGHT_M_S / self.wavelength_m

    @property
    def dn_per_irradiance(self) -> float:
        """Slope of :meth:`expected` below saturation [DN per W/m^2]: ``electrons_per_irradiance / gain``."""
        return self.electrons_per_irradiance / self.gain

    @property
    def electrons_per_irradiance(self) -> float:
        """Mean signal photoelectrons per pixel per exposure for 1 W/m^2 [e- m^2 / W] (no dark current)."""
        return self.pixel_area_m2 * self.exposure_s / self.photon_energy_j * self.quantum_efficiency

    # ----------------------------------------------------------------------------------------------- model
    def photons(self, irradiance_w_m2: ArrayLike) -> np.ndarray:
        """Mean number of photons reaching one pixel during the exposure (float array, same shape)."""
        irradiance = _validated_irradiance(irradiance_w_m2)
        return irradiance * (self.pixel_area_m2 * self.exposure_s / self.photon_energy_j)

    def electrons(self, irradiance_w_m2: ArrayLike) -> np.ndarray:
        """Mean photoelectrons per pixel per exposure, signal plus dark current, before saturation [e-]."""
        irradiance = _validated_irradiance(irradiance_w_m2)
        return irradiance * self.electrons_per_irradiance + self.dark_current_e_per_s * self.exposure_s

    def expected(self, irradiance_w_m2: ArrayLike) -> np.ndarray:
        """Noiseless digital value [DN]: ``min(electrons, full_well) / gain`` clipped to ``[0, max_dn]``.

        No noise and no rounding. It is the mean of :meth:`measure` up to quantisation and to the effect of
        noise near the clipping limits (where the mean of a clipped noisy value is not the clipped mean).
        """
        electrons = np.minimum(self.electrons(irradiance_w_m2), self.full_well_e)
        return np.clip(self._to_dn(electrons), 0.0, self.max_dn)

    def expected_std_dn(self, irradiance_w_m2: ArrayLike, include_quantization: bool = True) -> np.ndarray:
        """Theoretical temporal noise of one mixel value [DN rms], valid below saturation and above zero.

        ``sqrt((electrons + read_noise^2) / N) / gain``, plus, if ``include_quantization``, the rounding noise
        of the N pixel values (1/12 DN^2 each, so 1/(12 N) DN^2 for their average; exact when the per-pixel
        noise is well above 1 DN).
        """
        n = self.pixels_averaged
        variance = (self.electrons(irradiance_w_m2) + self.read_noise_e**2) / n / self.gain**2
        if include_quantization:
            variance = variance + 1.0 / (12.0 * n)
        return np.sqrt(variance)

    def measure(
        self, irradiance_w_m2: ArrayLike, rng: np.random.Generator, method: MeasureMethod = "aggregate"
    ) -> np.ndarray:
        """Simulated digital readout [DN] (float array, same shape as ``irradiance_w_m2``).

        Parameters
        ----------
        irradiance_w_m2 : array_like of float
            Irradiance on the detector [W/m^2], >= 0, finite; uniform over the mixel's N pixels.
        rng : numpy.random.Generator
            Sole source of randomness (e.g. ``np.random.default_rng(seed)``).
        method : {"aggregate", "per_pixel"}
            ``"per_pixel"`` simulates each of the N pixels (memory and time ~ N x size) and averages their
            digital values. ``"aggregate"`` (default) draws the sum over the N pixels directly: the sum of N
            Poisson draws is Poisson(N mean) and the sum of N Gaussian read noises is Gaussian with variance
            N sigma^2, both exact; the N per-pixel roundings are replaced by one Gaussian of variance N/12
            DN^2 (exact in mean and variance when the per-pixel noise exceeds ~0.5 DN). A sum cannot clip
            per pixel, so values whose pixels come within 10 noise sigmas of 0 DN or of full well / the ADC's
            top (:meth:`near_clipping`; e.g. a dark mixel, whose read noise each pixel's ADC clips at 0) are
            simulated pixel by pixel, from a child of ``rng`` (``SeedSequence.spawn``: the other values keep
            their draws). With N = 1 both methods follow the same distribution.

        Returns
        -------
        numpy.ndarray
            Digital numbers [DN] in ``[0, max_dn]``; integers when N = 1, multiples of 1/N otherwise.
        """
        if not isinstance(rng, np.random.Generator):
            raise TypeError(
                f"rng must be a numpy.random.Generator, got {type(rng).__name__}; "
                "pass np.random.default_rng(seed) (no global random state is used)"
            )
        if method not in ("aggregate", "per_pixel"):
            raise InputError(f"method must be 'aggregate' or 'per_pixel', got {method!r}")
        mean_electrons = np.asarray(self.electrons(irradiance_w_m2), dtype=np.float64)
        flat = mean_electrons.reshape(-1)  # a scalar irradiance used to fail (numpy scalars from rng.poisson)
        measure = self._measure_per_pixel if method == "per_pixel" else self._measure_aggregate
        return measure(flat, rng).reshape(mean_electrons.shape)

    def _measure_per_pixel(self, mean_electrons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        n = self.pixels_averaged
        lam = np.broadcast_to(np.minimum(mean_electrons, POISSON_MEAN_CAP_E)[..., np.newaxis],
                              (*mean_electrons.shape, n))
        electrons = np.minimum(rng.poisson(lam).astype(np.float64), self.full_well_e)
        electrons += rng.normal(0.0, self.read_noise_e, size=lam.shape) if self.read_noise_e > 0 else 0.0
        digital = np.clip(np.rint(self._to_dn(electrons)), 0.0, self.max_dn)
        return digital.mean(axis=-1)

    def near_clipping(self, mean_electrons: ArrayLike, n_sigma: float = 10.0) -> np.ndarray:
        """Where a pixel's value can reach the clipping limits: within ``n_sigma`` noise standard deviations
        (shot + read) of 0 DN or of the smaller of the full well and the ADC's top [e-] (boolean array)."""
        lam = np.asarray(mean_electrons, dtype=np.float64)
        spread = n_sigma * np.sqrt(lam + self.read_noise_e**2) + 1.0
        top = min(self.full_well_e, (self.max_dn + 0.5) * self.gain)
        return (lam - spread < 0.5 * self.gain) | (lam + spread > top)

    def _measure_aggregate(self, mean_electrons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        n = self.pixels_averaged
        # a mean beyond the cap saturates either way; numpy refuses one near 9.2e18 ("lam value too large")
        electrons_sum = np.minimum(rng.poisson(np.minimum(n * mean_electrons, POISSON_MEAN_CAP_E)).astype(np.float64),
                                   n * self.full_well_e)
        if self.read_noise_e > 0:
            electrons_sum += rng.normal(0.0, self.read_noise_e * np.sqrt(n), size=mean_electrons.shape)
        digital_sum = self._to_dn(electrons_sum)
        if n > 1:
            digital_sum += rng.normal(0.0, np.sqrt(n / 12.0), size=mean_electrons.shape)
        digital = np.clip(np.rint(digital_sum) / n, 0.0, self.max_dn)
        if n > 1:
            # The sum cannot reproduce per-pixel clipping: near 0 DN (each pixel's negative read noise is
            # clipped, raising the mean) or near full well / the ADC's top. Simulate those values pixel by
            # pixel, from a child stream (seed-sequence spawn) so the other values keep their draws.
            edge = self.near_clipping(mean_electrons)
            if np.any(edge):
                child = _child_generator(rng)
                lam = mean_electrons[edge]
                chunk = max(1, (1 << 22) // n)  # ~32 MiB of float64 per chunk
                digital[edge] = np.concatenate(
                    [self._measure_per_pixel(lam[i : i + chunk], child) for i in range(0, lam.size, chunk)]
                )
        return digital

    # ----------------------------------------------------------------------------------------------- exposure
    def exposure_for(self, irradiance_peak_w_m2: float, fill: float = 0.8) -> float:
        """Exposure [s] at which ``irradiance_peak_w_m2`` gives ``fill`` x full well (dark current included).

        Useful when a simulation's irradiance scale is arbitrary: pick the brightest expected irradiance and a
        fill fraction below 1 to leave headroom for shot noise before saturation.
        """
        if not is_finite_real(irradiance_peak_w_m2) or irradiance_peak_w_m2 <= 0:
            raise InputError(
                f"irradiance_peak_w_m2 must be a finite number > 0, got {irradiance_peak_w_m2!r}; "
                "pass the brightest irradiance the mixel should record"
            )
        if not is_finite_real(fill) or not 0 < fill <= 1:
            raise InputError(f"fill must be in (0, 1], got {fill!r}; e.g. 0.8 fills 80 % of the full well")
        electrons_per_second = (
            irradiance_peak_w_m2 * self.pixel_area_m2 / self.photon_energy_j * self.quantum_efficiency
            + self.dark_current_e_per_s
        )
        return fill * self.full_well_e / electrons_per_second

    def auto_exposed(self, irradiance_peak_w_m2: float, fill: float = 0.8) -> SensorModel:
        """A copy of this model with ``exposure_s = exposure_for(irradiance_peak_w_m2, fill)``."""
        return replace(self, exposure_s=self.exposure_for(irradiance_peak_w_m2, fill))


def _validated_irradiance(irradiance_w_m2: ArrayLike) -> np.ndarray:
    irradiance = np.asarray(irradiance_w_m2, dtype=np.float64)
    if not np.all(np.isfinite(irradiance)):
        bad = int(np.count_nonzero(~np.isfinite(irradiance)))
        raise InputError(
            f"irradiance_w_m2 has {bad} non-finite value(s) (NaN or inf); "
            "replace them (e.g. np.nan_to_num) before simulating the readout"
        )
    if np.any(irradiance < 0):
        raise InputError(
            f"irradiance_w_m2 must be >= 0 (minimum given: {irradiance.min():.6g}); irradiance is a power "
            "per area and cannot be negative: check signs or subtract backgrounds after measuring, not before"
        )
    return irradiance


def _child_generator(rng: np.random.Generator) -> np.random.Generator:
    """A generator independent of ``rng`` that does not advance its stream (its seed sequence spawns a child;
    deterministic for a given seed and history). Falls back to drawing a seed from ``rng`` if it has none."""
    seed_seq = getattr(rng.bit_generator, "seed_seq", None)
    if isinstance(seed_seq, np.random.SeedSequence):
        return np.random.Generator(type(rng.bit_generator)(seed_seq.spawn(1)[0]))
    return np.random.default_rng(rng.integers(0, 2**63))
