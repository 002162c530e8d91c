"""Mitsuba scene dictionaries built by small pure functions (the style of ``mitsuba.util.cornell_box``).

Conventions (see :mod:`mincam_sim.model.geometry`, :mod:`mincam_sim.masks`, :mod:`mincam_sim.scene.display`):

* Mitsuba's ``rectangle`` spans [-1, 1]^2 in its local xy plane, normal +z, with ``uv = (x + 1, y + 1) / 2``;
  ``bitmap`` row 0 is at ``v = 0``.
* A mask rectangle is placed with ``scale(-w/2, -h/2, 1)`` in the mixel frame (whose +x is the viewer's left),
  so ``u`` grows to the viewer's right and ``v = 0`` is the top: the mask array maps onto it unflipped.
* A screen rectangle uses ``scale(w/2, h/2, 1)`` in the screen frame (+x is the viewer's right, +y up), so its
  ``v = 0`` is the bottom: frames (row 0 at the top) are flipped vertically when uploaded.
"""

from __future__ import annotations

import numpy as np

from mincam_sim.errors import InputError, is_finite_real
from mincam_sim.model.optics import Mixel
from mincam_sim.render import backend
from mincam_sim.render.kernels.mask_eval import opacity_texture
from mincam_sim.render.scene.textures import bitmap_dict, texture_tensor
from mincam_sim.scene.display import Screen


class SceneFrame:
    """Where world metres go in a Mitsuba scene: ``scene = scale * (world - origin_m)``.

    Mitsuba restarts a ray that crossed a surface (the reference form's mask) at an offset of about
    ``9e-5 * (1 + max|p|)`` scene units. In metres with the mixel near the origin that is ~90 um: close
    occluders would seem that much nearer. Scenes of the literal mixel are therefore built in millimetres
    around the mixel itself (``SceneFrame.millimetres_around(p)``), where the offset is ~0.3 um.
    Irradiance and radiance do not depend on the length unit.
    """

    def __init__(self, origin_m=(0.0, 0.0, 0.0), scale: float = 1.0) -> None:
        self.origin_m = np.asarray(origin_m, dtype=np.float64)
        self.scale = float(scale)

    @classmethod
    def millimetres_around(cls, origin_m) -> SceneFrame:
        return cls(origin_m, 1e3)

    def matrix(self) -> np.ndarray:
        """4 x 4 world -> scene matrix."""
        m = np.eye(4) * self.scale
        m[3, 3] = 1.0
        m[:3, 3] = -self.scale * self.origin_m
        return m

    def apply(self, matrix: np.ndarray) -> np.ndarray:
        """A local -> world matrix turned into local -> scene."""
        return self.matrix() @ np.asarray(matrix, dtype=np.float64)


WORLD = SceneFrame()


def _transform(matrix: np.ndarray, frame: SceneFrame = WORLD):
    mi = backend.mitsuba()
    return mi.ScalarTransform4f(frame.apply(matrix).tolist())


def black_bsdf() -> dict:
    """A perfectly absorbing surface (housings, detectors, screen surface)."""
    return {"type": "diffuse", "reflectance": {"type": "spectrum", "value": 0.0}}


def irradiancemeter(spp: int) -> dict:
    """Mitsuba's irradiance meter (attach to a shape): mean irradiance over the shape [W/m^2], 1 x 1 film."""
    return {
        "type": "irradiancemeter",
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {"type": "hdrfilm", "width": 1, "height": 1, "pixel_format": "luminance", "rfilter": {"type": "box"}},
    }


def mask_surface_matrix(mixel: Mixel) -> np.ndarray:
    """World matrix of a mixel's mask rectangle (see module docstring for the orientation)."""
    w, h = mixel.mask.width_m, mixel.mask.height_m
    local = np.diag([-w / 2, -h / 2, 1.0, 1.0])
    local[2, 3] = mixel.d_f_m
    return mixel.pose.matrix() @ local


def housing_matrices(mixel: Mixel) -> list[np.ndarray]:
    """World matrices of the 4 walls of the black tube between detector plane (z = 0) and mask (z = d_f)."""
    w, h, d = mixel.mask.width_m, mixel.mask.height_m, mixel.d_f_m
    walls = []
    for axis, half, other_half in ((0, w / 2, h / 2), (1, h / 2, w / 2)):
        for sign in (-1.0, 1.0):
            m = np.eye(4)
            normal = np.zeros(3)
            normal[axis] = sign
            along = np.zeros(3)
            along[1 - axis] = other_half
            depth = np.array([0.0, 0.0, d / 2])
            m[:3, 0] = along
            m[:3, 1] = depth
            m[:3, 2] = normal
            m[:3, 3] = normal * half + np.array([0.0, 0.0, d / 2])
            walls.append(mixel.pose.matrix() @ m)
    return walls


BACK_PLATE_GAP = 1e-3  # back plate this fraction of d_f behind the detector plane (no coplanar surfaces)


def back_plate_matrix(mixel: Mixel) -> np.ndarray:
    """World matrix of the body's back (a black plate of the mask's size just behind the detector plane)."""
    w, h = mixel.mask.width_m, mixel.mask.height_m
    local = np.diag([w / 2, h / 2, 1.0, 1.0])
    local[2, 3] = -BACK_PLATE_GAP * mixel.d_f_m
    return mixel.pose.matrix() @ local


def mixel_body_shapes(mixel: Mixel, key: str, frame: SceneFrame = WORLD) -> dict:
    """A mixel's body as an occluder for the other mixels: 4 black housing walls and a black back plate.

    The front (the mask) is left open: whatever enters through it is absorbed inside the closed black box, so
    from outside the body is an opaque black box, and a mixel's own rays (which start on its mask plane) never
    meet its own body.
    """
    back, *walls = mixel_body_matrices(mixel)
    shapes = {f"{key}_body_back": {"type": "rectangle", "to_world": _transform(back, frame), "bsdf": black_bsdf()}}
    for i, wall in enumerate(walls):
        shapes[f"{key}_body_wall{i}"] = {"type": "rectangle", "to_world": _transform(wall, frame),
                                         "bsdf": black_bsdf()}
    return shapes


#: The key of the one mesh that holds every mixel's body in a scene (:func:`mincam_body_shapes`).
BODIES_KEY = "mincam_bodies"

_RECTANGLE_CORNERS = np.array([[-1.0, -1.0, 0.0, 1.0], [1.0, -1.0, 0.0, 1.0], [1.0, 1.0, 0.0, 1.0],
                               [-1.0, 1.0, 0.0, 1.0]]).T  # a Mitsuba rectangle's corners, local, homogeneous


def mixel_body_matrices(mixel: Mixel) -> list[np.ndarray]:
    """World matrices of a mixel's body rectangles (local [-1, 1]^2 at z = 0): the back plate, then the 4 walls."""
    return [back_plate_matrix(mixel), *housing_matrices(mixel)]


def mincam_body_keys(mincam) -> set[str]:
    """The scene keys :func:`mincam_body_shapes` uses for ``mincam`` (none for an idealised mincam)."""
    return {BODIES_KEY} if mincam.occluding_bodies else set()


def mincam_body_shapes(mincam, frame: SceneFrame = WORLD, skip: int | None = None) -> dict:
    """Bodies of every mixel (except index ``skip``) as one black triangle mesh under :data:`BODIES_KEY`, or none
    for an idealised, overlapping mincam.

    Each body is the 5 rectangles of :func:`mixel_body_shapes` (2 triangles each). One mesh rather than 5 shapes
    a mixel: a frozen launch walks every shape of its scene per call (~9 us a shape), which for 20 rectangles was
    ~15 % of a 4-mixel change frame; what a ray meets is the same surface (black: it absorbs)."""
    if not mincam.occluding_bodies:
        return {}
    matrices = [frame.apply(m) for k, mixel in enumerate(mincam) if k != skip for m in mixel_body_matrices(mixel)]
    if not matrices:
        return {}
    vertices = np.concatenate([(m @ _RECTANGLE_CORNERS)[:3].T for m in matrices])
    base = 4 * np.arange(len(matrices))[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return {BODIES_KEY: mesh_object(BODIES_KEY, vertices, faces, 0.0)}


def mixel_reference_shapes(mixel: Mixel, key: str, spp: int, frame: SceneFrame = WORLD) -> dict:
    """The literal mixel: detector with an ``irradiancemeter``, textured transmissive mask, black housing.

    The mask is Mitsuba's ``mask`` BSDF (stochastic null pass-through with probability = transmission) over a
    black BSDF, so transmitted light continues unchanged and the rest is absorbed. Analytic masks use an exact
    texture (:func:`.mask_eval.opacity_texture`).
    """
    s = mixel.detector_size_m
    detector = mixel.pose.matrix() @ np.diag([s / 2, s / 2, 1.0, 1.0])
    shapes = {
        f"{key}_detector": {
            "type": "rectangle",
            "to_world": _transform(detector, frame),
            "bsdf": black_bsdf(),
            "sensor": irradiancemeter(spp),
        },
        f"{key}_mask": {
            "type": "rectangle",
            "to_world": _transform(mask_surface_matrix(mixel), frame),
            "bsdf": {"type": "mask", "opacity": opacity_texture(mixel.mask), "bsdf": black_bsdf()},
        },
    }
    shapes.update(mixel_body_shapes(mixel, key, frame))
    return shapes


def screen_matrix(screen: Screen) -> np.ndarray:
    return screen.pose.matrix() @ np.diag([screen.width_m / 2, screen.height_m / 2, 1.0, 1.0])


def frame_tensor(frame: np.ndarray):
    """A frame (row 0 at the top) as the screen emitter's texture data (row 0 at the bottom)."""
    return texture_tensor(np.asarray(frame)[::-1])


def screen_shape(screen: Screen, frame: np.ndarray | None = None, scene_frame: SceneFrame = WORLD) -> dict:
    """An emissive display: black surface, area emitter whose radiance is the frame (nearest texel)."""
    frame = screen.blank() if frame is None else screen.check_frame(frame)
    radiance = bitmap_dict(frame[::-1], filter_type="nearest")
    return {
        "type": "rectangle",
        "to_world": _transform(screen_matrix(screen), scene_frame),
        "bsdf": black_bsdf(),
        "emitter": {"type": "area", "radiance": radiance},
    }


SCREEN_KEY = "screen"
SCREEN_RADIANCE_PARAM = f"{SCREEN_KEY}.emitter.radiance.data"


def mesh_object(name: str, vertices_m: np.ndarray, faces: np.ndarray, albedo: float = 0.8):
    """An in-memory triangle mesh (``mi.Mesh``) with a diffuse gray albedo in [0, 1]."""
    mi = backend.mitsuba()
    vertices_m = _numbers(vertices_m, f"object {name!r}: vertices")
    if vertices_m.ndim != 2 or vertices_m.shape[1] != 3 or len(vertices_m) == 0:
        raise InputError(f"object {name!r}: vertices must be a non-empty (n, 3) array [m], got {vertices_m.shape}")
    if not np.all(np.isfinite(vertices_m)):
        raise InputError(f"object {name!r}: vertices hold NaN or infinite values; give finite positions [m]")
    faces = _numbers(faces, f"object {name!r}: faces")
    if (faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0 or not np.all(faces == np.round(faces))
            or faces.min() < 0 or faces.max() >= len(vertices_m)):
        raise InputError(f"object {name!r}: faces must be a non-empty (m, 3) array of vertex indices (0 to "
                         f"{len(vertices_m) - 1})")
    if _not_number(albedo) or not 0.0 <= albedo <= 1.0:
        raise InputError(f"object {name!r}: albedo must lie in [0, 1], got {albedo!r}")
    vertices_m, faces = vertices_m.astype(np.float32), faces.astype(np.uint32)
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "diffuse", "reflectance": {"type": "spectrum", "value": float(albedo)}})
    mesh = mi.Mesh(name, len(vertices_m), len(faces), props=props)
    params = mi.traverse(mesh)
    # copies: Dr.Jit maps float32 / uint32 numpy arrays without copying, and the mesh must not alias the caller's
    params["vertex_positions"] = mi.Float(vertices_m.ravel().copy())
    params["faces"] = mi.UInt32(faces.ravel().copy())
    params.update()
    return mesh


def textured_plane(albedo: np.ndarray, width_m: float, height_m: float, matrix: np.ndarray) -> dict:
    """A diffuse rectangle whose albedo texture (row 0 at the local +y edge) spans ``width_m x height_m``.

    ``matrix`` places the plane (local +z is its normal); the texture is flipped so that row 0 lies at +y.
    """
    albedo = np.asarray(albedo, dtype=float)
    if albedo.ndim != 2 or albedo.size == 0 or albedo.min() < 0 or albedo.max() > 1 or not np.isfinite(albedo).all():
        raise ValueError("plane albedo must be a non-empty 2D array of finite values in [0, 1]")
    return {
        "type": "rectangle",
        "to_world": _transform(np.asarray(matrix) @ np.diag([width_m / 2, height_m / 2, 1.0, 1.0])),
        "bsdf": {"type": "diffuse", "reflectance": bitmap_dict(albedo[::-1])},
    }


def _not_number(value) -> bool:
    """Not a real number that a 32-bit float holds (Mitsuba's scene values)."""
    return not is_finite_real(value) or abs(value) > np.finfo(np.float32).max


def _numbers(value, what: str) -> np.ndarray:
    """``value`` as a float64 array, or one :class:`InputError` naming ``what``."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be numbers, got {type(value).__name__}") from None


def _placement(matrix, what: str) -> np.ndarray:
    """A 4 x 4 finite placement matrix (an array, or a Mitsuba transform), or one :class:`InputError` naming
    ``what``."""
    matrix = _numbers(getattr(matrix, "matrix", matrix), what)
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        raise InputError(f"{what} must be a finite 4 x 4 matrix (e.g. Pose(...).matrix()), got shape {matrix.shape}")
    return matrix


def area_light(width_m: float, height_m: float, matrix: np.ndarray, radiance_w_m2_sr: float) -> dict:
    """A rectangular area light emitting ``radiance_w_m2_sr`` along its local +z."""
    for name, value in (("width_m", width_m), ("height_m", height_m)):
        if _not_number(value) or value <= 0:
            raise InputError(f"area_light: {name} must be a positive size [m] (a light of no area emits nothing), "
                             f"got {value!r}")
    if _not_number(radiance_w_m2_sr) or radiance_w_m2_sr < 0:
        raise InputError(f"area_light: radiance_w_m2_sr must be a finite radiance >= 0, got {radiance_w_m2_sr!r}")
    matrix = _placement(matrix, "area_light: matrix")
    return {
        "type": "rectangle",
        "to_world": _transform(np.asarray(matrix) @ np.diag([width_m / 2, height_m / 2, 1.0, 1.0])),
        "bsdf": black_bsdf(),
        "emitter": {"type": "area", "radiance": {"type": "spectrum", "value": float(radiance_w_m2_sr)}},
    }


def point_light(position_m, intensity_w_sr: float) -> dict:
    """An isotropic point light at ``position_m`` (3,) [m] of radiant intensity ``intensity_w_sr`` [W/sr]."""
    return {"type": "point", "position": [float(x) for x in position_m],
            "intensity": {"type": "spectrum", "value": float(intensity_w_sr)}}


def spot_light(matrix: np.ndarray, intensity_w_sr: float, cutoff_deg: float) -> dict:
    """A spot light placed by ``matrix`` (4 x 4, shining along its local +z) of on-axis intensity
    ``intensity_w_sr`` [W/sr], falling off to zero at ``cutoff_deg`` [deg] from a beam of 3/4 of that."""
    return {"type": "spot", "to_world": _transform(matrix),
            "intensity": {"type": "spectrum", "value": float(intensity_w_sr)},
            "cutoff_angle": float(cutoff_deg), "beam_width": 0.75 * float(cutoff_deg)}


def sky(radiance_w_m2_sr: float) -> dict:
    """A uniform environment (overcast sky) of the given radiance."""
    return {"type": "constant", "radiance": {"type": "spectrum", "value": float(radiance_w_m2_sr)}}


def pinhole_camera(matrix: np.ndarray, fov_deg: float, width_px: int, height_px: int, spp: int = 64) -> dict:
    """A perspective (pinhole) camera; ``matrix`` is a pose matrix (local +z forward, +y up)."""
    mi = backend.mitsuba()
    m = np.asarray(matrix, dtype=float).copy()
    # Mitsuba's perspective camera looks along local +z with +x to the left: the pose convention already.
    return {
        "type": "perspective",
        "to_world": mi.ScalarTransform4f(m.tolist()),
        "fov": float(fov_deg),
        "fov_axis": "x",
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {"type": "hdrfilm", "width": int(width_px), "height": int(height_px), "pixel_format": "luminance",
                 "rfilter": {"type": "box"}},
    }
