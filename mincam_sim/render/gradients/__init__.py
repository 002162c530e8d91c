"""Gradients through the physics: Dr.Jit automatic differentiation for the design floor.

* ``differentiable.py``: differentiable mixel measurements of objects on a plane.
* ``autodiff.py``: the Dr.Jit namespace the design optimiser is written against.
"""
