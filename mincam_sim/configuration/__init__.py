"""Typed configuration: every TOML file of mincam_sim, read in one place and checked section by section.

Sits above the render layer (it names the solver classes) and below the runs.

* ``toml_files.py``: every TOML file is read here, and only here.
* ``schema.py``: one mechanism for every section: a dataclass whose fields carry defaults, units and checks.
* ``config.py``: a render of a display (``mincam-sim render``): mincam, screen, frames, ``[run]``.
* ``world_config.py``: a render of a world: a Mitsuba scene file and/or meshes and lights, movers, ``[run]``.
"""
