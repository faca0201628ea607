"""Scene and object properties of the Relight tab (thin: values only, no logic).

The job's options are generated from their declarations (``engine/options.py``: the job-wide
``JOB_PARAMS`` and every registered method's ``params``): one scene property per option, of the
option's name (an EnumProperty per method choice, listing its registry; Int/Float/Bool with the
declared default, range and description), plus ``use_<name>`` for an option drawn with a
checkbox (``ui="toggle"``: off = not set). ``ui_value`` reads a property back as the option's value.
"""
import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       IntProperty, PointerProperty, StringProperty)

from .. import results
from . import display
from ...engine import options as engine_options

INT_MAX = 2 ** 31 - 1  # Blender's IntProperty is 32-bit


def option_property(p):
    """The scene property of one declared option (engine.registry.Param)."""
    kw = dict(name=p.title, description=p.description)
    if p.type is bool:
        return BoolProperty(default=bool(p.default), **kw)
    if p.registry is not None:  # the enum items derive from the registry
        return EnumProperty(items=p.registry.enum_items(), default=p.default, **kw)
    if p.type is str:  # a free text (a fixture library: a folder or "builtin"); empty = None
        return StringProperty(default=p.default or "", **kw)
    if p.ui == "zero":
        default, lo = 0, 0
        kw["description"] += f" (0 = {p.none or 'automatic'})"
    else:
        default = p.default if p.default is not None else (p.ui_default if p.ui_default is not None else 0)
        lo = p.min
    if p.type is int:
        kw.update(default=int(default), min=int(lo) if lo is not None else -INT_MAX,
                  max=min(int(p.max), INT_MAX) if p.max is not None else INT_MAX)
        if p.soft_max is not None:
            kw["soft_max"] = int(p.soft_max)
        return IntProperty(**kw)
    kw.update(default=float(default), precision=3 if not default or abs(default) >= 0.01 else 5)
    if lo is not None:
        kw["min"] = float(lo)
    if p.max is not None:
        kw["max"] = float(p.max)
    if p.soft_max is not None:
        kw["soft_max"] = float(p.soft_max)
    if p.unit == "LENGTH":
        kw.update(subtype="DISTANCE", unit="LENGTH")
    elif p.unit == "FACTOR":
        kw["subtype"] = "FACTOR"
    return FloatProperty(**kw)


def option_properties():
    """{property name: property} of every declared option the scene shows (not ``ui="hidden"``)."""
    out = {}
    for p in engine_options.PARAMS.values():
        if p.ui == "hidden":
            continue
        if p.ui == "toggle":
            out["use_" + p.name] = BoolProperty(name=p.title, default=p.default is not None,
                                                description=f"Use this option: {p.description}")
        out[p.name] = option_property(p)
    return out


def ui_value(settings, p):
    """The option's value from the scene's property (None where the property says "not set")."""
    value = getattr(settings, p.name)
    if (p.ui == "zero" or (p.type is str and p.registry is None)) and not value:
        return None
    if p.ui == "toggle" and not getattr(settings, "use_" + p.name):
        return None
    if p.type is float:  # the property's float32, as the number shown (0.1, not 0.10000000149)
        return float(f"{value:.7g}")
    return value


_QUIET = {"on": False}


def set_curve_index(settings, index):
    """Select a row of the curve without applying it through the update callback."""
    _QUIET["on"] = True
    try:
        settings.curve_index = index
    finally:
        _QUIET["on"] = False


def show_row_panel(settings, panel) -> None:
    """The Results panel follows the row shown: its lights and its targets' light (``panel``: the
    stored result's ``meta["rows"]`` entry of that row; None, a result written before: unchanged)."""
    if panel is not None:
        settings.last_lights, settings.last_photometric = panel["lights"], panel["photometric"]


def apply_curve_point(context, index):
    """A click on a row of the list: show that configuration. When it cannot be shown (the scene
    changed since the solve, ...), the list goes back to the row the scene shows, and the panel
    (and, in a window, a popup) says why: the list never claims what the scene does not show."""
    if _QUIET["on"]:
        return
    settings = context.scene.relight
    try:
        show_row_panel(settings, results.apply_stored_point(context.scene, index)["panel"])
        display.refresh(context.scene)  # the view the Results panel's View asks for, of this row
        settings.apply_error = ""
        results.update_chart(context.scene)
    except (ValueError, KeyError) as exc:  # e.g. the stored result is missing or stale
        text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
        settings.apply_error = f"Configuration {index} not applied: {text}"
        shown = context.scene.get("relight_shown")
        set_curve_index(settings, int(shown) if shown is not None and 0 <= int(shown) < len(settings.curve) else -1)
        wm = getattr(context, "window_manager", None)
        if not bpy.app.background and wm is not None:
            wm.popup_menu(lambda menu, _c: menu.layout.label(text=settings.apply_error),
                          title="Relight", icon="ERROR")
        print(f"Relight: {settings.apply_error}")


def _apply_curve_point(self, context):
    apply_curve_point(context, self.curve_index)


class RELIGHT_CurvePoint(bpy.types.PropertyGroup):
    n_lights: IntProperty(name="Lights")
    error: FloatProperty(name="Error", description="Eq. 1 error, W/m^2")
    relative_error: FloatProperty(name="Relative error", subtype="FACTOR")
    n_negative: IntProperty(name="Negatives")
    curve_index: IntProperty(name="Curve Index", description="Position of this configuration on the whole curve")


def _get_target_scale(self):
    """The scene custom property ``relight_target_scale`` (the one source of truth, read by the CLI
    too), 1 when missing; a value that is not a finite number shows as 1 here and is refused, with
    its name, by a solve."""
    import math

    from ..layers import TARGET_SCALE_PROP

    value = self.id_data.get(TARGET_SCALE_PROP, 1.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return 1.0
    return float(value)


def _set_target_scale(self, value):
    from ..layers import TARGET_SCALE_PROP

    self.id_data[TARGET_SCALE_PROP] = float(value)


_SETTINGS = {
    "target_scale": FloatProperty(
        name="Target Scale", default=1.0, min=0.0, soft_max=100.0, get=_get_target_scale, set=_set_target_scale,
        description="Painted colours are radiance; the target radiosity is pi x colour x this scale (W/m^2). "
                    "Stored as the scene custom property relight_target_scale (the CLI reads the same)"),
    "paint_color": bpy.props.FloatVectorProperty(
        name="Target Colour", subtype="COLOR", size=3, default=(1.0, 1.0, 1.0), min=0.0, soft_max=1.0,
        description="The radiance Fill (Edit Mode) gives the selected faces, W/m^2/sr x Target Scale: the colour "
                    "they should show. A grey is read as a brightness on the face's own colour"),
    "paint_lux": FloatProperty(
        name="Illuminance", default=500.0, min=0.0, soft_max=5000.0, precision=0,
        description="Illuminance target, lx, that Fill Selected (lx) gives the selected faces: the light arriving "
                    "there, whatever the face's reflectance (EN 12464-1: 500 lx on a desk). Stored in the Face "
                    "attribute relight_target_lux"),
    # the job's options: rays_per_patch, max_patch_size, seed, solver, selection, distribution,
    # use_max_lights / max_lights, use_error_threshold / error_threshold, require_positive,
    # patch_model, estimator, and every method's parameters (tolerance, light_size, ...)
    **option_properties(),
    "curve": CollectionProperty(type=RELIGHT_CurvePoint),
    "curve_index": IntProperty(name="Configuration", default=0, update=_apply_curve_point,
                               description="The configuration shown in the scene"),
    "status": StringProperty(name="Status", default=""),
    "curve_result": StringProperty(name="Listed Result", default="",
                                   description="The id of the stored result the list of configurations shows"),
    "apply_error": StringProperty(name="Not Applied", default="",
                                  description="Why the configuration last clicked in the list was not applied"),
    # display: what the panel shows about the last solve, and the viewport shading to give back
    "last_summary": StringProperty(name="Last Solve", default="",
                                   description="Summary of the last Solve & Reduce (shown in the Results panel)"),
    "last_auto": StringProperty(name="Automatic Values", default="",
                                description="The values the last Solve & Reduce used for the options left "
                                            "automatic (JSON: option -> value, lengths in metres)"),
    "last_warnings": StringProperty(name="Warnings", default="",
                                    description="Warnings of the last Solve & Reduce, one per line"),
    "last_lights": StringProperty(name="Lights", default="",
                                  description="The last Solve & Reduce's final lights: name, kind, power (W), "
                                              "luminous flux (lm), temperature (K), one per line"),
    "last_photometric": StringProperty(name="Targets' Light", default="",
                                       description="The last Solve & Reduce's predicted illuminance on each target "
                                                   "object: name, mean and min (lx), U0, one per line"),
    "last_fixed_light": StringProperty(name="Scene Light", default="",
                                       description="The scene's own light the last Solve & Reduce kept (lamps, "
                                                   "World, emissive objects): kind, name and share of the "
                                                   "targets, one per line"),
    "view_restore": StringProperty(name="Viewport Shading to Restore", default="",
                                   description="The 3D Viewports' shading before Relight showed its radiosity "
                                               "(JSON); restored by Hide Radiosity and Clear Results"),
}

# built with type(): the generated annotations are a plain dict on every Python Blender ships
RELIGHT_SceneSettings = type("RELIGHT_SceneSettings", (bpy.types.PropertyGroup,),
                             {"__annotations__": _SETTINGS, "__module__": __name__,
                              "__doc__": "The Relight tab's scene settings (scene.relight)"})


CLASSES = (RELIGHT_CurvePoint, RELIGHT_SceneSettings)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.relight = PointerProperty(type=RELIGHT_SceneSettings)
    bpy.types.Object.relight_no_lights = BoolProperty(
        name="No Lights on This Object", default=False,
        description="No face of this object may become a light (it still reflects and occludes)")
    bpy.types.Object.relight_work_plane = BoolProperty(
        name="Work Plane", default=False,
        description="A plane where the light is measured: light passes through it and it reflects none into the "
                    "scene (give it illuminance targets: Fill Selected (lx)); Match Cycles Light Paths turns its Ray "
                    "Visibility off so that Cycles renders it so")


def unregister():
    del bpy.types.Object.relight_no_lights
    del bpy.types.Object.relight_work_plane
    del bpy.types.Scene.relight
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
