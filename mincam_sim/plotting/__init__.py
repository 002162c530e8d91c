"""Figures: matplotlib drawings of results, and the README's figures.

* ``plots.py``: figures of results (Agg backend, pure numpy + matplotlib); sits beside the core.
* ``figures.py``: the README's figures (``mincam-sim figures``), rendered through the front door.
"""
