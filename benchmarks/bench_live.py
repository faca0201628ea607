"""Live mode (issue 20): a stroke of about a dozen faces, through the add-on's Live session in one
bpy process (blender/live.py, ticked as the modal operator's timer ticks it), against a cold solve
of the same painted scene, one run each; then Solve & Reduce (the operator's export, meshing,
solve and write) once Live's later answers to the last stroke are in, against that cold solve.

Per scene: Live's first answer (a full solve through the session: the preparation), the transfer
to every patch (InverseProblem.all_rows_transfer, made at the first stroke) and what the session
keeps, then three strokes of 12 unpainted faces next to the painted ones: each stroke's re-solve in
the worker (PreparedScene.live: the selection, the certificate, the curve, the report), the write
on the main thread (the lights, the radiosity layer, the chart: operators.show_solve), the final
relative error, the main thread's longest tick while the stroke was read, solved and written (the
depsgraph update and Live's tick: what the brush would wait for), the process's memory, the time
from the stroke (its depsgraph update) to the answer written, ticked every live.TICK as the timer
ticks (Live reads the paint QUIET seconds after the last update), each stroke painted as soon as the
answer before is written; then a fourth stroke once the later answer to the third has run for
LATER_AFTER seconds (it is cancelled: what a stroke during a later answer waits); and a cold solve
(jobs.run_solve) of the last stroke's painted scene with its error and stages; then Live's first
answer against a cold solve (the export and jobs.run_solve) of the same, first, paint.

    .venv/bin/python benchmarks/bench_live.py [--only NAME]

Writes benchmarks/results/bench_live.json and prints a table (docs/benchmarks.md).
"""
import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))
OUT = os.path.join(ROOT, "benchmarks", "results", "bench_live.json")

import bpy  # noqa: E402

import artist_scenes  # noqa: E402
import relight_addon  # noqa: E402
from relight_addon.blender import export, live, preparation  # noqa: E402
from relight_addon.blender.ui import operators  # noqa: E402
from relight_addon.engine import by_content  # noqa: E402
from relight_addon.pipeline import jobs, prepared  # noqa: E402

#: (name, living_room detail or a sample, paint object, patch model)
CASES = [("living room 22k", 2, "Floor", "adaptive"), ("living room 1M", 5, "Floor", "adaptive"),
         ("staircase", "staircase_targets.blend", "flight_1", "polygon")]


def nbytes(x, seen=None) -> int:
    """Bytes of the numpy arrays and sparse matrices reachable from ``x`` (each counted once)."""
    seen = set() if seen is None else seen
    if id(x) in seen:
        return 0
    seen.add(id(x))
    if isinstance(x, np.ndarray):
        return x.nbytes
    if hasattr(x, "data") and hasattr(x, "indices") and hasattr(x, "indptr"):
        return x.data.nbytes + x.indices.nbytes + x.indptr.nbytes
    if isinstance(x, (list, tuple)):
        return sum(nbytes(v, seen) for v in x)
    if isinstance(x, dict):
        return sum(nbytes(v, seen) for v in x.values())
    if hasattr(x, "lu") and isinstance(getattr(x, "lu"), tuple):  # a dense LU factor
        return sum(nbytes(v, seen) for v in x.lu)
    if hasattr(x, "__dict__") and type(x).__module__.startswith(("relight_addon",)):
        return sum(nbytes(v, seen) for v in vars(x).values())
    return 0


#: the longest main-thread tick (the depsgraph update and Live's tick) since the last stroke, s
TICKS = []
#: seconds a later answer (live.LATER_PAUSE after a quick answer) has run when the last stroke comes
LATER_AFTER = 0.5


def rss_gb() -> float:
    """The process's resident memory, GB (Linux)."""
    return int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**30


def run(s, until, timeout=1800):
    t0 = time.monotonic()
    while not until():
        if time.monotonic() - t0 > timeout or s.paused:
            raise RuntimeError(f"Live did not answer: {s.status} {s.paused}")
        t = time.perf_counter()
        bpy.context.view_layer.update()
        s.tick(bpy.context)
        TICKS.append(time.perf_counter() - t)
        time.sleep(live.TICK)  # (the modal operator's timer)


def stroke_faces(ob, n, k):
    """The k-th dozen of the object's unpainted polygons nearest its painted ones (as a brush extends paint)."""
    me = ob.data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    me.color_attributes["relight_target"].data.foreach_get("color", col.ravel())
    starts = np.zeros(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_start", starts)
    painted = col[starts, 3] >= 0.5
    cen = np.zeros(3 * len(me.polygons))
    me.polygons.foreach_get("center", cen)
    cen = cen.reshape(-1, 3)
    hub = cen[painted].mean(axis=0)
    free = np.flatnonzero(~painted)
    free = free[np.argsort(np.linalg.norm(cen[free] - hub, axis=1))]
    return free[:n].tolist(), tuple(col[starts[np.flatnonzero(painted)[0]], :3])


def open_case(source, model):
    """A fresh session with ``source``: the living room of that detail (an int) or a shipped sample;
    the add-on's patch model set to ``model``. Returns the scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if isinstance(source, int):
        artist_scenes.living_room(source)
    else:
        bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "sample_blends", source))
    scene = bpy.context.scene
    scene.relight.patch_model = model
    return scene


def case(name, source, paint_on, model):
    scene = open_case(source, model)
    preparation.PREPARED.clear()
    by_content.forget()  # (Live's first answer: nothing kept from the cases before)
    s = live.start(bpy.context, operators.job_options, operators.show_solve)
    t0 = time.perf_counter()
    run(s, lambda: s.updates == 1)
    t_first = time.perf_counter() - t0
    first_error = float(scene.relight.curve[scene.relight.curve_index].relative_error)
    run(s, lambda: s.prewarm_seconds is not None and s.worker is None)  # the transfer to every patch
    state = preparation.PREPARED[scene.name]
    job = preparation.PREPARED_JOBS[scene.name]
    first_faces = job.exp.faces  # (the first answer's paint)
    t_rows = s.prewarm_seconds
    ob = bpy.data.objects[paint_on]
    strokes = []
    for k in range(4):
        faces, rgb = stroke_faces(ob, 12, k)
        if k == 3:  # the last stroke once the later answer to the one before has run for LATER_AFTER s
            run(s, lambda: s.worker is not None and "refining" in s.result)
            t_later = time.monotonic()
            run(s, lambda: time.monotonic() - t_later >= LATER_AFTER)
        artist_scenes.paint(ob, faces, rgb)
        n = s.updates
        TICKS.clear()
        t0 = time.perf_counter()
        run(s, lambda: s.updates == n + 1)
        latency = time.perf_counter() - t0
        rep = export.repaint(job.exp)
        strokes.append({"solve_s": s.last_seconds[0], "write_s": s.last_seconds[1], "latency_s": latency,
                        "from_state": state.reason is None, "live": state.live_solves,
                        "error": float(bpy.context.scene.relight.curve[
                            bpy.context.scene.relight.curve_index].relative_error),
                        "targets": int(rep.target.sum()), "longest_tick_s": max(TICKS),
                        "rss_gb": rss_gb(), "during_later": k == 3})
        print(name, "stroke", k, strokes[-1], flush=True)
    # Solve & Reduce once Live's later answers to the last stroke are in (issue 37: <= 1/5 of a cold
    # solve of the same paint): the operator's export, meshing (its cost estimate), solve and write
    run(s, lambda: s.worker is None and s.to_refine is None)
    t0 = time.perf_counter()
    button = preparation.SolveJob.export(bpy.context, operators.job_options(scene.relight), session=True)
    button.mesh()
    answer = button.run()
    operators.show_solve(bpy.context, button, answer)
    t_button = time.perf_counter() - t0
    print(name, "the button after the later answers", {"s": t_button, "taken": answer.report["prepared"].get("taken"),
                                                        "error": answer.report["final"]["relative_error"]}, flush=True)
    live.stop(scene.name)
    faces = export.repaint(job.exp)
    options = job.options
    t0 = time.perf_counter()
    cold = jobs.run_solve(faces, options, **job.inputs)
    t_cold = time.perf_counter() - t0
    print(name, "cold solve", {"patches": int(cold.patches.n_patches), "timings_s": cold.report["timings_s"],
                               "rss_gb": rss_gb()}, flush=True)
    # Live's first answer against a cold solve of the same paint (issue 37: <= 1.1 x): the export
    # (of the scene as it is now: the same objects and modifiers) and the solve, one after the other
    by_content.forget()  # (cold: the export's ray checks cast again, as in a new session)
    t0 = time.perf_counter()
    export.export_scene()
    t_export = time.perf_counter() - t0
    t0 = time.perf_counter()
    cold_first = jobs.run_solve(first_faces, options, **job.inputs)
    t_cold_first = t_export + time.perf_counter() - t0
    print(name, "cold solve of the first paint", {"export_s": t_export, "total_s": t_cold_first,
                                                   "timings_s": cold_first.report["timings_s"]}, flush=True)
    kept = nbytes([state.model, state.form_factors, state.kernel_rows, state._products])  # (each array once)
    row = {"scene": name, "model": model, "triangles": int(len(job.exp.faces.triangles)),
           "patches": int(state.patches.n_patches), "lights": int(state.model.problem.n_lights),
           "first_s": t_first, "all_rows_s": t_rows, "kept_bytes": int(kept), "strokes": strokes,
           "cold_s": t_cold, "cold_error": float(cold.report["final"]["relative_error"]),
           "first_error": first_error, "cold_first_s": t_cold_first,
           "cold_first_error": float(cold_first.report["final"]["relative_error"]),
           "button_s": t_button, "button_error": float(answer.report["final"]["relative_error"]),
           "button_taken": bool(answer.report["prepared"].get("taken"))}
    print(json.dumps(row), flush=True)
    return row


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", action="append", help="run only the cases of these names (the others' rows are kept)")
    args = ap.parse_args()
    relight_addon.register()
    rows = []
    if args.only and os.path.exists(OUT):
        rows = [r for r in json.load(open(OUT))["rows"] if r["scene"] not in args.only]
    for name, source, on, model in CASES:
        if args.only and name not in args.only:
            continue
        rows.append(case(name, source, on, model))
    order = [c[0] for c in CASES]
    rows.sort(key=lambda r: order.index(r["scene"]))
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as fh:
        json.dump({"command": "benchmarks/bench_live.py", "load": os.getloadavg(), "rows": rows}, fh, indent=1)
    print("| scene | triangles | patches | lights | preparation (first answer) | transfer to every patch | kept "
          "| stroke: solve / write | stroke to answer written | error live / cold | cold solve |")
    for r in rows:
        st = [x for x in r["strokes"] if not x.get("during_later")]
        print(f"| {r['scene']}, {r['model']} | {r['triangles']:,} | {r['patches']:,} | {r['lights']} | "
              f"{r['first_s']:.1f} s | {r['all_rows_s']:.2f} s | {r['kept_bytes'] / 2**20:.0f} MB | "
              + ", ".join(f"{1000 * x['solve_s']:.0f} / {1000 * x['write_s']:.0f} ms" for x in st) + " | "
              + ", ".join(f"{1000 * x['latency_s']:.0f} ms" if "latency_s" in x else "-" for x in st)
              + f" | {r['strokes'][-1]['error']:.4f} / {r['cold_error']:.4f} | {r['cold_s']:.1f} s |")
    print("\n| scene | a stroke during a later answer: solve / write | stroke to answer written | main thread's longest tick |")
    for r in rows:
        for x in r["strokes"]:
            if x.get("during_later"):
                print(f"| {r['scene']} | {1000 * x['solve_s']:.0f} / {1000 * x['write_s']:.0f} ms | "
                      f"{1000 * x['latency_s']:.0f} ms | {1000 * x['longest_tick_s']:.0f} ms |")
    print("\n| scene | Live's first answer | a cold solve of the same paint (export + solve) | ratio | error first / cold |")
    for r in rows:
        if "cold_first_s" in r:
            print(f"| {r['scene']} | {r['first_s']:.1f} s | {r['cold_first_s']:.1f} s | "
                  f"{r['first_s'] / r['cold_first_s']:.2f} | {r['first_error']:.4f} / {r['cold_first_error']:.4f} |")
    print("\n| scene | Solve & Reduce after the last stroke's later answers | a cold solve of that paint | ratio "
          "| error button / cold | the warm solve's answer taken |")
    for r in rows:
        if "button_s" in r:
            print(f"| {r['scene']} | {r['button_s']:.2f} s | {r['cold_s']:.1f} s | {r['button_s'] / r['cold_s']:.3f} | "
                  f"{r['button_error']:.4f} / {r['cold_error']:.4f} | {r['button_taken']} |")


if __name__ == "__main__":
    main()
