"""The camera-view target in Blender (issue 40): an image of the file painted in the Image Editor, a
reference picture loaded as targets, the solve reading it, and the predicted camera image (bpy).

- ``scene.relight_camera_target`` (RELIGHT_ViewTarget): the view-target image (a data-block of the file,
  packed), whether the solve uses it, the working resolution (pixels on the longer side).
- *New View Target* (relight.new_view_target): a float image at the working resolution and the
  camera's aspect, alpha 0 everywhere (every pixel free), opened in an Image Editor in Paint mode.
  A pixel's colour is the radiance the camera should see there, scene linear, in the render's
  units (W m^-2 sr^-1 per channel: the value a Cycles render of the file has there before the view
  transform, i.e. at Exposure 0); the editor shows it through the scene's view transform and
  Exposure, as it shows a render. Painting sets alpha 1 (a target); the Erase Alpha blend frees.
- *Load Reference* (relight.load_view_reference): an OpenEXR (linear) or PNG (through the scene's
  view transform, inverted: pipeline.view_targets.display_to_linear; AgX/Filmic refused) times
  2^Exposure, every pixel a target except where its own alpha, or the Mask's alpha (or its value
  for a mask without alpha), is 0; resized to the working resolution by pipeline.view_targets.view_spec
  (what ``solve --view-target`` reads, with the same refusals). It becomes a new view-target image:
  the earlier one stays in the file.
- Solve & Reduce (and Live's first, full solve) reads the image (camera_view.scene_view_target:
  image_view_target, the CLI's parser); their worker threads add the report's ``view_target``
  block, its notes and the predicted image (camera_view.predict_view; ``solved`` when a solve ran
  on the main thread: scripts, ``blender -b``); ``write_prediction`` makes
  the image "Relight Prediction" (the final configuration's radiance, alpha = the share of each
  pixel's rays that hit a surface), owned by the result (visibility.tag_owned: Clear Results
  removes it, results.clear_results), with the error over the painted pixels (the report's) that
  the Results panel shows (``draw_prediction``); shown beside the view target when an Image Editor
  shows it (else Show in Image Editor: a solve does not change the window's layout by itself).
- Live's first answer (a full solve) reads the view target too; its strokes keep the one that solve
  read (Live watches meshes, not images) and write no prediction: the earlier one goes with its
  result, and the next Solve & Reduce writes one again.
"""
from __future__ import annotations

import json
import os

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ...engine.scene import SceneError
from ...pipeline.view_targets import WORKING_SIDE, display_to_linear, resample, view_spec
from .. import camera_view, live
from ..visibility import owner_of, tag_owned

__all__ = ["solved", "write_prediction", "prediction_image", "draw_view_target",
           "draw_prediction", "register", "unregister"]

VIEW_TARGET_NAME = "Relight View Target"
PREDICTION_NAME = "Relight Prediction"
#: the brush made for painting a view target when the Blender running has none (Debian's 4.3 package
#: ships without the Essentials brushes: no paint mode has a brush there, a stroke paints nothing)
PAINT_BRUSH_NAME = "Relight View Paint"
#: the prediction image's custom property: the report's view_target block (JSON)
ERROR_PROP = "relight_view_error"


def _update_redraw(self, context):
    from .. import results

    results.redraw_sidebars()


class RELIGHT_ViewTarget(bpy.types.PropertyGroup):
    """The scene's camera-view target (scene.relight_camera_target)."""

    image: PointerProperty(
        type=bpy.types.Image, name="View Target", update=_update_redraw,
        description="The image the scene camera should see: colour = radiance (scene linear, the render's "
                    "units), alpha 0 = free pixel. New View Target or Load Reference make one")
    use: BoolProperty(name="Use in Solve", default=True,
                      description="Solve & Reduce asks for the view target's painted pixels (off: the image stays, "
                                  "unused)")
    resolution: IntProperty(
        name="Working Resolution", default=WORKING_SIDE, min=16, max=4096, soft_max=1920,
        description="Pixels on the longer side of the camera's image at which the view target is painted and "
                    "solved (the other side from the camera's aspect); more pixels cost more rows")


def _props(scene):
    return scene.relight_camera_target


def _one_line(exc) -> str:
    return " ".join(str(exc.args[0] if isinstance(exc, KeyError) and exc.args else exc).split())


def _refuse(op, exc):
    op.report({"ERROR"}, _one_line(exc))
    return {"CANCELLED"}


# --- the Image Editors ----------------------------------------------------------------------------

def _largest(areas):
    return max(areas, key=lambda a: a.width * a.height) if areas else None


def _editor_showing(screen, image):
    return next((a for a in screen.areas if a.type == "IMAGE_EDITOR" and a.spaces.active.image == image), None)


def show_image(context, image, paint=False, keep=None, only_beside=False):
    """Show ``image`` in an Image Editor of the window (Paint mode when ``paint``): the one showing it
    already, else one not showing ``keep`` (the image to stay in sight beside it), else a new one
    split off the editor showing ``keep`` (side by side), or off the largest 3D View.
    ``only_beside``: only when an editor shows ``keep`` (after a solve: the layout the artist chose
    is not changed otherwise). The area, or None (headless, or nothing shown)."""
    window = context.window
    if window is None or bpy.app.background:
        return None
    screen = window.screen
    beside = _editor_showing(screen, keep) if keep is not None else None
    if only_beside and beside is None:
        return None
    area = _editor_showing(screen, image)
    if area is None:
        area = next((a for a in screen.areas if a.type == "IMAGE_EDITOR" and a != beside
                     and (keep is None or a.spaces.active.image != keep)), None)
    if area is None:
        host = beside or _largest([a for a in screen.areas if a.type == "VIEW_3D"])
        if host is None:
            return None
        before = set(screen.areas[:])
        region = next((r for r in host.regions if r.type == "WINDOW"), None)
        with context.temp_override(window=window, screen=screen, area=host, region=region):
            bpy.ops.screen.area_split(direction="VERTICAL", factor=0.5)
        area = next((a for a in screen.areas if a not in before), None)
        if area is None:
            return None
        area.type = "IMAGE_EDITOR"
    space = area.spaces.active
    space.image = image
    space.ui_mode = "PAINT" if paint else "VIEW"
    area.tag_redraw()
    return area


def ensure_paint_brush(context, area) -> str:
    """The Image Editor's Paint mode with a brush: when the Blender running has none (its Essentials
    brushes missing), a plain one (PAINT_BRUSH_NAME, the file's own: an asset of the file on Blender
    4.3 and later, where a paint mode's brush is an asset, activated a moment later from a timer: in
    the operator that has just split the editor off, activating it crashes Blender 4.3). A sentence
    for the report when it did, else ''."""
    paint = context.scene.tool_settings.image_paint
    if paint.brush is not None:
        return ""
    brush = bpy.data.brushes.get(PAINT_BRUSH_NAME) or bpy.data.brushes.new(PAINT_BRUSH_NAME, mode="TEXTURE_PAINT")
    if not hasattr(bpy.ops.brush, "asset_activate"):  # (before 4.3: a paint mode's brush is set directly)
        paint.brush = brush
    else:
        if brush.asset_data is None:
            brush.asset_mark()
        image = area.spaces.active.image
        bpy.app.timers.register(lambda: _activate_brush(brush.name, image), first_interval=0.2)
    return (f"; this Blender has no paint brush (its Essentials brushes are missing): the brush {brush.name!r} "
            "was added to the file")


def _activate_brush(name, image):
    """(A timer's, once) the brush asset ``name`` of the file made the Image Editor's paint brush,
    in the editor showing ``image``."""
    window = bpy.context.window_manager.windows[0] if bpy.context.window_manager.windows else None
    area = _editor_showing(window.screen, image) if window is not None else None
    if area is None or bpy.data.brushes.get(name) is None:
        return None
    region = next((r for r in area.regions if r.type == "WINDOW"), None)
    with bpy.context.temp_override(window=window, screen=window.screen, area=area, region=region):
        bpy.ops.brush.asset_activate(asset_library_type="LOCAL", relative_asset_identifier=f"Brush/{name}")
    return None


# --- operators ----------------------------------------------------------------------------------

def _keep_earlier(props):
    """The view-target image being replaced stays in the file (a fake user), named in the report."""
    old = props.image
    if old is None:
        return ""
    old.use_fake_user = True
    return f"; the earlier view target {old.name!r} stays in the file"


class _CameraView:
    """An operator on the scene camera's view: greyed out, with the reason, without a scene camera."""

    @classmethod
    def poll(cls, context):
        if context.scene.camera is None:
            cls.poll_message_set("Set a scene camera (Scene > Camera): a view target is its image")
            return False
        return True


def _paint_in(context, image) -> str:
    """Show ``image`` in Paint mode with a brush (``ensure_paint_brush``'s sentence, or '')."""
    area = show_image(context, image, paint=True)
    return ensure_paint_brush(context, area) if area is not None else ""


class RELIGHT_OT_new_view_target(_CameraView, bpy.types.Operator):
    """Make an image of the camera's view to paint the light it should see: colour = radiance (scene
    linear, the render's units), painted pixels are targets, unpainted (alpha 0) pixels are free.
    Opens it in an Image Editor in Paint mode"""
    bl_idname = "relight.new_view_target"
    bl_label = "New View Target"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        scene = context.scene
        props = _props(scene)
        try:
            w, h = camera_view.camera_working_size(scene, props.resolution)
        except SceneError as exc:
            return _refuse(self, exc)
        old = props.image
        if old is not None and tuple(old.size) == (w, h):  # the camera's: painted on, not replaced
            brush = _paint_in(context, old)
            self.report({"INFO"}, f"Painting the view target {old.name!r} ({w} x {h}); colour = radiance the camera "
                                  f"should see (scene linear), Erase Alpha frees pixels{brush}")
            return {"FINISHED"}
        note = _keep_earlier(props)
        if old is not None:
            note = f" (the camera's aspect or the resolution changed: {old.size[0]} x {old.size[1]}){note}"
        img = camera_view.new_view_image(VIEW_TARGET_NAME, w, h)
        props.image = img
        note += _paint_in(context, img)
        self.report({"INFO"}, f"New view target {img.name!r}, {w} x {h}, every pixel free: paint the radiance the "
                              f"camera should see (scene linear, the render's units){note}")
        return {"FINISHED"}


def _mask_of(path, shape) -> np.ndarray:
    """(h, w) in [0, 1]: the mask image at ``path`` resized to ``shape`` (its alpha, or its value
    when its alpha is 1 everywhere). ValueError for an unreadable mask or another aspect."""
    rgba, _linear = camera_view.read_image(path)
    mh, mw = rgba.shape[:2]
    h, w = shape
    if abs((mw / mh) / (w / h) - 1) > 0.01:
        raise ValueError(f"the mask {os.path.basename(path)} is {mw} x {mh}, the reference {w} x {h}: give a mask "
                         f"of the reference's aspect")
    alpha = rgba[..., 3]
    value = alpha if np.any(alpha < 1) else rgba[..., :3].mean(axis=2)
    if not np.all(np.isfinite(value)):
        raise ValueError(f"the mask {os.path.basename(path)} holds NaN or infinite values")
    return np.clip(resample(np.clip(value, 0, 1)[..., None], h, w)[..., 0], 0.0, 1.0)


def reference_pixels(scene, path, exposure=0.0, mask=None, side=WORKING_SIDE) -> tuple:
    """The view target a reference picture asks for: (ViewSpec at ``side``, its RGBA (H, W, 4):
    radiance, alpha 1 painted / 0 free). ``path``: an OpenEXR (linear) or PNG (through the scene's
    view transform, inverted), times 2^``exposure``; painted where its alpha x ``mask``'s is not 0
    (view_spec: a working pixel is painted when its pixels' mean is at least 0.5). ValueError or
    SceneError (one line) for what the CLI refuses, or a bad mask."""
    camera = camera_view.read_camera(scene)
    rgba, linear = camera_view.read_image(path)
    if not np.all(np.isfinite(rgba)):
        raise ValueError(f"the reference {os.path.basename(path)} holds NaN or infinite values")
    rgb = rgba[..., :3] if linear else display_to_linear(rgba[..., :3], camera_view.view_settings(scene))
    if not np.isfinite(exposure):
        raise ValueError("the exposure is not a number")
    rgba = np.concatenate([rgb * 2.0 ** float(exposure), rgba[..., 3:]], axis=2)
    if mask:
        rgba[..., 3] *= _mask_of(mask, rgba.shape[:2])
    spec = view_spec(camera, rgba, True, {}, os.path.basename(path), side)
    out = np.concatenate([spec.radiance, spec.painted[..., None].astype(np.float64)], axis=2)
    return spec, out


class RELIGHT_OT_load_view_reference(_CameraView, bpy.types.Operator):
    """Load a picture (OpenEXR, linear radiance, or PNG through the scene's view transform) as the light
    the camera should see at every pixel, scaled by an exposure; an optional mask frees pixels
    (alpha or value 0). It becomes a new view-target image (an earlier one stays in the file)"""
    bl_idname = "relight.load_view_reference"
    bl_label = "Load Reference"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(subtype="FILE_PATH", options={"SKIP_SAVE"})
    filter_glob: StringProperty(default="*.exr;*.png", options={"HIDDEN"})
    exposure: FloatProperty(name="Exposure", default=0.0, soft_min=-10.0, soft_max=10.0, unit="NONE",
                            description="Stops: the picture's radiance times 2^Exposure is the target")
    mask: StringProperty(name="Mask", subtype="FILE_PATH", default="", options={"SKIP_SAVE"},
                         description="Optional image of the picture's aspect: its alpha (or its value, without "
                                     "alpha) 0 frees a pixel, 1 makes it a target")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        scene = context.scene
        props = _props(scene)
        path = bpy.path.abspath(self.filepath)
        mask = bpy.path.abspath(self.mask) if self.mask else None
        if not self.filepath:
            return _refuse(self, ValueError("no reference picture given (an OpenEXR or a PNG)"))
        try:
            spec, rgba = reference_pixels(scene, path, self.exposure, mask, props.resolution)
        except (SceneError, ValueError) as exc:
            return _refuse(self, exc)
        note = _keep_earlier(props)
        h, w = rgba.shape[:2]
        img = camera_view.new_view_image(f"{VIEW_TARGET_NAME} ({os.path.basename(path)})", w, h)
        camera_view.set_pixels(img, rgba)
        props.image = img
        note += _paint_in(context, img)
        painted = int(spec.painted.sum())
        self.report({"INFO"}, f"Reference {os.path.basename(path)} x 2^{self.exposure:g}: view target {img.name!r}, "
                              f"{w} x {h}, {painted} of {w * h} pixels targets{note}")
        return {"FINISHED"}


class RELIGHT_OT_show_view_target(bpy.types.Operator):
    """Show the view target (Paint mode) and the last solve's predicted camera image in Image Editors"""
    bl_idname = "relight.show_view_target"
    bl_label = "Show in Image Editor"

    @classmethod
    def poll(cls, context):
        return context.window is not None and (context.scene.relight_camera_target.image is not None
                                               or prediction_image(context.scene) is not None)

    def execute(self, context):
        shown, brush = show_images(context)
        self.report({"INFO"}, f"Shown: {', '.join(shown) if shown else 'nothing (no Image Editor can open here)'}"
                              f"{brush}")
        return {"FINISHED"}


def show_images(context, after_solve=False) -> tuple:
    """The view target (Paint mode, with a brush) and the prediction beside it, in Image Editors:
    (their names, ``ensure_paint_brush``'s sentence or ''). ``after_solve``: the prediction only,
    and only beside an editor that shows the view target."""
    painted, pred = _props(context.scene).image, prediction_image(context.scene)
    shown, brush = [], ""
    if not after_solve and painted is not None:
        area = show_image(context, painted, paint=True)
        if area is not None:
            shown.append(painted.name)
            brush = ensure_paint_brush(context, area)
    if pred is not None and show_image(context, pred, keep=painted, only_beside=after_solve) is not None:
        shown.append(pred.name)
    return shown, brush


# --- the solve ----------------------------------------------------------------------------------

def solved(job, outcome) -> bool:
    """After a solve with a view target (before it is stored): camera_view.predict_view, unless the
    solve's worker did it (Solve & Reduce's, Live's first). False without a view target."""
    return job.exp.faces.view_target is not None and camera_view.predict_view(outcome)


def prediction_image(scene):
    """The current result's prediction image, or None (by its owner mark: never by name alone)."""
    from ..results import result_id

    rid = result_id(scene)
    if rid is None:
        return None
    return next((img for img in bpy.data.images if ERROR_PROP in img.keys() and owner_of(img) == rid), None)


def write_prediction(context, outcome):
    """The final configuration's camera image as image "Relight Prediction" (radiance, premultiplied
    by the share of each pixel's rays that hit a surface), owned by the result shown (Clear Results
    removes it), packed, holding the report's view_target block; shown beside the view target when
    an Image Editor shows it."""
    from ..results import result_id

    rgba = getattr(outcome, "view_prediction", None)
    rid = result_id(context.scene)
    if rgba is None or rid is None:
        return None
    rgba = np.where(np.isfinite(rgba), rgba, 0.0)
    h, w = rgba.shape[:2]
    img = bpy.data.images.new(PREDICTION_NAME, w, h, alpha=True, float_buffer=True)
    img.alpha_mode = "PREMUL"
    img.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], dtype=np.float32).ravel())
    img.update()
    img.pack()
    img.use_fake_user = True  # (the file keeps it while no editor shows it; Clear removes it)
    tag_owned(img, rid)
    img[ERROR_PROP] = json.dumps(outcome.report.get("view_target") or {})
    show_images(context, after_solve=True)
    return img


# --- the sidebar ----------------------------------------------------------------------------------

def draw_view_target(layout, context):
    """The Targets panel's camera-view rows."""
    scene = context.scene
    props = _props(scene)
    box = layout.box()
    col = box.column(align=True)
    col.label(text="Camera View", icon="CAMERA_DATA")
    if scene.camera is None:
        col.label(text="Set a scene camera to paint its view", icon="INFO")
    col.template_ID(props, "image")
    if props.image is not None:
        img = props.image
        col.label(text=f"{img.size[0]} x {img.size[1]}, scene-linear radiance", icon="IMAGE_DATA")
        col.prop(props, "use")
    row = col.row(align=True)
    row.operator("relight.new_view_target", icon="BRUSH_DATA")
    row.operator("relight.load_view_reference", icon="FILEBROWSER")
    col.prop(props, "resolution")
    if props.image is not None or prediction_image(scene) is not None:
        col.operator("relight.show_view_target", icon="IMAGE")
    if props.image is not None and live.session(scene) is not None:
        col.label(text="Live: the view target as the last solve read it;", icon="INFO")
        col.label(text="strokes on the image: Solve & Reduce", icon="BLANK1")


def _error_line(block) -> str:
    if not block:
        return ""
    return (f"{100 * block['mean_relative_error']:.1f} % mean error over {block['seen']:,} of "
            f"{block['painted']:,} painted pixels (RMS {block['rms_error']:.3g} W/m\u00b2/sr)")


def draw_prediction(layout, context):
    """The Results panel's line on the camera view: the error over its painted pixels."""
    img = prediction_image(context.scene)
    if img is None:
        return
    try:
        line = _error_line(json.loads(img.get(ERROR_PROP) or "{}"))
    except (ValueError, KeyError, TypeError):
        line = ""
    col = layout.box().column(align=True)
    col.label(text=f"Camera view: {img.name} (final configuration)", icon="CAMERA_DATA")
    if line:
        col.label(text=line)
    col.operator("relight.show_view_target", icon="IMAGE")


# --- registration ---------------------------------------------------------------------------------

@bpy.app.handlers.persistent
def _pack_painted(*_args):
    """Before a save: a view target painted since it was packed is packed again (the file stores
    what was painted, not the image as it was made)."""
    for scene in bpy.data.scenes:
        img = getattr(scene, "relight_camera_target", None) and scene.relight_camera_target.image
        if img is not None and img.is_dirty and img.source in {"GENERATED", "FILE"} and img.library is None:
            img.pack()


CLASSES = (RELIGHT_ViewTarget, RELIGHT_OT_new_view_target, RELIGHT_OT_load_view_reference,
           RELIGHT_OT_show_view_target)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.relight_camera_target = PointerProperty(type=RELIGHT_ViewTarget)
    bpy.app.handlers.save_pre.append(_pack_painted)


def unregister():
    if _pack_painted in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.remove(_pack_painted)
    del bpy.types.Scene.relight_camera_target
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
