"""Path tracing with the inter-reflection bounce guided toward what a frame moves.

The light a moving object throws onto the table (or takes from it) reaches a mixel through one bounce: a ray
meets the table, the bounce direction meets the object. Mitsuba's ``path`` integrator draws that direction from
the BSDF alone, so from most of the table the object is met by one bounce in ~10^4: ``dP`` outside the change
region is then a rare-event estimate whose reported standard error scatters widely. Here the bounce
direction is drawn from a *mixture*: with probability ``share`` uniformly in the cone that holds a sphere around
the changing part of the scene (the *guide*: one sphere, or a few, one per group of moving shapes, of which a
bounce picks one of those usable at its shading point uniformly), otherwise from the BSDF, and weighted by
``f cos / p_mix`` with

    p_mix(w) = (1 - share) p_bsdf(w) + share * mean over usable cones k of p_cone_k(w).

Every direction the BSDF can draw keeps a positive density, so the estimate is unbiased whatever the guide
(a guide around the wrong place only costs variance); emitter sampling at the next vertex and emitter hits are
combined with multiple importance sampling with ``p_mix`` as the BSDF strategy's density, so the two strategies'
weights still sum to one. The rest follows Mitsuba's ``path`` (and its Python sibling ``prb``): next-event
estimation with the power heuristic, emitters met by the camera ray counted in full. The path is unrolled in
Python (``max_depth`` is small, no Russian roulette below Mitsuba's ``rr_depth`` of 5), so it equals ``path`` in
expectation; :func:`supports` says which depths.

Where the BSDF has a delta component (mirrors, glass, null), where the shading point lies inside the guide's
sphere or sees it under less than :data:`MIN_CONE_SIN2` (sin^2 of the half angle), and at the last bounce (whose
hit only adds emission) the bounce is the BSDF's own, but for one thing: at smooth glass (a delta reflection and
a delta transmission) reflection and refraction are drawn with even odds (:data:`FRESNEL_SHARE`) rather than
Fresnel's, and weighted back (:func:`_even_fresnel`), so that the few percent of a lamp that a glass face
reflects are found in every run. The guides of a moving glass block hold the lights and their images in its
faces (``change_geometry.delta_light_spheres``). The random numbers each vertex draws do not depend on
the scene (the mixture's choice and the cone sample are drawn on every lane), so two passes with the same seed
(a frame and its background) stay paired ray by ray until their paths part.
"""

from __future__ import annotations

import numpy as np

from mincam_sim.render import backend
from mincam_sim.render.kernels.split_scene import lights_of

GUIDE_SHARE = 0.5  # share of guided bounces drawn toward the guide's sphere
MIN_CONE_SIN2 = 1e-6  # below this (a sphere seen under < 0.06 degrees) float32 cone sampling is not trusted
MAX_GUIDED_DEPTH = 5  # Mitsuba's path uses Russian roulette from depth 5 (rr_depth); beyond it, use path itself
MAX_GUIDES = 4  # spheres per frame; more are merged into one holding them
FRESNEL_SHARE = 0.5  # at smooth glass, the probability of drawing the reflection (the BSDF's own: Fresnel's F)


def supports(max_depth: int) -> bool:
    """True if :func:`guided_radiance` reproduces ``path`` with this ``max_depth`` (1 .. 5)."""
    return 1 <= int(max_depth) <= MAX_GUIDED_DEPTH


def guide_sphere(points_m: np.ndarray | None) -> tuple[np.ndarray, float] | None:
    """A sphere (centre [m], radius [m]) holding ``points_m`` (the change points of a frame), or None if there
    are none or they are unbounded. Not the smallest such sphere: the box's centre and the farthest point."""
    if points_m is None:
        return None
    points_m = np.asarray(points_m, dtype=float).reshape(-1, 3)
    if points_m.size == 0 or not np.all(np.isfinite(points_m)):
        return None
    centre = 0.5 * (points_m.min(axis=0) + points_m.max(axis=0))
    radius = float(np.sqrt(((points_m - centre) ** 2).sum(axis=1).max()))
    return centre, max(radius, 1e-6)


def guide_spheres(point_sets: list[np.ndarray], merge_ratio: float = 8.0,
                  max_spheres: int = MAX_GUIDES) -> list[tuple[np.ndarray, float]]:
    """Guide spheres for a frame's moving shapes: one per shape (its change points: the shape and its shadow
    volume), groups merged while the merged sphere is compact.

    Two groups merge when the sphere holding both has at most ``merge_ratio`` times the volume of the two
    together (touching spheres of one size: ratio 4; one sphere inside the other: <= 1), and any groups beyond
    ``max_spheres`` (:data:`MAX_GUIDES` unless told) merge, the most compact pair first. One sphere around
    movers far apart would hold most of what the mixels see, and a shading point inside its sphere is not
    guided: the light a mover throws would then be found only by BSDF sampling again (rare hits, a standard
    error that scatters per run).
    """
    groups = [np.asarray(p, dtype=float).reshape(-1, 3) for p in point_sets if p is not None and np.size(p)]
    spheres = [guide_sphere(g) for g in groups]
    # every pair's merged sphere at once: the same numbers as guide_sphere of the two groups' points together (a
    # box's corners are exact minima and maxima; each point's squared distance is summed over x, y, z in that
    # order; the largest is the largest of either group's)
    while len(groups) > 1:
        n = len(groups)
        lo = np.array([g.min(axis=0) for g in groups])
        hi = np.array([g.max(axis=0) for g in groups])
        centres = 0.5 * (np.minimum(lo[:, None], lo[None, :]) + np.maximum(hi[:, None], hi[None, :]))  # (n, n, 3)
        points = np.concatenate(groups)
        starts = np.cumsum([0] + [len(g) for g in groups[:-1]])
        d = points[:, None, :] - centres[np.repeat(np.arange(n), [len(g) for g in groups])]  # (points, n, 3)
        d2 = d * d
        # each group's farthest point from the centre of every pair it is in, then the farther of the two groups
        far = np.maximum.reduceat((d2[..., 0] + d2[..., 1]) + d2[..., 2], starts, axis=0)  # (n, n)
        far2 = np.maximum(far, far.T)
        radius = np.maximum(np.sqrt(far2), 1e-6)
        own3 = np.array([s[1] for s in spheres]) ** 3
        ratio = radius ** 3 / (own3[:, None] + own3[None, :])
        a_idx, b_idx = np.triu_indices(n, 1)  # (a, b) with a < b, row by row: the first best, as a loop over pairs
        pick = int(np.argmin(ratio[a_idx, b_idx]))
        a, b, best_ratio = int(a_idx[pick]), int(b_idx[pick]), float(ratio[a_idx[pick], b_idx[pick]])
        if best_ratio > merge_ratio and len(groups) <= max(1, int(max_spheres)):
            break
        groups[a] = np.concatenate([groups[a], groups[b]])
        spheres[a] = (centres[a, b].copy(), float(radius[a, b]))
        del groups[b], spheres[b]
    return spheres


def mis_weight(dr, pdf_a, pdf_b):
    """Power heuristic (as Mitsuba's ``path``): weight of strategy a, 0 where undefined."""
    a2, b2 = dr.square(pdf_a), dr.square(pdf_b)
    w = a2 / (a2 + b2)
    return dr.select(dr.isfinite(w), w, 0.0)


def guided_radiance(scene, sampler, ray, max_depth: int, guide, share: float = GUIDE_SHARE):
    """Radiance along ``ray`` [W m^-2 sr^-1], as Mitsuba's ``path`` with ``max_depth``, bounces guided.

    Parameters
    ----------
    scene, sampler, ray
        Mitsuba scene (or a :class:`.split_scene.SplitScene`: a static and a movers scene traced as one), a
        seeded sampler (one lane per ray), the rays.
    max_depth : int
        Longest path in segments (1 .. :data:`MAX_GUIDED_DEPTH`), as ``path``'s ``max_depth``.
    guide : (centre (3,) [m], radius [m]), a sequence of them, or None
        Spheres toward which bounces are guided; a guided bounce picks one of the cones usable at its shading
        point uniformly (one sphere: exactly its cone). None (or no sphere) = Mitsuba's BSDF sampling only.
    share : float
        Probability (0 .. 1, exclusive of 1) that a guided bounce is drawn in a guide's cone.
    """
    return guided_radiance_watched(scene, sampler, ray, max_depth, guide, [], share)[0]


def guided_radiance_watched(scene, sampler, ray, max_depth: int, guide, boxes, share: float = GUIDE_SHARE):
    """:func:`guided_radiance` and, per lane, whether the path crossed one of ``boxes`` (a list of
    ``(lo, hi)`` ``mi.Point3f`` corners, scene coordinates): a ray segment up to its hit (or escaping), or a
    shadow ray up to the light's sample, passing through a box. A path that crosses no box meets the same
    surfaces whatever lies inside the boxes."""
    if not supports(max_depth):
        raise ValueError(f"max_depth must be 1 .. {MAX_GUIDED_DEPTH} for the guided path, got {max_depth!r}")
    if not 0.0 <= share < 1.0:
        raise ValueError(f"share (probability of a guided bounce) must be in [0, 1), got {share!r}")
    mi = backend.mitsuba()
    import drjit as dr

    ctx = mi.BSDFContext()
    ray = mi.Ray3f(ray)
    radiance = mi.Spectrum(0.0)
    beta = mi.Spectrum(1.0)
    active = mi.Bool(True)
    si_prev = dr.zeros(mi.SurfaceInteraction3f)
    pdf_prev = mi.Float(1.0)
    delta_prev = mi.Bool(True)
    spheres = opaque_spheres(guide) if share > 0 else []
    watched = [mi.BoundingBox3f(lo, hi) for lo, hi in boxes]
    met = mi.Bool(False)  # no width literal: a frozen launch replays with other lane counts
    even_fresnel = has_glass(scene)
    for depth in range(int(max_depth)):
        si = scene.ray_intersect(ray, ray_flags=mi.RayFlags.All, coherent=depth == 0, active=active)
        if watched:
            met |= active & _crosses(mi, dr, watched, ray.o, ray.d, dr.select(si.is_valid(), si.t, dr.inf))
        bsdf = si.bsdf(ray)
        ds = mi.DirectionSample3f(lights_of(scene), si=si, ref=si_prev)
        mis = mis_weight(dr, pdf_prev, scene.pdf_emitter_direction(si_prev, ds, ~delta_prev))
        radiance += dr.select(active, beta * mis * ds.emitter.eval(si, active), 0.0)
        if depth + 1 >= max_depth:
            break
        active_next = active & si.is_valid()

        guided = bool(spheres) and depth + 2 < max_depth
        if guided:
            cones = (_Cone if len(spheres) == 1 else _Cones)(mi, dr, si, bsdf, spheres, share, active_next)

        active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
        if watched:
            met |= active_em & _crosses(mi, dr, watched, si.p, ds.d, ds.dist)
        active_em &= ds.pdf != 0.0
        value_em, pdf_em = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), active_em)
        if guided:
            pdf_em = (1.0 - cones.alpha) * pdf_em + cones.alpha * cones.pdf(ds.d)
        mis_em = dr.select(ds.delta, 1.0, mis_weight(dr, ds.pdf, pdf_em))
        radiance += dr.select(active_em, beta * mis_em * value_em * em_weight, 0.0)

        choice, u_bsdf = sampler.next_1d(), sampler.next_2d()
        sample, weight = bsdf.sample(ctx, si, choice, u_bsdf, active_next)
        if even_fresnel:
            sample, weight = _even_fresnel(mi, dr, ctx, si, bsdf, choice, u_bsdf, sample, weight, active_next)
        direction = si.to_world(sample.wo)
        pdf_prev = mi.Float(sample.pdf)
        delta_prev = mi.has_flag(sample.sampled_type, mi.BSDFFlags.Delta)
        if guided:
            pick, u = sampler.next_1d(), sampler.next_2d()
            use_cone = active_next & (pick < cones.alpha)
            toward, chosen = cones.sample(pick, u)
            value_c, pdf_c = bsdf.eval_pdf(ctx, si, si.to_local(toward), use_cone)
            f_cos = dr.select(use_cone, value_c, weight * sample.pdf)
            pdf_b = dr.select(use_cone, pdf_c, sample.pdf)
            p_cone = dr.select(use_cone, cones.pdf(toward, chosen), cones.pdf(direction))
            pdf_mix = (1.0 - cones.alpha) * pdf_b + cones.alpha * p_cone
            mixed = cones.alpha > 0.0
            weight = dr.select(mixed, dr.select(pdf_mix > 0.0, f_cos / pdf_mix, 0.0), weight)
            direction = dr.select(use_cone, toward, direction)
            pdf_prev = dr.select(mixed, pdf_mix, pdf_prev)
            delta_prev = delta_prev & ~mixed
        beta *= weight
        ray = si.spawn_ray(direction)
        si_prev = si
        active = active_next & (dr.max(mi.unpolarized_spectrum(beta)) != 0.0)
    return radiance, met


def has_glass(scene) -> bool:
    """True if a shape of ``scene`` (or of both parts of a :class:`.split_scene.SplitScene`) has a BSDF with a
    delta reflection and a delta transmission (smooth glass: ``dielectric``, ``thindielectric``); the shapes that
    instances draw count too (an instance has a diffuse BSDF of its own: its group's are read from the scene's
    objects)."""
    mi = backend.mitsuba()
    parts = [scene.static, scene.movers] if hasattr(scene, "movers") else [scene]
    both = int(mi.BSDFFlags.DeltaReflection) | int(mi.BSDFFlags.DeltaTransmission)

    def glass(bsdf) -> bool:
        return bsdf is not None and int(bsdf.flags()) & both == both

    if any(glass(s.bsdf()) for part in parts for s in part.shapes()):
        return True
    return any(isinstance(obj, mi.BSDF) and glass(obj) for part in parts
               if any(s.class_name() == "Instance" for s in part.shapes()) for obj in mi.traverse(part).hierarchy)


def _even_fresnel(mi, dr, ctx, si, bsdf, choice, u, sample, weight, active):
    """At smooth glass, reflection or refraction drawn with even odds (:data:`FRESNEL_SHARE`) instead of
    Fresnel's reflectance ``F``, weighted by ``F / q`` (reflection) and ``(1 - F) / (1 - q)`` (refraction): the
    reflected light of glass (a few percent of a lamp, seen by a mixel in a face of the block) is then drawn
    about as often as the refracted light, and the estimate stays unbiased. ``F`` is what the BSDF reports as
    the pdf of its reflection (Mitsuba's ``dielectric`` and ``thindielectric``); where ``F`` is 0 or 1 (total
    internal reflection) the BSDF's own choice stands. The random numbers drawn are the BSDF's own (``choice``,
    ``u``), so paired passes stay paired."""
    flags = bsdf.flags()
    glass = (active & mi.has_flag(flags, mi.BSDFFlags.DeltaReflection)
             & mi.has_flag(flags, mi.BSDFFlags.DeltaTransmission))
    reflected, w_r = bsdf.sample(ctx, si, 0.0, u, glass)  # choice 0 <= F: the reflection, pdf F
    refracted, w_t = bsdf.sample(ctx, si, mi.Float(dr.one_minus_epsilon(mi.Float)), u, glass)  # > F: refraction
    is_r = mi.has_flag(reflected.sampled_type, mi.BSDFFlags.DeltaReflection)
    is_t = mi.has_flag(refracted.sampled_type, mi.BSDFFlags.DeltaTransmission)
    f = reflected.pdf
    split = glass & is_r & is_t & (f > 0.0) & (f < 1.0)
    take_r = choice < FRESNEL_SHARE
    q = dr.select(take_r, FRESNEL_SHARE, 1.0 - FRESNEL_SHARE)
    chosen = dr.select(take_r, reflected, refracted)
    w = dr.select(take_r, w_r * (f / q), w_t * ((1.0 - f) / q))
    chosen.pdf = q
    sample = dr.select(split, chosen, sample)
    weight = dr.select(split, w, weight)
    return sample, weight


def _crosses(mi, dr, boxes, origin, direction, length):
    """Whether the segment ``origin + t direction``, ``0 <= t <= length``, meets one of ``boxes``."""
    ray = mi.Ray3f(origin, direction)
    met = mi.Bool(False)
    for box in boxes:
        hit, near, far = box.ray_intersect(ray)
        met |= hit & (far >= 0.0) & (near <= length)
    return met


def spheres_of(guide) -> list[tuple[np.ndarray, float]]:
    """``guide`` (one sphere, a sequence of them, or None) as a list of (centre, radius); more than
    :data:`MAX_GUIDES` become one sphere holding them."""
    if guide is None:
        return []
    if len(guide) == 2 and (np.isscalar(guide[1]) or getattr(guide[1], "ndim", None) == 0):  # one sphere
        guide = [guide]
    spheres = [(np.asarray(c, dtype=float).reshape(3), float(r)) for c, r in guide]
    if len(spheres) > MAX_GUIDES:
        lo = np.min([c - r for c, r in spheres], axis=0)
        hi = np.max([c + r for c, r in spheres], axis=0)
        spheres = [(0.5 * (lo + hi), float(0.5 * np.linalg.norm(hi - lo)))]
    return spheres


def opaque_spheres(guide) -> list:
    """The guide's spheres as Dr.Jit values, ``[(mi.Point3f centre, mi.Float radius)]`` (opaque: a new frame's
    guide changes no kernel code); a list already in that form is returned as it is."""
    mi = backend.mitsuba()
    import drjit as dr

    if isinstance(guide, list) and guide and dr.is_jit_v(guide[0][1]):
        return guide
    return [(mi.Point3f(*(dr.opaque(mi.Float, float(c)) for c in centre)), dr.opaque(mi.Float, float(radius)))
            for centre, radius in spheres_of(guide)]


class _Cone:
    """One guide sphere's cone as seen from each lane's shading point: the mixture's share ``alpha`` (0 where
    the bounce is not guided: the point inside the sphere, a cone too small for float32, a delta BSDF),
    sampling and density [1/sr]."""

    def __init__(self, mi, dr, si, bsdf, spheres, share, active):
        ((centre, radius),) = spheres
        self.mi, self.dr = mi, dr
        to_centre = centre - si.p
        dist2 = dr.squared_norm(to_centre)
        sin2 = dr.square(radius) / dr.maximum(dist2, 1e-30)
        ok = active & (sin2 < 1.0 - 1e-4) & (sin2 >= MIN_CONE_SIN2) & ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
        cos_max = dr.safe_sqrt(1.0 - sin2)
        one_minus_cos = sin2 / (1.0 + cos_max)  # 1 - cos, without cancellation for small cones
        self.density = dr.select(ok, dr.rcp(dr.two_pi * dr.maximum(one_minus_cos, 1e-30)), 0.0)
        self.frame = mi.Frame3f(dr.normalize(dr.select(ok, to_centre, mi.Vector3f(0, 0, 1))))
        self.alpha = dr.select(ok, share, 0.0)
        self.cos = dr.select(ok, cos_max, 0.0)

    def sample(self, pick, u):
        """A uniform direction in the cone (``pick`` unused: there is one cone) and the cone's index (0)."""
        return self.frame.to_world(self.mi.warp.square_to_uniform_cone(u, self.cos)), 0

    def pdf(self, direction, chosen=None):
        """Density of the cone at ``direction`` [1/sr]; ``chosen`` (not None): drawn from it, so inside."""
        if chosen is not None:
            return self.density
        return self.dr.select(self.dr.dot(direction, self.frame.n) >= self.cos, 1.0, 0.0) * self.density


class _Cones:
    """Several guide spheres' cones as seen from each lane's shading point: which are usable, the mixture's
    share ``alpha`` (0 where no cone is usable or the BSDF has a delta component), sampling (a usable cone
    picked uniformly, then a uniform direction in it) and the cone mixture's density [1/sr]."""

    def __init__(self, mi, dr, si, bsdf, spheres, share, active):
        self.mi, self.dr = mi, dr
        self.frames, self.cos, self.density, self.usable = [], [], [], []
        for centre, radius in spheres:
            to_centre = centre - si.p
            sin2 = dr.square(radius) / dr.maximum(dr.squared_norm(to_centre), 1e-30)
            ok = active & (sin2 < 1.0 - 1e-4) & (sin2 >= MIN_CONE_SIN2)
            cos_max = dr.safe_sqrt(1.0 - sin2)
            one_minus_cos = sin2 / (1.0 + cos_max)
            self.usable.append(ok)
            self.cos.append(dr.select(ok, cos_max, 0.0))
            self.density.append(dr.select(ok, dr.rcp(dr.two_pi * dr.maximum(one_minus_cos, 1e-30)), 0.0))
            self.frames.append(mi.Frame3f(dr.normalize(dr.select(ok, to_centre, mi.Vector3f(0, 0, 1)))))
        self.count = mi.Float(0.0)
        for ok in self.usable:
            self.count += dr.select(ok, 1.0, 0.0)
        guidable = (self.count > 0.0) & ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
        self.alpha = dr.select(guidable, share, 0.0)

    def sample(self, pick, u):
        """A direction in the ``floor(pick / alpha * count)``-th usable cone (``pick`` in [0, alpha)) and that
        cone's index."""
        dr, mi = self.dr, self.mi
        pick = pick / dr.maximum(self.alpha, 1e-30)
        target = dr.minimum(mi.UInt32(pick * self.count), mi.UInt32(dr.maximum(self.count, 1.0) - 1.0))
        seen = mi.UInt32(0)
        chosen = mi.UInt32(0)
        direction = mi.Vector3f(0, 0, 1)
        for k, ok in enumerate(self.usable):
            take = ok & (seen == target)
            cone = self.frames[k].to_world(mi.warp.square_to_uniform_cone(u, self.cos[k]))
            direction = dr.select(take, cone, direction)
            chosen = dr.select(take, k, chosen)
            seen += dr.select(ok, 1, 0)
        return direction, chosen

    def pdf(self, direction, chosen=None):
        """Density of the cone mixture at ``direction`` [1/sr]; ``chosen``: the cone that drew it (counted as
        holding it whatever float32 says at its rim)."""
        dr = self.dr
        total = self.mi.Float(0.0)
        for k, ok in enumerate(self.usable):
            inside = dr.dot(direction, self.frames[k].n) >= self.cos[k]
            if chosen is not None:
                inside |= chosen == k
            total += dr.select(ok & inside, self.density[k], 0.0)
        return dr.select(self.count > 0.0, total / dr.maximum(self.count, 1.0), 0.0)
