"""Figures of the README: the paper's staircase, painted, solved and reduced, rendered by Cycles.

    .venv/bin/python docs/make_figures.py        # writes docs/img/*.png

1. targets.png   - the painted targets (radiance), everything else black;
2. e_x.png       - radiosity of the full inverse solution e_x (hundreds of lights, some negative);
3. reduced.png   - radiosity of the final configuration (ExitanceElimination + DistanceDistribute);
4. reduced_cycles.png - Cycles path tracing of the --out scene, its emissive faces the only light;
5. curve.png     - the error curve, the chart the add-on shows.
"""
import os
import sys

import bpy
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from relight_addon import export, jobs, results  # noqa: E402
from relight_addon.curve_store import error_chart  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402

IMG = os.path.join(ROOT, "docs", "img")
os.makedirs(IMG, exist_ok=True)
SAMPLES = 32

export.open_blend(os.path.join(ROOT, "sample_blends", "staircase_targets.blend"))
scene = bpy.context.scene
# a figure camera (the file's own looks up the stairwell): from the first landing's corner,
# down onto the painted ground floor and the first steps
from mathutils import Vector  # noqa: E402

cam = scene.camera
cam.location = Vector((3.6, 5.2, 2.4))
cam.rotation_mode = "QUATERNION"
cam.rotation_quaternion = (Vector((1.4, 0.6, 0.2)) - cam.location).to_track_quat("-Z", "Y")
cam.data.lens = 18
scene.render.resolution_x, scene.render.resolution_y = 360, 270
exp = export.export_scene()
outcome = jobs.run_solve(exp.faces, JobOptions(seed=0), **export.job_inputs(exp))

# 1. targets: relight_target RGB where painted, black elsewhere, into a temporary layer
for ob in exp.objects:
    me = ob.data
    n = len(me.loops)
    col = np.zeros(4 * n, dtype=np.float32)
    if "relight_target" in me.color_attributes:
        me.color_attributes["relight_target"].data.foreach_get("color", col)
    col = col.reshape(-1, 4)
    col[:, :3] *= (col[:, 3:] >= 0.5)
    col[:, 3] = 1.0
    tmp = me.color_attributes.new("relight_target_view", "FLOAT_COLOR", "CORNER")
    tmp.data.foreach_set("color", col.ravel())
results.render_radiosity(os.path.join(IMG, "targets.png"), samples=SAMPLES, attribute="relight_target_view")
for ob in exp.objects:
    ob.data.color_attributes.remove(ob.data.color_attributes["relight_target_view"])

# 2, 3: radiosity of e_x (row 0) and of the final configuration
results.show_outcome(scene, outcome, exp.fingerprints)
results.apply_stored_point(scene, 0)
results.render_radiosity(os.path.join(IMG, "e_x.png"), samples=SAMPLES)
results.apply_stored_point(scene, outcome.final_index)
results.render_radiosity(os.path.join(IMG, "reduced.png"), samples=SAMPLES)

# 4. Cycles path tracing with the emissive faces as the only light
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 64
scene.cycles.use_denoising = False
world = bpy.data.worlds.new("black")
world.color = (0, 0, 0)
scene.world = world
scene.view_settings.view_transform = "Standard"
scene.render.image_settings.file_format = "PNG"
scene.render.filepath = os.path.join(IMG, "reduced_cycles.png")
bpy.ops.render.render(write_still=True)

# 5. the error curve
data = results.load_result(scene)
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, ax = plt.subplots(figsize=(6, 3.2), dpi=110)
n, err, neg = data["curve_n_lights"], data["curve_relative_error"], data["curve_n_negative"]
ax.plot(n, np.maximum(err, 1e-16), color="tab:blue", lw=1.2, label="ExitanceElimination + Distance")
ax.scatter(n[neg > 0], np.maximum(err[neg > 0], 1e-16), s=4, color="tab:orange", label="has negative lights")
fi = int(data["final"])
ax.scatter([n[fi]], [err[fi]], s=40, color="gold", edgecolor="k", zorder=5, label=f"final: {n[fi]} light(s)")
ax.set_xscale("log")
ax.set_yscale("log")
ax.set_xlabel("number of lights")
ax.set_ylabel("relative error  ||b_P - b_g|| / ||b_P||")
ax.set_title("Staircase: error curve (paper Fig. 11)")
ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(os.path.join(IMG, "curve.png"))
print("figures written to", IMG)
