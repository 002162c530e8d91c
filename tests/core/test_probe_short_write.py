"""A write the disk cuts short, as numpy reports it (``OSError("36864 requested and 10224 written")``, no errno):
an ``OSError(ENOSPC)`` naming the destination, so the command line answers it in one line; before, it was a
traceback (``OSError: [Errno None] 36864 requested and 10224 written``) from ``export-maps`` on a full disk."""

from __future__ import annotations

import errno

import numpy as np
import pytest
from typer.testing import CliRunner

import mincam_sim  # noqa: F401  (before Dr.Jit / Mitsuba)
from mincam_sim.storage.atomic import atomic_path, atomic_save_npy


def _short_write(*args, **kwargs):
    raise OSError("36864 requested and 10224 written")


def test_a_short_write_is_a_full_disk_naming_the_destination_and_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setattr(np, "save", _short_write)
    target = tmp_path / "maps" / "x.npy"
    with pytest.raises(OSError) as err:
        atomic_save_npy(target, np.zeros(3))
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(target)
    assert "36864 requested and 10224 written" in err.value.strerror
    assert list(target.parent.iterdir()) == []


def test_another_errorless_oserror_is_not_taken_for_a_full_disk(tmp_path):
    with pytest.raises(OSError) as err, atomic_path(tmp_path / "a.bin"):
        raise OSError("something else")
    assert err.value.errno is None


def test_export_maps_on_a_disk_that_cuts_a_map_short_is_one_line(tmp_path, monkeypatch):
    from mincam_sim.cli import app

    config = tmp_path / "c.toml"
    config.write_text("[screen]\nresolution = [16, 9]\n")
    monkeypatch.setattr(np, "save", _short_write)
    out = tmp_path / "maps"
    result = CliRunner().invoke(app, ["--quiet", "export-maps", str(config), "--out", str(out), "--ideal"])
    assert result.exit_code == 2, result.output
    assert result.output.splitlines() == [
        f"error: No space left on device (only part of the file could be written: 36864 requested and 10224 "
        f"written): {out / 'maps' / 'x.npy'} (nothing half-written is left there); free some space or choose "
        "another output location"]
