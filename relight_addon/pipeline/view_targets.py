"""A view target read from an image (issue 40: ``solve --view-target IMAGE``), no bpy: the image's
pixels (read by blender/camera_view.py) turned into the radiance the camera should see, at the
camera's working resolution (engine.targets.view.ViewSpec), and the report's block on it.

- OpenEXR (float): linear scene radiance, W m^-2 sr^-1, as Cycles renders it (no view transform).
- PNG (8/16 bit): what the scene's view transform shows, inverted: ``display_to_linear``. The
  Standard view transform (and Raw) on an sRGB display are inverted exactly (the display's gamma, the
  scene's Gamma and Exposure); AgX, Filmic, Khronos PBR Neutral and the other tone maps, a Look or
  RGB Curves are refused (they clip and tone map: not invertible); save a linear OpenEXR instead.
- Alpha 0 marks a free pixel; at the working resolution a pixel is painted when its pixels' mean
  alpha is at least 0.5, asking for the alpha-weighted mean of their radiance.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..engine.targets.view import Camera, ViewSpec

__all__ = ["WORKING_SIDE", "ASPECT_TOLERANCE", "INVERTIBLE", "working_size", "display_to_linear", "resample",
           "view_spec", "view_report", "view_notes", "predicted_rgba"]

#: the working resolution's longer side, pixels (480 x 270 for a 16:9 camera)
WORKING_SIDE = 480
#: how far (relative) an image's aspect may differ from the camera's
ASPECT_TOLERANCE = 0.01
#: the view transforms a PNG is read through exactly (inverted)
INVERTIBLE = ("Standard", "Raw")


def working_size(aspect, side=WORKING_SIDE) -> tuple:
    """(width, height) of the working resolution for a camera of ``aspect`` (width / height)."""
    if aspect >= 1:
        return side, max(1, int(round(side / aspect)))
    return max(1, int(round(side * aspect))), side


def _srgb_to_linear(x):
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def display_to_linear(rgb, view) -> np.ndarray:
    """(H, W, 3) scene-linear radiance from display values ``rgb`` in [0, 1] seen through ``view``
    (dict: transform, look, exposure, gamma, curves (bool), display): the inverse of Blender's
    display processor (exposure in scene linear, the view transform, the display's encoding, then
    the Gamma in display space). ValueError for what cannot be inverted."""
    transform, look, display = view.get("transform", "Standard"), view.get("look", "None"), view.get("display", "sRGB")
    if transform not in INVERTIBLE:
        raise ValueError(f"a PNG view target is read through the scene's view transform, and {transform} tone maps "
                         f"(not invertible): set Color Management > View Transform to Standard, or give a linear "
                         f"OpenEXR")
    if look not in ("None", "", None) and not str(look).endswith("None"):
        raise ValueError(f"a PNG view target cannot be read through the Look {look!r}: set the Look to None, or give "
                         f"a linear OpenEXR")
    if view.get("curves"):
        raise ValueError("a PNG view target cannot be read through RGB Curves (Color Management > Use Curves): turn "
                         "them off, or give a linear OpenEXR")
    if transform == "Standard" and display != "sRGB":
        raise ValueError(f"a PNG view target is read for an sRGB display, not {display!r}: give a linear OpenEXR")
    gamma = float(view.get("gamma", 1.0))
    if not gamma > 0:
        raise ValueError(f"the scene's Gamma is {gamma:g}: a PNG view target needs a positive Gamma")
    x = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0) ** gamma
    if transform == "Standard":
        x = _srgb_to_linear(x)
    return x / 2.0 ** float(view.get("exposure", 0.0))


def _overlap(n_out, n_in) -> np.ndarray:
    """(n_out, n_in): the share of each output cell's span that each input cell covers (box filter)."""
    edges_out = np.linspace(0, n_in, n_out + 1)
    lo, hi = edges_out[:-1, None], edges_out[1:, None]
    k = np.arange(n_in)[None, :]
    w = np.clip(np.minimum(hi, k + 1) - np.maximum(lo, k), 0, None)
    return w / w.sum(axis=1, keepdims=True)


def resample(values, height, width) -> np.ndarray:
    """(height, width, C) box-filtered ``values`` (h, w, C) (row 0 at the top)."""
    values = np.asarray(values, dtype=np.float64)
    Ay, Ax = _overlap(height, values.shape[0]), _overlap(width, values.shape[1])
    rows = np.tensordot(Ay, values, axes=(1, 0))  # (height, w, C)
    return np.tensordot(rows, Ax, axes=(1, 1)).transpose(0, 2, 1)  # (two products: not one 4-index sum)


def view_spec(camera, rgba, linear, view, name, side=WORKING_SIDE) -> ViewSpec:
    """The ViewSpec of image ``rgba`` (h, w, 4, row 0 at the top; ``linear``: an OpenEXR's scene
    radiance, else display values read through ``view``, display_to_linear) for ``camera`` (an
    engine Camera; its frame's aspect half_x / half_y the image must have), at the working
    resolution. ValueError names what is wrong."""
    rgba = np.asarray(rgba, dtype=np.float64)
    if rgba.ndim != 3 or rgba.shape[2] != 4 or rgba.shape[0] < 1 or rgba.shape[1] < 1:
        raise ValueError(f"the view target {name} is not an RGBA image")
    h, w = rgba.shape[:2]
    aspect = float(camera.half[0] / camera.half[1])
    if abs((w / h) / aspect - 1) > ASPECT_TOLERANCE:
        raise ValueError(f"the view target {name} is {w} x {h} (aspect {w / h:.4g}), the camera's image has aspect "
                         f"{aspect:.4g}: give an image at the camera's aspect (Output > Resolution)")
    rgb, alpha = rgba[..., :3], np.clip(rgba[..., 3:], 0.0, 1.0)
    if not np.all(np.isfinite(rgba)):
        raise ValueError(f"the view target {name} holds NaN or infinite values")
    radiance = rgb if linear else display_to_linear(rgb, view)
    if linear and np.any(radiance[alpha[..., 0] > 0] < 0):
        raise ValueError(f"the view target {name} holds negative radiance in painted pixels")
    W, H = working_size(aspect, side)
    a = resample(alpha, H, W)[..., 0]
    painted = a >= 0.5
    rad = resample(np.maximum(radiance, 0.0) * alpha, H, W) / np.maximum(a, 1e-12)[..., None]
    if not np.any(painted):
        raise ValueError(f"the view target {name} paints no pixel (alpha 0 everywhere: every pixel free)")
    if not np.any(rad[painted] > 0):
        raise ValueError(f"every painted pixel of the view target {name} asks for radiance 0: there is nothing "
                         f"to light")
    return ViewSpec(replace(camera, width=W, height=H), rad, painted, name)


def _view_target(problem):
    from ..engine.targets.view import ViewTarget
    return next((t for t in problem.target_rows.targets if isinstance(t, ViewTarget)), None)


def view_notes(problem) -> list:
    """The warnings a view target gives: its painted pixels that see no surface's front (free)."""
    t = _view_target(problem)
    if t is None:
        return []
    notes = []
    if t.hits.missed:
        notes.append(f"view target: {t.hits.missed} painted pixels see the World (no surface): they are free")
    if t.hits.back:
        notes.append(f"view target: {t.hits.back} painted pixels see the back of a face: they are free")
    if t.channel_spread > 0.05:
        notes.append(f"view target: a glossy material's reflection differs between colour channels by up to "
                     f"{100 * t.channel_spread:.0f} %; its rows take their mean")
    return notes


def _lamps_of(outcome) -> list:
    """[(engine.lamps.Lamp, strength (3,))]: the final configuration's lights that are lamps (their
    highlights on a view target's glossy pixels: the radiosity holds their light Lambertian)."""
    lamps = outcome.problem.lights.lamps
    s = np.asarray(outcome.stored.exitance[outcome.final_index], dtype=np.float64)
    if lamps is None:
        return []
    if len(s) != len(lamps):
        raise ValueError(f"the final configuration has {len(s)} strengths for {len(lamps)} lights")
    return [(lamp, s[j]) for j, lamp in enumerate(lamps) if lamp is not None and np.any(s[j] != 0)]


def _own_first_reflection(outcome) -> np.ndarray:
    """(P, 3): what the final configuration's radiosity holds of its emitters' (and the scene's
    own emitters') first reflection beyond rho (InverseProblem.first_reflection), which a view
    target's glossy pixels see through their BSDF instead."""
    p = outcome.problem
    e = p.patch_exitance(outcome.stored.exitance[outcome.final_index])
    if p.background_exitance is not None:
        e = e + p.background_exitance
    return p.first_reflection(e)


def predicted_rgba(outcome, samples=4) -> np.ndarray | None:
    """(H, W, 4): the radiance the final configuration shows the camera (ViewTarget.image: its lamps'
    and the scene's lamps' highlights included) with
    alpha the share of each pixel's rays that hit a surface; None without a view target."""
    t = _view_target(outcome.problem)
    if t is None:
        return None
    img, cover = t.image(np.asarray(outcome.stored.radiosity[outcome.final_index], dtype=np.float64), samples,
                         _lamps_of(outcome), _own_first_reflection(outcome))
    return np.concatenate([img, cover[..., None]], axis=2)


def view_report(outcome) -> dict | None:
    """The report's ``view_target`` block: the final configuration's error over the painted pixels
    (engine.targets.view.ViewTarget.pixel_error), or None without a view target."""
    t = _view_target(outcome.problem)
    if t is None:
        return None
    B = np.asarray(outcome.stored.radiosity[outcome.final_index], dtype=np.float64)
    block = {"image": t.spec.name, "resolution": [t.spec.camera.width, t.spec.camera.height],
             "rows": int(t.matrix.shape[0])}
    block.update(t.pixel_error(B, _lamps_of(outcome), _own_first_reflection(outcome)))
    return block
