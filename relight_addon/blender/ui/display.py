"""The Results panel's View: how the 3D Viewports show the configuration shown (bpy).

``scene.relight_view`` holds the view the artist picks (pipeline/false_colour.py computes it): the
predicted light with an exposure (EV: radiance x 2^EV), the illuminance (lx) or the luminance
(cd/m^2) in false colour, the signed difference to the paint (%), or what was painted. Every view
but the predicted one at 0 EV (the ``relight_radiosity`` layer itself) is written as the corner
colour layer ``relight_display`` on each object the result covers (not on linked meshes: skipped
and named; a mesh shared by several objects shows the first one's values, as the radiosity layer
does) and made the active colour, which Solid shading with Color: Attribute shows. It is written
again when the view changes, when another row of the curve is shown (properties.apply_curve_point)
and when Show Radiosity shows the viewports; every apply of a configuration and Clear Results
remove it with the radiosity layer (results.remove_radiosity_layer).

Solid mode's attribute colours go through the scene's view transform, which would desaturate and
compress the false colours (AgX, Filmic). While a false-colour view is shown in viewports Relight
holds (viewport.show_radiosity), the scene's view transform is Standard, look None, exposure 0,
gamma 1; what the artist had is remembered in ``scene.relight_view.transform_restore`` (JSON, saved
with the file) and given back by a natural view (predicted, painted), Hide Radiosity and Clear
Results (viewport.restore), unless the artist set another view transform meanwhile (theirs stays).
"""
from __future__ import annotations

import json
import textwrap

import bpy
import bpy.utils.previews
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, PointerProperty, StringProperty

from ...engine.scene import SceneError
from ...pipeline import false_colour as fc
from .. import layers, meshes, results

#: the scene's colour management while a false-colour view is shown
STANDARD = {"view_transform": "Standard", "look": "None", "exposure": 0.0, "gamma": 1.0}

MODE_ITEMS = [
    ("PREDICTED", "Predicted", "The predicted light, radiance x 2^Exposure, through the scene's view transform"),
    ("ILLUMINANCE", "Illuminance (lx)", "False colour: the light arriving at each face, lx (grey: a face too dark "
                                        "to read it from)"),
    ("LUMINANCE", "Luminance (cd/m²)", "False colour: each face's luminance, cd/m²"),
    ("DIFFERENCE", "Difference to Paint (%)", "False colour: predicted against painted brightness on painted "
                                              "faces, % (blue: darker, red: brighter than painted)"),
    ("PAINTED", "Painted", "What was painted (radiance x 2^Exposure; dark grey: not painted)"),
]
MODE_NAMES = {key: name for key, name, _ in MODE_ITEMS}
TITLES = {"ILLUMINANCE": "Illuminance", "LUMINANCE": "Luminance", "DIFFERENCE": "Predicted vs painted"}
#: what the grey faces of a false-colour view are
GREY = {"ILLUMINANCE": "Grey: too dark to read its light", "DIFFERENCE": "Grey: not painted"}
#: the scale's maximum of each false-colour view (0 = automatic)
MAX_PROPS = {"ILLUMINANCE": "illuminance_max", "LUMINANCE": "luminance_max", "DIFFERENCE": "difference_max"}


def _update(self, context):
    refresh(context.scene)


class RELIGHT_ViewSettings(bpy.types.PropertyGroup):
    """How the viewports show the configuration shown (scene.relight_view)."""
    mode: EnumProperty(name="View", items=MODE_ITEMS, default="PREDICTED", update=_update,
                       description="What the 3D Viewports show of the configuration shown (Show Radiosity)")
    exposure: FloatProperty(name="Exposure", default=0.0, min=-20.0, max=20.0, soft_min=-10.0, soft_max=10.0,
                            step=50, precision=1, update=_update,
                            description="Stops: the radiance shown is multiplied by 2^Exposure (the scene's own "
                                        "colour management is left as it is)")
    illuminance_max: FloatProperty(name="Max", default=0.0, min=0.0, soft_max=5000.0, precision=0, update=_update,
                                   description="Top of the illuminance scale, lx (0 = automatic: a round number "
                                               "above the targets and 95 % of the surfaces)")
    luminance_max: FloatProperty(name="Max", default=0.0, min=0.0, soft_max=1000.0, precision=1, update=_update,
                                 description="Top of the luminance scale, cd/m² (0 = automatic: a round number "
                                             "above the targets and 95 % of the surfaces)")
    difference_max: FloatProperty(name="Max", default=0.0, min=0.0, soft_max=100.0, precision=0, update=_update,
                                  description="Ends of the difference scale, +- % (0 = automatic: a round number "
                                              "above 95 % of the painted faces)")
    log: BoolProperty(name="Logarithmic", default=False, update=_update,
                      description=f"A logarithmic scale over {fc.LOG_DECADES} decades below the max (illuminance "
                                  "and luminance)")
    scale_used: FloatProperty(name="Max Used", default=0.0, options={"HIDDEN"},
                              description="The top of the scale the view shown uses")
    message: StringProperty(name="Message", default="",
                            description="Why the view is not shown, or which objects it skips, one per line")
    transform_restore: StringProperty(name="View Transform to Restore", default="",
                                      description="The scene's view transform, look, exposure and gamma before a "
                                                  "false-colour view set Standard (JSON); given back by the "
                                                  "predicted view, Hide Radiosity and Clear Results")


# --- the scene's view transform ------------------------------------------------------------------

def _colour_management(scene) -> dict:
    vs = scene.view_settings
    return {"view_transform": vs.view_transform, "look": vs.look, "exposure": float(vs.exposure),
            "gamma": float(vs.gamma)}


def _set_colour_management(scene, values) -> None:
    vs = scene.view_settings
    for key in ("view_transform", "look", "exposure", "gamma"):  # (the transform first: it lists the looks)
        try:
            setattr(vs, key, values[key])
        except (TypeError, KeyError, ValueError):  # a value this Blender does not know: left as it is
            pass


def use_standard(scene) -> None:
    """The scene's view transform Standard (look None, exposure 0, gamma 1), what it was remembered once."""
    v = scene.relight_view
    if not v.transform_restore:
        v.transform_restore = json.dumps(_colour_management(scene))
    if _colour_management(scene) != STANDARD:
        _set_colour_management(scene, STANDARD)


def give_back(scene) -> bool:
    """Give the scene the view transform it had before a false-colour view, and forget it; when the
    artist set another one meanwhile, theirs stays. Returns whether it was given back."""
    v = getattr(scene, "relight_view", None)
    if v is None or not v.transform_restore:
        return False
    text, v.transform_restore = v.transform_restore, ""
    try:
        old = json.loads(text)
    except ValueError:
        return False
    if not isinstance(old, dict) or _colour_management(scene) != STANDARD:
        return False
    _set_colour_management(scene, old)
    return True


# --- the layer -----------------------------------------------------------------------------------

def _held(scene) -> bool:
    """Do the viewports show Relight's colours (viewport.show_radiosity remembered their shading)?"""
    return bool(scene.relight.view_restore)


def _remove_layers(scene) -> None:
    """``relight_display`` off every local mesh, the radiosity layer active again where there is one."""
    for ob in scene.objects:
        if ob.type != "MESH" or ob.data is None or ob.data.library is not None:
            continue
        colors = ob.data.color_attributes
        attr = colors.get(layers.DISPLAY_ATTRIBUTE)
        if attr is None:
            continue
        colors.remove(attr)
        radiosity = colors.get(layers.RADIOSITY_ATTRIBUTE)
        if radiosity is not None:
            colors.active_color = radiosity
        ob.data.update()


def write_layer(ob, poly_colours, smooth=False) -> None:
    """Per-polygon scene-linear colours (n_polygons, 3) into ``relight_display`` (corner colours, flat,
    or per vertex as the radiosity layer: ``smooth``), made the active colour (the render colour kept)."""
    me = ob.data
    values = np.asarray(poly_colours, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(values)):
        raise SceneError(f"{ob.name}: refusing to write non-finite colours")
    if smooth:
        area = meshes.foreach_array(me.polygons, "area", len(me.polygons), np.float64)
        corner = results._vertex_smoothed_corners(me, values, area)
    else:
        corner = values[meshes.loop_polygons(me)[0]]
    colors = me.color_attributes
    attr = colors.get(layers.DISPLAY_ATTRIBUTE)
    if attr is not None and (attr.domain != "CORNER" or attr.data_type != "FLOAT_COLOR"):
        colors.remove(attr)
        attr = None
    if attr is None:
        render = colors.render_color_index
        attr = colors.new(layers.DISPLAY_ATTRIBUTE, "FLOAT_COLOR", "CORNER")
        if 0 <= render < len(colors):
            colors.render_color_index = render
    rgba = np.ones((len(me.loops), 4), dtype=np.float32)
    rgba[:, :3] = corner
    attr.data.foreach_set("color", rgba.ravel())
    colors.active_color = attr
    me.update()


def current_view(scene) -> tuple:
    """(the view ``scene.relight_view`` asks for of the configuration shown, the stored result), or
    (None, None) when none is shown. Raises SceneError / ValueError / KeyError (a result that cannot be
    read or lacks what the view needs)."""
    if results.RESULT_PROP not in scene.keys() or "relight_shown" not in scene.keys():
        return None, None
    v = scene.relight_view
    prop = MAX_PROPS.get(v.mode)
    data = results.load_result(scene)
    return fc.view(data, int(scene["relight_shown"]), v.mode, exposure=v.exposure,
                   vmax=getattr(v, prop) if prop else 0.0, log=v.log), data


def refresh(scene, held=None) -> list:
    """Show ``scene.relight_view``'s view of the configuration shown: write ``relight_display`` on each
    object the result covers (none for the predicted view at 0 EV: the radiosity layer is shown), and
    set or give back the scene's view transform (a false-colour view in viewports Relight holds:
    Standard). ``held``: whether the viewports show Relight's colours (default: as viewport.py
    remembers). Returns the messages about objects skipped (also in ``relight_view.message``)."""
    v = scene.relight_view
    held = _held(scene) if held is None else held
    skipped, plan = [], []
    shown = data = None
    try:  # everything computed and checked before anything is written
        if v.mode != "PREDICTED" or v.exposure != 0.0:
            shown, data = current_view(scene)
        objects = results.check_stored(scene, data, trusted=True) if shown else {}
        colours = None if shown is None else layers.srgb_to_linear(shown.colours) if shown.display else shown.colours
        if colours is not None and not np.all(np.isfinite(colours)):
            raise SceneError("the stored result gives non-finite colours: solve again")
        seen = set()
        for oi, ob in objects.items():
            if results.linked_message(ob):
                skipped.append(f"{ob.name}: its mesh is linked (read-only): not shown in this view")
            elif ob.data.name not in seen:  # (a shared mesh: the first object's values, as the radiosity layer)
                seen.add(ob.data.name)
                plan.append((ob, colours[data.polygon_offset[oi]:data.polygon_offset[oi + 1]]))
    except (SceneError, ValueError, KeyError) as exc:
        shown, plan = None, []
        skipped.append(f"{MODE_NAMES.get(v.mode, v.mode)} not shown: "
                       f"{exc.args[0] if isinstance(exc, KeyError) and exc.args else exc}")
    if shown is None:
        _remove_layers(scene)
    else:
        for ob, values in plan:
            write_layer(ob, values, shown.smooth)
        v.scale_used = shown.vmax
    if shown is not None and shown.display and held:
        use_standard(scene)
    else:
        give_back(scene)
    text = "\n".join(skipped)
    if text != v.message:  # (once, not at every step of a slider)
        for line in skipped:
            print(f"Relight: {line}")
        v.message = text
    return skipped


# --- the sub-panel ---------------------------------------------------------------------------------

_legend = {"previews": None, "key": None, "geometry": None}
#: the legend's size in UI units (template_icon draws a square of that many rows)
LEGEND_UNITS = 6


def legend_icon(context, view_settings) -> int:
    """icon_value of the legend of the false-colour view shown (re-rasterised when it changes); 0 without."""
    pcoll = _legend["previews"]
    v = view_settings
    if pcoll is None or v.mode not in fc.FALSE_COLOUR or not v.scale_used > 0:
        return 0
    ui = context.preferences.system.ui_scale
    size = max(int(round(LEGEND_UNITS * 20 * ui)), LEGEND_UNITS * 10)
    scale = 2 if ui >= 1.75 else 1
    log, diverging = v.log and v.mode != "DIFFERENCE", v.mode == "DIFFERENCE"
    key = (float(v.scale_used), log, diverging, size, scale)
    preview = pcoll.get("legend") or pcoll.new("legend")
    if _legend["key"] != key:
        pixels, geometry = fc.legend(v.scale_used, log, diverging, size=size, scale=scale)
        preview.image_size = (size, size)
        preview.image_pixels_float = pixels.ravel()
        _legend["key"], _legend["geometry"] = key, geometry
    return preview.icon_id


class RELIGHT_PT_view(bpy.types.Panel):
    bl_label = "View"
    bl_parent_id = "RELIGHT_PT_results"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Relight"  # the parent's tab (register)

    @classmethod
    def poll(cls, context):
        return len(context.scene.relight.curve) > 0 and hasattr(context.scene, "relight_view")

    def draw(self, context):
        layout = self.layout
        v = context.scene.relight_view
        layout.prop(v, "mode", text="")
        if v.mode in fc.FALSE_COLOUR:
            prop = MAX_PROPS[v.mode]
            row = layout.row(align=True)
            row.prop(v, prop)
            if v.mode != "DIFFERENCE":
                row.prop(v, "log", text="Log")
            used = f"{fc.label(v.scale_used)} {fc.UNITS[v.mode]}"
            scale = "log" if v.log and v.mode != "DIFFERENCE" else "linear"
            auto = " (auto)" if getattr(v, prop) == 0 else ""
            layout.label(text=f"{TITLES[v.mode]}, {scale}, {'+-' if v.mode == 'DIFFERENCE' else 'max '}{used}{auto}",
                         icon="COLOR")
            icon = legend_icon(context, v)
            if icon:
                layout.template_icon(icon_value=icon, scale=LEGEND_UNITS)
            if v.mode in GREY:
                layout.label(text=GREY[v.mode], icon="INFO")
        else:
            layout.prop(v, "exposure")
        for line in filter(None, v.message.split("\n")):  # (wrapped: the sidebar's labels do not wrap)
            col = layout.column(align=True)
            for k, part in enumerate(textwrap.wrap(line, 44)):
                col.label(text=part, icon="ERROR" if k == 0 else "BLANK1")
        if not _held(context.scene):
            layout.label(text="Show Radiosity to see it in the viewports", icon="HIDE_ON")


def register_panel(category="Relight"):
    """The sub-panel, in the Results panel's tab (after it: a child needs its parent registered)."""
    RELIGHT_PT_view.bl_category = category
    bpy.utils.register_class(RELIGHT_PT_view)
    if _legend["previews"] is None:
        _legend["previews"] = bpy.utils.previews.new()
        _legend["key"] = None


def unregister_panel():
    if RELIGHT_PT_view.is_registered:
        bpy.utils.unregister_class(RELIGHT_PT_view)
    if _legend["previews"] is not None:
        bpy.utils.previews.remove(_legend["previews"])
        _legend["previews"] = None
        _legend["key"] = None


def register(category="Relight"):
    bpy.utils.register_class(RELIGHT_ViewSettings)
    bpy.types.Scene.relight_view = PointerProperty(type=RELIGHT_ViewSettings)
    register_panel(category)


def unregister():
    unregister_panel()
    del bpy.types.Scene.relight_view
    bpy.utils.unregister_class(RELIGHT_ViewSettings)
