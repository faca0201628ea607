"""The scene camera and a view target's image, read from Blender (bpy) for engine/targets/view.py:
``read_camera`` (an engine Camera of the scene's camera), ``read_image`` (an OpenEXR or PNG as RGBA
floats, row 0 at the top), ``view_settings`` (the scene's Color Management, for a PNG) and
``read_view_target`` (all three -> pipeline.view_targets.view_spec).

The add-on's view target is an image data-block of the file (``new_view_image``: float, scene
linear, packed), read by ``image_pixels`` / ``image_view_target`` and written by ``set_pixels``.
Float pixels (an OpenEXR's, a float data-block's) are premultiplied by their alpha, as Blender and
OpenEXR keep them: ``straight`` divides it out, so that a pixel painted at alpha 0.6 asks for its
colour, not 0.6 x its colour; a PNG's (byte) pixels are straight already."""
from __future__ import annotations

import os

import bpy
import numpy as np

from ..engine.scene import SceneError
from ..engine.targets.view import Camera
from ..pipeline.view_targets import WORKING_SIDE, predicted_rgba, view_notes, view_report, view_spec, working_size

__all__ = ["read_camera", "read_image", "write_image", "view_settings", "read_view_target", "straight",
           "camera_working_size", "new_view_image", "image_pixels", "set_pixels", "image_view_target",
           "scene_view_target", "predict_view"]

#: the image formats a view target is read from (Blender's file_format)
FORMATS = {"OPEN_EXR": True, "OPEN_EXR_MULTILAYER": True, "PNG": False}  # -> linear radiance


def read_camera(scene) -> Camera:
    """The scene camera as an engine Camera at the render resolution (its frame from Blender's own
    view_frame: sensor fit, shift, the pixel aspect). SceneError without a perspective camera."""
    cam = scene.camera
    if cam is None:
        raise SceneError(f"no camera: a view target is the image of the scene's camera; set one (Scene > Camera) "
                         f"in scene {scene.name!r}")
    if cam.type != "CAMERA" or cam.data.type != "PERSP":
        kind = cam.data.type.lower() if cam.type == "CAMERA" else cam.type.lower()
        raise SceneError(f"the scene camera {cam.name!r} is {kind}: a view target needs a perspective camera")
    corners = np.array([tuple(v) for v in cam.data.view_frame(scene=scene)], dtype=np.float64)  # local, z < 0
    depth = -corners[0, 2]
    lo, hi = corners[:, :2].min(axis=0) / depth, corners[:, :2].max(axis=0) / depth
    mw = np.array(cam.matrix_world, dtype=np.float64)
    axes = mw[:3, :3].T.copy()
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    r = scene.render
    w = max(1, int(r.resolution_x * r.resolution_percentage / 100))
    h = max(1, int(r.resolution_y * r.resolution_percentage / 100))
    return Camera(mw[:3, 3], axes, w, h, (hi - lo) / 2, (hi + lo) / 2)


def read_image(path) -> tuple:
    """((h, w, 4) float RGBA of the file at ``path``, row 0 at the top, values as stored: an
    OpenEXR's scene-linear floats (``straight``: its premultiplied alpha divided out), a PNG's
    display values in [0, 1]; linear: True for an OpenEXR).
    ValueError when it cannot be read or is neither OpenEXR nor PNG."""
    if not os.path.isfile(path):
        raise ValueError(f"the view target {path} does not exist")
    try:
        img = bpy.data.images.load(os.path.abspath(path), check_existing=False)
    except RuntimeError as exc:
        raise ValueError(f"the view target {path} cannot be read ({' '.join(str(exc).split())})") from None
    try:
        w, h = img.size  # (0 x 0: Blender could not decode it)
        if w == 0 or h == 0:
            raise ValueError(f"the view target {path} cannot be read (not an image Blender decodes)")
        fmt = img.file_format
        if fmt not in FORMATS:
            raise ValueError(f"the view target {path} is {fmt}: give an OpenEXR (linear radiance) or a PNG")
        img.colorspace_settings.name = "Non-Color"  # (the stored values, unconverted)
        px = np.empty(w * h * 4, dtype=np.float32)
        img.pixels.foreach_get(px)
        rgba = px.reshape(h, w, 4)[::-1].astype(np.float64)
        return (straight(rgba) if FORMATS[fmt] else rgba), FORMATS[fmt]
    finally:
        bpy.data.images.remove(img)


def view_settings(scene) -> dict:
    """The scene's Color Management, as pipeline.view_targets.display_to_linear reads it."""
    v = scene.view_settings
    return {"transform": v.view_transform, "look": v.look, "exposure": float(v.exposure), "gamma": float(v.gamma),
            "curves": bool(v.use_curve_mapping), "display": scene.display_settings.display_device}


def read_view_target(scene, path):
    """The ViewSpec of image ``path`` seen by the scene camera (pipeline.view_targets.view_spec)."""
    camera = read_camera(scene)
    rgba, linear = read_image(path)
    return view_spec(camera, rgba, linear, view_settings(scene), os.path.basename(path))


def write_image(path, rgba):
    """Write ``rgba`` (h, w, 4) floats, row 0 at the top, to ``path``: an OpenEXR of linear values
    (a name ending .png: a PNG of the values clipped to [0, 1], as stored)."""
    rgba = np.asarray(rgba, dtype=np.float32)
    h, w = rgba.shape[:2]
    png = str(path).lower().endswith(".png")
    img = bpy.data.images.new("relight_view", w, h, alpha=True, float_buffer=not png)
    try:
        img.colorspace_settings.name = "Non-Color"
        img.pixels.foreach_set(np.ascontiguousarray(rgba[::-1]).ravel())
        img.filepath_raw = os.path.abspath(path)
        img.file_format = "PNG" if png else "OPEN_EXR"
        img.save()
    finally:
        bpy.data.images.remove(img)


def straight(rgba) -> np.ndarray:
    """``rgba`` (.., 4) premultiplied (a float buffer's, an OpenEXR's) -> straight colour: the
    colour divided by the alpha where it is above 0 (a free pixel's colour stays as stored)."""
    rgba = np.array(rgba, dtype=np.float64)
    a = rgba[..., 3:]
    rgba[..., :3] = np.where(a > 0, rgba[..., :3] / np.where(a > 0, a, 1.0), rgba[..., :3])
    return rgba


def camera_working_size(scene, side=WORKING_SIDE) -> tuple:
    """(width, height) of the view target's working resolution for the scene camera (its aspect,
    ``side`` pixels on the longer side). SceneError without a perspective camera."""
    cam = read_camera(scene)
    return working_size(float(cam.half[0] / cam.half[1]), side)


def new_view_image(name, width, height):
    """A new image data-block for a view target: float (scene linear radiance), ``width`` x
    ``height``, alpha 0 everywhere (every pixel free), premultiplied as Blender paints float images,
    packed into the .blend (and given a fake user: the file keeps it while nothing shows it)."""
    img = bpy.data.images.new(name, int(width), int(height), alpha=True, float_buffer=True)
    img.alpha_mode = "PREMUL"
    img.pixels.foreach_set(np.zeros(int(width) * int(height) * 4, dtype=np.float32))
    img.pack()
    img.use_fake_user = True
    return img


def image_pixels(image) -> tuple:
    """((h, w, 4) straight RGBA of image data-block ``image``, row 0 at the top; linear): a float
    image's pixels are scene-linear radiance (linear True), a byte image's display values (read as
    a PNG is: through the scene's view transform). ValueError when it has no pixels."""
    w, h = image.size
    if w == 0 or h == 0:
        where = f" ({image.filepath})" if image.filepath else ""
        raise ValueError(f"the image {image.name!r}{where} has no pixels Blender can read: reload or replace it")
    px = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(px)
    rgba = px.reshape(h, w, image.channels)[::-1].astype(np.float64)
    if image.channels != 4:  # (an RGB image: every pixel painted)
        full = np.ones((h, w, 4))
        full[..., :min(3, image.channels)] = rgba[..., :3]
        rgba = full
    return (straight(rgba), True) if image.is_float else (rgba, False)


def set_pixels(image, rgba) -> None:
    """Write straight ``rgba`` (h, w, 4, row 0 at the top, the image's size) into float image
    ``image`` (premultiplied, as it keeps them) and pack it, so that the file stores it."""
    rgba = np.array(rgba, dtype=np.float64)
    rgba[..., :3] *= rgba[..., 3:]
    image.pixels.foreach_set(np.ascontiguousarray(rgba[::-1], dtype=np.float32).ravel())
    image.update()
    image.pack()


def image_view_target(scene, image, side=WORKING_SIDE):
    """The ViewSpec of image data-block ``image`` seen by the scene camera at ``side`` pixels on the
    longer side (pipeline.view_targets.view_spec, as ``solve --view-target`` reads a file)."""
    camera = read_camera(scene)
    rgba, linear = image_pixels(image)
    return view_spec(camera, rgba, linear, view_settings(scene), image.name, side)


def scene_view_target(scene):
    """The ViewSpec of the scene's view-target image (``scene.relight_camera_target``, registered by
    blender/ui/view_target_ops.py) for Solve & Reduce and Live, or None (no image, Use in Solve off,
    or the add-on's property not registered: the CLI). SceneError / ValueError in one line."""
    props = getattr(scene, "relight_camera_target", None)
    if props is None or props.image is None or not props.use:
        return None
    try:
        return image_view_target(scene, props.image, props.resolution)
    except SceneError as exc:  # (no perspective camera)
        raise SceneError(f"{exc}; or turn the View Target's Use in Solve off (Targets panel)") from None


def predict_view(outcome, progress=None, cancel=None) -> bool:
    """What a solve with a view target adds to its outcome, as ``solve --view-target`` has it (no bpy:
    the solve's worker thread calls it, so the main thread does not wait for it): the report's
    ``view_target`` block (the error over the painted pixels), its notes among the warnings, and
    ``outcome.view_prediction``, the final configuration's camera image (pipeline.view_targets
    .predicted_rgba: 4 rays a pixel; 7 s for 480 x 270 on the view room at load 10 on 2 cores).
    False without a view target, or when ``cancel()`` is set before it starts; done once."""
    if getattr(outcome, "view_prediction", None) is not None:
        return True
    if cancel is not None and cancel():
        return False
    block = view_report(outcome)
    if block is None:
        return False
    if progress is not None:
        progress("predicting the camera image", 0.0)
    outcome.report["view_target"] = block
    for w in view_notes(outcome.problem):
        for warnings in (outcome.warnings, outcome.report.setdefault("warnings", [])):
            if w not in warnings:
                warnings.append(w)
    outcome.view_prediction = predicted_rgba(outcome)
    return True
