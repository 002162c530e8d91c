"""Transmission masks: a 2D grayscale transmission texture in [0, 1] with a physical size.

Array convention (the same for every mask and every file this package writes): ``transmission[i, j]``
with row ``i = 0`` at the *top* and column ``j = 0`` at the *left*, as seen from the detector looking out
through the mask (mixel "up" is local +y). Because a lensless mask does not invert the scene, a mask point on
the right of the detector sees the scene on the right: the mask picture overlays directly on the scene as the
mixel sees it.

Normalised mask coordinates used by the generators: ``x`` in [0, 1] from left to right and ``y`` in [0, 1]
from bottom to top (the paper's M = x, 1 - x, y, 1 - y). Physical mask coordinates ``x_m``, ``y_m`` [m] are
centred on the mask, +x_m to the right, +y_m up.

This module holds the :class:`Mask` type, the analytic generators (ramps, constants, sinusoids; their exact
profiles are :mod:`mincam_sim.masks.profiles`) and area-averaged resampling.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from mincam_sim import paper
from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.masks import profiles as prof
from mincam_sim.masks.profiles import MaskProfile

DEFAULT_MASK_SIZE_M = paper.MASK_SIZE_M  # [m] square mask side: with d_f = 2 mm, a ~53 degree field of view
DEFAULT_RESOLUTION = 256  # texels per side of generated masks
MAX_TEXELS = 8192 * 8192
MAX_SINUSOID_OMEGA_RAD_PER_M = 1e8  # [rad/m] a 63 nm period: below it the profile is beyond optics and float32


@dataclass(frozen=True, eq=False)
class Mask:
    """A transmission mask.

    Parameters
    ----------
    transmission : (H, W) array_like of float
        Transmission in [0, 1] (fraction of light passed), row 0 at the top (see module docstring).
    width_m, height_m : float
        Physical size of the mask [m].
    name : str
        Short label used in file names and metadata.
    meta : dict
        Free-form description (generator parameters, film ...).
    profile : MaskProfile, optional
        The exact analytic transmission (set by the generators: ramps, sinusoids, circular ramps ...). The
        renderer evaluates it at every ray, so the texel array is then only a picture of the mask; without a
        profile the array *is* the mask, reconstructed with ``interpolation``.
    interpolation : {"bilinear", "nearest"}
        How a raster mask (no profile) is read between texels: ``"bilinear"`` between texel centres (smooth
        images) or ``"nearest"`` (piecewise-constant printer dots).
    """

    transmission: np.ndarray
    width_m: float = DEFAULT_MASK_SIZE_M
    height_m: float = DEFAULT_MASK_SIZE_M
    name: str = "mask"
    meta: dict = field(default_factory=dict)
    profile: MaskProfile | None = None
    interpolation: str = "bilinear"

    def __post_init__(self) -> None:
        t = np.array(self.transmission, dtype=np.float64, copy=True)
        if t.ndim == 3 and t.shape[2] == 1:
            t = t[..., 0]
        if t.ndim != 2:
            raise InputError(
                f"mask {self.name!r}: transmission must be a 2D array (H, W), got shape {t.shape}"
            )
        if t.size == 0:
            raise InputError(f"mask {self.name!r}: transmission array is empty; give at least 1x1 texels")
        if t.size > MAX_TEXELS:
            raise InputError(
                f"mask {self.name!r}: {t.shape} is too large (max {MAX_TEXELS} texels); downsample it"
            )
        bad = ~np.isfinite(t)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise InputError(
                f"mask {self.name!r}: {int(bad.sum())} texel(s) are NaN or infinite"
                f" (first at row {i}, column {j}); transmission must be finite numbers in [0, 1]"
            )
        lo, hi = float(t.min()), float(t.max())
        if lo < 0.0 or hi > 1.0:
            raise InputError(
                f"mask {self.name!r}: transmission must lie in [0, 1] but spans [{lo:.10g}, {hi:.10g}];"
                " rescale it (e.g. divide by its maximum) or clip it"
            )
        for key in ("width_m", "height_m"):
            v = getattr(self, key)
            if not (is_finite_real(v) and v > 0):
                raise InputError(f"mask {self.name!r}: {key} must be a positive size in metres, got {v!r}")
        if self.profile is not None and not isinstance(self.profile, MaskProfile):
            raise TypeError(f"mask {self.name!r}: profile must be a mincam_sim.masks.profiles.MaskProfile or None")
        if self.interpolation not in ("bilinear", "nearest"):
            raise InputError(f"mask {self.name!r}: interpolation must be 'bilinear' or 'nearest', "
                             f"got {self.interpolation!r}")
        t.setflags(write=False)
        object.__setattr__(self, "transmission", t)
        object.__setattr__(self, "width_m", float(self.width_m))
        object.__setattr__(self, "height_m", float(self.height_m))

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) in texels."""
        return self.transmission.shape  # type: ignore[return-value]

    @property
    def area_m2(self) -> float:
        """Physical aperture area [m^2]."""
        return self.width_m * self.height_m

    def scaled(self, k: float) -> Mask:
        """The same mask with transmission multiplied by ``k`` (result must stay in [0, 1])."""
        profile = None if self.profile is None else prof.Affine(self.profile, float(k), 0.0)
        return Mask(self.transmission * k, self.width_m, self.height_m, f"{self.name}*{k:g}", dict(self.meta),
                    profile, self.interpolation)

    def complement(self) -> Mask:
        """The complementary mask 1 - M."""
        profile = None if self.profile is None else prof.Affine(self.profile, -1.0, 1.0)
        return Mask(1.0 - self.transmission, self.width_m, self.height_m, f"1-{self.name}", dict(self.meta),
                    profile, self.interpolation)

    @property
    def is_analytic(self) -> bool:
        """True when the renderer evaluates the mask exactly (a profile), not from its texel array."""
        return self.profile is not None

    def normalized_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Texel-centre coordinates (x, y) in [0, 1], x left to right, y bottom to top, each (H, W)."""
        h, w = self.shape
        return _normalized_grid(h, w)

    def physical_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Texel-centre coordinates (x_m, y_m) [m] centred on the mask, +x right, +y up, each (H, W)."""
        x, y = self.normalized_coords()
        return (x - 0.5) * self.width_m, (y - 0.5) * self.height_m


def _normalized_grid(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    x = (np.arange(w) + 0.5) / w
    y = 1.0 - (np.arange(h) + 0.5) / h
    return np.meshgrid(x, y)


def _check_resolution(resolution: int | tuple[int, int]) -> tuple[int, int]:
    """``(H, W)`` texels from an integer or a pair of integers; anything else, or more than :data:`MAX_TEXELS`
    texels, is refused (InputError) before an array is allocated."""
    if np.isscalar(resolution):
        hw: tuple = (resolution, resolution)
    else:
        try:
            hw = tuple(resolution)  # type: ignore[arg-type]
        except TypeError:
            hw = ()
    if (len(hw) != 2 or not all(is_finite_real(v) and int(v) == v and v >= 1 for v in hw)):
        raise InputError(f"mask resolution must be a positive integer or a pair of them (H, W) in texels, got "
                         f"{resolution!r}")
    h, w = int(hw[0]), int(hw[1])
    if h * w > MAX_TEXELS:
        raise InputError(f"mask resolution {(h, w)} is too large (max {MAX_TEXELS} texels); give a smaller one")
    return h, w


def from_function(
    func,
    name: str,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
    **meta,
) -> Mask:
    """Mask sampled at texel centres from ``func(x, y) -> transmission`` with x, y in [0, 1] (y up)."""
    h, w = _check_resolution(resolution)
    x, y = _normalized_grid(h, w)
    values = np.broadcast_to(np.asarray(func(x, y), dtype=float), (h, w))
    return Mask(values, width_m, width_m if height_m is None else height_m, name, meta)


def from_profile(
    profile: MaskProfile,
    name: str,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
    **meta,
) -> Mask:
    """An analytic mask: exact ``profile`` (evaluated per ray when rendering) and its texel picture."""
    h, w = _check_resolution(resolution)
    hgt = width_m if height_m is None else height_m
    for key, v in (("width_m", width_m), ("height_m", hgt)):
        if not (is_finite_real(v) and v > 0):
            raise InputError(f"mask {name!r}: {key} must be a positive size in metres, got {v!r}")
    return Mask(prof.sample(profile, (h, w), width_m, hgt), width_m, hgt, name, meta, profile)


def ramp(
    kind: str = "x",
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
) -> Mask:
    """Linear ramp mask: ``kind`` is ``"x"``, ``"1-x"``, ``"y"`` or ``"1-y"`` (the paper's Eq. 2 and 5)."""
    kinds = ("x", "1-x", "y", "1-y")
    if kind not in kinds:
        raise InputError(f"unknown ramp {kind!r}: choose one of {', '.join(kinds)}")
    hgt = width_m if height_m is None else height_m
    return from_profile(prof.Ramp(kind, float(width_m), float(hgt)), f"ramp_{kind}", resolution, width_m, hgt,
                        kind="ramp", ramp=kind)


def constant(
    value: float = 1.0,
    resolution: int | tuple[int, int] = 1,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
) -> Mask:
    """Uniform mask of transmission ``value`` (1 = open aperture)."""
    if not (is_finite_real(value) and 0.0 <= value <= 1.0):
        raise InputError(f"constant mask transmission must be a number in [0, 1], got {value!r}")
    return from_profile(prof.Constant(float(value)), f"constant_{value:g}", resolution, width_m, height_m,
                        kind="constant", value=value)


def sinusoid(
    omega_rad_per_m: float,
    a0: float = 0.5,
    a1: float = 0.5,
    phase_rad: float = 0.0,
    direction_deg: float = 0.0,
    resolution: int | tuple[int, int] = DEFAULT_RESOLUTION,
    width_m: float = DEFAULT_MASK_SIZE_M,
    height_m: float | None = None,
) -> Mask:
    """Sinusoid mask M = a0 + a1 cos(omega (x_m cos t + y_m sin t) + phase) (the paper's Eq. 9).

    Parameters
    ----------
    omega_rad_per_m : float
        Angular spatial frequency on the mask [rad/m] (omega_df in the paper).
    a0, a1 : float
        Mean and amplitude; ``a0 - |a1| >= 0`` and ``a0 + |a1| <= 1`` keep the mask physical.
    phase_rad : float
        Phase at the mask centre [rad].
    direction_deg : float
        Direction t of the wave vector, degrees counter-clockwise from +x (right).
    """
    if not is_finite_real(omega_rad_per_m) or not 0 <= omega_rad_per_m <= MAX_SINUSOID_OMEGA_RAD_PER_M:
        raise InputError(f"omega_rad_per_m must be a frequency from 0 to {MAX_SINUSOID_OMEGA_RAD_PER_M:g} rad/m (a "
                         f"period of at least {2e9 * np.pi / MAX_SINUSOID_OMEGA_RAD_PER_M:.3g} nm, finer than light "
                         f"resolves), got {omega_rad_per_m!r}")
    if not (is_finite_real(direction_deg) and abs(direction_deg) <= 360.0):
        raise InputError(f"direction_deg must be an angle in degrees between -360 and 360, got {direction_deg!r} "
                         "(take it modulo 360)")
    if not (is_finite_real(phase_rad) and abs(phase_rad) <= 1e3):
        raise InputError(f"phase_rad must be a finite phase of at most 1000 rad in size, got {phase_rad!r} "
                         "(take it modulo 2 pi)")
    for key, v in (("a0", a0), ("a1", a1)):
        if not is_finite_real(v):
            raise InputError(f"sinusoid {key} must be a finite number (a0 the mean, a1 the amplitude), got {v!r}")
    if a0 - abs(a1) < -1e-12 or a0 + abs(a1) > 1 + 1e-12:
        raise InputError(f"sinusoid a0={a0}, a1={a1} leaves [0, 1]: need a0 - |a1| >= 0 and a0 + |a1| <= 1")
    hgt = width_m if height_m is None else height_m
    profile = prof.Sinusoid(float(omega_rad_per_m), float(a0), float(a1), float(phase_rad), float(direction_deg))
    return from_profile(
        profile, f"sinusoid_{omega_rad_per_m:g}", resolution, width_m, hgt, kind="sinusoid",
        omega_rad_per_m=omega_rad_per_m, a0=a0, a1=a1, phase_rad=phase_rad, direction_deg=direction_deg,
    )


def _box_matrix(n_src: int, n_dst: int):
    """(n_dst, n_src) sparse matrix averaging piecewise-constant source cells over each destination cell."""
    i = np.arange(n_dst)
    lo, hi = i / n_dst, (i + 1) / n_dst
    first = np.floor(lo * n_src).astype(int)
    m = int(np.ceil(n_src / n_dst)) + 2
    k = first[:, None] + np.arange(m)[None, :]
    k_ok = (k >= 0) & (k < n_src)
    kc = np.clip(k, 0, n_src - 1)
    right = np.minimum(hi[:, None], (kc + 1) / n_src)
    overlap = np.clip(right - np.maximum(lo[:, None], kc / n_src), 0.0, None)
    wgt = np.where(k_ok, overlap * n_dst, 0.0)
    wgt /= wgt.sum(axis=1, keepdims=True)
    rows = np.broadcast_to(i[:, None], k.shape)
    mat = sparse.csr_matrix((wgt.ravel(), (rows.ravel(), kc.ravel())), shape=(n_dst, n_src))
    mat.sum_duplicates()
    return mat


def resample(mask: Mask, shape: tuple[int, int]) -> np.ndarray:
    """Area-average the mask (taken as piecewise constant over its texels) onto a regular (H, W) grid.

    Works for up- and down-sampling; a constant mask stays exactly constant and the mean is preserved.
    """
    h, w = _check_resolution(shape)
    ay = _box_matrix(mask.shape[0], h)
    ax = _box_matrix(mask.shape[1], w)
    out = ay @ (ax @ mask.transmission.T).T
    return np.clip(np.asarray(out), 0.0, 1.0)
