"""The paper's numbers, each defined once: the prototype's geometry and sensor, the experiments' set-up and the
error rates the paper reports (Pooj, Grossberg, Belhumeur, Nayar, "The Minimalist Camera", BMVC 2018).

Two kinds of value live here. *Stated* ones are quoted from the paper (the section is given). *Assumed* ones
are what the paper's prototype needs but the paper does not state (its mask-to-detector distance, mask size,
pixel pitch and working distance): the values this simulator takes for them, chosen to be consistent with the
stated ones. Every default of the package that stands for the paper's prototype reads this module (the
set-up of the experiments, the sensor model, the mask and mixel defaults, the design task, the studies), so
changing a value here changes it everywhere at once. Pure constants: no imports.
"""

from __future__ import annotations

# ------------------------------------------------------------------------------------- the prototype mincam
#: Mixel spacing [m]: Sec. 4.1.1, "our mixels are placed 3.3 cm apart".
SPACING_M = 0.033

#: Pixels per side of each mixel's region of interest [px]: Sec. 3.1 and Fig. 2a, "the 48x48 px region of
#: interest at the center of the sensor array is averaged to obtain the mixel measurement".
DETECTOR_SIDE_PX = 48

#: Pixels averaged into one mixel value [1]: the 48 x 48 region of interest (Sec. 3.1).
PIXELS_AVERAGED = DETECTOR_SIDE_PX * DETECTOR_SIDE_PX

#: Side of the effective mixel [m]: Sec. 3.1, "occupies an approximately 0.1 mm x 0.1 mm area of the sensor
#: array".
DETECTOR_SIZE_M = 1e-4

#: Pixel pitch [m] (assumed: not stated; 48 x 2.2 um = 0.106 mm, consistent with the ~0.1 mm of Sec. 3.1).
PIXEL_PITCH_M = 2.2e-6

#: ADC resolution of a mixel value [bits]: Sec. 3.1 and Fig. 2a, "the measurement is quantized to 12 bits".
ADC_BITS = 12

#: Mask-to-detector distance d_f [m] (assumed: Fig. 1a and Eq. 9-10 use d_f without a value; with the 2 mm
#: mask it gives a ~53 deg field of view, which covers the 50 cm field at 0.5 m).
D_F_M = 2e-3

#: Side of the square mask (aperture) [m] (assumed: not stated; the prototype's film masks slide into a slot in
#: front of each camera, Fig. 2b, and Sec. 3.1 puts a manufactured mixel under 1 mm x 1 mm x 1 mm).
MASK_SIZE_M = 2e-3

# --------------------------------------------------------------------------------------- the experiments
#: Calibrated range [m]: Sec. 4.1.1, the square intrudes "from y = -25 cm to y = 25 cm"; Sec. 4.2.1, "a 50 cm
#: diameter field of view". Error rates are % of it.
FIELD_M = 0.5

#: Distance from the mincam to the screen or table at which it is calibrated [m] (assumed: not stated; the
#: 50 cm field of view of Sec. 4.2.1 is taken at 0.5 m).
CALIBRATION_DEPTH_M = 0.5

#: Diagonal of the calibration display [inch]: Sec. 4.1.1, "a one-time offline calibration using a 50" screen".
SCREEN_DIAGONAL_IN = 50.0

#: Aspect ratio (width, height) of that display [1] (assumed: not stated; a common 16:9 television).
SCREEN_ASPECT = (16, 9)

#: Side of the white square displayed for the calibrations [m] (assumed: Sec. 4.1.1 and 4.2.1 display "a white
#: square" without its size).
CALIBRATION_SQUARE_M = 0.03

#: The intrusion experiment's boundary x0 [m]: Sec. 4.1.1, "the finish line at x0 = -13.78 cm".
INTRUSION_BOUNDARY_X_M = -0.1378

# ---------------------------------------------------------------------------- the error rates it reports
#: 1D intrusion [% of the calibrated range]: Sec. 4.1.1 and Fig. 5, "a maximum error rate of 11.42% and an
#: average error rate of 4.83%".
INTRUSION_MAX_ERROR_PCT = 11.42
INTRUSION_AVG_ERROR_PCT = 4.83

#: Naive object tracking [% of the calibrated range]: Sec. 4.2.1 and Fig. 7, "a maximum error rate of 6.78%
#: with an average error rate of 2.82%".
TRACKING_MAX_ERROR_PCT = 6.78
TRACKING_AVG_ERROR_PCT = 2.82

#: Speed estimation [% of the true speed]: Sec. 4.3.1 and Fig. 9b, "the maximum error rate is 7.55 % and the
#: average error rate is 2.85%".
SPEED_MAX_ERROR_PCT = 7.55
SPEED_AVG_ERROR_PCT = 2.85
