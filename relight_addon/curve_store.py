"""The error curve as stored in a .blend. No bpy here.

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
