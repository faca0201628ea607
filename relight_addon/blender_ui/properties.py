"""Scene and object properties of the Relight tab (thin: values only, no logic)."""
import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       IntProperty, PointerProperty, StringProperty)

from ..engine import options as engine_options
from ..engine.registry import DISTRIBUTIONS, SELECTIONS, SOLVERS  # the enum items derive from them


def _apply_curve_point(self, context):
    from . import operators  # late import: operators import this module

    operators.apply_curve_point(context, self.curve_index)


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

    from ..export import TARGET_SCALE_PROP

    value = self.id_data.get(TARGET_SCALE_PROP, 1.0)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return 1.0
    return float(value)


def _set_target_scale(self, value):
    from ..export import TARGET_SCALE_PROP

    self.id_data[TARGET_SCALE_PROP] = float(value)


class RELIGHT_SceneSettings(bpy.types.PropertyGroup):
    target_scale: FloatProperty(
        name="Target Scale", default=1.0, min=0.0, soft_max=100.0, get=_get_target_scale, set=_set_target_scale,
        description="Painted colours are radiance; the target radiosity is pi x colour x this scale (W/m^2). "
                    "Stored as the scene custom property relight_target_scale (the CLI reads the same)")
    paint_color: bpy.props.FloatVectorProperty(
        name="Target Colour", subtype="COLOR", size=3, default=(1.0, 1.0, 1.0), min=0.0, soft_max=1.0,
        description="Colour used by Fill Targets")
    rays_per_patch: IntProperty(
        name="Rays per Patch", default=engine_options.DEFAULT_RAYS_PER_PATCH, min=0, soft_max=65536,
        description="Form-factor quality: rays cast from every patch; 0 = automatic "
                    "(about 4 million rays in all, 1024 to 16384 per patch)")
    max_patch_size: FloatProperty(
        name="Max Patch Size", default=0.0, min=0.0, subtype="DISTANCE", unit="LENGTH",
        description="Faces larger than this are split into patches; 0 = automatic (scene diagonal / 20)")
    seed: IntProperty(name="Seed", default=0, min=0, description="Random seed: results are reproducible")
    solver: EnumProperty(name="Solver", items=SOLVERS.enum_items(), default=engine_options.DEFAULT_SOLVER)
    selection: EnumProperty(name="Selection", items=SELECTIONS.enum_items(), default=engine_options.DEFAULT_SELECTION)
    distribution: EnumProperty(name="Distribution", items=DISTRIBUTIONS.enum_items(),
                               default=engine_options.DEFAULT_DISTRIBUTION)
    use_max_lights: BoolProperty(name="Max Lights", default=True, description="Stop at this number of lights")
    max_lights: IntProperty(name="Max Lights", default=engine_options.DEFAULT_MAX_LIGHTS, min=1)
    use_error_threshold: BoolProperty(name="Error Threshold", default=False,
                                      description="Stop when the relative error would exceed this")
    error_threshold: FloatProperty(name="Relative Error", default=0.1, min=0.0, soft_max=1.0, subtype="FACTOR")
    require_positive: BoolProperty(name="No Negatives", default=True,
                                   description="The final configuration must have no negative exitance")
    curve: CollectionProperty(type=RELIGHT_CurvePoint)
    curve_index: IntProperty(name="Configuration", default=0, update=_apply_curve_point,
                             description="The configuration shown in the scene")
    status: StringProperty(name="Status", default="")
    # display: what the panel shows about the last solve, and the viewport shading to give back
    last_summary: StringProperty(name="Last Solve", default="",
                                 description="Summary of the last Solve & Reduce (shown in the Results panel)")
    last_warnings: StringProperty(name="Warnings", default="",
                                  description="Warnings of the last Solve & Reduce, one per line")
    view_restore: StringProperty(name="Viewport Shading to Restore", default="",
                                 description="The 3D Viewports' shading before Relight showed its radiosity "
                                             "(JSON); restored by Hide Radiosity and Clear Results")


CLASSES = (RELIGHT_CurvePoint, RELIGHT_SceneSettings)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.relight = PointerProperty(type=RELIGHT_SceneSettings)
    bpy.types.Object.relight_no_lights = BoolProperty(
        name="No Lights on This Object", default=False,
        description="No face of this object may become a light (it still reflects and occludes)")


def unregister():
    del bpy.types.Object.relight_no_lights
    del bpy.types.Scene.relight
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
