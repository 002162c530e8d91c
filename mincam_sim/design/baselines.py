"""The baselines the field uses beside a designed mincam, all printable through the design's own film:

* ``random``: logits drawn on the design grid from a fixed seed (``[task.seed, 61]``), normal with standard
  deviation :data:`RANDOM_LOGIT_STD`, through the same chain as the designed masks (bilinear onto the dots,
  sigmoid, 256 grey levels, the film's ``[t_min, t_max]``).
* ``pca``: the leading principal components of the training frames the design samples (the classic
  feature-specific-imaging choice), each frame an image on the printer-dot grid as the idealised model maps the
  field onto the mask (:func:`training_images`). Components are unit vectors with both signs; a mask cannot
  subtract, so each is printed single-rail with an offset: ``grey = 0.5 + 0.5 p / max|p|`` (mid grey for 0,
  the component's largest entry clear and its opposite dark), the sign fixed so that the largest ``|p|`` entry
  is positive (the convention of scikit-learn's ``svd_flip``). Components 1-4 go to the left, right, top and
  bottom mixels. The offset adds the frame's total change to every reading; the decoder's normalised features
  see it.
* ``ideal_trained``: the design's optimiser run through the idealised model (:class:`~mincam_sim.render.solvers.
  DotProduct`, the bare model of learned-mask simulators) instead of the traced physics: :func:`ideal_rows`
  builds the optimiser's linear model ``E = A @ T`` from DotProduct response maps.

Each baseline's decoder is refitted on physical measurements, as a user would calibrate printed masks
(:func:`~mincam_sim.design.optimise.fit_decoder` on the traced model), exactly as the designed masks' decoder is.

How the DotProduct maps become a linear model on the dots: the bare model sees every mixel's mask from the
mincam's centre, so a fronto-parallel screen at depth ``D`` whose side is ``mask_size * D / d_f`` and whose
texels are the printer's dots maps each texel onto exactly one dot (flipped). The maps of an open mask give
each dot's weight [sr]; the maps of a mask whose dots carry their own index give which texel is which dot; a
frame's reading through printed dots ``T`` is then ``sum_t frame[t] * W_open[t] * T[dot(t)]``, exact for
nearest-neighbour masks (``tests/design/test_design_baselines.py`` checks it against the maps of a random mask).
"""

from __future__ import annotations

import numpy as np

from mincam_sim.design import parameterization as par
from mincam_sim.design import tracking as tr
from mincam_sim.masks import Mask
from mincam_sim.model.geometry import Pose
from mincam_sim.scene.display import Screen, coverage

RANDOM_LOGIT_STD = 2.0  # standard deviation of the random masks' logits (grey values spread over the range)
N_MIXELS = 4


def dot_screen(task: tr.TrackingTask, depth_m: float) -> Screen:
    """A fronto-parallel screen at ``depth_m`` whose texels the idealised model maps one to one onto the dots."""
    rows, cols = task.dot_shape()
    side = tr.MASK_SIZE_M * depth_m / task.d_f_m
    return Screen(side, side, (cols, rows),
                  Pose((0.0, 0.0, -depth_m), (0.0, 0.0, 1.0)))


def _dot_mask(task: tr.TrackingTask, values: np.ndarray, name: str) -> Mask:
    return Mask(np.asarray(values, dtype=np.float64).reshape(task.dot_shape()), tr.MASK_SIZE_M, tr.MASK_SIZE_M,
                name, {"kind": "dot grid"}, interpolation="nearest")


def dot_maps(task: tr.TrackingTask, depth_m: float, solver=None) -> tuple[np.ndarray, np.ndarray]:
    """The idealised model at ``depth_m`` on :func:`dot_screen`: each mixel's weight of every dot for an open
    mask, ``(4, D)`` [sr] in dot order (row-major on the printer's grid), and the dot each texel maps onto
    (``(rows * cols,)``, row-major texels; -1 outside every mixel's aperture)."""
    from mincam_sim.render.solvers import DotProduct

    solver = solver or DotProduct()
    screen = dot_screen(task, depth_m)
    n_dots = int(np.prod(task.dot_shape()))
    code = (1.0 + np.arange(n_dots)) / (n_dots + 2)
    open_maps = solver.maps(task.mincam([_dot_mask(task, np.ones(n_dots), f"open_{p}") for p in tr.POSITIONS]),
                            screen).weights_sr.reshape(N_MIXELS, -1)
    coded = solver.maps(task.mincam([_dot_mask(task, code, f"code_{p}") for p in tr.POSITIONS]),
                        screen).weights_sr.reshape(N_MIXELS, -1)
    seen = open_maps[0] > 0
    dot_of_texel = np.full(open_maps.shape[1], -1)
    dot_of_texel[seen] = np.rint(coded[0, seen] / open_maps[0, seen] * (n_dots + 2) - 1).astype(int)
    if np.any((open_maps > 0) != seen) or len(set(dot_of_texel[seen].tolist())) != seen.sum():
        raise RuntimeError("the idealised model did not map the dot screen's texels one to one onto the dots")
    weights = np.zeros((N_MIXELS, n_dots))
    weights[:, dot_of_texel[seen]] = open_maps[:, seen]
    return weights, dot_of_texel


def training_images(task: tr.TrackingTask, frames, texel_dots: list[np.ndarray]) -> np.ndarray:
    """Each training frame's radiance change on the dot grid ``(n_frames, D)`` [W m^-2 sr^-1] as the idealised
    model maps the field onto the mask (the frames of :func:`~mincam_sim.design.optimise.training_set`; a dot's
    value is the change on the texel it sees). ``texel_dots`` per training depth, from :func:`dot_maps`."""
    n_dots = int(np.prod(task.dot_shape()))
    atoms = []
    for scenes, dot_of_texel in zip(frames.atoms, texel_dots, strict=True):
        screen = dot_screen(task, scenes.depth_m)
        seen = dot_of_texel >= 0
        rows = np.zeros((len(scenes.centers_m), n_dots))
        for i, ((cx, cy), w, h) in enumerate(zip(scenes.centers_m, scenes.sizes_m, scenes.heights_m, strict=True)):
            x, y = screen.from_world(np.array([cx, cy, -scenes.depth_m]))
            cov = coverage(screen, x - w / 2, x + w / 2, y - h / 2, y + h / 2).ravel()
            rows[i, dot_of_texel[seen]] = cov[seen]
        atoms.append(rows)
    out = np.zeros((len(frames.frame_atoms), n_dots))
    for f, objs in enumerate(frames.frame_atoms):
        for di, ai, change in objs:
            out[f] += change * atoms[di][ai]
    return out


def ideal_rows(task: tr.TrackingTask, frames) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """The optimiser's linear model from DotProduct maps: per mixel the frames' rows ``(n_frames, D)`` and the
    rows of a uniform plane of unit radiance per training depth ``(n_depths, D)`` [W/m^2 per unit
    transmission], and the training images (:func:`training_images`)."""
    per_depth = [dot_maps(task, s.depth_m) for s in frames.atoms]
    images = training_images(task, frames, [d for _, d in per_depth])
    matrices = [_weighted(images, frames, per_depth, k) for k in range(N_MIXELS)]
    background_rows = [np.stack([w[k] for w, _ in per_depth]) for k in range(N_MIXELS)]
    return matrices, background_rows, images


def _weighted(images: np.ndarray, frames, per_depth: list, k: int) -> np.ndarray:
    """Mixel ``k``'s rows: each frame's image times the dot weights at its plane's depth."""
    weights = np.stack([w[k] for w, _ in per_depth])
    return images * weights[frames.depth_index]


def random_masks(task: tr.TrackingTask) -> list[Mask]:
    """Four random printable masks (printer input on the dot grid) from the task's seed, through the design's
    parameterisation."""
    rng = np.random.default_rng([task.seed, 61])
    index, weight = par.bilinear_upsample(task.grid, task.dot_shape())
    film = task.film()
    return [par.printable_mask(par.dots_from_logits(RANDOM_LOGIT_STD * rng.standard_normal(task.grid**2), index,
                                                    weight, film), task.dot_shape(), tr.MASK_SIZE_M,
                               f"random_{name}", task="tracking", grid=task.grid, baseline="random")
            for name in tr.POSITIONS]


def principal_components(images: np.ndarray, n: int = N_MIXELS) -> np.ndarray:
    """The ``n`` leading principal components ``(n, D)`` of ``images`` (rows: frames), orthonormal, each signed
    so that its largest-magnitude entry is positive."""
    x = np.asarray(images, dtype=np.float64)
    _, _, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    comps = vt[:n].copy()
    signs = np.sign(comps[np.arange(n), np.argmax(np.abs(comps), axis=1)])
    return comps * signs[:, None]


def pca_grey(component: np.ndarray, levels: int | None) -> np.ndarray:
    """Printer grey values of one component: ``0.5 + 0.5 p / max|p|`` (single rail, offset mid grey),
    quantised to the film's ``levels``."""
    p = np.asarray(component, dtype=np.float64)
    grey = 0.5 + 0.5 * p / np.max(np.abs(p))
    return np.rint(grey * (levels - 1)) / (levels - 1) if levels is not None else grey


def pca_masks(task: tr.TrackingTask, images: np.ndarray) -> list[Mask]:
    """Printable masks (printer input) of the four leading principal components of the training images."""
    film = task.film()
    return [par.printable_mask(pca_grey(c, film.levels), task.dot_shape(), tr.MASK_SIZE_M, f"pca_{name}",
                               task="tracking", baseline="pca", component=i + 1)
            for i, (c, name) in enumerate(zip(principal_components(images), tr.POSITIONS, strict=True))]


__all__ = ["RANDOM_LOGIT_STD", "dot_maps", "dot_screen", "ideal_rows", "pca_grey", "pca_masks",
           "principal_components", "random_masks", "training_images"]
