"""``render --check`` estimates against timed renders: a display config and a world config, each run through the
real ``mincam-sim`` command, must take between a third and three times the estimate.

The time measured is the smaller of the wall time and the process's CPU time (all its threads). On an idle
machine that is the wall time (the tracing runs on every core, so the CPU time is larger); on a machine shared
with other work the wall time grows with the load while the CPU time stays what the render costs, and the
estimate (:data:`mincam_sim.runs.jobs.STARTUP_S`, ``SAMPLES_PER_S``, ``FRAME_S``, in CPU seconds) is about
that."""

from __future__ import annotations

import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
WORLD = ROOT / "scenes" / "world"

DISPLAY = """[run]
samples_per_texel = 16
out_dir = "out"
[frames]
n = 20000
[screen]
resolution = [64, 36]
"""

ROOM = """[run]
spp = 16384
out_dir = "out"
[mincam]
layout = "pair"
position_m = [0.0, 0.0, 0.4]
[world]
scene = "room.xml"
frame_rate_hz = 50.0
[[world.mover]]
id = "toy_car"
times_s = [0.0, 1.2]
keyframes_m = [[0.0, 0.0, 0.0], [0.24, 0.0, 0.0]]
"""


def _cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("MINCAM_VARIANT", None)
    return subprocess.run([sys.executable, "-m", "mincam_sim.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, check=False)


def _estimate_s(config: Path) -> float:
    check = _cli(["render", config.name, "--check"], config.parent)
    assert check.returncode == 0, check.stderr
    line = next(line for line in check.stdout.splitlines() if line.startswith("estimate:"))
    number, unit = re.match(r"estimate: about ([\d.]+) (s|min|h)", line).groups()
    return float(number) * {"s": 1, "min": 60, "h": 3600}[unit]


def _timed_s(config: Path) -> tuple[float, float]:
    """(wall, CPU) seconds of ``mincam-sim --quiet render CONFIG``."""
    shutil.rmtree(config.parent / "out", ignore_errors=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    run = _cli(["--quiet", "render", config.name], config.parent)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert run.returncode == 0, run.stderr
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _display(tmp_path: Path) -> Path:
    (tmp_path / "d.toml").write_text(DISPLAY)
    return tmp_path / "d.toml"


def _world(tmp_path: Path) -> Path:
    for name in ("room.xml", "toy_car.obj"):
        shutil.copy(WORLD / name, tmp_path / name)
    (tmp_path / "w.toml").write_text(ROOM)
    return tmp_path / "w.toml"


@pytest.mark.slow
@pytest.mark.parametrize("make", [_display, _world], ids=["display", "world"])
def test_check_estimate_holds_within_a_factor_of_three(make, tmp_path):
    config = make(tmp_path)
    estimate = _estimate_s(config)
    wall, cpu = _timed_s(config)
    ratio = min(wall, cpu) / estimate
    print(f"{config.name}: estimate {estimate:.0f} s, wall {wall:.1f} s, CPU {cpu:.1f} s, ratio {ratio:.2f}")
    assert 1 / 3 <= ratio <= 3, f"estimate {estimate} s, wall {wall:.1f} s, CPU {cpu:.1f} s"
