"""The "Relight" sidebar tab of the 3D View: Targets, Light Candidates, Solve, Results.

Written for the sidebar's default width (about 290 px): no label shares a row with a field
that would clip it, two buttons at most per row, hints say why a button is greyed out, and
the rows stay in place when a mesh becomes active. Every count also works in Edit Mode (read
from the edit BMesh). The error chart is rasterised by ``relight_addon.pipeline.chart`` at the panel's
width into a preview icon (never a data-block) and drawn with ``template_icon``.
"""
import json
import math
import textwrap

import bmesh
import bpy
import bpy.utils.previews
import numpy as np

from ...engine.lights.kind import lamp_kind_of_type
from ...pipeline import chart
from ...pipeline.report import SCHEDULE_LINE
from ...pipeline.notes import sidebar_lines
from .. import layers, results, visibility
from ...engine.formfactors import auto_rays_per_patch
from . import view_target_ops, viewport

#: beyond this many faces in Edit Mode, counts are not read from the BMesh on every redraw
EDIT_COUNT_LIMIT = 200_000

_last_object_mode_counts = {}  # object name -> (targets, candidates, faces), for Blender < 4.5


def _bmesh_counts(obj):
    """(targets, candidates or None, faces) of a mesh in Edit Mode, read from its BMesh.
    Candidates are None when this Blender's BMesh cannot read boolean layers (before 4.5)."""
    bm = bmesh.from_edit_mesh(obj.data)
    faces = len(bm.faces)
    if faces > EDIT_COUNT_LIMIT:
        return None, None, faces
    loop_layers = bm.loops.layers
    tl = loop_layers.float_color.get(layers.TARGET_ATTRIBUTE) or loop_layers.color.get(layers.TARGET_ATTRIBUTE)
    lux = bm.faces.layers.float.get(layers.LUX_ATTRIBUTE)  # (illuminance targets count too)
    targets = 0
    if tl is not None or lux is not None:
        for f in bm.faces:
            loops = f.loops
            if (lux is not None and f[lux] > 0) or (
                    tl is not None and sum(min(max(loop[tl][3], 0.0), 1.0) for loop in loops) >= 0.5 * len(loops)):
                targets += 1
    if layers.no_lights(obj):
        return targets, 0, faces
    bool_layers = getattr(bm.faces.layers, "bool", None)
    if bool_layers is None:
        return targets, (faces if layers.FORBIDDEN_ATTRIBUTE not in obj.data.attributes else None), faces
    fl = bool_layers.get(layers.FORBIDDEN_ATTRIBUTE)
    forbidden = sum(1 for f in bm.faces if f[fl]) if fl is not None else 0
    return targets, faces - forbidden, faces


def object_counts(obj):
    """(targets, candidates, faces, note) of one mesh object; None counts are unknown."""
    if obj.mode == "EDIT" and obj.data.is_editmode:
        t, c, f = _bmesh_counts(obj)
        note = None
        if t is None:
            note = f"{obj.name}: too large to count in Edit Mode"
        elif c is None:
            old = _last_object_mode_counts.get(obj.name)
            c = old[1] if old is not None and old[2] == f else None
            note = "Light candidates are counted again on leaving Edit Mode"
        return t, c, f, note
    t = int(layers.face_flags(obj, "target").sum())
    c = int(layers.face_flags(obj, "candidate").sum())
    f = len(obj.data.polygons)
    _last_object_mode_counts[obj.name] = (t, c, f)
    return t, c, f, None


def _counts(context):
    """(target faces, candidate faces, faces, notes) over the mesh objects a solve exports
    (visibility.exported_objects); a count is None when some object's share is unknown (see
    object_counts)."""
    targets = candidates = faces = 0
    notes = []
    for obj in visibility.exported_objects(context):
        t, c, f, note = object_counts(obj)
        faces += f
        targets = None if targets is None or t is None else targets + t
        candidates = None if candidates is None or c is None else candidates + c
        if note and note not in notes:
            notes.append(note)
    return targets, candidates, faces, notes


def effective_max_patch_size(scene):
    """(metres, source) the solve uses when Max Patch Size is 0: the scene's
    ``relight_max_patch_size`` ("scene"), else the last solve's automatic value ("last solve": the
    diagonal of the region that decides the answer / 20, engine.extent), else (None, "auto")."""
    size = layers.scene_settings(scene).get("max_patch_size")
    if size:
        return float(size), "scene"
    used = last_auto(scene.relight).get("max_patch_size")
    return (float(used), "last solve") if used else (None, "auto")


def last_auto(settings) -> dict:
    """{option: the value the last solve used} for the options left automatic (``last_auto``)."""
    try:
        out = json.loads(settings.last_auto or "{}")
    except ValueError:
        return {}
    return out if isinstance(out, dict) else {}


def auto_label(settings, p) -> str:
    """An automatic option's label: the value the last solve used when there is one."""
    v = last_auto(settings).get(p.name)
    if not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        return f"{p.title}: Auto"
    return f"{p.title}: Auto ({_fmt_length(v) if p.unit == 'LENGTH' else f'{v:g}'})"


def _fmt_length(m):
    if m is None:
        return "?"
    return f"{m * 100:.3g} cm" if m < 1 else f"{m:.3g} m"


def hints(context):
    """The hint texts the panels show for the current context (used by the GUI test)."""
    out = []
    obj = context.active_object
    if obj is None or obj.type != "MESH":
        out.append("Select a mesh object")
    if context.mode != "EDIT_MESH":
        out.append("Tab into Edit Mode to fill or forbid selected faces")
    return out


def _wrap(layout, text, context, icon="NONE", width_px=None):
    """Labels wrapped to the region's width (Blender's labels do not wrap)."""
    ui = context.preferences.system.ui_scale
    width_px = width_px or context.region.width - 50 * ui
    chars = max(16, int(width_px / (6.3 * ui)))
    col = layout.column(align=True)
    for k, line in enumerate(textwrap.wrap(text, chars) or [""]):
        col.label(text=line, icon=icon if k == 0 else "BLANK1" if icon != "NONE" else "NONE")
    return col


#: how the sidebar draws each fix a warning's line names (pipeline.notes.FIXES): on the row under it
FIX_BUTTONS = {
    "light_paths": ("operator", "relight.match_light_paths", "Match Cycles Light Paths", "LIGHT"),
    "more_lights": ("prop", "max_lights", None, None),
}


def draw_warnings(layout, settings, warnings):
    """The solve's warnings as the sidebar shows them (pipeline.notes): at most three short lines,
    the most consequential first, each with the button that fixes it under it (once: two lines
    that Match Cycles Light Paths fixes get one button, under the first; a click on a line puts
    its whole text in the status bar; its tooltip is the whole text), and Details for all."""
    col = layout.column(align=True)
    fixes = set()
    for line in sidebar_lines(warnings):
        col.operator("relight.warning_details", text=line.text, icon="ERROR", emboss=False).index = line.index
        fix = FIX_BUTTONS.get(line.fix) if line.fix not in fixes else None  # (a fix once: under its first line)
        fixes.add(line.fix)
        if fix is not None:
            kind, name, label, icon = fix
            if kind == "operator":
                col.operator(name, text=label, icon=icon)
            else:
                col.prop(settings, name)
    if warnings:
        col.operator("relight.warnings_popup", text=f"Details ({len(warnings)})", icon="INFO")


def photometric_line(name, mean, low, u0, target, patches) -> str:
    """A target object's predicted illuminance as the Results panel lists it: mean (and the lux
    asked beside it), min and U0; U0 over a single patch says nothing, so it is not given."""
    asked = f" (asked {float(target):.0f})" if target else ""
    spread = f", min {float(low):.0f}, U0 {float(u0):.2f}" if int(patches) > 1 else ", 1 patch: no U0"
    return f"{name}: {float(mean):.0f} lx{asked}{spread}"


class RELIGHT_PT_base:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Relight"  # replaced from the preferences at registration


class RELIGHT_PT_main(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Relight"

    def draw(self, context):
        layout = self.layout
        if context.mode not in {"OBJECT", "EDIT_MESH", "PAINT_VERTEX"}:
            layout.label(text="Object, Edit or Vertex Paint mode", icon="INFO")
        t, c, f, notes = _counts(context)
        col = layout.column(align=True)
        col.label(text=f"{'?' if t is None else t} target faces", icon="BRUSH_DATA")
        # two lines whatever the mode, so that nothing below moves; a clock when the count of
        # an object in Edit Mode is the one from Object Mode (the Light Candidates panel says so)
        col.label(text=f"{'?' if c is None else c} of {f} faces may be lights",
                  icon="TIME" if notes else "LIGHT_AREA")


def faces_selected(n) -> str:
    return f"{n} face selected" if n == 1 else f"{n} faces selected"


def _mesh(context):
    obj = context.active_object
    return obj if obj is not None and obj.type == "MESH" else None


class RELIGHT_PT_targets(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Targets"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.relight
        obj = _mesh(context)
        edit = context.mode == "EDIT_MESH"
        if obj is None:
            layout.label(text="Select a mesh object", icon="INFO")
        else:
            t = object_counts(obj)[0]
            layout.label(text=f"{obj.name}: {'?' if t is None else t} targets", icon="MESH_DATA")
        layout.prop(settings, "target_scale")
        layout.operator("relight.paint_targets", icon="BRUSH_DATA")
        if edit and obj is not None:
            layout.label(text=faces_selected(obj.data.total_face_sel), icon="FACESEL")
        else:
            layout.label(text="Edit Mode: fill selected faces", icon="EDITMODE_HLT")
        row = layout.row(align=True)
        row.prop(settings, "paint_color", text="")
        row.operator("relight.fill_targets", text="Fill").unpaint = False
        row = layout.row(align=True)
        row.prop(settings, "paint_lux", text="lx")
        row.operator("relight.fill_targets", text="Fill lx").illuminance = True
        layout.operator("relight.fill_targets", text="Unpaint", icon="X").unpaint = True
        row = layout.row(align=True)
        row.operator("relight.select_faces", text="Select Targets").kind = "TARGET"
        row.operator("relight.clear_targets", text="Clear Targets")
        view_target_ops.draw_view_target(layout, context)


class RELIGHT_PT_candidates(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Light Candidates"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        obj = _mesh(context)
        if obj is not None:
            layout.prop(obj, "relight_no_lights")
            layout.prop(obj, "relight_work_plane")
        else:  # (as many rows as with a mesh: the buttons below stay in place)
            layout.label(text="Select a mesh object", icon="INFO")
            layout.label(text="")
        if context.mode == "EDIT_MESH" and obj is not None:
            note = object_counts(obj)[3]
            if note:
                layout.label(text="Counted again on leaving Edit Mode", icon="TIME")
            else:
                layout.label(text=faces_selected(obj.data.total_face_sel), icon="FACESEL")
        else:
            layout.label(text="Edit Mode: forbid selected faces", icon="EDITMODE_HLT")
        row = layout.row(align=True)
        row.operator("relight.forbid_faces", text="Forbid").allow = False
        row.operator("relight.forbid_faces", text="Allow").allow = True
        layout.operator("relight.select_faces", text="Select Forbidden").kind = "FORBIDDEN"
        draw_light_kinds(layout, context.scene.relight)


def draw_light_kinds(layout, settings):
    """The kinds of candidate lights the solve offers on the surfaces that may hold lights: their
    own cells, and lamps mounted in front of them (engine/candidate_lamps.py); greyed out, with
    why, when the chosen selection runs on single-scale cells (the paper's heuristics)."""
    from . import operators
    from ...engine.options import LAMP_OPTIONS, PARAMS

    options = operators.job_options(settings, validate=False)
    box = layout.box()
    used = options.uses("surface_lights")
    box.label(text="Offer" if used else "Offer (this selection: cells only)", icon="LIGHT_SPOT")
    col = box.column(align=True)
    col.active = used
    names = ("surface_lights",) + LAMP_OPTIONS
    for k in range(0, len(names), 2):  # two a row: four in a row are cut at the sidebar's default width
        row = col.row(align=True)
        for name in names[k:k + 2]:
            row.prop(settings, name, toggle=True)
    col.prop(settings, "fixtures", text="Fixtures", icon="FILE_FOLDER")  # a library folder or "builtin" (empty: none)
    sub = col.column(align=True)
    sub.active = used and options.uses("lamp_drop")
    draw_option(sub, settings, PARAMS["lamp_drop"])
    draw_option(sub, settings, PARAMS["max_lamps"])
    sub.prop(settings, "refine_lamps")


def draw_option(layout, settings, p):
    """The row of one declared option (engine/options.py): a checkbox beside the field for an
    option that may be off, "Auto" in the label of one whose 0 means automatic."""
    if p.ui == "toggle":
        row = layout.row(align=True)
        row.prop(settings, "use_" + p.name, text="")
        sub = row.row()
        sub.active = getattr(settings, "use_" + p.name)
        sub.prop(settings, p.name)
    elif p.ui == "zero" and getattr(settings, p.name) == 0:
        layout.prop(settings, p.name, text=auto_label(settings, p))
    else:
        layout.prop(settings, p.name)


def draw_method(layout, settings, kind, options, note=""):
    """A method choice (its enum, label above: the sidebar is narrow) and, under it, the rows of
    the chosen method's parameters; greyed out (with ``note``) when the chosen methods do not
    use the choice."""
    from ...engine.options import method_params

    col = layout.column(align=True)
    col.active = options.uses(kind)
    col.label(text=settings.bl_rna.properties[kind].name if col.active or not note else note)
    col.prop(settings, kind, text="")
    for p in method_params(kind, getattr(settings, kind)):
        draw_option(col, settings, p)
    return col


class RELIGHT_PT_model(RELIGHT_PT_base, bpy.types.Panel):
    """How the scene becomes patches and lights, and how the form factors are estimated."""
    bl_label = "Model"
    bl_parent_id = "RELIGHT_PT_main"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from . import operators

        s = context.scene.relight
        options = operators.job_options(s, validate=False)
        for kind in ("patch_model", "estimator"):
            draw_method(self.layout, s, kind, options)


class RELIGHT_PT_solve(RELIGHT_PT_base, bpy.types.Panel):
    """The artist's choices: how the lights are chosen, when to stop, and Solve & Reduce; the
    rest (quality, seed, the paper's solver and distribution) is under Advanced."""
    bl_label = "Solve"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        from . import operators
        from ...engine.options import PARAMS

        layout = self.layout
        s = context.scene.relight
        options = operators.job_options(s, validate=False)
        draw_method(layout, s, "selection", options)
        draw_method(layout, s, "light_colour", options)
        box = layout.box()
        stops = options.uses("max_lights")
        if stops:  # (least-power: its tolerance decides)
            box.label(text="Stop when")
            draw_option(box.column(), s, PARAMS["max_lights"])
            draw_option(box.column(), s, PARAMS["error_threshold"])
        box.prop(s, "require_positive")
        state = operators.solve_state(context.scene)
        if state is not None:
            layout.progress(factor=state["fraction"], type="BAR",
                            text=f"{state['stage']} {100 * state['fraction']:.0f} %")
            layout.label(text="Cancelling..." if state["cancelling"] else "ESC cancels", icon="CANCEL")
        else:
            row = layout.row()
            row.scale_y = 1.4
            row.operator("relight.solve", icon="LIGHT_SUN")
        draw_live(layout, context)


#: the rows of Live's status in the sidebar (blender/live.status_parts, wrapped)
STATUS_ROWS = 4


def draw_live(layout, context):
    """The Live toggle and, while it is on, what it is doing (blender/live.py)."""
    from .. import live

    s = live.session(context.scene)
    row = layout.row()
    row.operator("relight.live", text="Live: On (ESC: off)" if s else "Live", icon="PAUSE" if s else "PLAY",
                 depress=s is not None)
    if s is not None:
        # Always STATUS_ROWS rows while Live is on: the panel keeps its height as the status
        # changes (a panel that grows between redraws drew its lines under the next header).
        lines = [ln for part in live.status_parts(s) for ln in textwrap.wrap(part, 44)]
        if len(lines) > STATUS_ROWS:
            lines = lines[:STATUS_ROWS - 1] + [lines[STATUS_ROWS - 1][:41] + "..."]
        col = layout.column(align=True)
        for line in lines + [""] * (STATUS_ROWS - len(lines)):
            col.label(text=line)


class RELIGHT_PT_solve_advanced(RELIGHT_PT_base, bpy.types.Panel):
    """Quality, seed and the paper's internals; only what the chosen selection uses."""
    bl_label = "Advanced"
    bl_parent_id = "RELIGHT_PT_solve"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        from . import operators

        layout = self.layout
        s = context.scene.relight
        col = layout.column(align=True)
        if s.rays_per_patch == 0:  # the last solve's, else the estimate for a solve (kernel pairs)
            used = last_auto(s).get("rays_per_patch")
            rays = f"{used:g}" if used else f"~{auto_rays_per_patch(max(_counts(context)[2], 1), kernel=True)}"
            col.prop(s, "rays_per_patch", text=f"Rays: Auto ({rays})")
        else:
            col.prop(s, "rays_per_patch")
        if s.max_patch_size == 0:
            size, _source = effective_max_patch_size(context.scene)
            col.prop(s, "max_patch_size", text="Max Patch: Auto" + (f" ({_fmt_length(size)})" if size else ""))
        else:
            col.prop(s, "max_patch_size")
        col.prop(s, "seed")
        options = operators.job_options(s, validate=False)
        for kind in ("solver", "distribution"):
            if options.uses(kind):  # the Distribution only for a selection that distributes
                draw_method(layout, s, kind, options)


class RELIGHT_UL_curve(bpy.types.UIList):
    """The configurations of the error curve: lights, relative error, negatives."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        split = layout.split(factor=0.36)
        split.label(text=f"{item.n_lights}", icon="LIGHT_AREA" if item.n_negative == 0 else "ERROR")
        split = split.split(factor=0.55)
        split.label(text=f"{item.relative_error:.3f}")
        split.label(text=f"{item.n_negative} neg" if item.n_negative else "")


# --- the chart ---------------------------------------------------------------------------

_chart = {"previews": None, "key": None, "geometry": None}

#: chart height / width
CHART_ASPECT = 0.85


def chart_size(region_width, ui_scale):
    """(width, height, scale) of the chart image for a sidebar region this wide: the panel's
    inner width less template_icon's padding (measured in Blender 4.3: inner = region - 55 x
    UI scale; padding 0.15 UI units a side), so that the image is drawn about 1:1."""
    inner = region_width - 55 * ui_scale
    w = int(max(120, inner - 2 * 0.15 * 20 * ui_scale))
    return w, int(w * CHART_ASPECT), 2 if ui_scale >= 1.75 else 1


def chart_pixels(scene, width, height, scale=1):
    """(pixels, geometry) of the scene's error chart at this size, or None without a result."""
    d = results.chart_data(scene)
    if d is None:
        return None
    return chart.render(d["n_lights"], d["relative_error"], d["n_negative"], current=d["current"],
                        bound=d["bound"], size=(width, height), scale=scale)


def chart_icon(context):
    """icon_value of the chart preview at this region's width (re-rasterised only when the
    curve, the shown configuration or the width change); 0 without a result."""
    pcoll = _chart["previews"]
    if pcoll is None:
        return 0
    ui = context.preferences.system.ui_scale
    w, h, s = chart_size(context.region.width, ui)
    d = results.chart_data(context.scene)
    if d is None:
        return 0
    key = (id(d["n_lights"]), len(d["n_lights"]), float(np.nansum(d["relative_error"])), d["current"],
           None if d["bound"] is None else float(np.nansum(d["bound"])), w, h, s)
    preview = pcoll.get("chart") or pcoll.new("chart")
    if _chart["key"] != key:
        pixels, geometry = chart.render(d["n_lights"], d["relative_error"], d["n_negative"], current=d["current"],
                                        bound=d["bound"], size=(w, h), scale=s)
        preview.image_size = (w, h)
        preview.image_pixels_float = pixels.ravel()
        _chart["key"] = key
        _chart["geometry"] = dict(geometry, current=d["current"])
    return preview.icon_id


def last_chart_geometry():
    """Geometry of the chart last drawn (chart.render's, plus ``current``), for the GUI test."""
    return _chart["geometry"]


#: the icon of each kind of the scene's own light (pipeline.jobs.fixed_light)
#: the icons of the fixed light's rows that are not a scene lamp (a lamp's: its Blender type's)
FIXED_SOURCE_ICONS = {"world": "WORLD", "emission": "MESH_DATA"}


def fixed_light_icon(kind: str) -> str:
    """A fixed-light row's icon: a scene lamp's is its Blender Light type's (the report's kind is
    that type, lower case), the World's and the emissive faces' their own."""
    if lamp_kind_of_type(kind.upper()) is not None:
        return "LIGHT_" + kind.upper()
    return FIXED_SOURCE_ICONS.get(kind, "LIGHT")


class RELIGHT_PT_results(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Results"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.relight
        if len(s.curve) == 0:
            _wrap(layout, "No result yet: paint targets, then Solve & Reduce", context, icon="INFO")
            return
        layout.operator("relight.match_light_paths", icon="LIGHT")
        box = layout.box()
        summary = s.last_summary
        if not summary and 0 <= s.curve_index < len(s.curve):
            p = s.curve[s.curve_index]
            summary = f"{p.n_lights} lights, relative error {p.relative_error:.3g}"
        _wrap(box, summary, context, icon="CHECKMARK", width_px=context.region.width - 70)
        draw_warnings(box, s, [w for w in s.last_warnings.split("\n") if w])
        _draw_fixed_light(layout, s)
        icon = chart_icon(context)
        if icon:
            ui = context.preferences.system.ui_scale
            layout.template_icon(icon_value=icon, scale=(context.region.width - 55 * ui) / (20 * ui))
        if s.apply_error:  # the row last clicked could not be shown: the list went back to the one shown
            _wrap(layout, s.apply_error, context, icon="ERROR")
        if 0 <= s.curve_index < len(s.curve):
            p = s.curve[s.curve_index]
            neg = f", {p.n_negative} negative" if p.n_negative else ""
            layout.label(text=f"Shown: {p.n_lights} lights, error {p.relative_error:.3f}{neg}", icon="HIDE_OFF")
        view_target_ops.draw_prediction(layout, context)
        split = layout.split(factor=0.36)
        split.label(text="Lights")
        split = split.split(factor=0.55)
        split.label(text="Error")
        split.label(text="Neg.")
        layout.template_list("RELIGHT_UL_curve", "", s, "curve", s, "curve_index", rows=6)
        layout.operator("relight.clear_results", text="Clear Results", icon="X")  # (a click on a row shows it)
        col = layout.column(align=True)
        col.operator("relight.select_faces", text="Select Light Faces", icon="RESTRICT_SELECT_OFF").kind = "LIGHT"
        col.operator("relight.make_area_lights", icon="LIGHT_AREA")
        col.operator("relight.keep_lamps", icon="PINNED")
        shown = viewport.is_shown(context.scene)
        col.operator("relight.show_radiosity", text="Hide Radiosity" if shown else "Show Radiosity",
                     icon="HIDE_ON" if shown else "SHADING_SOLID")
        # the row shown: its light on the targets and its lights (under the list, which then stays in place
        # whichever row is picked)
        _draw_shown_light(layout, s)


def _draw_fixed_light(layout, s):
    """The scene's own light the solve kept: each lamp, the World, each emissive object, with its
    share of the targets."""
    rows = [line.split("\t") for line in s.last_fixed_light.split("\n") if line.count("\t") == 2]
    if rows:
        col = layout.box().column(align=True)
        col.label(text="Scene light kept (share of the targets)", icon="OUTLINER_OB_LIGHT")
        for kind, name, share in rows:
            col.label(text=f"{name}: {100 * float(share):.0f} %", icon=fixed_light_icon(kind))


def _draw_shown_light(layout, s):
    """The configuration shown: the predicted illuminance on the targets, and its lights' power
    and luminous flux (a blackbody light's temperature; an implausible one marked)."""
    rows = [line.split("\t") for line in s.last_photometric.split("\n") if line.count("\t") == 5]
    if rows:
        col = layout.box().column(align=True)
        col.label(text="Targets' illuminance (predicted)", icon="LIGHT_SUN")
        for row in rows:
            col.label(text=photometric_line(*row))
    rows = [line.split("\t") for line in s.last_lights.split("\n") if line.count("\t") == 5]
    if rows:
        col = layout.box().column(align=True)
        col.label(text="Lights shown", icon="OUTLINER_OB_LIGHT")
        for name, kind, watts, lm, kelvin, mark in rows[:8]:  # two short lines each: the sidebar is narrow
            col.label(text=f"{name} ({kind})", icon="ERROR" if mark else "DOT")
            col.label(text=f"{float(watts):.3g} W, {float(lm):.3g} lm" + (f", {kelvin} K" if kelvin else ""),
                      icon="BLANK1")
            if mark:
                col.label(text=f"implausible: {mark}", icon="BLANK1")
        if len(rows) > 8:
            col.label(text=f"... and {len(rows) - 8} more")
    schedule = [line.split("\t", 1)[1] for line in s.last_lights.split("\n") if line.startswith(SCHEDULE_LINE + "\t")]
    if schedule:  # the catalogue fixtures shown: per type how many, dimmed to what, lumens and watts
        col = layout.box().column(align=True)
        col.label(text="Fixture schedule", icon="LIGHT_POINT")
        for line in schedule:
            col.label(text=line)


CLASSES = (RELIGHT_PT_main, RELIGHT_PT_targets, RELIGHT_PT_candidates, RELIGHT_PT_model, RELIGHT_PT_solve,
           RELIGHT_PT_solve_advanced, RELIGHT_UL_curve, RELIGHT_PT_results)
PANELS = [c for c in CLASSES if issubclass(c, bpy.types.Panel)]


def register(category="Relight"):
    for cls in PANELS:
        cls.bl_category = category
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    if _chart["previews"] is None:
        _chart["previews"] = bpy.utils.previews.new()
        _chart["key"] = None


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    if _chart["previews"] is not None:
        bpy.utils.previews.remove(_chart["previews"])
        _chart["previews"] = None
        _chart["key"] = None
