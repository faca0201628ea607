"""The scene camera and a view target's image, read from Blender (bpy) for engine/targets/view.py:
``read_camera`` (an engine Camera of the scene's camera), ``read_image`` (an OpenEXR or PNG as RGBA
floats, row 0 at the top), ``view_settings`` (the scene's Color Management, for a PNG) and
``read_view_target`` (all three -> pipeline.view_targets.view_spec)."""
from __future__ import annotations

import os

import bpy
import numpy as np

from ..engine.scene import SceneError
from ..engine.targets.view import Camera
from ..pipeline.view_targets import view_spec

__all__ = ["read_camera", "read_image", "write_image", "view_settings", "read_view_target"]

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
    OpenEXR's scene-linear floats, a PNG's display values in [0, 1]; linear: True for an OpenEXR).
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
        return px.reshape(h, w, 4)[::-1].astype(np.float64), FORMATS[fmt]
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
