"""Scene building: what a :class:`~mincam_sim.render.simulation.Simulation` accepts and the Mitsuba scene it builds.

The only part of the render layer, beside the front door, that the upper floors may import (scene pieces by
name, world coordinates).

* ``scene_dicts.py``: Mitsuba scene dictionaries from small pure functions (meshes, planes, lights, cameras).
* ``elements.py``: the pure scene descriptions of :mod:`mincam_sim.scene` turned into Mitsuba elements.
* ``world_input.py``: what a world accepts (elements, loaded scenes, updates), checked at the boundary.
* ``world_checks.py``: a built world's silent answers said (no light, a mincam inside a shape, a scene in
  other units than metres); the camera pixels that see a light.
* ``scene_files.py``: Mitsuba XML scene files (their ``<default>`` parameters, units, integrator depth, shape
  groups) and trimesh meshes, with clear errors; turning a y-up file.
* ``gltf_files.py``: glTF / GLB files with their materials (base colour and its texture, emission), one mesh
  per node, named by the node.
* ``textures.py``: bitmap textures from numpy arrays (masks, frames, printed backgrounds).
* ``updates.py``: parameter updates of a world scene by name, in world coordinates (and those that take a shape
  or light out).
* ``mincam_scene.py``: one scene object for a mincam anywhere (a display or a world).
* ``static_split.py``: a world split for a change run: the static shapes in a scene built once, the moving
  meshes in small scenes rebuilt per frame.
"""
