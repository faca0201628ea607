"""Values keyed by their content (no bpy): ``digest`` of arrays, lists, dicts and records, every
value whole (pipeline.prepared's scene key and answers).
"""
from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["digest"]


def _feed(h, x):
    """Hash ``x`` into ``h``: every value whole (a repr would cut a large array short)."""
    if isinstance(x, np.ndarray):
        h.update(f"{x.dtype}{x.shape}".encode())
        h.update(np.ascontiguousarray(x).tobytes())
    elif isinstance(x, (list, tuple)):
        h.update(f"{type(x).__name__}{len(x)}".encode())
        for v in x:
            _feed(h, v)
    elif isinstance(x, dict):
        for k in sorted(x, key=repr):
            _feed(h, k)
            _feed(h, x[k])
    elif hasattr(x, "__dict__") and not isinstance(x, type):
        h.update(type(x).__name__.encode())
        _feed(h, vars(x))
    else:
        h.update(repr(x).encode())


def digest(*items) -> str:
    """sha1 of ``items``, every value whole."""
    h = hashlib.sha1()
    for x in items:
        _feed(h, x)
    return h.hexdigest()
