"""Guards at the boundary: a budget refused alike in Python and TOML, estimates that count every frame, the
memory guard, ``--check`` on a million frames, messages that name the user's field, and one warning for a key
that does not apply. Fast: nothing is rendered."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import mincam_sim as ms
from mincam_sim.configuration.config import load_config
from mincam_sim.configuration.schema import IgnoredSettingWarning
from mincam_sim.configuration.world_config import load_world_config
from mincam_sim.errors import ConfigError, InputError
from mincam_sim.runs import jobs

SMALL = {"run": {"samples_per_texel": 16, "out_dir": "out"}, "frames": {"n": 2}, "screen": {"resolution": [32, 18]}}
MESH = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def _display(**run) -> dict:
    """SMALL with ``run`` keys (an aperture or reference run without the maps' samples_per_texel)."""
    table = {**SMALL["run"], **run}
    if table.get("solver", "response_map") != "response_map" and "samples_per_texel" not in run:
        del table["samples_per_texel"]
    return {**SMALL, "run": table}


def _world(tmp_path, head: str = "", mover: str = "offsets_m = [[0, 0, 0]]\n", world: str = "") -> str:
    (tmp_path / "m.obj").write_text(MESH)
    text = (f'{head}[world]\n{world}[[world.object]]\nid = "toy"\nmesh = "m.obj"\n[[world.mover]]\nid = "toy"\n'
            f"{mover}")
    (tmp_path / "w.toml").write_text(text)
    return tmp_path / "w.toml"


# ------------------------------------------------------------------------------ one budget rule, two doors
#: Budget fields and the [run] table that gives them (aperture: spp is its count; response_map: samples_per_texel).
PARITY = [
    dict(spp=0), dict(spp=-4), dict(spp=1.5), dict(spp=True), dict(replicates=1), dict(replicates=5000),
    dict(replicates=2.0), dict(seed=-1), dict(seed=1.5), dict(target_rel_stderr=1.5), dict(target_rel_stderr=-0.1),
    dict(target_rel_stderr=float("nan")), dict(spp=4, replicates=8), dict(spp=100, replicates=4096 + 1),
    dict(samples_per_texel=1), dict(samples_per_texel=0), dict(samples_per_texel=16, replicates=64),
]


#: (solver, scene kind, budget fields set) -> the fields it ignores (one warning names them), or none.
UNREAD = [
    (ms.Aperture(), "display", dict(spp=256, target_rel_stderr=0.1, max_spp=1024), []),
    (ms.Aperture(), "display", dict(spp=256, samples_per_texel=16), ["samples_per_texel"]),
    (ms.Aperture(), "world", dict(spp=256, target_rel_stderr=0.1, max_spp=1024), ["target_rel_stderr", "max_spp"]),
    (ms.PlaneReplay(), "world", dict(spp=256, seed=3), []),
    (ms.PlaneReplay(), "world", dict(spp=256, target_rel_stderr=0.1), ["target_rel_stderr"]),
    (ms.ResponseMap(), "display", dict(samples_per_texel=16, target_rel_stderr=0.1), []),
    (ms.ResponseMap(), "display", dict(spp=256, max_spp=512), ["spp", "max_spp"]),
    (ms.DotProduct(), "display", dict(seed=2), ["seed"]),
    (ms.DotProduct(), "display", dict(), []),
    (ms.StratifiedChange(), "world", dict(spp=256, target_rel_stderr=0.1, max_spp=1024), []),
    (ms.StratifiedChange(), "world", dict(spp=256, samples_per_texel=16), ["samples_per_texel"]),
]


@pytest.mark.parametrize("solver, kind, fields, ignored", UNREAD,
                         ids=[f"{s.name}-{k}-{','.join(f) or 'none'}" for s, k, f, _ in UNREAD])
def test_a_budget_field_the_solver_does_not_read_gets_one_warning(solver, kind, fields, ignored):
    """A Budget field the solver never reads is not silently dropped: one warning, naming each such field."""
    from mincam_sim.render.simulation import Simulation

    sim = Simulation.__new__(Simulation)  # only the check: nothing is built or traced
    sim.kind = kind
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sim._warn_ignored_budget(solver, ms.Budget(**fields))
    said = [str(w.message) for w in caught if w.category is IgnoredSettingWarning]
    if not ignored:
        assert said == []
        return
    assert len(said) == 1 and said[0].startswith("Budget." + ", Budget.".join(ignored) + " ")
    assert f"the {solver.name} solver on {kind} scenes" in said[0]


@pytest.mark.parametrize("solver, fields", [("dot_product", dict(spp=256, seed=3)),
                                             ("aperture", dict(spp=256, samples_per_texel=16))])
def test_a_run_key_the_solver_does_not_read_is_one_warning_through_toml_and_python(solver, fields):
    """A ``[run]`` key the file's solver does not read: one warning from the file's reader, and the budget it
    hands on leaves the field out, so the solver does not warn a second time."""
    from mincam_sim.render.simulation import Simulation

    with pytest.warns(IgnoredSettingWarning, match=r"\[run\] .* ignored") as caught:
        cfg = load_config(_display(solver=solver, **fields))
    assert len([w for w in caught if w.category is IgnoredSettingWarning]) == 1
    sim = Simulation.__new__(Simulation)
    sim.kind = "display"
    with warnings.catch_warnings(record=True) as again:
        warnings.simplefilter("always")
        sim._warn_ignored_budget(cfg.run.solver, cfg.run.budget)
    assert [w for w in again if w.category is IgnoredSettingWarning] == []


@pytest.mark.parametrize("fields", PARITY, ids=lambda f: ",".join(f"{k}={v}" for k, v in f.items()))
def test_budget_and_toml_refuse_the_same_values_with_the_same_words(fields):
    with pytest.raises(InputError) as python:
        ms.Budget(**fields)
    solver = "response_map" if "samples_per_texel" in fields else "aperture"
    with pytest.raises(ConfigError) as toml:
        load_config(_display(solver=solver, **fields))
    said = str(python.value)
    assert said.startswith("Budget.")
    assert str(toml.value) == "[run] " + said.removeprefix("Budget.")


def test_a_world_file_refuses_a_budget_as_python_does(tmp_path):
    path = _world(tmp_path, head="[run]\nspp = 4\nreplicates = 8\n")
    with pytest.raises(InputError) as python:
        ms.Budget(spp=4, replicates=8)
    with pytest.raises(ConfigError) as toml:
        load_world_config(path)
    assert str(toml.value) == "[run] " + str(python.value).removeprefix("Budget.")


def test_budget_defaults_count_in_its_checks():
    """Python's defaults (8 replicates for rays, 4 blocks for maps) are checked as a TOML file's replicates are:
    before, Budget(samples_per_texel=2) failed deep in the map tracer with an internal ValueError."""
    with pytest.raises(InputError, match=r"Budget.samples_per_texel = 2 is fewer than the default 4 replicates.*"
                                         r"replicates = 2"):
        ms.Budget(samples_per_texel=2)
    with pytest.raises(InputError, match=r"Budget.spp = 4 is fewer than the default 8 replicates"):
        ms.Budget(spp=4)
    ms.Budget(samples_per_texel=2, replicates=2)
    ms.Budget(spp=8)


def test_the_budget_defaults_are_the_solvers():
    from mincam_sim import budget
    from mincam_sim.render.solvers import base, change, response_map

    assert budget.DEFAULT_MAP_REPLICATES == response_map.DEFAULT_MAP_BLOCKS
    assert budget.DEFAULT_RAY_REPLICATES == base.DEFAULT_RAY_REPLICATES == change.DEFAULT_REPLICATES


# ------------------------------------------------------------------------------ estimates count every frame
def test_the_estimate_counts_every_frame():
    """A 10^6-frame sweep was estimated at "about 2 s" (the maps only) and ran 130 s: each frame costs time."""
    few, _ = jobs.estimate_seconds(load_config({**SMALL, "frames": {"n": 1000}}))
    many, what = jobs.estimate_seconds(load_config({**SMALL, "frames": {"n": 1_000_000}}))
    per_frame = jobs.FRAME_S[ms.ResponseMap] + 576 * (jobs.TEXEL_S + 2 * jobs.TEXEL_MIXEL_S)
    assert many - few == pytest.approx(999_000 * per_frame)
    assert many > 100 and "1000000 frames" in what


def test_a_world_estimate_counts_frames_and_refuses_keyframes_at_a_high_rate(tmp_path):
    path = _world(tmp_path, head="[run]\nspp = 262144\n", world="frame_rate_hz = 100000.0\n",
                  mover="times_s = [0.0, 1.2]\nkeyframes_m = [[0, 0, 0], [0.2, 0, 0]]\n")
    cfg = load_world_config(path)
    seconds, what = jobs.estimate_seconds(cfg)
    assert cfg.n_frames == 120_001 and "120001 frames" in what
    assert seconds > 120_001 * jobs.FRAME_S[ms.StratifiedChange]
    with pytest.raises(ConfigError, match=r"about .* h .*--time-limit-s"):
        jobs.check_budget(cfg, None)


def test_check_summarises_a_million_frames_from_a_few(monkeypatch):
    cfg = load_config({**SMALL, "frames": {"n": 1_000_000}})
    made = []
    make = cfg.frames._make
    monkeypatch.setattr(cfg.frames, "_make", lambda i: made.append(i) or make(i))
    lines = jobs.config_summary(cfg, None)
    assert len(made) <= jobs.SUMMARY_FRAMES
    assert any("in 64 frames spread over the 1000000" in line for line in lines)
    small = jobs.config_summary(load_config(SMALL), None)
    assert not any("spread over" in line for line in small)  # every frame of a short run


def test_check_says_when_render_would_refuse():
    cfg = load_config(_display(solver="aperture", spp=2**30))
    line = next(line for line in jobs.config_summary(cfg, None, limit_s=10.0) if line.startswith("estimate"))
    assert "limit 10 s" in line and "OVER THE TIME LIMIT" in line
    line = next(line for line in jobs.config_summary(load_config(SMALL), None) if line.startswith("estimate"))
    assert "OVER" not in line and "GiB of arrays in memory" in line


# ------------------------------------------------------------------------------------------- memory guard
def test_memory_guard_names_the_gib(monkeypatch):
    cfg = load_config({**SMALL, "frames": {"n": 1_000_000}})
    n_bytes, what = jobs.estimate_bytes(cfg)
    assert n_bytes >= 1_000_000 * 2 * jobs.RESULT_BYTES_PER_VALUE and "1000000 frames" in what
    monkeypatch.setattr(jobs, "available_bytes", lambda: n_bytes / 2)
    with pytest.raises(ConfigError, match=r"about 0\.\d+ GiB in memory .* more than the 0\.\d+ GiB free.*fewer frames"):
        jobs.check_budget(cfg, None)
    monkeypatch.setattr(jobs, "available_bytes", lambda: 2 * n_bytes)
    jobs.check_budget(cfg, None)


def test_world_updates_are_counted_before_they_are_made(tmp_path):
    """Each frame holds the moving meshes' vertices: ~10^6 frames of a 10^6-vertex mesh are refused before the
    per-frame list is built (it grew to 24 GB before the kernel killed it)."""
    path = _world(tmp_path, world="frame_rate_hz = 833332.0\n",
                  mover="times_s = [0.0, 1.2]\nkeyframes_m = [[0, 0, 0], [0.2, 0, 0]]\n")
    cfg = load_world_config(path)
    params = {"toy.vertex_positions": np.zeros(3 * 1_000_000, dtype=np.float32)}
    with pytest.raises(ConfigError, match=r"GiB in memory \(999999 frames x 3000000 floats"):
        jobs._check_update_memory(params, cfg)
    jobs._check_update_memory({"toy.vertex_positions": np.zeros(9)}, cfg)  # 72 MB: fine


def test_world_camera_images_count_in_memory(tmp_path):
    path = _world(tmp_path)
    with open(path, "a") as fh:
        fh.write("[world.camera]\nposition_m = [0, 0, 1]\nlook_at_m = [0, 0, 0]\nwidth_px = 8192\nheight_px = 8192\n")
    n_bytes, what = jobs.estimate_bytes(load_world_config(path))
    assert n_bytes >= 2 * 8192 * 8192 * 8 * 2 and "2 camera images of 8192 x 8192 px" in what


# ---------------------------------------------------------------------------- messages name the user's field
def test_strata_shares_of_the_wrong_length_name_the_field_and_the_length():
    solver = ms.StratifiedChange(strata_shares=(0.5, 0.5))
    with pytest.raises(InputError) as err:
        solver.shares()
    message = str(err.value)
    assert message.startswith("strata_shares needs 5 shares") and "got 2" in message
    assert "counts" not in message
    with pytest.raises(InputError, match="strata_expansions .* must start at 1 and grow"):
        ms.StratifiedChange(strata_expansions=(2.0, 1.0), strata_shares=(1, 1, 1)).shares()
    assert ms.StratifiedChange(strata_shares=(1, 1), strata_expansions=(1.0,)).shares().tolist() == [1.0, 1.0]


# ------------------------------------------------------------------------------- keys that do not apply
@pytest.mark.parametrize("config, said", [
    (_display(spp=1024), "[run] spp is ignored: solver = \"response_map\""),
    (_display(solver="aperture", samples_per_texel=32), "[run] samples_per_texel is ignored"),
    ({**SMALL, "frames": {"n": 2, "nx": 4, "path": "f.npy"}}, "[frames] nx, path are ignored: kind = \"line_sweep\""),
    ({**SMALL, "mincam": {"wavelengths_m": [600e-9]}}, "[mincam] wavelengths_m is ignored"),
    ({**SMALL, "mincam": {"mask_encoding": "srgb"}}, "[mincam] mask_encoding is ignored"),
    ({**SMALL, "mincam": {"layout": "custom", "spacing_m": 0.05},
      "mixel": [{"mask": "ramp:x", "mask_encoding": "srgb"}]}, "[mincam] spacing_m is ignored"),
    ({**SMALL, "mincam": {"layout": "custom"}, "mixel": [{"mask": "ramp:x", "mask_encoding": "srgb"}]},
     "[[mixel]] #1 mask_encoding is ignored"),
])
def test_a_key_that_does_not_apply_is_one_warning(config, said):
    with pytest.warns(IgnoredSettingWarning) as caught:
        load_config(config)
    assert any(str(w.message).startswith(said) for w in caught), [str(w.message) for w in caught]


def test_a_default_written_out_or_a_key_that_applies_says_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("error", IgnoredSettingWarning)
        load_config(_display(spp=65536))  # the default: changes nothing
        load_config(_display(samples_per_texel=32))
        load_config(_display(solver="aperture", spp=1024))
        load_config({**SMALL, "frames": {"kind": "grid_sweep", "nx": 2, "ny": 2}})


@pytest.mark.parametrize("world, mover, light, said", [
    ("up = \"y\"\n", "offsets_m = [[0, 0, 0]]\n", "", "[world] up is ignored"),
    ("", "offsets_m = [[0, 0, 0]]\ntimes_s = [0.0, 1.0]\n", "", "times_s is ignored: it times keyframes_m"),
    ("", "offsets_m = [[0, 0, 0]]\n", 'kind = "point"\nsize_m = [1.0, 1.0]\ncutoff_deg = 10.0\n',
     "[[world.light]] #1 (bulb) size_m, cutoff_deg are ignored: a point light uses only position_m, intensity_w_sr"),
])
def test_a_world_key_that_does_not_apply_is_one_warning(tmp_path, world, mover, light, said):
    path = _world(tmp_path, world=world, mover=mover)
    if light:
        text = path.read_text().replace("[[world.mover]]", f'[[world.light]]\nid = "bulb"\n{light}[[world.mover]]')
        path.write_text(text)
    with pytest.warns(IgnoredSettingWarning) as caught:
        load_world_config(path)
    assert any(said in str(w.message) for w in caught), [str(w.message) for w in caught]


def test_world_mincam_placement_is_ignored_by_a_custom_layout(tmp_path):
    path = _world(tmp_path)
    path.write_text('[mincam]\nlayout = "custom"\nposition_m = [0, 0, 1]\n[[mixel]]\nmask = "ramp:x"\n'
                    'position_m = [0, 0, 0.5]\n' + path.read_text())
    with pytest.warns(IgnoredSettingWarning, match=r"\[mincam\] position_m is ignored: layout = \"custom\""):
        load_world_config(path)


def test_the_overlap_prefilter_finds_every_pair_the_box_test_finds():
    """The mincam's overlap check runs the box test only on pairs whose circumscribed spheres meet: over random
    tilted clusters it finds exactly the pairs the brute-force box test finds, and 400 mixels check fast."""
    import mincam_sim as ms
    from mincam_sim.model import optics

    rng = np.random.default_rng(0)

    def mixel(name, pose):
        return ms.Mixel(mask=ms.masks.ramp("x", 8), pose=pose, name=name)

    found = 0
    for _ in range(20):
        mixels = [mixel(f"m{k}", ms.Pose(tuple(rng.uniform(-0.004, 0.004, 3)), tuple(rng.normal(size=3)),
                                         tuple(rng.normal(size=3)))) for k in range(12)]
        brute = {(i, j) for i in range(12) for j in range(i + 1, 12) if optics.bodies_overlap(mixels[i], mixels[j])}
        kept = {(i, j) for i, j in optics._overlap_candidates(mixels) if optics.bodies_overlap(mixels[i], mixels[j])}
        assert kept == brute
        found += len(brute)
    assert found > 50  # the clusters are dense enough to test something
    grid = [mixel(f"m{i}", ms.Pose((0.0025 * (i % 20), 0.0025 * (i // 20), 0.0), (0, 0, -1), (0, 1, 0)))
            for i in range(400)]
    assert len(ms.Mincam(tuple(grid))) == 400
