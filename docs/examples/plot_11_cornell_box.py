"""
A Cornell box in centimetres, with its parameters
=================================================

Scene files found elsewhere are rarely in metres and often carry ``<default>`` parameters, an integrator and
a camera of their own. This box is modelled in cm (55.5 cm on a side, red and green side walls, a ceiling
lamp), its lamp's radiance and a card's albedo are ``<default>`` parameters, and its ``<integrator>`` asks for
direct light only. :class:`mincam_sim.render.simulation.Simulation` reads it with ``unit_m=0.01``, sets the
parameters through Mitsuba's loader, takes the file's ``max_depth`` and ignores its camera (with one warning).
A small point light (a bulb) hangs in a corner, and two 6 cm blocks are instances of one ``shapegroup``. Two
mixels hang 15 cm under the ceiling looking down; a 10 x 5 cm card (a rectangle, moved by its ``to_world``)
slides across the box, then the lamp itself moves, then one block (an instance, moved by its ``to_world``:
its mesh is never rewritten) slides along the floor.
"""

# %%
# The scene file
# --------------
import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import mincam_sim as ms

CBOX_CM = """<scene version="3.0.0">
    <default name="lamp" value="12"/>
    <default name="card_albedo" value="0.8"/>
    <integrator type="path"><integer name="max_depth" value="2"/></integrator>
    <sensor type="perspective"><transform name="to_world"><lookat origin="27.75, -80, 27.75"
        target="27.75, 0, 27.75" up="0, 0, 1"/></transform></sensor>
    <bsdf type="diffuse" id="white"><spectrum name="reflectance" value="0.75"/></bsdf>
    <bsdf type="diffuse" id="red"><spectrum name="reflectance" value="0.4"/></bsdf>
    <bsdf type="diffuse" id="green"><spectrum name="reflectance" value="0.3"/></bsdf>
    <shape type="rectangle" id="floor"><ref id="white"/>
        <transform name="to_world"><scale value="27.75"/><translate x="27.75" y="27.75"/></transform></shape>
    <shape type="rectangle"><ref id="white"/>  <!-- the ceiling: no id, static -->
        <transform name="to_world"><scale value="27.75"/><rotate x="1" angle="180"/>
            <translate x="27.75" y="27.75" z="55.5"/></transform></shape>
    <shape type="rectangle"><ref id="white"/>  <!-- the back wall -->
        <transform name="to_world"><scale value="27.75"/><rotate x="1" angle="-90"/>
            <translate x="27.75" y="55.5" z="27.75"/></transform></shape>
    <shape type="rectangle"><ref id="red"/>  <!-- the left wall -->
        <transform name="to_world"><scale value="27.75"/><rotate y="1" angle="90"/>
            <translate z="27.75" y="27.75"/></transform></shape>
    <shape type="rectangle"><ref id="green"/>  <!-- the right wall -->
        <transform name="to_world"><scale value="27.75"/><rotate y="1" angle="-90"/>
            <translate x="55.5" y="27.75" z="27.75"/></transform></shape>
    <shape type="rectangle" id="lamp">
        <transform name="to_world"><scale x="6.5" y="5.25"/><rotate x="1" angle="180"/>
            <translate x="27.75" y="27.75" z="55.4"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="0.0"/></bsdf>
        <emitter type="area"><spectrum name="radiance" value="$lamp"/></emitter></shape>
    <emitter type="point" id="bulb"><point name="position" x="8" y="47" z="40"/>
        <spectrum name="intensity" value="0.05"/></emitter>
    <shape type="shapegroup" id="block">
        <shape type="cube"><transform name="to_world"><scale value="3"/><translate z="3"/></transform>
            <bsdf type="diffuse"><spectrum name="reflectance" value="0.6"/></bsdf></shape>
    </shape>
    <shape type="instance" id="block_a"><ref id="block"/>
        <transform name="to_world"><translate x="42" y="42"/></transform></shape>
    <shape type="instance" id="block_b"><ref id="block"/>
        <transform name="to_world"><translate x="14" y="14"/></transform></shape>
    <shape type="rectangle" id="card">
        <transform name="to_world"><scale x="5" y="2.5"/><translate x="10" y="27.75" z="12"/></transform>
        <bsdf type="diffuse"><spectrum name="reflectance" value="$card_albedo"/></bsdf></shape>
</scene>
"""
folder = Path(tempfile.mkdtemp())
(folder / "cbox_cm.xml").write_text(CBOX_CM)

# %%
# Read it in metres, with its parameters
# --------------------------------------
# Read as metres, the box would be 55 m wide around a rig of 3 cm: one warning says so. With ``unit_m=0.01``
# everything the API shows is in metres (``sim.params``, updates), and the file's integrator gives the depth.
cam = ms.pair_layout(spacing_m=0.033, center=ms.Pose((0.2775, 0.2775, 0.40), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)))
with warnings.catch_warnings(record=True) as said:
    warnings.simplefilter("always")
    ms.Simulation(cam, world=folder / "cbox_cm.xml")
print("read as metres:", *sorted({str(w.message)[:110] for w in said}), sep="\n  ")
with warnings.catch_warnings():
    warnings.simplefilter("ignore", UserWarning)  # the file's camera is ignored (said above)
    sim = ms.Simulation(cam, world=folder / "cbox_cm.xml", unit_m=0.01)
    dark = ms.Simulation(cam, world=folder / "cbox_cm.xml", unit_m=0.01, parameters={"lamp": 0})
print(f"max_depth {sim.mincam_scene.max_depth} from {sim.max_depth_source}; movable: {', '.join(sim.movable())}")
budget = ms.Budget(spp=1 << 14, seed=1)
p_on = sim.measure([{}], budget=budget).irradiance_w_m2[0]
p_off = dark.measure([{}], budget=budget).irradiance_w_m2[0]
print(f"P with the lamp on {np.round(p_on, 4)} W/m^2; with parameters={{'lamp': 0}} (the bulb only): "
      f"{np.round(p_off, 4)}")

# %%
# The card slides, then the lamp moves
# ------------------------------------
# The background is the box without the card (:meth:`~mincam_sim.render.simulation.Simulation.without`
# shrinks it to a 1 µm speck). The lamp's frames move it by 6 cm along y against the box as built.
card0 = sim.params["card.to_world"]
xs_m = np.linspace(0.08, 0.47, 9)
frames = []
for x in xs_m:
    m = card0.copy()
    m[0, 3] = x
    frames.append({"card.to_world": m})
ch = sim.measure_changes(frames, sim.without("card"), budget=ms.Budget(spp=8192, seed=2))
lamp0 = sim.params["lamp.to_world"]
shifts_m = np.linspace(-0.06, 0.06, 5)
lamp_frames = []
for dy in shifts_m:
    m = lamp0.copy()
    m[1, 3] += dy
    lamp_frames.append({"lamp.to_world": m})
with warnings.catch_warnings():
    warnings.simplefilter("ignore", UserWarning)  # a moving emitter is sampled over the whole aperture (said)
    lamp_ch = sim.measure_changes(lamp_frames, {}, solver=ms.PlainChange(), budget=ms.Budget(spp=8192, seed=3))

block0 = sim.params["block_b.to_world"]  # in metres, with the file's 0.01 scale on its own shapes
block_xs_m = np.linspace(0.10, 0.40, 7)
block_frames = []
for x in block_xs_m:
    m = block0.copy()
    m[0, 3] = x
    block_frames.append({"block_b.to_world": m})
block_ch = sim.measure_changes(block_frames, sim.without("block_b"), budget=ms.Budget(spp=8192, seed=4))
print("the block's dP [W/m^2], first mixel:", np.round(block_ch.dp.irradiance_w_m2[:, 0], 4))

fig, axes = plt.subplots(1, 4, figsize=(14, 3.4), constrained_layout=True)
axes[0].bar(["lamp on", "lamp = 0"], [p_on.mean(), p_off.mean()], color=["0.3", "0.7"])
axes[0].set_ylabel("P, mean of the mixels [W/m²]")
axes[0].set_title("parameters={'lamp': ...}")
for k, name in enumerate(ch.mixel_names):
    axes[1].errorbar(100 * xs_m, ch.dp.irradiance_w_m2[:, k], yerr=ch.dp.stderr_w_m2[:, k], marker="o", ms=3,
                     capsize=2, label=name)
    axes[2].errorbar(100 * shifts_m, lamp_ch.dp.irradiance_w_m2[:, k], yerr=lamp_ch.dp.stderr_w_m2[:, k],
                     marker="o", ms=3, capsize=2, label=name)
    axes[3].errorbar(100 * block_xs_m, block_ch.dp.irradiance_w_m2[:, k], yerr=block_ch.dp.stderr_w_m2[:, k],
                     marker="o", ms=3, capsize=2, label=name)
axes[1].set_xlabel("card centre x [cm]")
axes[1].set_ylabel("ΔP against the box without it [W/m²]")
axes[1].set_title("a 10 x 5 cm card slides")
axes[2].set_xlabel("lamp shift along y [cm]")
axes[2].set_ylabel("ΔP against the box as built [W/m²]")
axes[2].set_title("the lamp moves")
axes[3].set_xlabel("block x [cm]")
axes[3].set_ylabel("ΔP against the box without it [W/m²]")
axes[3].set_title("an instance slides")
for ax in axes[1:]:
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.legend(fontsize=8)
plt.show()
