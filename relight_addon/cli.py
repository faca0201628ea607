"""Relight's command line: ``python -m relight_addon radiosity SCENE.blend --report R.json ...``.

Exit codes: 0 done; 2 any failure (ONE line ``relight: error: ...`` on stderr, never a
traceback; ``RELIGHT_DEBUG=1`` re-raises instead); 130 cancelled (Ctrl-C at any stage: the
job runs in a worker thread and SIGINT sets its cancel flag). ``main(argv)`` returns the exit
code and can be called from any Python that has bpy: the PyPI ``bpy`` module or a Blender
binary (``blender -b --python-expr``); see README.md.

Order of work: every output path is checked first (not the input, not each other, writable),
then the scene is exported and meshed, the estimate printed (stderr), the job run with a
progress display on stderr (lines when stderr is not a terminal, one updating line when it
is; ``--quiet`` turns both off), the result applied to the open scene, the report written,
and only then ``--out`` and ``--render`` (a failing save still leaves the report).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
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


def _seed(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= v < 2 ** 63:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer (0 to 2^63 - 1), got {v}")
    return v


def _positive_number(message):
    """An argparse type: a finite number > 0; ``message`` says what else was given ({} = the text)."""

    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not (v > 0 and math.isfinite(v)):
            raise argparse.ArgumentTypeError(message.format(text))
        return v

    return parse


_positive_length = _positive_number("must be a positive length in metres, got {}")
_target_scale = _positive_number("must be a positive number, got {} (0 asks every target for no light)")


def _non_negative_int(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {v}")
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
    r.add_argument("--seed", type=_seed, default=0, help="random seed >= 0 (results are reproducible)")
    r.add_argument("-q", "--quiet", action="store_true", help="no estimate or progress on stderr")
    r.add_argument("--threads", type=_positive_int, default=None, help="worker threads (default: all cores)")
    r.add_argument("--render", help="render the result with Cycles (CPU) to this PNG")
    r.add_argument("--render-samples", type=_positive_int, default=16, help="Cycles samples for --render")
    r.add_argument("--view-transform", choices=("AgX", "Standard", "Filmic"), default="AgX",
                   help="view transform of --render (default AgX, Blender's: it compresses the lights' "
                        "highlights; Standard shows a radiance of 1 as white)")
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
        s.add_argument("--refine-passes", type=_non_negative_int, default=o.JobOptions.refine_passes,
                       help="adaptive model: importance-driven refinement passes (default %(default)s, 0 = none)")
        s.add_argument("--estimator", choices=ESTIMATORS.names(), default=o.DEFAULT_ESTIMATOR,
                       help="form-factor estimator (default %(default)s)")
        s.add_argument("--seed", type=_seed, default=0, help="random seed >= 0")
        s.add_argument("-q", "--quiet", action="store_true", help="no estimate or progress on stderr")
        s.add_argument("--threads", type=_positive_int, default=None)
        if name == "solve":
            s.add_argument("--solver", choices=SOLVERS.names(), default=o.DEFAULT_SOLVER)
            s.add_argument("--target-scale", type=_target_scale, default=None,
                           help="multiplies the painted target colours, > 0 (default: the scene's)")
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
        s.add_argument("--view-transform", choices=("AgX", "Standard", "Filmic"), default="AgX",
                       help="view transform of --render (default AgX, Blender's)")
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
    try:
        with open(tmp, "w") as fh:
            json.dump(data, fh, indent=1, allow_nan=False)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _same_file(a, b):
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _check_writable(option, path):
    """UsageError unless ``path`` can be written: not a directory, its file (if any) writable,
    its nearest existing folder a writable directory (missing folders are made when writing)."""
    full = os.path.abspath(path)
    if os.path.isdir(full):
        raise UsageError(f"cannot write --{option} {path}: it is a directory")
    if os.path.lexists(full):
        if not os.access(full, os.W_OK):
            raise UsageError(f"cannot write --{option} {path}: permission denied")
        return
    parent = os.path.dirname(full)
    while not os.path.lexists(parent):
        up = os.path.dirname(parent)
        if up == parent:
            break
        parent = up
    if not os.path.isdir(parent):
        raise UsageError(f"cannot write --{option} {path}: {parent} is not a directory")
    try:  # the one sure test (permissions, read-only mounts, /proc): create a file there
        import tempfile

        with tempfile.NamedTemporaryFile(dir=parent, prefix=".relight-check-"):
            pass
    except OSError as exc:
        raise UsageError(f"cannot write --{option} {path}: {parent} is not writable ({exc.strerror})") from None


def _check_paths(args):
    """Before any work: no output may be the input file or another output, and every output
    must be writable."""
    scene_path = os.path.abspath(args.scene)
    outputs = [(name, getattr(args, name)) for name in ("report", "out", "render") if getattr(args, name, None)]
    for name, path in outputs:
        if _same_file(path, scene_path):
            raise UsageError(f"--{name} must not be the input file {args.scene}")
    for i, (a, pa) in enumerate(outputs):
        for b, pb in outputs[i + 1:]:
            if _same_file(pa, pb):
                raise UsageError(f"--{a} and --{b} name the same file {pa}: give them different paths")
    for name, path in outputs:
        _check_writable(name, path)
    return scene_path


# --------------------------------------------------------------------------- feedback on stderr

class Progress:
    """``progress(stage, fraction)`` on a stream: one updating line on a terminal, else a line
    per stage and per 10 % (Blender's background style: ``relight: 12.3 s | form factors 40 %``).
    Called from the worker thread; ``close()`` ends the updating line."""

    WIDTH = 24

    def __init__(self, stream=None, tty=None):
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.t0 = time.perf_counter()
        self.last = (None, -1)
        self.open = False
        self.lock = threading.Lock()

    def __call__(self, stage, fraction):
        f = min(max(float(fraction), 0.0), 1.0) if math.isfinite(float(fraction)) else 0.0
        stage = str(stage).replace("_", " ")
        with self.lock:
            t = time.perf_counter() - self.t0
            if self.tty:
                n = int(round(self.WIDTH * f))
                self.stream.write(f"\r{PROG}: [{'#' * n}{'.' * (self.WIDTH - n)}] {100 * f:3.0f} % {stage:<16}"
                                  f" {t:7.1f} s")
                self.open = True
            else:
                step = int(10 * f)
                if (stage, step) == self.last or (stage == self.last[0] and step < self.last[1]):
                    return
                self.last = (stage, step)
                self.stream.write(f"{PROG}: {t:8.1f} s | {stage} {100 * f:3.0f} %\n")
            self.stream.flush()

    def close(self):
        with self.lock:
            if self.open:
                self.stream.write("\n")
                self.stream.flush()
                self.open = False


def _say(args, text):
    if not getattr(args, "quiet", False):
        print(f"{PROG}: {text}", file=sys.stderr, flush=True)


def _print_estimate(args, patches, cost):
    from .engine.cost import format_bytes

    _say(args, f"{patches.n_patches} patches: about {format_bytes(cost['memory_bytes'])} of memory and "
               f"{cost['seconds']:.3g} s (estimate)")
    for w in cost["warnings"]:
        _say(args, f"warning: {w}")


# --------------------------------------------------------------------------- running the job

class _Worker:
    """Runs ``fn(progress, cancel)`` in a daemon thread; the main thread waits, so that Ctrl-C
    (SIGINT, delivered to the main thread) is seen at once whatever the job is doing, even in a
    long scipy factorisation: it sets the cancel flag, and the job ends at its next check or
    is left behind (daemon) when the process exits."""

    GRACE_S = 2.0
    #: the jobs still running after a cancel (left behind: see ``abandoned_jobs``)
    left = []

    def __init__(self, fn, progress):
        self.fn, self.progress = fn, progress
        self.cancel = threading.Event()
        self.result = {}

    def _run(self):
        try:
            self.result["value"] = self.fn(self.progress, self.cancel.is_set)
        except BaseException as exc:  # re-raised on the main thread
            self.result["error"] = exc

    def run(self):
        t = threading.Thread(target=self._run, name="relight-job", daemon=True)
        t.start()
        try:
            while t.is_alive():
                t.join(0.1)
        except KeyboardInterrupt:
            self.cancel.set()
            try:
                t.join(self.GRACE_S)
            except KeyboardInterrupt:
                pass
            _Worker.left.append(t)
            raise
        if "error" in self.result:
            raise self.result["error"]
        return self.result["value"]


def abandoned_jobs() -> bool:
    """True when a job was cancelled: a process that exits now should leave with ``os._exit``,
    as ``__main__`` does. The job may still run inside a long native call (interpreter shutdown
    under it can crash), or have been cut short inside one (scipy's splu, interrupted by SIGINT,
    can end its thread leaving a stray error that fails the shutdown's flush of stdout)."""
    return bool(_Worker.left)


def _job(args, fn):
    progress = None if getattr(args, "quiet", False) else Progress()
    try:
        return _Worker(fn, progress).run()
    finally:
        if progress is not None:
            progress.close()


def _save_outputs(args, report, timings, t0, apply):
    """Apply the result to the open scene (for --out/--render), write the report, then save the
    copy and render; the report is rewritten with the apply/render timings at the end. When the
    apply fails, the report is still written (then the error raised)."""
    from . import results

    t1 = time.perf_counter()
    try:
        if args.out or args.render:
            apply()
    except BaseException:
        _write_json(args.report, report)
        raise
    timings["apply"] = time.perf_counter() - t1
    timings["total"] = time.perf_counter() - t0
    _write_json(args.report, report)
    if args.out:
        try:
            results.save_copy(args.out)
        except RuntimeError as exc:
            raise OSError(f"cannot write --out {args.out}: {_blender_message(exc)}") from None
    if args.render:
        t2 = time.perf_counter()
        try:
            results.render_radiosity(args.render, samples=args.render_samples, view_transform=args.view_transform)
        except RuntimeError as exc:
            raise OSError(f"cannot render --render {args.render}: {_blender_message(exc)}") from None
        timings["render"] = time.perf_counter() - t2
    timings["total"] = time.perf_counter() - t0
    _write_json(args.report, report)
    return report


def _blender_message(exc):
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    text = lines[-1] if lines else type(exc).__name__
    return text[len("Error: "):] if text.startswith("Error: ") else text


def run_radiosity_command(args, progress=None, cancel=None):
    import bpy

    from . import export, jobs, light_paths, results, viewing
    from .engine.options import JobOptions

    t0 = time.perf_counter()
    _check_paths(args)
    export.open_blend(args.scene)
    exp = export.export_scene()
    options = JobOptions(rays_per_patch=args.rays_per_patch, max_patch_size=args.max_patch_size,
                         seed=args.seed, threads=args.threads).validate()
    inputs = export.job_inputs(exp)

    def mesh(progress, cancel):
        patches = jobs.mesh_for_job(exp.faces, options, inputs["default_max_patch_size"], mode="direct")
        return patches, jobs.radiosity_cost(patches, options)

    patches, cost = _job(args, mesh)
    _print_estimate(args, patches, cost)
    report, result = _job(args, lambda progress, cancel: jobs.run_radiosity(
        exp.faces, options, progress=progress, cancel=cancel, patches=patches, **inputs))
    report["timings_s"]["export"] = exp.seconds
    report["input"] = os.path.abspath(args.scene)
    block, warns = light_paths.assess_radiosity(bpy.context.scene, result)
    report["render_settings"] = light_paths._json(block)
    report["warnings"].extend(w for w in warns if w not in report["warnings"])
    if result.form_factors is not None and result.patches.n_patches <= viewing.MAX_PATCHES // 4:
        rad = viewing.normal_radiance(exp.faces, result.patches, result.form_factors, result.patch_radiosity,
                                      exp.face_material, exp.material_lobes, inputs["polygon_counts"],
                                      exitance=result.patches.exitance)
        for name, rows in rad.items():
            if name in report["objects"]:  # the reported objects (instance groups are not)
                report["objects"][name]["radiance_normal"] = rows

    def apply():
        results.write_radiosity(exp.objects, result.polygon_radiosity, result.polygon_area, report["warnings"])
        _match_light_paths(args, report)

    return _save_outputs(args, report, report["timings_s"], t0, apply)


def _add_normal_radiance(outcome, exp):
    """objects.<name>.radiance_normal: what a bake shows on the target faces (viewing.py)."""
    from . import export, viewing

    prob = outcome.problem
    mask = getattr(prob, "target_mask", outcome.patches.target)
    if not np.any(mask) or np.sum(mask) > viewing.MAX_PATCHES:
        return
    B = np.asarray(outcome.stored["radiosity"][outcome.final_index], dtype=np.float64)
    e = prob.patch_exitance(outcome.stored["exitance"][outcome.final_index])
    if outcome.report.get("command") == "solve":
        e = e + outcome.patches.exitance  # the scene's own emitters (fixed background)
    rad = viewing.normal_radiance(outcome.faces, outcome.patches, prob.F, B, exp.face_material, exp.material_lobes,
                                  export.job_inputs(exp)["polygon_counts"], mask, exitance=e)
    for name, rows in rad.items():
        if name in outcome.report["objects"]:  # the reported objects (instance groups are not)
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
                         refine_passes=args.refine_passes, estimator=args.estimator).validate()
    mode = "inverse" if args.command == "solve" else "direct"
    inputs = export.job_inputs(exp)
    jobs.check_solvable(exp.faces, mode, exp.notes)

    def mesh(progress, cancel):
        patches = jobs.mesh_for_job(exp.faces, options, inputs["default_max_patch_size"], mode=mode)
        return patches, jobs.solve_cost(patches, options, mode=mode)

    patches, cost = _job(args, mesh)
    _print_estimate(args, patches, cost)
    outcome = _job(args, lambda progress, cancel: jobs.run_solve(
        exp.faces, options, progress=progress, cancel=cancel, mode=mode, patches=patches, **inputs))
    report = outcome.report
    report["timings_s"]["export"] = exp.seconds
    report["input"] = os.path.abspath(args.scene)

    import bpy

    from . import light_paths

    light_paths.add_to_outcome(bpy.context.scene, outcome)
    _add_normal_radiance(outcome, exp)

    def apply():
        shown = results.show_outcome(bpy.context.scene, outcome, exp.fingerprints)
        report["warnings"].extend(w for w in shown["skipped"] if w not in report["warnings"])
        _match_light_paths(args, report)

    return _save_outputs(args, report, report["timings_s"], t0, apply)


def _summary(args, report):
    if args.command == "radiosity":
        s = report["scene"]
        print(f"{PROG}: radiosity of {s['objects']} objects, {s['faces']} faces, {s['patches']} patches "
              f"in {report['timings_s']['total']:.2f} s; report {args.report}")
    else:
        inv, fin = report["inverse"], report["final"]
        print(f"{PROG}: {args.command}: {inv['n_targets']} target patches, {inv['n_candidates']} candidates; "
              f"e_x relative error {inv['relative_error']:.3g} with {inv['n_negative']} negative(s); "
              f"final {fin['n_lights']} light(s), relative error {fin['relative_error']:.3g}, "
              f"{fin['n_negative']} negative(s); {len(report['curve'])} configurations; "
              f"{report['timings_s']['total']:.2f} s; report {args.report}")
    for w in report["warnings"]:
        print(f"{PROG}: warning: {w}")


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def main(argv=None) -> int:
    """Run the CLI on ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    from .engine.sampling import Cancelled

    argv = sys.argv[1:] if argv is None else list(argv)
    restore = None
    if threading.current_thread() is threading.main_thread():
        try:  # Ctrl-C raises KeyboardInterrupt here (unless the shell made SIGINT ignored)
            previous = signal.getsignal(signal.SIGINT)
            if previous is not signal.SIG_IGN:
                signal.signal(signal.SIGINT, _interrupt)
                restore = previous
        except (ValueError, OSError):
            pass
    try:
        args = build_parser().parse_args(argv)
        if args.command == "radiosity":
            report = run_radiosity_command(args)
        else:
            report = run_solve_command(args)
        _summary(args, report)
        return 0
    except (KeyboardInterrupt, Cancelled):
        print(f"\n{PROG}: cancelled" if sys.stderr.isatty() else f"{PROG}: cancelled", file=sys.stderr)
        return 130
    except BaseException as exc:  # every failure: one line, exit 2
        if isinstance(exc, SystemExit) or os.environ.get("RELIGHT_DEBUG"):
            raise
        print(f"{PROG}: error: {error_line(exc)}", file=sys.stderr)
        return 2
    finally:
        if restore is not None:
            signal.signal(signal.SIGINT, restore)


def error_line(exc) -> str:
    """The one line a failure prints (after ``relight: error: ``)."""
    from .engine.scene import SceneError

    if isinstance(exc, (UsageError, SceneError)):
        return _one_line(exc)
    if isinstance(exc, MemoryError):
        return ("out of memory: " + _one_line(exc) if str(exc) else "out of memory") + \
            "; use a larger patch size (--max-patch-size) or fewer rays per patch"
    if isinstance(exc, OSError):
        if exc.filename:
            return f"{exc.filename}: {exc.strerror or _one_line(exc)}"
        return _one_line(exc)
    if isinstance(exc, ValueError):
        return _one_line(exc)
    return f"unexpected {type(exc).__name__}: {_one_line(exc)} (please report it; RELIGHT_DEBUG=1 shows the traceback)"


def _one_line(exc):
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
