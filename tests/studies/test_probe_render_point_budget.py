"""A render study's point that ``mincam-sim render`` would refuse (estimated over its 4 h) is refused before the
study starts, naming the point and the key; before, the study's estimate counted a typical render point (seconds)
and began a point that runs for hours."""

from __future__ import annotations

import pytest

from mincam_sim.errors import ConfigError
from mincam_sim.studies import load_study, run_study


def _spec(tmp_path, samples: list[int]) -> dict:
    config = tmp_path / "sweep.toml"
    config.write_text("[run]\ntarget_rel_stderr = 0.0\n[frames]\nn = 2\n")
    return {"study": {"name": "heavy", "experiment": "render", "config": str(config)},
            "grid": {"run.samples_per_texel": samples}}


def test_a_point_render_would_refuse_is_refused_before_anything_runs(tmp_path):
    out = tmp_path / "out"
    spec = load_study(_spec(tmp_path, [64, 100_000_000]), quick=True)
    with pytest.raises(ConfigError, match=r"^study heavy, point \(run\.samples_per_texel=1e\+08\): its render would "
                                          r"take about .* over the 4\.0 h that `mincam-sim render` allows: lower "
                                          r"\[run\] samples_per_texel \(or the frames\) for this point; change the "
                                          r"grid \(nothing was computed\)$"):
        run_study(spec, workers=1, quick=True, out_dir=out, show_progress=False)
    assert not out.exists()


def test_points_render_allows_pass_the_check(tmp_path):
    spec = load_study(_spec(tmp_path, [64, 128]), quick=True)
    for params in spec.points:
        spec.experiment.check(dict(params), True)
