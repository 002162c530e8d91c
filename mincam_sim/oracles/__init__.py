"""Independent oracles of the renderer, pure numpy / scipy: closed forms and float64 quadrature of the mixel
integral. They share no code with the render layer, so agreeing with them checks the scene, not the code path.

* ``closed_forms.py``: closed-form radiometry (view factors, disks and rectangles, Lambertian emitters).
* ``quadrature.py``: independent float64 quadrature of the mixel integral over detector and mask.
"""
