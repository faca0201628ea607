"""Relight's command line: ``python -m relight_addon radiosity SCENE.blend --report R.json ...``.

Exit codes: 0 done; 2 bad input or options (ONE line on stderr, no traceback); 130
cancelled. ``main(argv)`` returns the exit code and can be called from any Python that has
bpy: the PyPI ``bpy`` module or a Blender binary (``blender -b --python-expr``); see
README.md.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

PROG = "relight"


class UsageError(ValueError):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit code 2 (argparse prints the usage too)
        raise UsageError(message)


def _positive_int(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


def _positive_length(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a positive length in metres, got {text}")
    return v


def build_parser():
    p = _Parser(prog=PROG, description="Relight: radiosity and inverse lighting on .blend scenes.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("radiosity", help="forward radiosity from the scene's own emissive materials")
    r.add_argument("scene", help="input .blend file (never modified)")
    r.add_argument("--report", required=True, help="JSON report to write")
    r.add_argument("--out", help="write a copy of the scene with the relight_radiosity colour attribute and "
                                 "Cycles light paths that render the prediction (no clamping, enough bounces)")
    r.add_argument("--rays-per-patch", type=_positive_int, default=None,
                   help="rays shot per patch for the form factors (default: the engine's)")
    r.add_argument("--max-patch-size", type=_positive_length, default=None,
                   help="largest patch edge in metres (default: the scene's relight_max_patch_size, "
                        "else the bounding-box diagonal / 20)")
    r.add_argument("--seed", type=int, default=0, help="random seed (results are reproducible)")
    r.add_argument("--threads", type=_positive_int, default=None, help="worker threads (default: all cores)")
    r.add_argument("--render", help="render the result with Cycles (CPU) to this PNG")
    r.add_argument("--render-samples", type=_positive_int, default=16, help="Cycles samples for --render")
    from .engine import options as o
    from .engine.registry import DISTRIBUTIONS, ESTIMATORS, PATCH_MODELS, SELECTIONS, SOLVERS

    for name, helptext in (("solve", "inverse lighting: lights for the painted targets, then reduction"),
                           ("reduce", "direct-lighting mode: reduce the scene's own emitters")):
        s = sub.add_parser(name, help=helptext)
        s.add_argument("scene", help="input .blend file (never modified)")
        s.add_argument("--report", required=True, help="JSON report to write")
        s.add_argument("--out", help="write a copy with the final lights as emissive materials, the "
                                     "relight_radiosity layer, the whole curve and Cycles light paths "
                                     "that render the prediction (no clamping, enough bounces)")
        s.add_argument("--rays-per-patch", type=_positive_int, default=None)
        s.add_argument("--max-patch-size", type=_positive_length, default=None)
        s.add_argument("--patch-model", choices=PATCH_MODELS.names(), default=o.DEFAULT_PATCH_MODEL,
                       help="how the scene becomes patches and candidate lights (default %(default)s)")
        s.add_argument("--light-size", type=_positive_length, default=None,
                       help="adaptive model: size of the light cells in metres (default: the patch size)")
        s.add_argument("--refine-passes", type=int, default=o.JobOptions.refine_passes,
                       help="adaptive model: importance-driven refinement passes (default %(default)s, 0 = none)")
        s.add_argument("--estimator", choices=ESTIMATORS.names(), default=o.DEFAULT_ESTIMATOR,
                       help="form-factor estimator (default %(default)s)")
        s.add_argument("--seed", type=int, default=0)
        s.add_argument("--threads", type=_positive_int, default=None)
        if name == "solve":
            s.add_argument("--solver", choices=SOLVERS.names(), default=o.DEFAULT_SOLVER)
            s.add_argument("--target-scale", type=float, default=None,
                           help="multiplies the painted target colours (default: the scene's)")
        s.add_argument("--selection", choices=SELECTIONS.names(), default=o.DEFAULT_SELECTION)
        s.add_argument("--distribution", choices=DISTRIBUTIONS.names(), default=o.DEFAULT_DISTRIBUTION)
        s.add_argument("--max-lights", type=_positive_int, default=o.DEFAULT_MAX_LIGHTS,
                       help=f"stop criterion: at most this many lights (default {o.DEFAULT_MAX_LIGHTS})")
        s.add_argument("--error-threshold", type=float, default=None,
                       help="stop criterion: relative error (Eq. 1 / ||b_P||) at most this")
        s.add_argument("--tolerance", type=float, default=None,
                       help="least-power selection: every target within +-this fraction of its painted value")
        s.add_argument("--allow-negative", action="store_true",
                       help="do not require the final configuration to be free of negative exitances")
        s.add_argument("--render", help="render the result with Cycles (CPU) to this PNG")
        s.add_argument("--render-samples", type=_positive_int, default=16)
    return p


def script_argv(argv):
    """Arguments for ``main`` from a full ``sys.argv`` (Blender's come before ``--``)."""
    argv = list(argv)
    if "--" in argv:
        return argv[argv.index("--") + 1:]
    return argv[1:]


def _write_json(path, data):
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(data, fh, indent=1, allow_nan=False)
    os.replace(tmp, path)


def _check_paths(args):
    """No output may overwrite the input file."""
    scene_path = os.path.abspath(args.scene)
    for name in ("out", "report", "render"):
        path = getattr(args, name)
        if path is not None and os.path.abspath(path) == scene_path:
            raise UsageError(f"--{name} must not be the input file {args.scene}")
    return scene_path


def _write_outputs(args, report, exp, apply, t0):
    """Apply the result to the open scene (for --out/--render), save the copy, render, and
    write the report with the export/apply/render/total timings."""
    from . import export, results

    t1 = time.perf_counter()
    if args.out or args.render:
        apply()
    if args.out:
        results.save_copy(args.out)
    timings = report["timings_s"]
    timings["export"] = exp.seconds
    timings["apply"] = time.perf_counter() - t1
    if args.render:
        t2 = time.perf_counter()
        results.render_radiosity(args.render, samples=args.render_samples)
        timings["render"] = time.perf_counter() - t2
    timings["total"] = time.perf_counter() - t0
    report["input"] = os.path.abspath(args.scene)
    _write_json(args.report, report)
    return report


def run_radiosity_command(args, progress=None, cancel=None):
    import bpy

    from . import export, jobs, light_paths, results, viewing
    from .engine.options import JobOptions

    t0 = time.perf_counter()
    _check_paths(args)
    export.open_blend(args.scene)
    exp = export.export_scene()
    options = JobOptions(rays_per_patch=args.rays_per_patch, max_patch_size=args.max_patch_size,
                         seed=args.seed, threads=args.threads)
    report, result = jobs.run_radiosity(exp.faces, options, progress=progress, cancel=cancel,
                                        **export.job_inputs(exp))
    block, warns = light_paths.assess_radiosity(bpy.context.scene, result)
    report["render_settings"] = light_paths._json(block)
    report["warnings"].extend(w for w in warns if w not in report["warnings"])
    if result.form_factors is not None and result.patches.n_patches <= viewing.MAX_PATCHES // 4:
        rad = viewing.normal_radiance(exp.faces, result.patches, result.form_factors, result.patch_radiosity,
                                      exp.face_material, exp.material_lobes, exp.polygon_counts)
        for name, rows in rad.items():
            report["objects"][name]["radiance_normal"] = rows

    def apply():
        results.write_radiosity(exp.objects, result.polygon_radiosity, result.polygon_area)
        _match_light_paths(args, report)

    return _write_outputs(args, report, exp, apply, t0)


def _add_normal_radiance(outcome, exp):
    """objects.<name>.radiance_normal: what a bake shows on the target faces (viewing.py)."""
    from . import viewing

    prob = outcome.problem
    mask = getattr(prob, "target_mask", outcome.patches.target)
    if not np.any(mask) or np.sum(mask) > viewing.MAX_PATCHES:
        return
    B = np.asarray(outcome.stored["radiosity"][outcome.final_index], dtype=np.float64)
    rad = viewing.normal_radiance(outcome.faces, outcome.patches, prob.F, B, exp.face_material, exp.material_lobes,
                                  exp.polygon_counts, mask)
    for name, rows in rad.items():
        outcome.report["objects"][name]["radiance_normal"] = rows


def _match_light_paths(args, report):
    """--out: the copy renders with light paths that show the prediction (light_paths.py)."""
    if not args.out:
        return
    import bpy

    from . import light_paths

    scene = bpy.context.scene
    block = report["render_settings"]
    changed = light_paths.match_light_paths(scene, block["max_reflectance"])
    block["written"] = {"settings": light_paths.current_settings(scene),
                        "changed": {k: list(v) for k, v in changed.items()}}


def run_solve_command(args, progress=None, cancel=None):
    from . import export, jobs, results
    from .engine.options import JobOptions

    t0 = time.perf_counter()
    _check_paths(args)
    if args.error_threshold is not None and not (args.error_threshold >= 0 and math.isfinite(args.error_threshold)):
        raise UsageError("--error-threshold must be a non-negative number")
    export.open_blend(args.scene)
    exp = export.export_scene(target_scale=getattr(args, "target_scale", None))
    options = JobOptions(rays_per_patch=args.rays_per_patch, max_patch_size=args.max_patch_size, seed=args.seed,
                         threads=args.threads, solver=getattr(args, "solver", "reduced"),
                         selection=args.selection, distribution=args.distribution, max_lights=args.max_lights,
                         error_threshold=args.error_threshold, require_positive=not args.allow_negative,
                         tolerance=args.tolerance,
                         patch_model=args.patch_model, light_size=args.light_size,
                         refine_passes=args.refine_passes, estimator=args.estimator)
    outcome = jobs.run_solve(exp.faces, options, progress=progress, cancel=cancel,
                             mode="inverse" if args.command == "solve" else "direct", **export.job_inputs(exp))

    import bpy

    from . import light_paths

    light_paths.add_to_outcome(bpy.context.scene, outcome)
    _add_normal_radiance(outcome, exp)

    def apply():
        shown = results.show_outcome(bpy.context.scene, outcome, exp.fingerprints)
        outcome.report["warnings"].extend(shown["skipped"])
        _match_light_paths(args, outcome.report)

    return _write_outputs(args, outcome.report, exp, apply, t0)


def main(argv=None) -> int:
    """Run the CLI on ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    from .engine.formfactors import Cancelled
    from .engine.scene import SceneError

    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = build_parser().parse_args(argv)
        if args.command == "radiosity":
            report = run_radiosity_command(args)
            s = report["scene"]
            print(f"{PROG}: radiosity of {s['objects']} objects, {s['faces']} faces, {s['patches']} patches "
                  f"in {report['timings_s']['total']:.2f} s; report {args.report}")
            for w in report["warnings"]:
                print(f"{PROG}: warning: {w}")
        elif args.command in ("solve", "reduce"):
            report = run_solve_command(args)
            inv, fin = report["inverse"], report["final"]
            print(f"{PROG}: {args.command}: {inv['n_targets']} target patches, {inv['n_candidates']} candidates; "
                  f"e_x relative error {inv['relative_error']:.3g} with {inv['n_negative']} negative(s); "
                  f"final {fin['n_lights']} light(s), relative error {fin['relative_error']:.3g}, "
                  f"{fin['n_negative']} negative(s); {len(report['curve'])} configurations; "
                  f"{report['timings_s']['total']:.2f} s; report {args.report}")
            for w in report["warnings"]:
                print(f"{PROG}: warning: {w}")
        return 0
    except (UsageError, SceneError, ValueError) as exc:
        print(f"{PROG}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{PROG}: error: {exc.filename or ''}: {exc.strerror or exc}".replace(": :", ":"), file=sys.stderr)
        return 2
    except Cancelled:
        print(f"{PROG}: cancelled", file=sys.stderr)
        return 130


def _one_line(exc):
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
