"""A learned decoder that runs in plain NumPy: a polynomial of gain-free mixel ratios -> field position."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_sim.design import tracking as tr
from mincam_sim.estimation import polynomial
from mincam_sim.storage.atomic import atomic_write_json


@dataclass
class Decoder:
    """``q = poly(features(dn)) @ coefficients.T``: field position (normalised, :mod:`.tracking`) from the
    four background-subtracted mixel changes [DN, any gain].

    Attributes
    ----------
    features : str
        Key of :data:`mincam_sim.design.tracking.FEATURES`.
    degree : int
        Total degree of the polynomial.
    coefficients : (2, n_terms) ndarray
        Rows: field x, field y.
    """

    features: str
    degree: int
    coefficients: np.ndarray

    def __post_init__(self) -> None:
        if self.features not in tr.FEATURES:
            raise ValueError(f"Decoder.features must be one of {', '.join(tr.FEATURES)}, got {self.features!r}")
        self.coefficients = np.asarray(self.coefficients, dtype=np.float64)

    def __call__(self, dn: np.ndarray) -> np.ndarray:
        """Positions (n, 2) in field units from changes (n, 4) [DN]; NaN where the changes sum to zero."""
        dn = np.asarray(dn, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            feats = tr.FEATURES[self.features](dn.T)
            return np.stack(polynomial.poly_terms(*feats, degree=self.degree), axis=-1) @ self.coefficients.T

    def to_json(self, path: str | Path) -> Path:
        return atomic_write_json(path, {"kind": "mincam_sim.design.Decoder", "features": self.features,
                                        "degree": self.degree, "coefficients": self.coefficients.tolist(),
                                        "output": "field position (x, y) in units of the 50 cm field at 0.5 m"},
                                 indent=1)

    @classmethod
    def from_json(cls, path: str | Path) -> Decoder:
        d = json.loads(Path(path).read_text())
        return cls(d["features"], int(d["degree"]), np.array(d["coefficients"]))


__all__ = ["Decoder"]
