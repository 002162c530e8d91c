"""The physical model of a mincam, pure numpy: where the mixels are, what a detector and its read-out make of
light, and the paper's ideal forward model the estimators are derived from. Nothing here renders.

* ``optics.py``: :class:`~mincam_sim.model.optics.Mixel` and :class:`~mincam_sim.model.optics.Mincam` (masked
  photodetectors with their poses) and the paper's layouts.
* ``geometry.py``: poses and frames, with Mitsuba's ``look_at`` conventions.
* ``sensor.py``: the photodetector and read-out model: irradiance [W/m^2] -> digital numbers (DN).
* ``readout.py``: rendered irradiances read out through the sensor model (noise, quantisation, dark level).
* ``forward_model.py``: the paper's ideal forward model (Eq. 1), a thin mask before a point detector.
"""
