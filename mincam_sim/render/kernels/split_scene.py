"""Rays traced against two Mitsuba scenes as if they were one: a *static* scene built once and a small *movers*
scene rebuilt per frame.

Mitsuba 3.9 rebuilds the acceleration structure of every geometry of a scene whenever one of its shapes changes
(``Scene::parameters_changed``), so a frame that moves a 12-triangle box on a million-triangle table pays for the
table. Split in two, a frame rebuilds only the movers' scene. :class:`SplitScene` offers what
:mod:`.guided_path` asks of a scene:

* ``ray_intersect``: the nearer hit of the two (the movers' scene is searched up to the static hit);
* ``ray_test``: blocked by either;
* ``sample_emitter_direction``: an emitter sampled from the static scene (every light is static: a moving emitter
  is not split), its visibility tested against both;
* ``pdf_emitter_direction``, the environment: the static scene's (its emitters are the whole scene's).

Each is what one scene holding every shape returns, up to which of two coincident surfaces a ray meets first.
"""

from __future__ import annotations

from dataclasses import dataclass

from mincam_sim.render import backend


@dataclass
class SplitScene:
    """A static scene and a movers scene traced as one (a dataclass: ``dr.freeze`` traverses both scenes as the
    frozen launch's inputs).

    Parameters
    ----------
    static : mitsuba.Scene
        Every shape no frame moves, and every light.
    movers : mitsuba.Scene
        The shapes the frames move (no lights), where the current pass has them.
    movers_box : (mi.Point3f, mi.Point3f), optional
        A box holding them (:meth:`set_movers_box`): only rays that cross it are traced through ``movers``
        (each Embree call costs about as much on 12 triangles as on a thousand).
    """

    static: object
    movers: object
    movers_box: tuple | None = None

    def set_movers_box(self, lo, hi) -> None:
        """Hold the movers (where this scene has them) in the box ``lo`` .. ``hi`` (scene coordinates [m], grown
        past Mitsuba's ray offsets): rays that miss it skip the movers' scene. Opaque values: a frozen launch
        replays with the next frame's box."""
        mi = backend.mitsuba()
        import drjit as dr

        self.movers_box = tuple(mi.Point3f(*(dr.opaque(mi.Float, float(x)) for x in corner)) for corner in (lo, hi))

    def _may_meet_movers(self, ray, active):
        """``active`` where ``ray`` (up to its ``maxt``) crosses the movers' box, or everywhere without one."""
        if self.movers_box is None:
            return active
        mi = backend.mitsuba()
        hit, near, far = mi.BoundingBox3f(*self.movers_box).ray_intersect(ray)
        return mi.Bool(active) & hit & (far >= 0.0) & (near <= ray.maxt)

    @property
    def lights(self):
        """The scene whose emitters are the whole scene's (for ``DirectionSample3f`` and environment lookups)."""
        return self.static

    def ray_intersect(self, ray, ray_flags=None, coherent=False, active=True):
        """The nearer surface interaction of the two scenes (invalid where neither is hit): the preliminary hits
        of both (the movers' scene searched up to the static hit), one surface interaction computed from the
        nearer, as ``mitsuba.Scene.ray_intersect`` computes it from its own."""
        mi = backend.mitsuba()
        import drjit as dr

        flags = mi.RayFlags.All if ray_flags is None else ray_flags
        hit = self.static.ray_intersect_preliminary(ray, coherent=coherent, active=active)
        nearer = mi.Ray3f(ray)
        nearer.maxt = dr.select(hit.is_valid(), dr.minimum(ray.maxt, hit.t), ray.maxt)
        hit_movers = self.movers.ray_intersect_preliminary(nearer, coherent=coherent,
                                                           active=self._may_meet_movers(nearer, active))
        hit = dr.select(hit_movers.is_valid(), hit_movers, hit)
        return hit.compute_surface_interaction(ray, flags, active)

    def ray_test(self, ray, active=True):
        """True where either scene blocks ``ray`` (up to its ``maxt``)."""
        return self.static.ray_test(ray, active) | self.movers.ray_test(ray, self._may_meet_movers(ray, active))

    def sample_emitter_direction(self, ref, sample, test_visibility=True, active=True):
        """As ``mitsuba.Scene.sample_emitter_direction``: an emitter and a direction toward it from the static
        scene; where ``test_visibility`` and either scene blocks the segment, the weight and pdf are set to 0."""
        mi = backend.mitsuba()
        import drjit as dr

        ds, weight = self.static.sample_emitter_direction(ref, sample, False, active)
        if test_visibility:
            live = mi.Bool(active) & (ds.pdf != 0.0)
            blocked = self.ray_test(ref.spawn_ray_to(ds.p), live)
            weight = dr.select(blocked, 0.0, weight)
            ds.pdf = dr.select(blocked, 0.0, ds.pdf)
        return ds, weight

    def pdf_emitter_direction(self, ref, ds, active=True):
        """As ``mitsuba.Scene.pdf_emitter_direction`` (the static scene holds every emitter)."""
        return self.static.pdf_emitter_direction(ref, ds, active)

    def bbox(self):
        """The bounding box of both scenes."""
        mi = backend.mitsuba()
        box = mi.ScalarBoundingBox3f(self.static.bbox())
        box.expand(self.movers.bbox())
        return box


def lights_of(scene):
    """The Mitsuba scene whose emitters a path through ``scene`` (a scene or a :class:`SplitScene`) samples."""
    return scene.lights if isinstance(scene, SplitScene) else scene


__all__ = ["SplitScene", "lights_of"]
