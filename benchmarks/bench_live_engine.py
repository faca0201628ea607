"""Live's re-solve on the 1M-triangle living room, engine only (no Live session, no bpy writes):
the first solve through a PreparedScene, the transfer to every patch, then three live re-solves of
one 12-face stroke (PreparedScene.live), with the process's memory after each.

    .venv/bin/python benchmarks/bench_live_engine.py [DETAIL]   # living_room(DETAIL), default 5 (1M)

Prints one line per step (docs/benchmarks.md, "Live").
"""
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:0] = [ROOT, os.path.join(ROOT, "tests"), os.path.join(ROOT, "benchmarks")]

import bpy  # noqa: E402

import artist_scenes  # noqa: E402
import bench_prepared  # noqa: E402
from relight_addon.blender import export  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.pipeline import prepared  # noqa: E402


def rss_gb():
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**30


def main():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    artist_scenes.living_room(int(sys.argv[1]) if len(sys.argv) > 1 else 5)
    exp = export.export_scene()
    print(f"export: {len(exp.faces.triangles):,} triangles, {rss_gb():.2f} GB", flush=True)
    options = JobOptions(patch_model="adaptive").validate()
    state = prepared.PreparedScene.prepare(exp.faces, options, exp.settings.get("max_patch_size"))
    t = time.perf_counter()
    state.solve(exp.faces)
    print(f"first solve: {time.perf_counter() - t:.1f} s, {state.patches.n_patches} patches, {rss_gb():.2f} GB",
          flush=True)
    t = time.perf_counter()
    state.prepare_live(exp.faces)
    print(f"prepare_live: {time.perf_counter() - t:.2f} s, {rss_gb():.2f} GB", flush=True)
    faces, _ = bench_prepared.stroke(exp.faces, state.patches)
    for i in range(3):
        t = time.perf_counter()
        out = state.live(faces, key=state.key)  # (as Live calls it: the main thread checked the scene)
        print(f"live {i}: {time.perf_counter() - t:.3f} s, error {out.report['final']['relative_error']:.4f}, "
              f"{rss_gb():.2f} GB", flush=True)


if __name__ == "__main__":
    main()
