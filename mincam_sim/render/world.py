"""A mincam in a general scene (tabletop, road ...): fast form, per-frame parameter updates, correlated seeds.

Frames change only what moves, through ``mi.traverse`` parameters (no scene reload). All mixels of a frame
are traced in one kernel. A frame and its background are traced with the same seed, replicate by replicate,
so the Monte Carlo noise of the two largely cancels in their difference ``dP`` (what the estimators use); the
standard error of ``dP`` comes from the spread of the per-replicate differences, so it includes that
correlation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..identity import fingerprint, library_versions
from ..measurements import Measurements
from ..optics import Mincam
from ..progress import progress
from ..store import ResultStore
from . import backend
from .elements import transform_update, vertex_update
from .estimation import derive_seed, samples_for_target, warn_unreached, worst_relative_stderr
from .mask_eval import mask_model_meta
from .mincam_scene import CAMERA_KEY, SENSOR_KEY, MincamScene, geometry_meta

MAX_SPP = 1 << 26  # cap of the target-noise budget, samples per mixel per frame
Updates = Mapping[str, np.ndarray]
__all__ = ["CAMERA_KEY", "SENSOR_KEY", "WorldRenderer", "transform_update", "vertex_update"]


class WorldRenderer:
    """Render a mincam's measurements of an arbitrary Mitsuba scene.

    Parameters
    ----------
    mincam : Mincam
    elements : dict
        Scene content: name -> Mitsuba dict or object (shapes, emitters). Names are the prefixes of the
        parameters that :meth:`update` changes (e.g. ``"car.vertex_positions"``, ``"road.to_world"``).
    replicates : int
        Independent estimates per measurement (>= 2), for the standard error.
    max_depth : int
        Path length of the ``path`` integrator (3 = direct lighting of diffuse objects).
    camera : dict, optional
        A ground-truth camera (:func:`~.scene_dicts.pinhole_camera`) rendered by :meth:`camera_image`.
    """

    def __init__(self, mincam: Mincam, elements: dict, replicates: int = 8, max_depth: int = 3,
                 camera: dict | None = None) -> None:
        if isinstance(replicates, bool) or int(replicates) != replicates or replicates < 2:
            raise ValueError(f"replicates must be an integer >= 2, got {replicates!r}")
        backend.require_jit("The fast mixel sensor (a Python Mitsuba plugin)")
        self.world = MincamScene.world(mincam, elements, max_depth, camera)
        self.mi = backend.mitsuba()
        self.mincam, self.replicates = mincam, int(replicates)
        self.scene = self.world.fast_scene
        self.sensor = self.world.sensor(SENSOR_KEY)
        self.camera = self.world.sensor(CAMERA_KEY)
        self.params = self.world.params
        self._content_key: str | None = None
        self._content_key = self.content_fingerprint()  # before any update: the scene as built

    def update(self, updates: Updates) -> None:
        """Set scene parameters (numpy arrays or Mitsuba values) and apply them without reloading."""
        self.world.update(updates)

    def estimates(self, spp: int, seed: int) -> np.ndarray:
        """(replicates, n_mixels) independent irradiance estimates [W/m^2], ``spp / replicates`` rays each."""
        return self.world.fast_estimates(spp, self.replicates, seed)

    def measure_changes(
        self,
        frames: Sequence[Updates],
        background: Updates,
        spp: int = 1 << 16,
        seed: int = 0,
        correlated: bool = True,
        out_dir: str | Path | None = None,
        show_progress: bool = False,
        target_rel_stderr: float = 0.0,
        overwrite: bool = False,
    ) -> tuple[Measurements, Measurements]:
        """Measure each frame's change from the background: ``dP = P(frame) - P(background)``.

        Parameters
        ----------
        frames : sequence of dict
            Parameter updates of each frame (applied on top of ``background``).
        background : dict
            Parameter updates that restore the background (e.g. objects moved out of view).
        correlated : bool
            True: each frame uses the background's seed (noise cancels in dP). False: independent seeds.
        out_dir : path, optional
            Write results per frame as they come; a rerun of the same run (scene content, mincam, frames,
            budget, seed, versions) resumes there, a different one is refused unless ``overwrite``.
        target_rel_stderr : float
            If > 0, ``spp`` is only the pilot: up to 4 frames spread over the sequence are measured with it,
            and the sample count is extrapolated (variance ~ 1/samples, x 1.5 margin, at most ``MAX_SPP``)
            so that every significant change (|dP| > 3 sigma in the pilot) reaches this relative standard
            error; ``meta["spp_per_mixel_per_frame"]`` is what was used and ``meta["reached_rel_stderr"]``
            what was reached over the significant changes.

        Returns
        -------
        (dP, P) : Measurements
            Changes and absolute frame measurements, each (n_frames, n_mixels) with standard errors.
        """
        n = len(self.mincam)
        if not (np.isfinite(target_rel_stderr) and target_rel_stderr >= 0):
            raise ValueError(f"target_rel_stderr must be >= 0 (0 = use spp as given), got {target_rel_stderr!r}")
        budget: dict = {}
        if target_rel_stderr > 0 and len(frames):
            pilot_idx = np.unique(np.linspace(0, len(frames) - 1, min(4, len(frames))).astype(int))
            pilot, _ = self.measure_changes([frames[i] for i in pilot_idx], background, spp, seed, correlated)
            worst = worst_relative_stderr(pilot.irradiance_w_m2, pilot.stderr_w_m2, significance=3.0)
            budget = {"pilot_spp": int(spp), "pilot_worst_rel_stderr": worst, "target_rel_stderr": target_rel_stderr}
            spp = samples_for_target(spp, worst, target_rel_stderr, MAX_SPP)
        self.update(background)
        bg = self.estimates(spp, seed)
        columns = [f"dP_{m}" for m in self.mincam.names] + [f"P_{m}" for m in self.mincam.names]
        values = np.full((len(frames), 2 * n), np.nan)
        errors = np.full_like(values, np.nan)
        store = None
        todo = np.arange(len(frames))
        if out_dir is not None:
            identity = {"spp": int(spp), "seed": int(seed), "correlated": correlated, "replicates": self.replicates,
                        "n_frames": len(frames), "frames": _fingerprint(frames),
                        "background": _fingerprint([background]), "mincam": fingerprint(self.mincam),
                        "scene": self.content_fingerprint(), "variant": backend.variant(),
                        "versions": library_versions()}
            store = ResultStore(out_dir, len(frames), columns, identity, overwrite=overwrite)
            values[:], errors[:] = store.values, store.stderr
            todo = store.pending()
        try:
            self._measure_into(frames, background, todo, spp, seed, correlated, bg, values, errors, store,
                               show_progress)
        finally:
            if store is not None:
                store.close()
        self.update(background)

        meta = {"form": "fast_world", "spp_per_mixel_per_frame": int(spp), "seed": seed, "correlated_seeds": correlated,
                "replicates": self.replicates, "background_w_m2": bg.mean(0).tolist(),
                "masks": {m.name: mask_model_meta(m.mask) for m in self.mincam},
                "background_stderr_w_m2": (bg.std(0, ddof=1) / np.sqrt(self.replicates)).tolist(),
                **backend.describe(), **geometry_meta(self.mincam)}
        meta.update(budget)
        reached = worst_relative_stderr(values[:, :n], errors[:, :n], significance=3.0)
        meta["reached_rel_stderr"] = reached if np.isfinite(reached) else None
        names = self.mincam.names
        warn_unreached(Measurements(values[:, n:], errors[:, n:], names))
        dp = Measurements(values[:, :n], errors[:, :n], names, {**meta, "quantity": "dP = P(frame) - P(background)"})
        p = Measurements(values[:, n:], errors[:, n:], names, {**meta, "quantity": "P(frame)"})
        return dp, p

    def _measure_into(self, frames, background, todo, spp, seed, correlated, bg, values, errors, store,
                      show_progress) -> None:
        for i in progress(todo, desc="frames", disable=not show_progress):
            self.update(background)
            self.update(frames[i])
            frame_seed = seed if correlated else derive_seed(seed, "frame", int(i))
            est = self.estimates(spp, frame_seed)
            diff = est - bg
            r = self.replicates
            row_v = np.concatenate([diff.mean(0), est.mean(0)])
            row_e = np.concatenate([diff.std(0, ddof=1), est.std(0, ddof=1)]) / np.sqrt(r)
            values[i], errors[i] = row_v, row_e
            if store is not None:
                store.write([i], row_v[None], row_e[None])

    def content_fingerprint(self) -> str:
        """Content key of the scene as Mitsuba holds it: every traversable parameter's value (meshes,
        textures, transforms, radiances), the element names and plugin types, and the path depth."""
        if self._content_key is None:
            params = self.params
            parts = {key: _param_array(params[key]) for key in sorted(params.keys())
                     if not key.startswith(SENSOR_KEY)}
            types = {name: (value.get("type") if isinstance(value, dict) else type(value).__name__)
                     for name, value in self.world.elements.items()}
            self._content_key = fingerprint({"params": parts, "types": types, "max_depth": self.world.max_depth})
        return self._content_key

    def camera_image(self, spp: int = 64, seed: int = 0) -> np.ndarray:
        """Image (rows, cols) of the ground-truth pinhole camera [W m^-2 sr^-1], row 0 at the top."""
        return self.world.camera_image(spp, seed)


def _param_array(value) -> np.ndarray:
    """A traversed Mitsuba parameter as a numeric array (transforms by their matrix)."""
    matrix = getattr(value, "matrix", None)
    arr = np.asarray(matrix if matrix is not None else value)
    if arr.dtype.hasobject:
        arr = np.frombuffer(repr(value).encode(), dtype=np.uint8)
    return arr


def _fingerprint(updates: Sequence[Updates]) -> list:
    import hashlib

    h = hashlib.sha256()
    for u in updates:
        for k in sorted(u):
            h.update(k.encode())
            h.update(np.ascontiguousarray(np.asarray(u[k], dtype=np.float64)).tobytes())
    return [len(updates), h.hexdigest()[:16]]
