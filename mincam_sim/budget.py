"""How much Monte Carlo work a measurement gets: one :class:`Budget` for every solver (pure Python).

A budget is either explicit sample counts or a target relative standard error (with the counts then as the
first pilot), plus the number of independent replicates whose spread gives the standard error, the seed and a
cap. Solvers read what applies to them: rays per mixel per frame (``spp``) for the aperture, reference and
change solvers, samples per screen texel for response maps.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from mincam_sim.errors import InputError

DEFAULT_SPP = 1 << 16  # rays per mixel per frame when a budget names none
DEFAULT_SAMPLES_PER_TEXEL = 64


def _positive_int(name: str, value, minimum: int = 1) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InputError(f"Budget.{name} must be an integer >= {minimum}, got {value!r}")


@dataclass(frozen=True)
class Budget:
    """Sample counts or a target noise, replicates, seed and cap of one measurement.

    Parameters
    ----------
    spp : int, optional
        Rays per mixel per frame (aperture, reference and change solvers; default 65,536). With a target, the
        first pilot's count.
    samples_per_texel : int, optional
        Samples per screen texel of response maps (default 64; rounded to ``replicates x k^2``, and the map's
        ``meta["samples_per_texel"]`` says what was traced).
    target_rel_stderr : float
        If > 0, pilots measure the noise and the counts are raised until the worst significant measurement
        reaches this relative standard error (or the cap); what was reached is in the result.
    replicates : int, optional
        Independent estimates per measurement (>= 2); default 8 for rays, 4 blocks for response maps.
    seed : int
        Same seed, same numbers.
    max_spp : int, optional
        Cap of the target search, rays per mixel per frame.
    """

    spp: int | None = None
    samples_per_texel: int | None = None
    target_rel_stderr: float = 0.0
    replicates: int | None = None
    seed: int = 0
    max_spp: int | None = None

    def __post_init__(self) -> None:
        _positive_int("spp", self.spp)
        _positive_int("samples_per_texel", self.samples_per_texel)
        _positive_int("replicates", self.replicates, 2)
        _positive_int("max_spp", self.max_spp)
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise InputError(f"Budget.seed must be an integer >= 0, got {self.seed!r}")
        t = self.target_rel_stderr
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t) or not 0 <= t < 1:
            raise InputError(f"Budget.target_rel_stderr must be in [0, 1) (0 = use the counts as given), got {t!r}")
        if self.samples_per_texel is not None and self.replicates is not None and \
                self.samples_per_texel < self.replicates:
            raise InputError(f"Budget.samples_per_texel = {self.samples_per_texel} is fewer than its {self.replicates} "
                             "replicates; each replicate needs samples of its own in every texel: raise "
                             "samples_per_texel or lower replicates")
        if self.spp is not None and self.replicates is not None and self.spp < self.replicates:
            raise InputError(f"Budget.spp = {self.spp} is fewer than its {self.replicates} replicates; each replicate "
                             "needs rays of its own")

    def rays(self, default: int = DEFAULT_SPP) -> int:
        """Rays per mixel per frame this budget gives (or ``default``)."""
        return int(self.spp if self.spp is not None else default)

    def replicates_or(self, default: int) -> int:
        return int(self.replicates if self.replicates is not None else default)

    def describe(self) -> dict:
        """JSON-friendly record of the budget."""
        return {k: v for k, v in asdict(self).items() if v is not None}
