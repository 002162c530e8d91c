"""Scene building: what a :class:`~mincam_sim.render.simulation.Simulation` accepts and the Mitsuba scene it builds.

The only part of the render layer, beside the front door, that the upper floors may import (scene pieces by
name, world coordinates).

* ``scene_dicts.py``: Mitsuba scene dictionaries from small pure functions (meshes, planes, lights, cameras).
* ``elements.py``: the pure scene descriptions of :mod:`mincam_sim.scene` turned into Mitsuba elements.
* ``world_input.py``: what a world accepts (elements, loaded scenes, updates), checked at the boundary.
* ``scene_files.py``: Mitsuba XML scene files and trimesh meshes, with clear errors; turning a y-up file.
* ``textures.py``: bitmap textures from numpy arrays (masks, frames, printed backgrounds).
* ``updates.py``: parameter updates of a world scene by name, in world coordinates.
* ``mincam_scene.py``: one scene object for a mincam anywhere (a display or a world).
"""
