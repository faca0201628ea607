"""Live with a camera-view target (issues 37 and 40): the living room of bench_view_target.py (its
surface paint and a 480 x 270 OpenEXR asking 0.1 W m^-2 sr^-1 of every pixel, loaded as the view
target), prepared as Live prepares it (PreparedScene: a solve, then prepare_live), then a stroke's
re-solve (PreparedScene.live, in this thread) for strokes of 12 floor faces, with the view target
used and without, and for the view target painted anew (``repaints``: a dab brighter, the dab
erased, the top half freed: each another ViewSpec);
each stroke's seconds and final relative error, and a cold solve (jobs.run_solve) of the last
paint with its error.

    .venv/bin/python benchmarks/bench_live_view.py [--out DIR]
"""
import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests"), os.path.join(ROOT, "benchmarks")]

import bpy  # noqa: E402

import bench_view_target  # noqa: E402
import relight_addon  # noqa: E402
from relight_addon.blender import export  # noqa: E402
from relight_addon.blender.camera_view import read_view_target  # noqa: E402
from relight_addon.blender.ui import operators  # noqa: E402
from relight_addon.engine.targets.view import ViewSpec  # noqa: E402
from relight_addon.pipeline import jobs, prepared  # noqa: E402


def strokes(faces, n=3):
    """Paint of ``faces`` with 12 more floor faces at a time (the painted faces' mean radiosity)."""
    floor = np.flatnonzero((faces.face_object == list(faces.object_names).index("Floor")) & ~faces.target)
    for k in range(n):
        tgt, rad = faces.target.copy(), faces.target_radiosity.copy()
        idx = floor[[25 * k + j for j in range(12)]]
        tgt[idx] = True
        rad[idx] = rad[faces.target].mean(axis=0)
        yield replace(faces, target=tgt, target_radiosity=rad)


def repaints(view, radius=24):
    """(what, ViewSpec) of the view target painted anew, one after the other (Live's strokes in the
    Image Editor): a dab of ``radius`` pixels twice as bright, then the same dab erased (its pixels
    free), then the top half freed."""
    H, W = view.painted.shape
    r, c = np.mgrid[:H, :W]
    dab = (r - H // 2) ** 2 + (c - W // 3) ** 2 <= radius ** 2
    radiance = view.radiance.copy()
    radiance[dab] *= 2.0
    yield "view target, a dab twice as bright", ViewSpec(view.camera, radiance, view.painted, view.name)
    painted = view.painted & ~dab
    yield "view target, the dab erased", ViewSpec(view.camera, radiance, painted, view.name)
    painted = painted.copy()
    painted[: H // 2] = False
    yield "view target, its top half freed", ViewSpec(view.camera, radiance, painted, view.name)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    folder = args.out or tempfile.mkdtemp(prefix="bench_live_view_")
    os.makedirs(folder, exist_ok=True)
    surface, _, image = bench_view_target.build(folder)
    relight_addon.register()
    bpy.ops.wm.open_mainfile(filepath=surface)
    scene = bpy.context.scene
    view = read_view_target(scene, image)
    exp = export.export_scene()
    inputs = export.job_inputs(exp)
    options = operators.job_options(scene.relight).validate()
    print("uptime:", os.popen("uptime").read().strip())
    for use_view in (False, True):
        faces = replace(exp.faces, view_target=view if use_view else None)
        st = prepared.PreparedScene.prepare(faces, options, inputs["default_max_patch_size"])
        t0 = time.perf_counter()
        st.solve(faces, inputs["polygon_counts"])
        t1 = time.perf_counter()
        st.prepare_live(faces)
        t2 = time.perf_counter()
        rows = []
        last = None
        for f in strokes(faces):
            t = time.perf_counter()
            out = st.live(f, inputs["polygon_counts"])
            rows.append((time.perf_counter() - t, out.reduction.final.relative_error, "floor"))
            last = f
        if use_view:  # the view target painted anew: a dab brighter, a dab erased, its top half freed
            for what, spec in repaints(view):
                last = replace(last, view_target=spec)
                t = time.perf_counter()
                out = st.live(last, inputs["polygon_counts"])
                rows.append((time.perf_counter() - t, out.reduction.final.relative_error, what))
            last = next(strokes(last, 1))
            t = time.perf_counter()
            out = st.live(last, inputs["polygon_counts"])
            rows.append((time.perf_counter() - t, out.reduction.final.relative_error,
                         "floor again, the new view target kept"))
        print(f"view target {'used' if use_view else 'none'}: solve {t1 - t0:.1f} s, prepare_live {t2 - t1:.1f} s")
        for s, err, what in rows:
            print(f"  stroke on the {what}: {1e3 * s:.0f} ms, relative error {err:.4f}")
        t = time.perf_counter()
        cold = jobs.run_solve(last, options, inputs["polygon_counts"], inputs["default_max_patch_size"])
        print(f"  cold solve of the last paint: {time.perf_counter() - t:.1f} s, relative error "
              f"{cold.reduction.final.relative_error:.4f}")
    print("uptime:", os.popen("uptime").read().strip())


if __name__ == "__main__":
    main()
