"""Figures of the README: the paper's staircase, painted, solved and reduced, rendered by Cycles.

    .venv/bin/python docs/make_figures.py        # writes docs/img/*.png

1. targets.png   - the painted targets (radiance), everything else black;
2. e_x.png       - radiosity of the full inverse solution e_x (hundreds of lights, some negative);
3. reduced_paper.png - radiosity of the paper's reduction to 3 lights (ExitanceElimination +
                   DistanceDistribute, the paper's patch per polygon);
4. reduced.png   - radiosity of the default: Best k Lights, 3 lights (adaptive model, kernel estimator);
5. reduced_cycles.png - Cycles path tracing of that result, its emitters object the only light;
6. curve.png     - both error curves and the certificate (the best any k non-negative lights can do).
"""
import os
import sys

import bpy
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from relight_addon.blender import blend_files, export, results
from relight_addon.pipeline import jobs  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402

IMG = os.path.join(ROOT, "docs", "img")
os.makedirs(IMG, exist_ok=True)
SAMPLES = 32
VIEW = "AgX"  # compresses the lights' highlights (the add-on's own renders use Standard: radiance 1 = white)

blend_files.open_blend(os.path.join(ROOT, "sample_blends", "staircase_targets.blend"))
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
paper = jobs.run_solve(exp.faces, JobOptions(seed=0, patch_model="polygon", selection="exitance-elimination"),
                       **export.job_inputs(exp))

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
results.render_radiosity(os.path.join(IMG, "targets.png"), samples=SAMPLES, attribute="relight_target_view", view_transform=VIEW)
for ob in exp.objects:
    ob.data.color_attributes.remove(ob.data.color_attributes["relight_target_view"])

# 2, 3: the paper's run: radiosity of e_x (its row 0) and of its final configuration
results.show_outcome(scene, paper, exp.fingerprints)
paper_data = results.load_result(scene)
results.apply_stored_point(scene, 0)
results.render_radiosity(os.path.join(IMG, "e_x.png"), samples=SAMPLES, view_transform=VIEW)
results.apply_stored_point(scene, paper.final_index)
results.render_radiosity(os.path.join(IMG, "reduced_paper.png"), samples=SAMPLES, view_transform=VIEW)
# 4: the default's final configuration
results.show_outcome(scene, outcome, exp.fingerprints)
results.render_radiosity(os.path.join(IMG, "reduced.png"), samples=SAMPLES, view_transform=VIEW)

# 5. Cycles path tracing with the emitters object as the only light
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 64
scene.cycles.use_denoising = False
world = bpy.data.worlds.new("black")
world.color = (0, 0, 0)
scene.world = world
scene.view_settings.view_transform = VIEW
scene.render.image_settings.file_format = "PNG"
scene.render.filepath = os.path.join(IMG, "reduced_cycles.png")
bpy.ops.render.render(write_still=True)

# 6. the error curves and the certificate
data = results.load_result(scene)
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, ax = plt.subplots(figsize=(6, 3.2), dpi=110)
for d, label, colour in ((paper_data, "the paper: ExitanceElimination + Distance", "tab:blue"),
                         (data, "default: Best k Lights", "tab:green")):
    n, err, neg = d["curve_n_lights"], d["curve_relative_error"], d["curve_n_negative"]
    o = np.argsort(n)
    ax.plot(n[o], np.maximum(err[o], 1e-16), color=colour, lw=1.2, label=label)
    ax.scatter(n[neg > 0], np.maximum(err[neg > 0], 1e-16), s=4, color="tab:orange")
    fi = int(d["final"])
    ax.scatter([n[fi]], [err[fi]], s=40, color="gold", edgecolor="k", zorder=5)
b = data.curve_bound_relative_error
n = data.curve_n_lights
o = np.argsort(n)
ax.plot(n[o], np.maximum(b[o], 1e-16), color="k", lw=0.8, ls="--", label="certificate: no k non-negative lights below")
ax.set_xscale("log")
ax.set_yscale("log")
ax.set_xlim(0.8, 800)
ax.set_xlabel("number of lights")
ax.set_ylabel("relative error  ||b_P - b_g|| / ||b_P||")
ax.set_title("Staircase: error curves (orange: negative lights; gold: the final 3)")
ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(os.path.join(IMG, "curve.png"))
print("figures written to", IMG)
