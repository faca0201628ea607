"""The "Relight" sidebar tab of the 3D View: Targets, Light Candidates, Solve, Results."""
import bpy

from .. import export, results


def _counts(context):
    """(target faces, candidate faces, faces) over the scene's mesh objects, from the base meshes."""
    targets = candidates = faces = 0
    for obj in context.scene.objects:
        if obj.type != "MESH" or obj.hide_render:
            continue
        n = len(obj.data.polygons)
        faces += n
        targets += int(export.face_flags(obj, "target").sum())
        candidates += int(export.face_flags(obj, "candidate").sum())
    return targets, candidates, faces


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
        t, c, f = _counts(context)
        row = layout.row()
        row.label(text=f"{t} target(s)", icon="BRUSH_DATA")
        row.label(text=f"{c} / {f} candidates", icon="LIGHT_AREA")


class RELIGHT_PT_targets(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Targets"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.relight
        layout.prop(settings, "target_scale")
        layout.operator("relight.paint_targets", icon="BRUSH_DATA")
        row = layout.row(align=True)
        row.prop(settings, "paint_color", text="")
        row.operator("relight.fill_targets", text="Fill Selected").unpaint = False
        row.operator("relight.fill_targets", text="Unpaint").unpaint = True
        row = layout.row(align=True)
        row.operator("relight.select_faces", text="Select Targets", icon="RESTRICT_SELECT_OFF").kind = "TARGET"
        row.operator("relight.clear_targets", icon="X")


class RELIGHT_PT_candidates(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Light Candidates"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        obj = context.active_object
        if obj is not None and obj.type == "MESH":
            layout.prop(obj, "relight_no_lights")
        row = layout.row(align=True)
        row.operator("relight.forbid_faces", text="Forbid Selected").allow = False
        row.operator("relight.forbid_faces", text="Allow Selected").allow = True
        layout.operator("relight.select_faces", text="Select Forbidden", icon="RESTRICT_SELECT_OFF").kind = "FORBIDDEN"


class RELIGHT_PT_solve(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Solve"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.relight
        col = layout.column(align=True)
        col.prop(s, "rays_per_patch")
        col.prop(s, "max_patch_size")
        col.prop(s, "seed")
        layout.prop(s, "solver")
        layout.prop(s, "selection")
        layout.prop(s, "distribution")
        box = layout.box()
        box.label(text="Stop when")
        row = box.row(align=True)
        row.prop(s, "use_max_lights", text="")
        sub = row.row()
        sub.active = s.use_max_lights
        sub.prop(s, "max_lights")
        row = box.row(align=True)
        row.prop(s, "use_error_threshold", text="")
        sub = row.row()
        sub.active = s.use_error_threshold
        sub.prop(s, "error_threshold")
        box.prop(s, "require_positive")
        layout.operator("relight.solve", icon="LIGHT_SUN")


class RELIGHT_UL_curve(bpy.types.UIList):
    """The configurations of the error curve: lights, relative error, negatives."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname, index):
        row = layout.row(align=True)
        row.label(text=f"{item.n_lights} lights", icon="LIGHT_AREA" if item.n_negative == 0 else "ERROR")
        row.label(text=f"err {item.relative_error:.3g}")
        row.label(text=f"{item.n_negative} neg")


class RELIGHT_PT_results(RELIGHT_PT_base, bpy.types.Panel):
    bl_label = "Results"
    bl_parent_id = "RELIGHT_PT_main"

    def draw(self, context):
        layout = self.layout
        s = context.scene.relight
        layout.operator("relight.match_light_paths", icon="LIGHT")
        if len(s.curve) == 0:
            layout.label(text="No result yet")
            return
        icon = results.chart_icon(context.scene)
        if icon:
            layout.template_icon(icon_value=icon, scale=8.0)
        layout.template_list("RELIGHT_UL_curve", "", s, "curve", s, "curve_index", rows=6)
        row = layout.row(align=True)
        row.operator("relight.apply_configuration", text="Apply", icon="CHECKMARK").index = -1
        row.operator("relight.clear_results", icon="X")
        layout.operator("relight.select_faces", text="Select Light Faces", icon="RESTRICT_SELECT_OFF").kind = "LIGHT"
        row = layout.row(align=True)
        row.operator("relight.make_area_lights", icon="LIGHT_AREA")
        row.operator("relight.show_radiosity", icon="SHADING_SOLID")


CLASSES = (RELIGHT_PT_main, RELIGHT_PT_targets, RELIGHT_PT_candidates, RELIGHT_PT_solve,
           RELIGHT_UL_curve, RELIGHT_PT_results)
PANELS = [c for c in CLASSES if issubclass(c, bpy.types.Panel)]


def register(category="Relight"):
    for cls in PANELS:
        cls.bl_category = category
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
