"""A Ctrl-C says what the same command will do next: ``render`` resumes from its store, ``export-maps`` keeps
nothing of an interrupted export and starts again (before, it was told that it resumes), and a folder the command
made and left empty is removed."""

from __future__ import annotations

import pytest

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)


def _interrupted(*args, **kwargs):
    raise KeyboardInterrupt


def test_an_interrupted_export_says_it_starts_again_and_leaves_no_empty_folder(tmp_path, monkeypatch, capsys):
    from mincam_sim import cli
    from mincam_sim.render.simulation import Simulation

    config = tmp_path / "c.toml"
    config.write_text("[screen]\nresolution = [16, 9]\n")
    monkeypatch.setattr(Simulation, "export_maps", _interrupted)
    out = tmp_path / "new" / "maps"
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["export-maps", str(config), "--out", str(out), "--ideal"])
    assert exit_info.value.code == 130
    assert capsys.readouterr().err == ("error: interrupted; no file is left half-written, and the same command "
                                       "starts again from the beginning\n")
    assert not (tmp_path / "new").exists()


def test_an_interrupted_render_still_says_it_resumes(tmp_path, monkeypatch, capsys):
    from mincam_sim import cli
    from mincam_sim.runs import jobs

    config = tmp_path / "c.toml"
    config.write_text("[screen]\nresolution = [16, 9]\n[run]\nsamples_per_texel = 8\nreplicates = 2\n")
    monkeypatch.setattr(jobs, "run_render_config", _interrupted)
    with pytest.raises(SystemExit) as exit_info:
        cli.main(["render", str(config), "--out", str(tmp_path / "r")])
    assert exit_info.value.code == 130
    assert capsys.readouterr().err == ("error: interrupted; results written so far are kept, and the same command "
                                       "resumes\n")
