"""The "Match Cycles Light Paths" operator (relight.match_light_paths): the scene's Cycles light
paths set so that a render shows the light Relight predicts (light_paths.py)."""
import bpy

from .. import light_paths


class RELIGHT_OT_match_light_paths(bpy.types.Operator):
    """Set Cycles' light paths so that a render shows the light Relight predicts: no direct or
    indirect clamping, reflective caustics on, and enough Diffuse/Glossy/Total bounces for the
    scene's most reflective material (less than 0.5 % of the light left after them)"""

    bl_idname = "relight.match_light_paths"
    bl_label = "Match Cycles Light Paths"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        scene = context.scene
        rho = light_paths.scene_max_reflectance(context)
        changed = light_paths.match_light_paths(scene, rho)
        self.report({"INFO"}, f"Relight: {light_paths.describe(changed)} (most reflective material: {rho:.2f})")
        if scene.render.engine != "CYCLES":
            self.report({"WARNING"}, f"Relight: the scene renders with {scene.render.engine}; these settings are "
                                     "Cycles' (set Render Engine to Cycles to render the prediction)")
        return {"FINISHED"}


CLASSES = (RELIGHT_OT_match_light_paths,)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
