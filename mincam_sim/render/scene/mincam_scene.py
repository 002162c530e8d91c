"""One scene object for a mincam anywhere (a display or a world), with the forms as solvers over it.

:class:`MincamScene` holds the mincam and its content (a :class:`~mincam_sim.scene.display.Screen`, or Mitsuba elements
of a world in metres) and builds, on demand, the Mitsuba scenes the forms trace:

* the *fast* scene: content + every mixel's body (opaque boxes, :func:`.scene_dicts.mincam_body_shapes`) + the
  mixel-array sensor (rays start on the mask apertures); response maps use it for their visibility rays;
* the *reference* scenes (displays only): one per mixel, in millimetres around that mixel
  (:class:`.scene_dicts.SceneFrame`), with its literal detector, mask surface and housing and the other
  mixels' bodies.

Parameter updates (a display frame, moved meshes) go to every scene built so far. The estimates of every form
come back as ``(replicates, n_mixels)`` arrays of independent estimates [W/m^2]; seeds follow
:func:`.estimation.derive_seed` with the form as purpose.
"""

from __future__ import annotations

import ctypes
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from mincam_sim.model.optics import Mincam
from mincam_sim.render import backend
from mincam_sim.render.kernels import frozen
from mincam_sim.render.kernels.camera_window import window_render
from mincam_sim.render.kernels.mixel_sensor import mixel_position_sample, sensor_dict
from mincam_sim.render.kernels.monte_carlo import check_counts, derive_seed
from mincam_sim.render.kernels.tracing import trace_groups
from mincam_sim.render.scene.scene_dicts import (
    BODIES_KEY,
    SCREEN_KEY,
    SCREEN_RADIANCE_PARAM,
    WORLD,
    SceneFrame,
    frame_tensor,
    mincam_body_shapes,
    mixel_reference_shapes,
    screen_shape,
)
from mincam_sim.scene.display import Screen, check_visible
from mincam_sim.storage.identity import mask_parts

SENSOR_KEY = "mincam"
CAMERA_KEY = "ground_truth_camera"
REFERENCE_MAX_DEPTH = 3  # detector ray -> mask pass-through (one bounce) -> screen emission, plus margin
RESERVED_KEYS = {SENSOR_KEY, CAMERA_KEY, BODIES_KEY, "integrator", "type"}


def _unshared(value):
    """``value`` (an element: a Mitsuba dict, nested) with its Dr.Jit arrays wrapped anew: Mitsuba's
    ``load_dict`` takes a tensor out of the dict it loads (a ``textured_plane``'s bitmap ``data`` is left empty,
    shape ``()``), so a second scene built from the same dict (a second ``Simulation`` in the same world) failed
    with "Bitmap raw tensor has dimension 0". The arrays' data is shared, not copied."""
    import drjit as dr

    if isinstance(value, Mapping):
        return {key: _unshared(item) for key, item in value.items()}
    if dr.is_array_v(value):
        return type(value)(value)
    return value


class MincamScene:
    """A mincam in a display or world scene.

    Use :meth:`display` or :meth:`world` to build one.
    """

    def __init__(self, mincam: Mincam, *, screen: Screen | None = None, elements: dict | None = None,
                 max_depth: int = 2, camera: dict | None = None) -> None:
        if (screen is None) == (elements is None):
            raise ValueError("a MincamScene holds either a screen or world elements")
        if isinstance(max_depth, bool) or int(max_depth) != max_depth or max_depth < 2:
            raise ValueError(f"max_depth must be an integer >= 2 (2 = emitters seen directly), got {max_depth!r}")
        if elements is not None:
            reserved = RESERVED_KEYS & set(elements)
            if reserved:
                raise ValueError(f"scene element names {sorted(reserved)} are reserved; rename them")
        self.mincam, self.screen, self.elements = mincam, screen, elements
        self.max_depth, self.camera_dict = int(max_depth), camera
        self.mi = backend.mitsuba()
        self._fast = None
        self._fast_params = None
        self._own_vertices: set[str] = set()  # vertex buffers this scene allocated itself (safe to write in place)
        self._reference: list | None = None
        self._reference_params: list = []
        self._frame: np.ndarray | None = None

    @classmethod
    def display(cls, mincam: Mincam, screen: Screen) -> MincamScene:
        """A mincam in front of an emissive display in a dark room.

        The scene is built around the mincam (``scene = world - mincam.centre_m``; its :attr:`mincam` and
        :attr:`screen` are the moved ones): in float32 a rig 1.2 km from the origin placed its detector points
        on a ~0.1 mm grid, and a tilted rig's response maps read 40 % low.
        """
        check_visible(screen, mincam)
        offset = -mincam.centre_m
        moved = replace(screen, pose=screen.pose.translated(tuple(offset)))
        return cls(mincam.translated(offset), screen=moved, max_depth=2)

    @classmethod
    def world(cls, mincam: Mincam, elements: dict, max_depth: int = 3, camera: dict | None = None) -> MincamScene:
        """A mincam in a general scene (elements: name -> Mitsuba dict or object, in metres)."""
        return cls(mincam, elements=dict(elements), max_depth=max_depth, camera=camera)

    # ------------------------------------------------------------------------------------------ scenes
    def _content(self, frame: SceneFrame | None = None) -> dict:
        if self.screen is not None:
            return {SCREEN_KEY: screen_shape(self.screen, self._frame, frame or WORLD)}
        return {name: _unshared(value) for name, value in self.elements.items()}

    @property
    def fast_scene(self):
        """The scene of the fast forms (loaded on first use)."""
        if self._fast is None:
            scene = {"type": "scene", "integrator": {"type": "path", "max_depth": self.max_depth},
                     SENSOR_KEY: sensor_dict(len(self.mincam)), **self._content(),
                     **mincam_body_shapes(self.mincam)}
            if self.camera_dict is not None:
                scene[CAMERA_KEY] = self.camera_dict
            # World scenes keep every shape as built: Mitsuba's default merges shapes that share a BSDF into one
            # anonymous mesh, whose parameters then belong to no element (the mixels' bodies, a user's card).
            self._fast = self.mi.load_dict(scene, optimize=self.screen is not None)
            frozen.release_with(self, self._fast)
            sensors = {s.id(): s for s in self._fast.sensors()}
            sensors[SENSOR_KEY].set_mixels(list(self.mincam))
            self._fast_params = self.mi.traverse(self._fast)
        return self._fast

    @property
    def params(self):
        """``mi.traverse`` parameters of the fast scene (keys such as ``"car.vertex_positions"``)."""
        _ = self.fast_scene
        return self._fast_params

    def sensor(self, key: str = SENSOR_KEY):
        sensors = {s.id(): s for s in self.fast_scene.sensors()}
        return sensors.get(key)

    def reference_scenes(self) -> list:
        """One literal scene per mixel, in millimetres around it (displays only)."""
        if self.screen is None:
            raise ValueError("the reference form renders display scenes only; use the fast form for worlds")
        wave = [m.name for m in self.mincam if m.optics == "wave"]
        if wave:
            raise ValueError(f"mixel(s) {wave} have optics = 'wave', but the reference form is the literal "
                             "(geometric-optics) scene; render them with the 'fast' or 'response_map' form")
        if self._reference is None:
            self._reference, self._reference_params = [], []
            for k, mixel in enumerate(self.mincam):
                frame = SceneFrame.millimetres_around(mixel.pose.to_world(np.array([0.0, 0.0, mixel.d_f_m])))
                scene = {"type": "scene", "integrator": {"type": "path", "max_depth": REFERENCE_MAX_DEPTH},
                         **self._content(frame), **mixel_reference_shapes(mixel, f"mixel{k}", spp=1, frame=frame),
                         **mincam_body_shapes(self.mincam, frame, skip=k)}
                loaded = self.mi.load_dict(scene, optimize=False)
                self._reference.append(loaded)
                self._reference_params.append(self.mi.traverse(loaded))
        return self._reference

    # ------------------------------------------------------------------------------------------ updates
    def set_frame(self, frame: np.ndarray) -> None:
        """Show ``frame`` (radiance, W m^-2 sr^-1, row 0 at the top) on the display."""
        if self.screen is None:
            raise ValueError("set_frame needs a display scene")
        self._frame = self.screen.check_frame(frame)
        tensor = frame_tensor(self._frame)
        for params in ([self._fast_params] if self._fast is not None else []) + self._reference_params:
            params[SCREEN_RADIANCE_PARAM] = tensor
            params.update()

    def update(self, updates: Mapping[str, object]) -> None:
        """Set fast-scene parameters (numpy arrays or Mitsuba values) without reloading."""
        if not updates:
            return
        params = self.params
        for key, value in updates.items():
            if key not in params:
                raise KeyError(f"unknown scene parameter {key!r}; see the scene's params.keys()")
            if key in self._own_vertices and _write_in_place(params, key, value):
                continue
            params[key] = as_param(self.mi, params[key], value, key)
            if key.endswith(".vertex_positions"):
                self._own_vertices.add(key)  # a private copy from now on: never a caller's array
        params.update()

    # ------------------------------------------------------------------------------------------ solvers
    def fast_estimates(self, spp: int, replicates: int, seed: int, purpose: str = "fast") -> np.ndarray:
        """(replicates, n_mixels) independent estimates [W/m^2] of the fast form, ``spp / replicates`` rays each."""
        plan = self.fast_plan(spp, replicates, seed, purpose)
        means = trace_groups(self.fast_scene, self.sensor(), *plan)
        return means.reshape(len(self.mincam), replicates).T

    def fast_plan(self, spp: int, replicates: int, seed: int, purpose: str = "fast") -> tuple:
        """The arguments after the sensor of :func:`.tracing.trace_groups` (or :func:`.tracing.sensor_launches`)
        for :meth:`fast_estimates`: groups (mixel-major, ``replicates`` each), rays per group, seed, and the
        position-sample map."""
        check_counts(spp, replicates)
        n = len(self.mincam)
        per_rep = max(1, -(-int(spp) // int(replicates)))
        return n * replicates, per_rep, derive_seed(seed, purpose), mixel_position_sample(n, replicates)

    def reference_estimates(self, spp: int, replicates: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent estimates [W/m^2] of the literal scene."""
        check_counts(spp, replicates)
        per_rep = max(1, -(-int(spp) // int(replicates)))
        out = np.zeros((replicates, len(self.mincam)))
        for k, scene in enumerate(self.reference_scenes()):
            sensor = next(shape.sensor() for shape in scene.shapes() if shape.sensor() is not None)
            out[:, k] = trace_groups(scene, sensor, replicates, per_rep, derive_seed(seed, "reference", k))
        return out

    def camera_image(self, spp: int = 64, seed: int = 0, freeze: tuple | None = None) -> np.ndarray:
        """Image (rows, cols) of the ground-truth pinhole camera [W m^-2 sr^-1], row 0 at the top.

        ``freeze``: replay the render from a recording (``dr.freeze``: no Python tracing of the integrator per
        image) made with this key, :func:`.stratified.buffers_key` of every object moved since the scene was
        loaded (None: trace). The same image bit for bit either way."""
        camera = self.sensor(CAMERA_KEY)
        if camera is None:
            raise ValueError("this scene has no ground-truth camera; pass camera=pinhole_camera(...)")
        scene = self.fast_scene
        if freeze is None:
            img = self.mi.render(scene, sensor=camera, spp=int(spp), seed=int(seed))
        else:
            import drjit as dr

            index = next(k for k, s in enumerate(scene.sensors()) if s.id() == CAMERA_KEY)
            render = frozen.frozen(scene, camera_render)
            with frozen.no_cyclic_gc():
                img = render(scene, index, int(spp), dr.opaque(self.mi.UInt32, int(seed)), freeze)
        return np.asarray(img, dtype=np.float64)[..., 0]

    def camera_window(self, window: tuple[int, int, int, int], spp: int, seed: int,
                      freeze: tuple | None = None) -> np.ndarray:
        """The ground-truth camera's image over ``window`` (first row, first column, rows, columns) [px] of its
        film [W m^-2 sr^-1] (``kernels.camera_window.window_render``: the same estimator as :meth:`camera_image`,
        whose random numbers depend on the window's shape and the seed only, so that two renders of one window
        pair up pixel by pixel). Only on Dr.Jit's JIT variants; ``freeze`` as in :meth:`camera_image`."""
        import drjit as dr

        scene = self.fast_scene
        if self.sensor(CAMERA_KEY) is None:
            raise ValueError("this scene has no ground-truth camera; pass camera=pinhole_camera(...)")
        row, col, rows, cols = (int(v) for v in window)
        index = next(k for k, s in enumerate(scene.sensors()) if s.id() == CAMERA_KEY)
        origin = (dr.opaque(self.mi.UInt32, row), dr.opaque(self.mi.UInt32, col))
        args = (scene, index, int(spp), dr.opaque(self.mi.UInt32, int(seed)), origin, (rows, cols))
        if freeze is None:
            values = window_render(*args, ())
        else:
            with frozen.no_cyclic_gc():
                # the window's shape named in the key as text: Dr.Jit 1.5 replayed a 32 x 48 recording for a
                # 48 x 48 window keyed on the integers alone
                values = frozen.frozen(scene, window_render)(*args, (f"{rows}x{cols} px, {int(spp)} spp", *freeze))
        return np.asarray(values, dtype=np.float64).reshape(rows, cols)


def camera_render(scene, sensor_index: int, spp: int, seed, buffers: tuple):
    """``mi.render`` of one of the scene's sensors (frozen by :meth:`MincamScene.camera_image`); ``buffers`` only
    keys the recording."""
    return backend.mitsuba().render(scene, sensor=sensor_index, spp=spp, seed=seed)


def geometry_meta(mincam: Mincam, screen: Screen | None = None) -> dict:
    """JSON-friendly description of the set-up (poses, sizes, mask contents), stored with every output."""
    meta: dict = {
        "mixels": [
            {
                "name": m.name,
                "position_m": list(m.pose.position_m),
                "forward": list(m.pose.forward),
                "up": list(m.pose.up),
                "d_f_m": m.d_f_m,
                "detector_size_m": m.detector_size_m,
                "mask": {"name": m.mask.name, **mask_parts(m.mask)},
            }
            for m in mincam
        ],
        "mixel_bodies": "occluding" if mincam.occluding_bodies else "ignored (idealised overlapping mincam)",
    }
    if screen is not None:
        meta["screen"] = {
            "width_m": screen.width_m,
            "height_m": screen.height_m,
            "resolution": list(screen.resolution),
            "position_m": list(screen.pose.position_m),
            "forward": list(screen.pose.forward),
            "up": list(screen.pose.up),
        }
    return meta


def _write_in_place(params, key: str, value) -> bool:
    """Write new vertex positions into the mesh's buffer (LLVM: host memory; one this scene allocated, never a
    caller's array) and mark them changed; False (nothing written) where that does not apply.

    The buffer keeps its address, so a frozen launch that read the vertices from there replays with the new ones
    (Dr.Jit replays a recording with the addresses it was recorded with); Mitsuba's update then refits the mesh
    and rebuilds the acceleration structure as usual."""
    import drjit as dr

    if not (key.endswith(".vertex_positions") and isinstance(value, np.ndarray)
            and dr.backend_v(params[key]) == dr.JitBackend.LLVM):
        return False
    current = params[key]
    flat = np.asarray(value, dtype=np.float32).ravel()
    if dr.depth_v(current) != 1 or dr.width(current) != flat.size:
        return False
    dr.eval(current)
    dr.sync_thread()  # no queued kernel may still read the old vertices
    address = np.from_dlpack(current).__array_interface__["data"][0]  # Dr.Jit's view is read-only
    np.ctypeslib.as_array((ctypes.c_float * flat.size).from_address(address))[:] = flat
    params.set_dirty(key)
    return True


def as_param(mi, current, value, key: str = "parameter"):
    """A numpy update in the type of the parameter it replaces: 4 x 4 -> transform; 3-vectors (a point light's
    position, colours) as (3, n); textures keep their (rows, cols, channels) shape."""
    import drjit as dr

    if not isinstance(value, np.ndarray):
        return value
    if value.shape == (4, 4):
        return mi.Transform4f(value.tolist())
    if value.shape == (3, 3) and "Transform3" in type(current).__name__:  # a texture's to_uv
        return type(current)(np.ascontiguousarray(value, dtype=np.float32))
    # a copy: Dr.Jit maps a float32 numpy array without copying, and the scene must never alias the caller's
    flat = np.array(value, dtype=np.float32).ravel()
    if dr.is_tensor_v(current):
        shape = tuple(current.shape)
        if flat.size != int(np.prod(shape)):
            raise ValueError(f"{key}: a texture of shape {shape} needs {int(np.prod(shape))} values, got "
                             f"{flat.size}; pass an array of that shape")
        return type(current)(flat.reshape(shape))
    width = dr.size_v(current) if dr.depth_v(current) > 1 else -1  # static width of a Point3f / Color3f
    if width > 0:
        if flat.size % width:
            raise ValueError(f"{key}: needs a multiple of {width} values (one {width}-vector each), got {flat.size}")
        return type(current)(flat.reshape(-1, width).T)
    return type(current)(flat)
