"""The error curve as stored in a .blend, and its chart. No bpy here.

A solve produces a sequence of configurations (the error curve, paper Fig. 11).
Everything needed to re-apply any of them later, without the engine, is packed into one
string (zlib-compressed npz, base64) kept in the scene's custom property ``relight_result``
(jobs.stored_result lists the arrays): the whole curve (for the chart), and for the
configurations kept re-appliable (every one up to 32 lights, ~40 log-spaced above, e_x and the
final one) each light's exitance and every patch's radiosity; the lights (object, kind, area,
centre, normal, polygons), their cells' triangles and reflectance, and the patches -> polygons
weights. Floating-point arrays are stored as float32: no loss of range (float16 overflowed
above 65,504 W/m^2), 7 significant digits. Non-finite values are refused when packing.
"""
from __future__ import annotations

import base64
import io
import json
import zlib

import numpy as np

FORMAT = 2


def pack_curve(data: dict) -> str:
    buf = io.BytesIO()
    arrays = {k: np.asarray(v) for k, v in data.items() if k not in ("objects", "meta")}
    arrays["objects_json"] = np.frombuffer(json.dumps(list(data["objects"])).encode(), dtype=np.uint8)
    arrays["meta_json"] = np.frombuffer(json.dumps(data.get("meta", {})).encode(), dtype=np.uint8)
    for k, a in arrays.items():
        if a.dtype.kind == "f":
            if not np.all(np.isfinite(a)):
                raise ValueError(f"refusing to store non-finite values ({k})")
            a32 = a.astype(np.float32)
            if not np.all(np.isfinite(a32)):
                raise ValueError(f"values of {k} exceed the float32 range")
            arrays[k] = a32
    arrays["format"] = np.array(FORMAT)
    np.savez(buf, **arrays)
    return base64.b64encode(zlib.compress(buf.getvalue(), 6)).decode("ascii")


def unpack_curve(text: str) -> dict:
    raw = zlib.decompress(base64.b64decode(text.encode("ascii")))
    with np.load(io.BytesIO(raw)) as z:
        out = {k: z[k] for k in z.files}
    if int(out.pop("format")) != FORMAT:
        raise ValueError("this file's Relight result was written by an incompatible version")
    out["objects"] = json.loads(out.pop("objects_json").tobytes().decode())
    out["meta"] = json.loads(out.pop("meta_json").tobytes().decode())
    return out


# --- the chart: error against number of lights, rasterised with numpy --------------

_BG = np.array([0.10, 0.10, 0.10, 1.0], dtype=np.float32)
_AXIS = np.array([0.45, 0.45, 0.45, 1.0], dtype=np.float32)
_LINE = np.array([0.35, 0.70, 1.00, 1.0], dtype=np.float32)
_NEG = np.array([1.00, 0.45, 0.30, 1.0], dtype=np.float32)
_MARK = np.array([1.00, 0.85, 0.20, 1.0], dtype=np.float32)


def _plot_line(img, x0, y0, x1, y1, color, width=1):
    n = int(max(abs(x1 - x0), abs(y1 - y0))) + 1
    xs = np.rint(np.linspace(x0, x1, n)).astype(int)
    ys = np.rint(np.linspace(y0, y1, n)).astype(int)
    h, w = img.shape[:2]
    for dx in range(-(width // 2), width // 2 + 1):
        for dy in range(-(width // 2), width // 2 + 1):
            xx = np.clip(xs + dx, 0, w - 1)
            yy = np.clip(ys + dy, 0, h - 1)
            img[yy, xx] = color


def error_chart(n_lights, error, n_negative=None, current=None, size=(256, 160)) -> np.ndarray:
    """RGBA float image (h, w, 4), row 0 at the bottom (Blender's pixel order).

    x: number of lights (log scale when it spans more than a decade), y: log10 error.
    Points with negative exitances are drawn in orange, the current point in yellow.
    """
    w, h = size
    img = np.empty((h, w, 4), dtype=np.float32)
    img[:] = _BG
    n_lights = np.asarray(n_lights, dtype=np.float64)
    error = np.asarray(error, dtype=np.float64)
    if len(n_lights) == 0:
        return img
    m = 10
    _plot_line(img, m, m, w - m, m, _AXIS)
    _plot_line(img, m, m, m, h - m, _AXIS)
    xv = np.maximum(n_lights, 1.0)
    logx = xv.max() / xv.min() > 10
    xs = np.log10(xv) if logx else xv
    err = np.maximum(error, max(error[error > 0].min() if np.any(error > 0) else 1e-12, 1e-12) * 0.5)
    ys = np.log10(err)

    def scale(v, lo, hi, a, b):
        return a + (b - a) * (v - lo) / (hi - lo) if hi > lo else np.full_like(v, (a + b) / 2)

    px = scale(xs, xs.min(), xs.max(), m + 2, w - m - 2)
    py = scale(ys, ys.min(), ys.max(), m + 2, h - m - 2)
    neg = np.zeros(len(px), bool) if n_negative is None else np.asarray(n_negative) > 0
    order = np.argsort(px, kind="stable")
    for a, b in zip(order[:-1], order[1:]):
        _plot_line(img, px[a], py[a], px[b], py[b], _NEG if (neg[a] and neg[b]) else _LINE)
    if current is not None and 0 <= current < len(px):
        _plot_line(img, px[current], m, px[current], h - m, _MARK)
        _plot_line(img, px[current] - 3, py[current], px[current] + 3, py[current], _MARK, width=3)
    return img
