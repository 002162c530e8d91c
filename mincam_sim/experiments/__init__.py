"""The paper's experiments reproduced in simulation: ``reproduce(names, setup, out_dir)``."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .common import PAPER, Setup

EXPERIMENTS = ("intrusion", "tracking", "speed")


def reproduce(names, setup: Setup, out_dir: str | Path, show_progress: bool = False) -> dict:
    """Run experiments by name; write ``results.json`` (updated after each experiment) and plots."""
    from importlib import import_module

    from ..render import backend

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results_path = out_dir / "results.json"
    results: dict = json.loads(results_path.read_text()) if results_path.exists() else {}
    for name in names:
        if name not in EXPERIMENTS:
            raise ValueError(f"unknown experiment {name!r}: choose from {', '.join(EXPERIMENTS)} or 'all'")
        t = time.perf_counter()
        result = import_module(f".{name}", __name__).run(setup, out_dir, show_progress=show_progress)
        result["seconds"] = time.perf_counter() - t
        results[name] = result
        results["meta"] = {"setup": setup.as_dict(), **backend.describe(),
                           "definitions": {
                               "position_error_pct": "|predicted - ground truth| (Euclidean in 2D) / calibrated "
                                                     "range (field_m) x 100",
                               "speed_error_pct": "|predicted - true speed| / true speed x 100"}}
        results_path.write_text(json.dumps(results, indent=1, default=float))
    return results


__all__ = ["EXPERIMENTS", "PAPER", "Setup", "reproduce"]
