"""Mask transmission inside Dr.Jit kernels: one uv convention, exact analytic profiles, raster textures.

Conventions (the only place they are coded):

* A mixel's local frame has +x to the viewer's *left*, +y up, +z out through the mask (see
  :mod:`mincam_sim.model.geometry`). Physical mask coordinates (:mod:`mincam_sim.masks.profiles`) have +x to the
  viewer's *right*: ``x_m = -x_local``, ``y_m = y_local``.
* Texture coordinates of the mask array (row 0 at the top, column 0 at the left): ``u = 0.5 + x_m / w``,
  ``v = 0.5 - y_m / h``.

Masks with a profile are evaluated exactly at every ray; raster masks (files, printed films, polyline ramps)
through a Mitsuba ``bitmap`` with the mask's own interpolation (bilinear between texel centres, or nearest for
printer dots). :func:`mask_model_meta` records which, for every output.

:class:`RayWeight` is the one hook the fast forms use: a ray through the mask is weighted by ``T(x_m)``
(``optics = "geometric"``) or, for a mixel with ``optics = "wave"``, by its tabulated wave response for the
ray's direction divided by the open-aperture fraction (:meth:`mincam_sim.wave.ResponseTable.directional_weight`),
which averaged over the detector gives back the wave response.
"""

from __future__ import annotations

from mincam_sim.masks import Mask
from mincam_sim.masks.profiles import MaskProfile
from mincam_sim.model.optics import Mixel
from mincam_sim.render import backend
from mincam_sim.render.scene.textures import bitmap_dict

ANALYTIC_TEXTURE_PLUGIN = "mincam_analytic_mask"


class DrJitOps:
    """:class:`mincam_sim.masks.profiles.ArrayOps` on Dr.Jit arrays."""

    def __init__(self) -> None:
        import drjit as dr

        self.cos, self.sqrt, self.atan2, self.abs = dr.cos, dr.sqrt, dr.atan2, dr.abs
        self.floor, self.minimum, self.maximum = dr.floor, dr.minimum, dr.maximum
        self.where = dr.select


def local_to_mask_xy(x_local, y_local):
    """Physical mask coordinates (+x right, +y up) [m] of a point given in the mixel's local frame."""
    return -x_local, y_local


def mask_xy_to_uv(x_m, y_m, mask: Mask):
    """Texture coordinates of the mask array from physical mask coordinates."""
    return 0.5 + x_m / mask.width_m, 0.5 - y_m / mask.height_m


def mask_uv_to_xy(u, v, mask: Mask):
    """Physical mask coordinates [m] from the mask array's texture coordinates."""
    return (u - 0.5) * mask.width_m, (0.5 - v) * mask.height_m


def inside_aperture(x_m, y_m, mask: Mask):
    """True where the point lies on the mask (outside, the housing blocks the light)."""
    hw, hh = 0.5 * mask.width_m, 0.5 * mask.height_m
    return (x_m >= -hw) & (x_m <= hw) & (y_m >= -hh) & (y_m <= hh)


def raster_texture_dict(mask: Mask) -> dict:
    """A raw, clamped Mitsuba bitmap of the mask array with the mask's interpolation."""
    return bitmap_dict(mask.transmission, filter_type=mask.interpolation)


class MaskEvaluator:
    """Transmission of one mask at physical mask points, inside a kernel (0 outside the aperture)."""

    def __init__(self, mask: Mask) -> None:
        self.mask = mask
        self.mi = backend.mitsuba()
        if mask.profile is not None:
            self._ops = DrJitOps()
            self._texture = None
        else:
            self._texture = self.mi.load_dict(raster_texture_dict(mask))

    def __call__(self, x_m, y_m, active=True):
        import drjit as dr

        mi = self.mi
        inside = inside_aperture(x_m, y_m, self.mask) & active
        if self._texture is None:
            value = mi.Float(self.mask.profile.evaluate(mi.Float(x_m), mi.Float(y_m), self._ops))
        else:
            si = dr.zeros(mi.SurfaceInteraction3f)
            u, v = mask_xy_to_uv(x_m, y_m, self.mask)
            si.uv = mi.Point2f(u, v)
            value = self._texture.eval_1(si, inside)
        return dr.select(inside, value, 0.0)


_TABLES: dict[str, object] = {}


def wave_table(mixel: Mixel):
    """The mixel's :class:`mincam_sim.wave.ResponseTable`, computed once per process and mixel content."""
    from mincam_sim.storage.identity import fingerprint
    from mincam_sim.wave import response_table

    key = fingerprint({"mask": mixel.mask, "d_f_m": mixel.d_f_m, "detector_size_m": mixel.detector_size_m,
                       "wavelengths_m": list(mixel.wavelengths_m)})
    if key not in _TABLES:
        _TABLES[key] = response_table(mixel, mixel.wavelengths_m)
    return _TABLES[key]


class RayWeight:
    """A ray's mask weight for one mixel: ``T(x_m)`` (geometric) or the wave response for its direction.

    ``__call__(x_m, y_m, tan_x, tan_y, active)`` takes the mask point [m] and the direction tangents in physical
    mask coordinates (+x right, +y up): ``tan_x = -d_local.x / d_local.z``, ``tan_y = d_local.y / d_local.z``.
    Outside the aperture the weight is 0 either way.
    """

    def __init__(self, mixel: Mixel) -> None:
        self.mixel = mixel
        self.optics = mixel.optics
        self.mi = backend.mitsuba()
        if self.optics == "wave":
            table = wave_table(mixel)
            self._table = table
            weight = table.directional_weight()
            self._texture = self.mi.load_dict(bitmap_dict(weight, filter_type="bilinear"))
            tx, ty = table.tan_x, table.tan_y
            self._ux = (float(tx[0]), float(tx[-1]), len(tx))
            self._uy = (float(ty[0]), float(ty[-1]), len(ty))
            self._mask = None
        else:
            from mincam_sim.wave import quick_check

            quick_check(mixel)  # warns when diffraction likely puts the ray model > 1 % off
            self._mask = MaskEvaluator(mixel.mask)

    def __call__(self, x_m, y_m, tan_x, tan_y, active=True):
        import drjit as dr

        if self._mask is not None:
            return self._mask(x_m, y_m, active)
        mi = self.mi
        inside = inside_aperture(x_m, y_m, self.mixel.mask) & active
        (x0, x1, nx), (y0, y1, ny) = self._ux, self._uy
        u = (tan_x - x0) / (x1 - x0) * ((nx - 1) / nx) + 0.5 / nx
        v = (tan_y - y0) / (y1 - y0) * ((ny - 1) / ny) + 0.5 / ny
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.uv = mi.Point2f(u, v)
        value = self._texture.eval_1(si, inside)
        return dr.select(inside, value, 0.0)


def optics_meta(mixel: Mixel) -> dict:
    """How the renderer weighs this mixel's rays (for outputs' metadata)."""
    if mixel.optics == "geometric":
        return {"optics": "geometric"}
    table = wave_table(mixel)
    return {"optics": "wave", "wavelengths_m": list(mixel.wavelengths_m),
            "table": {k: v for k, v in table.meta.items() if k in ("n_tan", "method", "qe", "weights",
                                                                    "band_covered_min")}}


def mask_model_meta(mask: Mask) -> dict:
    """How the renderer reads this mask, and the discretisation error that adds (0 for analytic masks)."""
    if mask.profile is not None:
        return {"model": "analytic profile, evaluated exactly per ray", "discretisation_error": 0.0,
                "profile": mask.profile.describe()}
    return {"model": f"raster {mask.shape[1]}x{mask.shape[0]} texels, {mask.interpolation} interpolation "
                     "(the array is the mask)",
            "discretisation_error": None}


_registered = False


def register_analytic_texture() -> None:
    """Register a Mitsuba texture that evaluates a mask profile exactly (for the literal reference scene)."""
    global _registered
    if _registered:
        return
    backend.require_jit("Analytic mask textures (a Python Mitsuba plugin)")
    mi = backend.mitsuba()

    class AnalyticMaskTexture(mi.Texture):
        """Transmission (or, with ``opacity``, 1 - transmission) of a mask profile at the surface's uv."""

        def __init__(self, props):
            super().__init__(props)
            self._mask: Mask | None = None
            self._opacity = False
            self._ops = DrJitOps()

        def configure(self, mask: Mask, opacity: bool) -> None:
            self._mask, self._opacity = mask, opacity

        def eval_1(self, si, active=True):
            x_m, y_m = mask_uv_to_xy(si.uv.x, si.uv.y, self._mask)
            t = mi.Float(self._mask.profile.evaluate(x_m, y_m, self._ops))
            return 1.0 - t if self._opacity else t

        def eval(self, si, active=True):
            return mi.UnpolarizedSpectrum(self.eval_1(si, active))

        def mean(self):
            return 0.5

        def to_string(self):
            return f"AnalyticMaskTexture[{None if self._mask is None else self._mask.name}]"

    mi.register_texture(ANALYTIC_TEXTURE_PLUGIN, lambda props: AnalyticMaskTexture(props))
    _registered = True


def opacity_texture(mask: Mask):
    """A texture of ``1 - transmission`` for Mitsuba's ``mask`` BSDF: exact for profiles, else the raster."""
    if mask.profile is None or not backend.is_jit():
        return bitmap_dict(1.0 - mask.transmission, filter_type=mask.interpolation)
    register_analytic_texture()
    mi = backend.mitsuba()
    texture = mi.load_dict({"type": ANALYTIC_TEXTURE_PLUGIN})
    texture.configure(mask, opacity=True)
    return texture


__all__ = [
    "MaskEvaluator",
    "MaskProfile",
    "RayWeight",
    "optics_meta",
    "wave_table",
    "inside_aperture",
    "local_to_mask_xy",
    "mask_model_meta",
    "mask_uv_to_xy",
    "mask_xy_to_uv",
    "opacity_texture",
]
