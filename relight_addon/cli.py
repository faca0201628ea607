"""Relight's command line: ``python -m relight_addon radiosity SCENE.blend --report R.json ...``.

Exit codes: 0 done; 2 any failure (ONE line ``relight: error: ...`` on stderr, never a
traceback; ``RELIGHT_DEBUG=1`` re-raises instead); 130 cancelled (Ctrl-C at any stage: the
job runs in a worker thread and SIGINT sets its cancel flag), 143 for SIGTERM. Every output is
written whole or not at all (a temporary beside it, then a rename), and a cancel says which were. ``main(argv)`` returns the exit
code and can be called from any Python that has bpy: the PyPI ``bpy`` module or a Blender
binary (``blender -b --python-expr``); see README.md.

Order of work: every output path is checked first (not the input, not each other, writable, a
regular file or nothing), then the scene is opened and no output may be a file it reads (its
libraries, images, ...), then it is exported and meshed, the estimate printed (stderr), the job run with a
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


def _target_scale(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text} (0 asks every target for no light)")
    return v


def _param_type(param):
    """An argparse ``type`` from an option's declaration (engine/options.py, engine/registry.py)."""

    def parse(text):
        try:
            return param.parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = param.type.__name__  # argparse's "invalid <name> value"
    return parse


def _add_option(parser, param, users=()):
    """The flag of one declared option (``users``: the methods whose parameter it is). Not
    given: absent from the namespace (SUPPRESS), so that the job's default applies and
    ``_options`` knows which flags were given."""
    prefix = "".join(f"{m.name} {kind.replace('_', ' ')}: " for kind, m in users)
    kw = dict(dest=param.name, default=argparse.SUPPRESS, help=param.help(prefix))
    if param.type is bool:
        parser.add_argument(param.cli_flag, action="store_false" if param.invert else "store_true", **kw)
    elif param.registry is not None:
        parser.add_argument(param.cli_flag, choices=param.choices(), **kw)
    else:
        parser.add_argument(param.cli_flag, type=_param_type(param), metavar=param.name.upper(), **kw)


#: the options of the radiosity command (no inverse problem, no methods to choose)
RADIOSITY_OPTIONS = ("rays_per_patch", "max_patch_size", "seed", "threads")


def build_parser():
    from .engine.options import PARAMS

    p = _Parser(prog=PROG, description="Relight: radiosity and inverse lighting on .blend scenes.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    r = sub.add_parser("radiosity", help="forward radiosity from the scene's own emissive materials")
    r.add_argument("scene", help="input .blend file (never modified)")
    r.add_argument("--report", required=True, help="JSON report to write")
    r.add_argument("--out", help="write a copy of the scene with the relight_radiosity colour attribute and "
                                 "Cycles light paths that render the prediction (no clamping, enough bounces)")
    for name in RADIOSITY_OPTIONS:
        _add_option(r, PARAMS[name])
    r.add_argument("-q", "--quiet", action="store_true", help="no estimate or progress on stderr")
    r.add_argument("--render", help="render the result with Cycles (CPU) to this PNG")
    r.add_argument("--render-samples", type=_positive_int, default=16, help="Cycles samples for --render")
    r.add_argument("--view-transform", choices=("AgX", "Standard", "Filmic"), default="AgX",
                   help="view transform of --render (default AgX, Blender's: it compresses the lights' "
                        "highlights; Standard shows a radiance of 1 as white)")

    for name, helptext in (("solve", "inverse lighting: lights for the painted targets, then reduction"),
                           ("reduce", "direct-lighting mode: reduce the scene's own emitters (its lamps and "
                                      "emissive polygons)")):
        s = sub.add_parser(name, help=helptext)
        s.add_argument("scene", help="input .blend file (never modified)")
        s.add_argument("--report", required=True, help="JSON report to write")
        s.add_argument("--out", help="write a copy with the final lights as emissive materials (reduce: the "
                                     "kept lamps' power set, the others disabled, restorably), the "
                                     "relight_radiosity layer, the whole curve and Cycles light paths "
                                     "that render the prediction (no clamping, enough bounces)")
        # every job option and every method's parameter, from their declarations
        jobs_group = s.add_argument_group("job options")
        methods_group = s.add_argument_group("method parameters (each used only by its method)")
        from .engine.options import METHOD_PARAMS

        for pname, param in PARAMS.items():
            if pname in METHOD_PARAMS:
                _add_option(methods_group, param, METHOD_PARAMS[pname][1])
            else:
                _add_option(jobs_group, param)
        s.add_argument("-q", "--quiet", action="store_true", help="no estimate or progress on stderr")
        if name == "solve":
            s.add_argument("--target-scale", type=_target_scale, default=None,
                           help="multiplies the painted target colours, > 0 (default: the scene's)")
            s.add_argument("--view-target", metavar="IMAGE",
                           help="the scene camera's image painted with the radiance it should show: an OpenEXR "
                                "(linear radiance) or PNG (read through the scene's view transform: Standard or "
                                "Raw) at the camera's aspect, alpha 0 where a pixel is free; solved at 480 pixels "
                                "on the longer side, with the painted faces")
            s.add_argument("--view-prediction", metavar="IMAGE",
                           help="with --view-target: write the radiance the solved lights show the camera (OpenEXR, "
                                "linear; alpha: the share of a pixel that sees a surface)")
            s.add_argument("--keep", metavar="REPORT",
                           help="keep the lamps of an earlier report's final configuration at their place and "
                                "power (written as the scene's lamps) and find Max Lights more around them")
        s.add_argument("--render", help="render the result with Cycles (CPU) to this PNG")
        s.add_argument("--render-samples", type=_positive_int, default=16)
        s.add_argument("--view-transform", choices=("AgX", "Standard", "Filmic"), default="AgX",
                       help="view transform of --render (default AgX, Blender's)")
    return p


def _options(args):
    """The job's options from the flags given (the rest: the declared defaults). An option that
    the chosen methods do not use is refused (UsageError naming it), as is an inverse-only
    option given to ``reduce``."""
    from .engine.options import PARAMS, JobOptions

    given = {name: getattr(args, name) for name in PARAMS if hasattr(args, name)}
    if args.command == "reduce":
        for name in given:
            if PARAMS[name].inverse_only:
                raise UsageError(f"{PARAMS[name].cli_flag} is used only by solve (inverse lighting), not by reduce")
    try:
        return JobOptions(**given).validate(given=set(given))
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def script_argv(argv):
    """Arguments for ``main`` from a full ``sys.argv`` (Blender's come before ``--``)."""
    argv = list(argv)
    if "--" in argv:
        return argv[argv.index("--") + 1:]
    return argv[1:]


def _write_json(path, data):
    """Write the report ``data`` to ``path`` whole or not at all (pipeline.files.atomic_output)."""
    from .pipeline.files import atomic_output

    def write(tmp):
        with open(tmp, "w") as fh:
            json.dump(data, fh, indent=1, allow_nan=False)

    atomic_output(path, write)


def _same_file(a, b):
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


#: Blender keeps a file path in 1024 bytes (FILE_MAX), its terminating zero included
BLENDER_PATH_MAX = 1024


def _check_writable(option, path):
    """UsageError unless ``path`` can be written: nothing there or a regular file (never a FIFO, a
    device node, a socket, a directory or a symbolic link: an output replaces only a regular file,
    pipeline.files.not_regular), its file (if any) writable, its nearest existing folder a writable
    directory (missing folders are made when writing); a path Blender writes (--out, --render) must
    fit in Blender's path length."""
    from .pipeline.files import not_regular

    full = os.path.abspath(path)
    n = len(os.fsencode(full))
    if option in ("out", "render") and n >= BLENDER_PATH_MAX:
        raise UsageError(f"cannot write --{option}: its path is {n} bytes long, and Blender keeps paths of at most "
                         f"{BLENDER_PATH_MAX - 1} bytes: choose a shorter one")
    if os.path.isdir(full) and not os.path.islink(full):
        raise UsageError(f"cannot write --{option} {path}: it is a directory")
    kind = not_regular(full)
    if kind:
        raise UsageError(f"cannot write --{option} {path}: it is {kind}, not a regular file, and Relight replaces "
                         "only regular files: give another path")
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
    outputs = [(name, getattr(args, name)) for name in ("report", "out", "render", "view_prediction")
               if getattr(args, name, None)]
    if getattr(args, "view_prediction", None) and not getattr(args, "view_target", None):
        raise UsageError("--view-prediction needs --view-target (the camera's painted image)")
    for name, path in outputs:
        if _same_file(path, scene_path):
            raise UsageError(f"--{name.replace('_', '-')} must not be the input file {args.scene}")
        if getattr(args, "view_target", None) and _same_file(path, args.view_target):
            raise UsageError(f"--{name.replace('_', '-')} must not be the view target {args.view_target}")
    for i, (a, pa) in enumerate(outputs):
        for b, pb in outputs[i + 1:]:
            if _same_file(pa, pb):
                raise UsageError(f"--{a.replace('_', '-')} and --{b.replace('_', '-')} name the same file {pa}: "
                                 "give them different paths")
    for name, path in outputs:
        _check_writable(name, path)
    if getattr(args, "render", None):
        from .blender.results import RENDER_FORMATS

        ext = os.path.splitext(args.render)[1].lower()
        if ext not in RENDER_FORMATS:
            raise UsageError(f"--render {args.render}: the picture's format is read from its extension, and "
                             f"{ext or 'no extension'} is not one Relight writes ({', '.join(RENDER_FORMATS)})")
    return scene_path


def _check_not_read(args):
    """After the scene is open, before any work: no output may replace a file the scene reads (a
    library it links from, an image, font or sound it uses: blend_files.files_read)."""
    from .blender.blend_files import files_read

    read = files_read()
    for name in ("report", "out", "render"):
        path = getattr(args, name, None)
        for what, p in read if path else ():
            if _same_file(path, p):
                raise UsageError(f"--{name} {path} is a file the scene reads ({what}): Relight never replaces "
                                 "it; give another path")


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
    from .blender import results

    t1 = time.perf_counter()
    try:
        if args.out or args.render:
            apply()
    except BaseException:
        _write_json(args.report, report)
        raise
    timings["apply"] = time.perf_counter() - t1
    timings["total"] = time.perf_counter() - t0
    written = []  # each output is whole or absent: a cancel says which are which
    try:
        _write_json(args.report, report)
        written.append("the report")
        if args.out:
            try:
                results.save_copy(args.out)
            except RuntimeError as exc:
                raise OSError(f"cannot write --out {args.out}: {_blender_message(exc)}") from None
            written.append("--out")
        if args.render:
            t2 = time.perf_counter()
            try:
                results.render_radiosity(args.render, samples=args.render_samples, view_transform=args.view_transform)
            except RuntimeError as exc:
                raise OSError(f"cannot render --render {args.render}: {_blender_message(exc)}") from None
            timings["render"] = time.perf_counter() - t2
            written.append("--render")
        timings["total"] = time.perf_counter() - t0
        _write_json(args.report, report)
    except KeyboardInterrupt as exc:
        missing = [name for name, on in (("--out", args.out), ("--render", args.render))
                   if on and name not in written]
        exc.outputs = (f"{' and '.join(written)} {'was' if len(written) == 1 else 'were'} written"
                       if written else "nothing was written") + \
            "".join(f"; {name} was not written" for name in missing)
        raise
    return report


def _blender_message(exc):
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    text = lines[-1] if lines else type(exc).__name__
    return text[len("Error: "):] if text.startswith("Error: ") else text


def run_radiosity_command(args, progress=None, cancel=None):
    import bpy

    from .blender import blend_files, export, light_paths, results
    from .pipeline import jobs, meshing, report as reports, viewing

    t0 = time.perf_counter()
    _check_paths(args)
    blend_files.open_blend(args.scene)
    _check_not_read(args)
    exp = export.export_scene()
    options = _options(args)
    inputs = export.job_inputs(exp)

    def mesh(progress, cancel):
        patches = meshing.mesh_for_job(exp.faces, options, inputs["default_max_patch_size"], mode="direct")
        return patches, meshing.radiosity_cost(patches, options)

    patches, cost = _job(args, mesh)
    _print_estimate(args, patches, cost)
    report, result = _job(args, lambda progress, cancel: jobs.run_radiosity(
        exp.faces, options, progress=progress, cancel=cancel, patches=patches, **inputs))
    rows = None
    if result.form_factors is not None and result.patches.n_patches <= viewing.MAX_PATCHES // 4:
        rows = viewing.normal_radiance(exp.faces, result.patches, result.form_factors, result.patch_radiosity,
                                       exp.face_material, exp.material_lobes, inputs["polygon_counts"],
                                       exitance=result.patches.exitance, scene_light=result.scene_light)
    reports.finish(report, None, light_paths.assess_radiosity(bpy.context.scene, result), rows,
                   export_seconds=exp.seconds, input_path=os.path.abspath(args.scene))

    def apply():
        results.write_radiosity(exp.objects, result.polygon_radiosity, result.polygon_area, report["warnings"])
        _match_light_paths(args, report)

    return _save_outputs(args, report, report["timings_s"], t0, apply)


def _match_light_paths(args, report):
    """--out: the copy renders with light paths that show the prediction (light_paths.py)."""
    if not args.out:
        return
    import bpy

    from .blender import light_paths

    from .blender.lamp_state import animated

    scene = bpy.context.scene
    block = report["render_settings"]
    changed = light_paths.match_light_paths(scene, block["max_reflectance"])
    overridden = animated(scene, [f"cycles.{k}" for k in changed if "." not in k])
    if overridden:  # what Relight wrote, overridden by animation (issue 35): said; the lights are right
        report["warnings"].append(
            f"the scene's Cycles light paths are animated ({', '.join(overridden)}): --out sets them for the "
            "prediction, and the animation sets other values when the copy is opened or rendered; remove the "
            "keyframes or drivers to render what was predicted")
    block["written"] = {"settings": light_paths.current_settings(scene),
                        "changed": {k: list(v) for k, v in changed.items()}}


def run_solve_command(args, progress=None, cancel=None):
    import bpy

    from .blender import blend_files, results
    from .blender.preparation import SolveJob

    from .pipeline import kept

    t0 = time.perf_counter()
    _check_paths(args)
    options = _options(args)  # before any work: an unusable option exits 2 at once
    keep = None
    if getattr(args, "keep", None):
        try:
            keep = kept.read_kept(args.keep)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    blend_files.open_blend(args.scene)
    _check_not_read(args)
    view = None
    if getattr(args, "view_target", None):
        from .blender.camera_view import read_view_target

        view = read_view_target(bpy.context.scene, args.view_target)
    names = results.add_kept_lamps(bpy.context.scene, keep[0]) if keep else []
    job = SolveJob.export(None, options, "inverse" if args.command == "solve" else "direct",
                          target_scale=getattr(args, "target_scale", None), view_target=view)
    if args.command == "reduce" and (args.out or args.render):  # before the work: what apply will write
        _check_lamps_not_animated(bpy.context.scene, job.exp.faces.lamps)
    patches, cost = _job(args, job.mesh)
    _print_estimate(args, patches, cost)
    outcome = _job(args, job.run)
    # (a view target's glossy rows read every patch they gather from: radiance_normal, of the patches
    # the rows read, is left out of its report)
    job.finish(bpy.context.scene, outcome, view_radiance=view is None, input_path=os.path.abspath(args.scene))
    report = outcome.report
    if view is not None:
        from .pipeline import view_targets

        report["view_target"] = view_targets.view_report(outcome)
        report["warnings"].extend(view_targets.view_notes(outcome.problem))
        if args.view_prediction:
            from .blender.camera_view import write_image

            write_image(args.view_prediction, view_targets.predicted_rgba(outcome))
    if keep:
        report["kept"] = {"from": os.path.abspath(args.keep), "lamps": [
            {"object": n, "type": r["type"].lower(), "location": r["position"], "energy": r["energy"],
             "color": r["color"], "power": r["power"]} for n, r in zip(names, keep[0])]}
        report["warnings"].extend(keep[1])
        report["warnings"].extend(kept.foreign_notes(
            [(n, r["position"]) for n, r in zip(names, keep[0])], report.get("fixed_light"), job.exp.faces.vertices,
            args.keep, solved_for=keep[2], this_input=os.path.abspath(args.scene)))

    def apply():
        shown = results.show_outcome(bpy.context.scene, outcome, job.exp.fingerprints)
        report["warnings"].extend(w for w in shown["skipped"] if w not in report["warnings"])
        _match_light_paths(args, report)

    return _save_outputs(args, report, report["timings_s"], t0, apply)


def _check_lamps_not_animated(scene, lamps):
    """reduce --out/--render sets every lamp it reduces (Power and colour, or Disable in Renders):
    refused at once when a driver or keyframes would override that (lamp_state.check_not_animated;
    apply checks it again before writing)."""
    from .blender import lamp_state

    for lamp in lamps:
        ob = scene.objects.get(lamp.name)
        if ob is not None and ob.type == "LIGHT" and ob.library is None and ob.data.library is None:
            lamp_state.check_not_animated(ob)


def _summary(args, report):
    from .pipeline.report import kinds_text

    if args.command == "radiosity":
        s = report["scene"]
        print(f"{PROG}: radiosity of {s['objects']} objects, {s['faces']} faces, {s['patches']} patches "
              f"in {report['timings_s']['total']:.2f} s; report {args.report}")
    else:
        inv, fin = report["inverse"], report["final"]
        print(f"{PROG}: {args.command}: {inv['n_targets']} target patches, {inv['n_candidates']} candidates; "
              f"e_x relative error {inv['relative_error']:.3g} with {inv['n_negative']} negative(s); "
              f"final {fin['n_lights']} light(s), relative error {fin['relative_error']:.3g} over "
              f"{inv.get('error_over', 'the target patches')}, "
              f"{fin['n_negative']} negative(s) ({kinds_text(report)}); {len(report['curve'])} configurations; "
              f"{report['timings_s']['total']:.2f} s; report {args.report}")
    for w in report["warnings"]:
        print(f"{PROG}: warning: {w}")


class Terminated(KeyboardInterrupt):
    """SIGTERM: cancelled as Ctrl-C is, with the shell's exit code for it (128 + 15)."""


def _interrupt(signum, frame):
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def main(argv=None) -> int:
    """Run the CLI on ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    from .engine.sampling import Cancelled

    argv = sys.argv[1:] if argv is None else list(argv)
    restore = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:  # Ctrl-C (or SIGTERM) raises KeyboardInterrupt here (unless the shell made it ignored)
                previous = signal.getsignal(sig)
                if previous is not signal.SIG_IGN:
                    signal.signal(sig, _interrupt)
                    restore[sig] = previous
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
    except (KeyboardInterrupt, Cancelled) as exc:
        outputs = getattr(exc, "outputs", None)
        line = f"{PROG}: cancelled" + (f": {outputs}" if outputs else "")
        print(f"\n{line}" if sys.stderr.isatty() else line, file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    except BaseException as exc:  # every failure: one line, exit 2
        if isinstance(exc, SystemExit) or os.environ.get("RELIGHT_DEBUG"):
            raise
        print(f"{PROG}: error: {error_line(exc)}", file=sys.stderr)
        return 2
    finally:
        for sig, previous in restore.items():
            # None: the handler was set outside Python (blender -b's own SIGINT handler), which
            # Python cannot put back; the default is the nearest (blender -b quits after the script)
            signal.signal(sig, signal.SIG_DFL if previous is None else previous)


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
