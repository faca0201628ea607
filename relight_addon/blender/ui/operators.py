"""Operators of the Relight tab. Thin: Blender data in and out through export.py and results.py, the
work in ``jobs`` (the same code path as the CLI)."""
from __future__ import annotations

import json
import textwrap
import threading

import bmesh
import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty

from .. import ADDON_PACKAGE, layers, live, results
from ...pipeline import jobs
from ...pipeline.notes import for_addon, sidebar_lines
from ...pipeline.report import fixed_light_rows, light_rows, photometric_rows, summary_line
from ..camera_view import predict_view, scene_view_target
from ..preparation import SolveJob
from . import display, view_target_ops, viewport
from .properties import set_curve_index, show_row_panel, ui_value
from ...engine.options import JobOptions
from ...engine.scene import SceneError

TARGET = layers.TARGET_ATTRIBUTE
FORBIDDEN = layers.FORBIDDEN_ATTRIBUTE


def job_options(settings, validate=True) -> JobOptions:
    """The job's options from the scene's properties (properties.py, generated from the
    declarations): the job-wide options the chosen methods use (the others keep their
    defaults: e.g. a selection that distributes no power gets the default distribution), and
    the parameters of the chosen methods only, so that nothing the sidebar shows is refused."""
    from ...engine.options import JOB_PARAMS, METHOD_CHOICES, method_params

    options = JobOptions(threads=_preferences_threads(),
                         **{p.name: ui_value(settings, p) for p in JOB_PARAMS if p.ui != "hidden"})
    for p in JOB_PARAMS:
        if p.ui != "hidden" and not options.uses(p.name):
            setattr(options, p.name, p.default)
    for kind, _registry in METHOD_CHOICES:
        for p in method_params(kind, getattr(options, kind)):
            if options.uses(p.name):
                setattr(options, p.name, ui_value(settings, p))
    return options.validate() if validate else options


def _preferences_threads():
    addon = bpy.context.preferences.addons.get(ADDON_PACKAGE)
    threads = getattr(addon.preferences, "threads", 0) if addon else 0
    return threads or None


def _mesh_objects(context, selected_only=False):
    objs = context.selected_objects if selected_only else context.scene.objects
    return [o for o in objs if o.type == "MESH"]


def _message(exc) -> str:
    """The user's message of an exception (a KeyError's without the quotes str() adds; an
    OptionError's worded for the sidebar, naming its options as it shows them)."""
    if getattr(exc, "panel", None):
        return exc.panel
    if isinstance(exc, KeyError) and exc.args:
        return str(exc.args[0])
    return str(exc)


def _refuse(op, exc):
    """Report a refusal (the scene is unchanged) and cancel."""
    op.report({"ERROR"}, _message(exc))
    return {"CANCELLED"}


# --- targets ---------------------------------------------------------------------------

class RELIGHT_OT_paint_targets(bpy.types.Operator):
    """Create the target colour layer if missing (alpha 0 = unpainted), make it active and
    enter Vertex Paint: painted corners get alpha 1"""
    bl_idname = "relight.paint_targets"
    bl_label = "Paint Targets"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "MESH"

    def execute(self, context):
        obj = context.active_object
        try:  # validated first: a linked mesh, or a relight_target of another domain or type, is refused
            layers.check_writable_mesh(obj)
            layer = layers.ensure_target_layer(obj.data)  # the existing layer of either colour type
        except SceneError as exc:
            return _refuse(self, exc)
        colors = obj.data.color_attributes
        colors.active_color = colors[layer.name]  # vertex paint paints the active colour layer
        if context.mode != "PAINT_VERTEX":
            bpy.ops.object.mode_set(mode="VERTEX_PAINT")
        color = context.scene.relight.paint_color
        ups = getattr(context.tool_settings, "unified_paint_settings", None)
        for holder in (ups, getattr(context.tool_settings.vertex_paint, "brush", None)):
            try:  # brushes can be read-only assets (Blender 4.3+): the unified colour is enough
                holder.color = color
            except (AttributeError, TypeError, RuntimeError):
                pass
        self.report({"INFO"}, f"Painting targets on {obj.name}: painted colour x scale is the wanted radiance")
        return {"FINISHED"}


class RELIGHT_OT_fill_targets(bpy.types.Operator):
    """Set the selected faces (Edit Mode) of the objects in Edit Mode as targets of the target
    colour (radiance), or of the Illuminance (lx); a face holds one kind: the other is removed"""
    bl_idname = "relight.fill_targets"
    bl_label = "Fill Selected Faces"
    bl_options = {"REGISTER", "UNDO"}

    # (not remembered between calls: each button says what it does)
    unpaint: BoolProperty(name="Unpaint", default=False, description="Make the selected faces non-targets",
                          options={"SKIP_SAVE"})
    illuminance: BoolProperty(name="Illuminance", default=False, options={"SKIP_SAVE"},
                              description="Fill with the illuminance target (lx) instead of the target colour")

    @classmethod
    def poll(cls, context):
        return context.mode == "EDIT_MESH"

    def execute(self, context):
        color = tuple(context.scene.relight.paint_color) + (1.0,)
        objs = [o for o in context.objects_in_mode if o.type == "MESH"]
        try:  # every object checked before any is written: all or nothing
            for obj in objs:
                layers.check_writable_mesh(obj)
                layers.target_layer(obj.data, obj.name)  # None, or a Face Corner colour layer of either type
                layers.lux_layer(obj.data, obj.name)  # None, or a Face float layer
        except SceneError as exc:
            return _refuse(self, exc)
        count = 0
        lux = float(context.scene.relight.paint_lux) if self.illuminance and not self.unpaint else 0.0
        for obj in objs:
            mesh = obj.data
            bm = bmesh.from_edit_mesh(mesh)
            lux_layer = bm.faces.layers.float.get(layers.LUX_ATTRIBUTE)
            if lux_layer is None and lux > 0:
                lux_layer = bm.faces.layers.float.new(layers.LUX_ATTRIBUTE)
            if lux_layer is not None:
                for f in bm.faces:
                    if f.select:
                        f[lux_layer] = lux
            # write into the existing layer whatever its type (BMesh byte colours hold sRGB values)
            layer = bm.loops.layers.float_color.get(TARGET)
            value = (0.0, 0.0, 0.0, 0.0) if self.unpaint or self.illuminance else color
            if layer is None and bm.loops.layers.color.get(TARGET) is not None:
                layer = bm.loops.layers.color.get(TARGET)
                if not self.unpaint:
                    value = tuple(layers.linear_to_srgb(color[:3])) + (1.0,)
            if layer is None:  # BMesh starts a new colour layer white and opaque: "painted" to Relight
                layer = bm.loops.layers.float_color.new(TARGET)
                for f in bm.faces:
                    for loop in f.loops:
                        loop[layer] = (0.0, 0.0, 0.0, 0.0)
            for f in bm.faces:
                if f.select:
                    for loop in f.loops:
                        loop[layer] = value
                    count += 1
            bmesh.update_edit_mesh(mesh)
        done = "Unpainted" if self.unpaint else (f"Set {lux:g} lx on" if self.illuminance else "Painted")
        self.report({"INFO"}, f"{done} {count} face(s)")
        return {"FINISHED"}


class RELIGHT_OT_clear_targets(bpy.types.Operator):
    """Remove the painted targets of the selected objects (all mesh objects if none is selected)"""
    bl_idname = "relight.clear_targets"
    bl_label = "Clear Targets"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):  # (greyed out when no object of the scene has targets)
        if not any(o.type == "MESH" and (o.data.attributes.get(TARGET) is not None
                                        or o.data.attributes.get(layers.LUX_ATTRIBUTE) is not None)
                   for o in context.scene.objects):
            cls.poll_message_set("No object of the scene has targets")
            return False
        return True

    def execute(self, context):
        objs = _mesh_objects(context, selected_only=True) or _mesh_objects(context)
        objs = [o for o in objs if o.data.attributes.get(TARGET) is not None
                or o.data.attributes.get(layers.LUX_ATTRIBUTE) is not None]
        try:  # all or nothing: a linked (read-only) mesh among them refuses the whole operation
            for obj in objs:
                layers.check_writable_mesh(obj)
        except SceneError as exc:
            return _refuse(self, exc)
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        n = 0
        for obj in objs:
            for name in (TARGET, layers.LUX_ATTRIBUTE):
                attr = obj.data.attributes.get(name)
                if attr is not None:
                    obj.data.attributes.remove(attr)
            n += 1
        self.report({"INFO"}, f"Cleared targets on {n} object(s)")
        return {"FINISHED"}


class RELIGHT_OT_select_faces(bpy.types.Operator):
    """Select the target or the forbidden faces in Edit Mode, to see them against the rest"""
    bl_idname = "relight.select_faces"
    bl_label = "Select Faces"
    bl_options = {"REGISTER", "UNDO"}

    kind: EnumProperty(items=[("TARGET", "Targets", ""), ("FORBIDDEN", "Forbidden", ""),
                              ("LIGHT", "Lights", "")], default="TARGET")

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "MESH"

    def execute(self, context):
        if context.mode != "OBJECT":  # the attributes are read in Object Mode (edit-mode changes flushed)
            bpy.ops.object.mode_set(mode="OBJECT")
        objs = [o for o in context.selected_objects if o.type == "MESH"] or [context.active_object]
        try:
            masks = {o.name: (results.shown_light_polygons(context.scene, o) if self.kind == "LIGHT"
                              else layers.face_flags(o, self.kind.lower())) for o in objs}
        except (SceneError, KeyError) as exc:
            return _refuse(self, exc)
        for o in objs:
            o.select_set(True)
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_mode(type="FACE")
        total = 0
        for obj in context.objects_in_mode:
            mask = masks.get(obj.name)
            if mask is None:
                continue
            bm = bmesh.from_edit_mesh(obj.data)
            bm.faces.ensure_lookup_table()
            for v in bm.verts:
                v.select = False
            for e in bm.edges:
                e.select = False
            for f in bm.faces:
                f.select = bool(mask[f.index])
            bm.select_flush_mode()
            bmesh.update_edit_mesh(obj.data)
            total += int(mask.sum())
        self.report({"INFO"}, f"Selected {total} {self.kind.lower()} face(s)")
        return {"FINISHED"}


# --- candidates -----------------------------------------------------------------------

class RELIGHT_OT_forbid_faces(bpy.types.Operator):
    """Forbid (or allow) lights on the selected faces (Edit Mode)"""
    bl_idname = "relight.forbid_faces"
    bl_label = "Forbid Selected Faces"
    bl_options = {"REGISTER", "UNDO"}

    allow: BoolProperty(name="Allow", default=False, description="Allow lights on the selected faces instead")

    @classmethod
    def poll(cls, context):
        return context.mode == "EDIT_MESH"

    def execute(self, context):
        # the selection is read in Edit Mode, the face attribute written in Object Mode (BMesh has
        # no boolean layers before Blender 4.3), into the existing relight_forbidden whatever its
        # numeric type (BOOLEAN, INT, INT8, FLOAT: non-zero = forbidden), else a new BOOLEAN one
        objs = [o for o in context.objects_in_mode if o.type == "MESH"]
        try:  # every object checked before any is written: all or nothing
            for obj in objs:
                layers.check_writable_mesh(obj)
                layers.forbidden_layer(obj.data, obj.name)
        except SceneError as exc:
            return _refuse(self, exc)
        bpy.ops.object.mode_set(mode="OBJECT")
        count = 0
        for obj in objs:
            mesh = obj.data
            n = len(mesh.polygons)
            sel = np.zeros(n, dtype=bool)
            mesh.polygons.foreach_get("select", sel)
            attr = layers.ensure_forbidden_layer(mesh)
            vals = layers.read_forbidden(attr, n)
            vals[sel] = not self.allow
            layers.write_forbidden(attr, vals)
            mesh.update()
            count += int(sel.sum())
        bpy.ops.object.mode_set(mode="EDIT")
        verb = "Allowed" if self.allow else "Forbade"
        self.report({"INFO"}, f"{verb} lights on {count} face(s)")
        return {"FINISHED"}


# --- solve ----------------------------------------------------------------------------

def _fill_curve_list(settings, rows, current):
    settings.curve.clear()
    for p in rows:
        item = settings.curve.add()
        item.n_lights = int(p["n_lights"])
        item.error = float(p["error"])
        item.relative_error = float(p["relative_error"])
        item.n_negative = int(p["n_negative"])
        item.curve_index = int(p["curve_index"])
    set_curve_index(settings, current)


#: the options whose 0 means automatic, whose value a solve reports (pipeline.report: options)
AUTO_OPTIONS = ("rays_per_patch", "max_patch_size", "light_size", "lamp_drop")


def auto_values(options) -> str:
    """The last_auto property's JSON: {option: the value a solve used} for the automatic options
    (a report's or a stored result's ``options``)."""
    return json.dumps({k: float(options[k]) for k in AUTO_OPTIONS if isinstance(options.get(k), (int, float))})


def sync_curve_list(scene):
    """Fill the UI list, the summary and the warnings from the stored result when they are not
    that result's: a file written by the CLI, or re-solved by it after the add-on showed another
    result (the list remembers the id of the result it shows, ``curve_result``)."""
    settings = scene.relight
    rid = results.result_id(scene)
    if results.RESULT_PROP not in scene.keys():
        return
    if len(settings.curve) and settings.curve_result == (rid or ""):
        return
    data = results.load_result(scene)
    rows = [{"n_lights": data.n_lights[k], "error": data.error[k],
             "relative_error": data.relative_error[k], "n_negative": data.n_negative[k],
             "curve_index": data.point_index[k]} for k in range(len(data.n_lights))]
    shown = scene.get("relight_shown")
    final = int(np.searchsorted(data.point_index, int(data.final)))
    shown = int(shown) if shown is not None and 0 <= int(shown) < len(rows) else final
    _fill_curve_list(settings, rows, shown)
    settings.last_summary = data.meta.get("summary", "")
    settings.last_auto = auto_values(data.meta.get("options") or {})
    settings.last_warnings = "\n".join(data.meta.get("warnings", []))
    settings.last_fixed_light = data.meta.get("fixed_light", "")
    settings.last_photometric = data.meta.get("photometric", "")
    settings.last_lights = data.meta.get("lights", "")
    panels = data.meta.get("rows") or []
    show_row_panel(settings, panels[shown] if shown < len(panels) else None)
    settings.curve_result = rid or ""
    results.update_chart(scene)


def store_outcome(context, outcome, fingerprints=None, trusted=False, packed=None):
    """Keep the curve in the scene and show the final configuration (main thread); returns the
    messages about objects that could not show everything (``trusted``, ``packed``:
    results.show_outcome's)."""
    shown = results.show_outcome(context.scene, outcome, fingerprints, trusted, packed)
    _fill_curve_list(context.scene.relight, outcome.curve, outcome.final_index)
    context.scene.relight.curve_result = results.result_id(context.scene) or ""
    context.scene.relight.apply_error = ""
    results.update_chart(context.scene)
    return shown["skipped"]


def show_solve(context, job, outcome, finished=False, trusted=False, show=True, packed=None) -> list:
    """A solve's outcome into the scene (main thread, Object Mode): the report finished (light
    paths; ``finished``: the worker did it), the curve stored and its final configuration shown,
    the sidebar's summary and warnings; returns the warnings. Raises SceneError / ValueError, the
    scene unchanged. ``trusted``: results.show_outcome's. ``show``: the viewports switched to the
    predicted radiosity (not while painting: Live in Vertex Paint). ``packed``: the outcome's
    results.packed_result, made by the worker (Live's; after ``finished``)."""
    if not finished:
        job.finish(context.scene, outcome, view_radiance=False)  # warns when Cycles would render darker
    view = not finished and view_target_ops.solved(job, outcome)  # (Live's answers: no prediction)
    skipped = store_outcome(context, outcome, job.exp.fingerprints, trusted, packed)
    if view:
        view_target_ops.write_prediction(context, outcome)
    warnings = list(outcome.warnings) + list(skipped or [])
    settings = context.scene.relight
    settings.last_summary = summary_line(outcome.report, len(outcome.curve))
    settings.last_auto = auto_values(outcome.report.get("options") or {})
    settings.last_fixed_light = fixed_light_rows(outcome.report)
    settings.last_photometric = photometric_rows(outcome.report)
    settings.last_lights = light_rows(outcome.report)
    settings.last_warnings = "\n".join(warnings)
    if show and not bpy.app.background:
        viewport.show_radiosity(context)  # the lights and the predicted radiosity
    return warnings


#: the interactive solve in progress (at most one): scene name, stage, fraction, cancelling.
#: Plain Python values, written by the modal handler on the main thread, read by the panels.
_SOLVING = {}


def solve_state(scene):
    """{"stage", "fraction", "cancelling"} of the interactive solve running on ``scene``, or None."""
    return _SOLVING if _SOLVING.get("scene") == scene.name else None


def _object_mode(context):
    """Leave Edit (or another) Mode for Object Mode; returns the mode to give back (None: none)."""
    mode = context.object.mode if context.object is not None and context.mode != "OBJECT" else None
    if mode is not None:
        bpy.ops.object.mode_set(mode="OBJECT")
    return mode


def _restore_mode(context, mode):
    if mode is not None and context.object is not None:
        bpy.ops.object.mode_set(mode=mode)


def _back_to_painting(context, mode):
    """After a solve: the user's mode given back (the solve ran in Object Mode). In Vertex Paint,
    the target layer is made the active colour again: the solve made the radiosity layer active,
    and the next stroke would have painted it."""
    if mode is None or context.object is None:
        return
    _restore_mode(context, mode)
    if mode == "VERTEX_PAINT" and context.object.type == "MESH":
        colors = context.object.data.color_attributes
        target = layers.target_layer(context.object.data)
        if target is not None:
            colors.active_color = colors[target.name]


class RELIGHT_OT_solve(bpy.types.Operator):
    """Solve the inverse lighting problem for the painted targets and reduce it to a few
    positive lights. ESC cancels and leaves the scene untouched"""
    bl_idname = "relight.solve"
    bl_label = "Solve & Reduce"
    bl_options = {"REGISTER", "UNDO"}

    confirmed: BoolProperty(name="Confirmed", default=False, options={"HIDDEN", "SKIP_SAVE"},
                            description="The cost warning was shown and accepted: solve without asking")

    _thread = None
    _timer = None

    def _prepare(self, context):
        """The shared preparation step (preparation.SolveJob): export, check, mesh, estimate.
        The solve reads the meshes in Object Mode; refused, it gives the user's mode back."""
        self._mode = _object_mode(context)
        try:
            # the target scale: the scene's relight_target_scale (= the settings')
            job = SolveJob.export(context, job_options(context.scene.relight), session=True,
                                  view_target=scene_view_target(context.scene))
            job.mesh()
        except BaseException:
            _restore_mode(context, self._mode)
            raise
        return job

    def execute(self, context):
        try:
            job = self._prepare(context)
            outcome = job.run()
        except (SceneError, ValueError) as exc:
            _restore_mode(context, getattr(self, "_mode", None))
            self.report({"ERROR"}, _message(exc))
            return {"CANCELLED"}
        return self._finish(context, job, outcome)

    def _finish(self, context, job, outcome):
        try:
            warnings = show_solve(context, job, outcome)
        except (SceneError, ValueError) as exc:
            _restore_mode(context, getattr(self, "_mode", None))
            self.report({"ERROR"}, _message(exc))
            return {"CANCELLED"}
        _back_to_painting(context, getattr(self, "_mode", None))
        # the status bar shows the last report: the summary first, then the warnings
        self.report({"INFO"}, "Relight: " + context.scene.relight.last_summary)
        top = sidebar_lines(warnings)
        first = {line.index for line in top}
        for w in [w for k, w in enumerate(warnings) if k not in first] + [warnings[ln.index] for ln in top[::-1]]:
            self.report({"WARNING"}, "Relight: " + for_addon(w))  # the status bar ends on the one that matters most
        return {"FINISHED"}

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        if _SOLVING:
            self.report({"ERROR"}, "A Relight solve is already running (ESC cancels it)")
            return {"CANCELLED"}
        try:
            job = self._prepare(context)
        except (SceneError, ValueError) as exc:
            self.report({"ERROR"}, _message(exc))
            return {"CANCELLED"}
        if job.cost["warnings"] and not self.confirmed:
            # a large solve: ask first. "Solve Anyway" invokes this operator again with
            # confirmed=True, so the solve still runs in the background with progress and ESC.
            _ask_to_confirm(context, job.cost["warnings"])
            return {"CANCELLED"}
        return self._start(context, job)

    def _start(self, context, job):
        self._job = job
        self._cancel = threading.Event()
        self._progress = [0.0, "starting"]
        self._result = {}

        def work():
            try:
                self._result["outcome"] = job.run(progress=self._set_progress, cancel=self._cancel.is_set)
                predict_view(self._result["outcome"], self._set_progress, self._cancel.is_set)  # (view target)
            except BaseException as exc:  # reported on the main thread
                self._result["error"] = exc

        self._thread = threading.Thread(target=work, daemon=True)
        self._thread.start()
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        _SOLVING.clear()
        _SOLVING.update(scene=context.scene.name, stage="starting", fraction=0.0, cancelling=False)
        wm.modal_handler_add(self)
        results.redraw_sidebars()
        return {"RUNNING_MODAL"}

    def _set_progress(self, stage, fraction):
        """Called from the worker thread: only plain Python values change here."""
        self._progress[0] = float(fraction)
        self._progress[1] = str(stage)

    def _end_ui(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        _SOLVING.clear()
        results.redraw_sidebars()

    def cancel(self, context):
        """Blender stops the modal (a file is opened, the window closes): stop the worker, free
        the UI (the worker's result, if any, is dropped)."""
        self._cancel.set()
        self._end_ui(context)

    def _status(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)

    def modal(self, context, event):
        # Never wait for the worker here: ESC only asks it to stop; the timer below notices
        # when it has, while the UI keeps running.
        if event.type == "ESC" and event.value == "PRESS":
            if not self._cancel.is_set():
                self._cancel.set()
                _SOLVING["cancelling"] = True
                self._status(context, "Relight: cancelling...")
                results.redraw_sidebars()
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        frac, text = self._progress
        if self._thread.is_alive():
            context.window_manager.progress_update(int(100 * frac))
            _SOLVING.update(stage=text, fraction=frac)
            if not self._cancel.is_set():
                self._status(context, f"Relight: {text} ({100 * frac:.0f} %) - ESC to cancel")
            results.redraw_sidebars()
            return {"RUNNING_MODAL"}
        self._end_ui(context)
        if "error" in self._result or self._cancel.is_set():
            exc = self._result.get("error")
            _restore_mode(context, self._mode)  # unchanged: the user's mode too
            if exc is None or isinstance(exc, jobs.Cancelled):
                self.report({"WARNING"}, "Relight: solve cancelled, the scene is unchanged")
            else:
                self.report({"ERROR"}, f"Relight: {_message(exc)}")
            return {"CANCELLED"}
        return self._finish(context, self._job, self._result["outcome"])


class RELIGHT_OT_live(bpy.types.Operator):
    """Live mode: while it is on, every stroke, Fill and Unpaint updates the lights, the radiosity
    layer and the chart, re-solved off the main thread from the prepared scene. Click again or
    press ESC to turn it off: the scene keeps the last answer"""
    bl_idname = "relight.live"
    bl_label = "Live"
    bl_options = {"REGISTER"}

    _timer = None

    def invoke(self, context, event):
        if live.session(context.scene) is not None:  # the toggle: off
            live.stop(context.scene.name)
            results.redraw_sidebars()
            return {"FINISHED"}
        if bpy.app.background or context.window is None:
            self.report({"ERROR"}, "Live mode follows the brush in a window; headless, use Solve & Reduce")
            return {"CANCELLED"}
        self._session = live.start(context, job_options, show_solve)
        self._timer = context.window_manager.event_timer_add(live.TICK, window=context.window)
        context.window_manager.modal_handler_add(self)
        results.redraw_sidebars()
        return {"RUNNING_MODAL"}

    def _end(self, context):
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        results.redraw_sidebars()

    def cancel(self, context):
        live.stop(self._session.scene)
        self._end(context)

    def modal(self, context, event):
        s = self._session
        if live.SESSIONS.get(s.scene) is not s:  # turned off (the toggle, another file)
            self._end(context)
            return {"FINISHED"}
        if event.type == "ESC" and event.value == "PRESS":
            live.stop(s.scene)
            self._end(context)
            self.report({"INFO"}, "Relight: Live off; the scene keeps the last answer")
            return {"FINISHED"}
        if event.type == "TIMER" and context.scene.name == s.scene and not _SOLVING:
            before, said = (s.status, s.updates, s.paused), False
            try:
                s.tick(context)
            except (SceneError, ValueError) as exc:  # e.g. a target layer made unreadable: said, Live waits
                s.paused, s.status = _message(exc), "paused"
            except ReferenceError:  # (an object deleted between two of Live's checks: said as they say it)
                s.paused, s.status = "an object Live reads was deleted: Solve & Reduce prepares again", "paused"
            except Exception as exc:  # noqa: BLE001  (a defect: said once, Live waits; never a dead modal)
                if s.paused is None:
                    self.report({"ERROR"}, f"Relight Live: {type(exc).__name__}: {exc}")
                s.paused, s.status, said = f"{type(exc).__name__}: {exc}", "paused", True
            if s.paused and s.paused != before[2] and not said:  # (the status bar names the cause, once)
                self.report({"WARNING"}, f"Relight {live.status_text(s)}")
            if (s.status, s.updates, s.paused) != before:
                results.redraw_sidebars()
        return {"PASS_THROUGH"}


def _ask_to_confirm(context, warnings):
    def draw(menu, _context):
        layout = menu.layout
        for w in warnings:
            for k, line in enumerate(textwrap.wrap(w, 60)):
                layout.label(text=line, icon="ERROR" if k == 0 else "BLANK1")
        layout.separator()
        layout.operator_context = "INVOKE_DEFAULT"
        layout.operator("relight.solve", text="Solve Anyway", icon="LIGHT_SUN").confirmed = True

    context.window_manager.popup_menu(draw, title="Relight: a large solve", icon="QUESTION")


# --- results --------------------------------------------------------------------------

class RELIGHT_OT_apply_configuration(bpy.types.Operator):
    """Show configuration k of the error curve in the scene"""
    bl_idname = "relight.apply_configuration"
    bl_label = "Apply Configuration"
    bl_options = {"REGISTER", "UNDO"}

    index: IntProperty(name="Configuration", default=-1, min=-1,
                       description="Row of the curve; -1 = the selected row")

    def execute(self, context):
        settings = context.scene.relight
        n = len(settings.curve)
        if n == 0:
            self.report({"ERROR"}, "No Relight result in this scene: run Solve & Reduce first")
            return {"CANCELLED"}
        k = settings.curve_index if self.index < 0 else self.index
        if not 0 <= k < n:
            self.report({"ERROR"}, f"Configuration {k} does not exist (0..{n - 1})")
            return {"CANCELLED"}
        try:
            shown = results.apply_stored_point(context.scene, k)
        except (ValueError, KeyError) as exc:
            return _refuse(self, exc)
        set_curve_index(settings, k)
        show_row_panel(settings, shown["panel"])
        display.refresh(context.scene)  # the Results panel's View, of this row
        settings.apply_error = ""
        results.update_chart(context.scene)
        for w in shown["skipped"]:  # e.g. linked meshes: the lights show, the radiosity layer cannot
            self.report({"WARNING"}, w)
        p = settings.curve[k]
        self.report({"INFO"}, f"Configuration {k}: {p.n_lights} light(s), relative error {p.relative_error:.3g}")
        return {"FINISHED"}


class RELIGHT_OT_clear_results(bpy.types.Operator):
    """Remove Relight's lights, colour layer and curve: the scene is exactly as before the solve"""
    bl_idname = "relight.clear_results"
    bl_label = "Clear Results"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        n = results.clear_results(context.scene)
        viewport.restore(context)  # the viewports' shading from before Show Radiosity
        settings = context.scene.relight
        settings.curve.clear()
        set_curve_index(settings, 0)
        self.report({"INFO"}, f"Cleared Relight results on {n} object(s)")
        return {"FINISHED"}


class RELIGHT_OT_make_area_lights(bpy.types.Operator):
    """Turn the shown configuration into lights of your own (an area light per light face, a copy
    of each lamp shown), in a new collection; Relight's own lights of it are removed, so a render
    shows its light once. A click on a row shows that row again beside them"""
    bl_idname = "relight.make_area_lights"
    bl_label = "Make Area Lights"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        k = context.scene.relight.curve_index
        try:
            made = results.make_area_lights(context.scene, k)
        except (ValueError, KeyError) as exc:
            return _refuse(self, exc)
        names = made["names"]
        self.report({"INFO"}, f"Configuration {k} is now {len(names)} light(s) of yours in collection "
                              f"'{made['collection']}' ({', '.join(names[:3])}{', ...' if len(names) > 3 else ''}); "
                              "Relight's own lights of it are removed, so a render shows it once. A click on a row "
                              "of the list shows that row again with Relight's lights, beside these")
        if made["reduce"]:
            self.report({"INFO"}, "The scene's own emitters and lamps stay as this configuration sets them while "
                                  "the result is kept; Clear Results gives them back as they were, beside your lights")
        return {"FINISHED"}


class RELIGHT_OT_keep_lamps(bpy.types.Operator):
    """Keep the shown lamps at their place and power: they become the scene's own lamps (move or
    resize them as you like; no result removes them), and the next Solve & Reduce finds Max Lights
    more around them, its certificate bounding the rest"""
    bl_idname = "relight.keep_lamps"
    bl_label = "Keep Lamps"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        try:
            names = results.keep_placed(context.scene)
        except (SceneError, ValueError, KeyError) as exc:
            return _refuse(self, exc)
        self.report({"INFO"}, f"Kept {len(names)} lamp(s) ({', '.join(names[:4])}): Solve & Reduce finds the rest "
                              "around them")
        return {"FINISHED"}


class RELIGHT_OT_show_radiosity(bpy.types.Operator):
    """Show the predicted radiosity (Solid shading, Color: Attribute, the relight_radiosity
    layer) in the 3D Viewports, or, when it is shown, give the viewports their shading back"""
    bl_idname = "relight.show_radiosity"
    bl_label = "Show Radiosity"

    action: EnumProperty(items=[("TOGGLE", "Toggle", ""), ("SHOW", "Show", ""), ("HIDE", "Hide", "")],
                         default="TOGGLE", options={"SKIP_SAVE"})

    def execute(self, context):
        hide = self.action == "HIDE" or (self.action == "TOGGLE" and viewport.is_shown(context.scene))
        if hide:
            n = viewport.restore(context)
            self.report({"INFO"}, f"Relight: viewport shading restored ({n} view(s))")
            return {"FINISHED"}
        if not viewport.show_radiosity(context):
            self.report({"ERROR"}, "No 3D Viewport to show the radiosity in")
            return {"CANCELLED"}
        return {"FINISHED"}


class RELIGHT_OT_warning_details(bpy.types.Operator):
    """A warning of the last solve, in full"""
    bl_idname = "relight.warning_details"
    bl_label = "Warning"
    bl_options = {"INTERNAL"}

    index: IntProperty(name="Warning", default=0, min=0)

    @classmethod
    def description(cls, context, properties):
        return for_addon(_warning(context, properties.index)) or "A warning of the last solve"

    def execute(self, context):
        text = _warning(context, self.index)
        if not text:
            return {"CANCELLED"}
        self.report({"WARNING"}, for_addon(text))  # the status bar and the Info editor keep it whole
        return {"FINISHED"}


class RELIGHT_OT_warnings_popup(bpy.types.Operator):
    """Every warning of the last solve, in full"""
    bl_idname = "relight.warnings_popup"
    bl_label = "Relight: the last solve's warnings"
    bl_options = {"INTERNAL"}

    def invoke(self, context, event):
        return context.window_manager.invoke_popup(self, width=560)

    def draw(self, context):
        col = self.layout.column(align=True)
        for w in (w for w in context.scene.relight.last_warnings.split("\n") if w):
            for k, line in enumerate(textwrap.wrap(for_addon(w), 90) or [""]):
                col.label(text=line, icon="DOT" if k == 0 else "BLANK1")
            col.separator()

    def execute(self, context):
        for w in (w for w in context.scene.relight.last_warnings.split("\n") if w):
            self.report({"INFO"}, for_addon(w))  # (headless, or from a script: the Info editor has them)
        return {"FINISHED"}


def _warning(context, index) -> str:
    lines = [w for w in context.scene.relight.last_warnings.split("\n") if w]
    return lines[index] if 0 <= index < len(lines) else ""


CLASSES = (
    RELIGHT_OT_warning_details,
    RELIGHT_OT_warnings_popup,
    RELIGHT_OT_paint_targets,
    RELIGHT_OT_fill_targets,
    RELIGHT_OT_clear_targets,
    RELIGHT_OT_select_faces,
    RELIGHT_OT_forbid_faces,
    RELIGHT_OT_solve,
    RELIGHT_OT_live,
    RELIGHT_OT_apply_configuration,
    RELIGHT_OT_clear_results,
    RELIGHT_OT_make_area_lights,
    RELIGHT_OT_keep_lamps,
    RELIGHT_OT_show_radiosity,
)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
