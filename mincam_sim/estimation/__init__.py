"""From mixel measurements to answers, pure numpy: the paper's estimators, calibration and error rates.

* ``estimators.py``: intrusion positions, 2D positions, speeds and paths from measurements (paper Eqs. 2-14).
* ``calibration.py``: the cubic calibration of observed relative positions to true positions.
* ``metrics.py``: the paper's error rates.
* ``polynomial.py``: polynomial features of a decoder (every monomial up to a total degree).
"""
