"""What the response-map solver says when a mixel reads 0 +/- 0: a map that sampled per texel and missed the
mixel's view (texels far larger than the part of the screen the mixel sees), a mask that shuts the screen off,
and frames lit only outside the view are three different things, each said as it is."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from conftest import assert_close_mc

import mincam_sim as ms
from mincam_sim import masks
from mincam_sim.render import backend
from mincam_sim.render.kernels.monte_carlo import UnseenWarning
from mincam_sim.scene.display import visible_screen_area_m2

pytestmark = pytest.mark.skipif(not backend.is_jit(), reason="needs a JIT variant (LLVM or CUDA)")

BEYOND_MASK_M = 0.5e-3  # the screen this far beyond a single mixel's mask: its view there is ~2.5 mm across


def _close_screen() -> tuple[ms.Simulation, ms.Screen]:
    cam = ms.single()
    screen = ms.Screen(resolution=(16, 9), pose=ms.Pose((0.0, 0.0, -(cam[0].d_f_m + BEYOND_MASK_M)), (0.0, 0.0, 1.0)))
    return ms.Simulation(cam, screen=screen), screen


def _said(measure) -> tuple[ms.Measurements, list[str]]:
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = measure()
    return result, [str(w.message) for w in said if issubclass(w.category, UnseenWarning)]


def test_texels_larger_than_the_view_are_said_not_unseen():
    """A uniform screen 0.5 mm beyond the mask: the aperture solver reads ~0.75 W/m^2, the response map 0 +/- 0
    because 16 samples per 69 mm texel put ~0.02 in the mixel's 6.4 mm^2 view. It said 'no sample reached a lit
    part' (untrue: the whole screen is lit and in view); it says the texels are larger than the view, by how much,
    and points to ms.Aperture() and to the samples per texel that would see it, which then agree with the
    aperture solver."""
    sim, screen = _close_screen()
    frames = [np.ones(screen.shape)]
    half = 0.525 * (sim.mincam[0].d_f_m + BEYOND_MASK_M) - 0.05e-3  # [m] tan(half fov) z - detector / 2
    assert visible_screen_area_m2(screen, sim.mincam[0]) == pytest.approx((2 * half) ** 2, rel=1e-9)
    m, told = _said(lambda: sim.measure(frames, ms.ResponseMap(), ms.Budget(samples_per_texel=16)))
    assert m.irradiance_w_m2[0, 0] == 0 and m.stderr_w_m2[0, 0] == 0
    assert len(told) == 1, told
    assert "reached a lit part" not in told[0]
    for part in ("mixel(s) m0 read 0 +/- 0 W/m^2 in 1 frame(s) (first: 0)", "though the screen is in view",
                 "is 750.7 times the part of the screen m0 sees through its aperture (6.38 mm^2)",
                 "16 samples per texel put about 0.021 sample(s) in that view", "ms.Aperture()",
                 "raise samples_per_texel to at least 753424"):
        assert part in told[0], (part, told[0])
    advised, told = _said(lambda: sim.measure(frames, ms.ResponseMap(), ms.Budget(samples_per_texel=753424)))
    aperture = sim.measure(frames, ms.Aperture(), ms.Budget(spp=1 << 16))
    assert told == []
    assert_close_mc(advised.irradiance_w_m2, aperture.irradiance_w_m2,
                    np.hypot(advised.stderr_w_m2, aperture.stderr_w_m2), what="the advised samples per texel")


def test_an_opaque_mask_is_said_apart_from_frames_lit_elsewhere():
    """An opaque mask (an empty map, the screen in view at 0.5 m) is said as such; a map that saw the screen and
    frames lit only outside the view keep the words 'not seen'."""
    screen = ms.Screen(resolution=(16, 9))
    dark = ms.Simulation(ms.single(masks.constant(0.0)), screen=screen)
    _, told = _said(lambda: dark.measure([np.ones(screen.shape)], ms.ResponseMap(), ms.Budget(samples_per_texel=16)))
    assert len(told) == 1 and "their masks are opaque toward it or the other mixels' bodies hide it" in told[0]
    corner = np.zeros(screen.shape)
    corner[0, 0] = 1.0
    aside = ms.Simulation(ms.single(pose=ms.Pose((0.0, 0.0, 0.0), (0.3, 0.0, -1.0))), screen=screen)
    m, told = _said(lambda: aside.measure([corner], ms.ResponseMap(), ms.Budget(samples_per_texel=16)))
    assert m.irradiance_w_m2[0, 0] == 0 and np.any(m.maps.weights_sr[0])
    assert len(told) == 1 and told[0].startswith("no sample of mixel(s) m0 reached a lit part")
    assert "not seen" in told[0]


# ------------------------------------------------------------------------------------------ the sigma's d.o.f.
def test_effective_dof_closed_forms():
    """Welch-Satterthwaite: one texel carries R - 1 degrees of freedom; m equal texels m (R - 1); a value with no
    spread has infinitely many (nothing to estimate)."""
    from mincam_sim.render.kernels.map_tracing import effective_dof

    v = np.array([[2.0, 0.0]])
    assert effective_dof(v, v * v, 4).tolist() == [[3.0, np.inf]]
    m = 5
    assert effective_dof(np.array([[m * 2.0]]), np.array([[m * 4.0]]), 8)[0, 0] == pytest.approx(7 * m)


def test_a_value_carried_by_one_texel_says_its_sigma_is_uncertain():
    """A frame lit in one texel at 0.5 m: its value's sigma is the spread of the maps' 4 blocks in that texel,
    3 degrees of freedom (|z| > 4.5 in 2 % of runs, against 0.3 % for 8 replicates): said once, with the
    replicates that reach 7; with 8 replicates it is 7 and nothing is said. A uniform frame's sigma pools every
    texel in view: tens of degrees of freedom (58 here)."""
    from mincam_sim.render.kernels.monte_carlo import UncertainSigmaWarning

    screen = ms.Screen(resolution=(16, 9))
    sim = ms.Simulation(ms.single(), screen=screen)
    one = np.zeros(screen.shape)
    one[4, 8] = 1.0

    def said(frames, budget):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            m = sim.measure(frames, ms.ResponseMap(), budget)
        return m, [str(w.message) for w in caught if issubclass(w.category, UncertainSigmaWarning)]

    m, told = said([np.ones(screen.shape), one], ms.Budget(samples_per_texel=64))
    assert m.meta["stderr_dof_min"] == pytest.approx(3.0)
    assert m.stderr_w_m2[1, 0] > 0 and m.irradiance_w_m2[1, 0] > 10 * m.stderr_w_m2[1, 0]
    assert len(told) == 1, told
    for part in ("1 value(s) of mixel(s) m0 (first: frame 1)", "fewest 3)", "about 2 % of runs",
                 "Raise replicates to 8 or more"):
        assert part in told[0], (part, told[0])
    uniform, told = said([np.ones(screen.shape)], ms.Budget(samples_per_texel=64))
    assert told == [] and uniform.meta["stderr_dof_min"] > 40
    m, told = said([one], ms.Budget(samples_per_texel=72, replicates=8))
    assert told == [] and m.meta["stderr_dof_min"] == pytest.approx(7.0)


def test_a_target_search_samples_every_view_before_it_gives_up():
    """Texels 751x the mixel's view: the search's first maps (16 per texel) put 0.02 samples in the view, read
    0 +/- 0 and the search stopped there. It now starts where every view holds ~10 samples, so the frame
    registers and the search goes on to the cap; the value agrees with the exact-shadow quadrature oracle
    within the t-quantile of its degrees of freedom (Student's t at 1e-4 two-sided)."""
    from scipy import stats

    from mincam_sim.oracles.quadrature import mixel_irradiance_polygon

    sim, screen = _close_screen()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = sim.measure([np.ones(screen.shape)], ms.ResponseMap(), ms.Budget(target_rel_stderr=0.05))
    trail = m.meta["budget_trail"]
    view_samples = trail[0]["samples_per_texel"] * visible_screen_area_m2(screen, sim.mincam[0]) / screen.texel_area_m2
    assert view_samples >= 9.5 and trail[0]["worst_rel_stderr"] is not None, trail
    assert m.irradiance_w_m2[0, 0] > 0
    oracle = mixel_irradiance_polygon(sim.mincam[0], screen, None, 1.0, n_detector=12, n_triangle=12)
    z = abs(m.irradiance_w_m2[0, 0] - oracle) / m.stderr_w_m2[0, 0]
    assert z <= stats.t.isf(0.5e-4, m.meta["stderr_dof_min"]), (z, m.meta["stderr_dof_min"])


@pytest.mark.slow
@pytest.mark.parametrize("replicates, samples_per_texel", [(4, 6400), (8, 6272)])
def test_per_run_tails_follow_the_reported_degrees_of_freedom(replicates, samples_per_texel):
    """Per run, not on average: 300 seeds of a map whose view holds ~8 samples (texels 751x the view), each
    value's z against the exact-shadow quadrature oracle. The count beyond 3 and beyond 4.5 sigma is what
    Student's t with each run's reported degrees of freedom expects (Poisson, p >= 1e-3 both ways); Gaussian
    z-scores would expect 0.0008 beyond 4.5."""
    from scipy import stats

    from mincam_sim.oracles.quadrature import mixel_irradiance_polygon

    sim, screen = _close_screen()
    oracle = mixel_irradiance_polygon(sim.mincam[0], screen, None, 1.0, n_detector=12, n_triangle=12)
    z, dof = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in range(300):
            m = sim.measure([np.ones(screen.shape)], ms.ResponseMap(),
                            ms.Budget(samples_per_texel=samples_per_texel, replicates=replicates, seed=seed))
            assert m.stderr_w_m2[0, 0] > 0, f"seed {seed}: no sample in view"
            z.append((m.irradiance_w_m2[0, 0] - oracle) / m.stderr_w_m2[0, 0])
            dof.append(m.meta["stderr_dof_min"])
    z, dof = np.abs(np.array(z)), np.array(dof)
    assert np.median(dof) < 4 * (replicates - 1), "the view must hold few texels for this test"
    for edge in (3.0, 4.5):
        expected = float(np.sum(2 * stats.t.sf(edge, dof)))
        seen = int(np.sum(z > edge))
        low, high = stats.poisson.cdf(seen, expected), stats.poisson.sf(seen - 1, expected)
        assert min(low, high) >= 1e-3, f"|z| > {edge}: {seen} of 300, t expects {expected:.2f}"


def test_mixel_names_that_share_a_file_are_measured_but_not_written(tmp_path):
    """From Python, mixels 'a_b' and 'a/b' (or 'X' and 'x') measure in memory; their maps written as files would
    be one response_a_b.exr and one maps/a_b.npy, one mixel's silently replacing the other's (the files' own
    check only covered [[mixel]] tables): writing them is one InputError naming both, and nothing is written."""
    from mincam_sim.errors import InputError

    screen = ms.Screen(resolution=(16, 9))
    for names in (("a_b", "a/b"), ("X", "x")):
        cam = ms.Mincam(tuple(ms.Mixel(masks.constant(1.0), pose=ms.Pose((0.01 * k, 0.0, 0.0), (0.0, 0.0, -1.0)),
                                       name=n) for k, n in enumerate(names)))
        sim = ms.Simulation(cam, screen=screen)
        m = sim.measure([np.ones(screen.shape)], ms.ResponseMap(), ms.Budget(samples_per_texel=16))
        assert m.irradiance_w_m2.shape == (1, 2)
        for write in (lambda m=m: m.maps.save_exr(tmp_path / "exr"),
                      lambda sim=sim: sim.export_maps(tmp_path / "maps")):
            with pytest.raises(InputError, match=f"mixels {names[0]!r} and {names[1]!r} would be written"):
                write()
        assert not (tmp_path / "exr").exists() and not any((tmp_path / "maps").glob("maps/*.npy"))
