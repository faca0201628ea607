"""Values keyed by their content (no bpy): ``digest`` of arrays, lists, dicts and records, every
value whole, and ``kept_by_content``, a costly pure function's last answers kept by the digest of
its arguments.

The export's ray checks (engine.two_sided: coincident faces back to back, what each side of a
face sees) are pure functions of the scene's geometry, which a stroke never changes: Solve &
Reduce pressed again on the same scene (after Live's strokes, say) takes their answers instead of
casting the rays again (1.9 s of a million-triangle export's 3.8 s). An answer kept is read-only
(shared by the calls that take it).
"""
from __future__ import annotations

import functools
import hashlib
import threading

import numpy as np

__all__ = ["digest", "forget", "kept_by_content"]

#: every kept_by_content function's answers (``forget`` empties them)
_KEPT = []


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


def _read_only(value):
    """``value`` with its arrays (its own, a tuple's, a record's) made read-only: shared."""
    if isinstance(value, np.ndarray):
        value.setflags(write=False)
    elif isinstance(value, (list, tuple)):
        for v in value:
            _read_only(v)
    elif hasattr(value, "__dict__"):
        for v in vars(value).values():
            _read_only(v)
    return value


def kept_by_content(kept: int = 4, unkeyed: tuple = ("scene",)):
    """Decorate a pure function: its last ``kept`` answers kept by the digest of its arguments
    (those named in ``unkeyed`` left out: what only makes the answer faster, such as a function
    that builds the Embree scene of the triangles given). The answers are read-only."""

    def decorate(fn):
        answers, lock = {}, threading.Lock()
        _KEPT.append(answers)

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            key = digest(args, {k: v for k, v in kwargs.items() if k not in unkeyed})
            with lock:
                if key in answers:
                    return answers[key]
            value = _read_only(fn(*args, **kwargs))
            with lock:
                answers[key] = value
                while len(answers) > kept:
                    del answers[next(iter(answers))]
            return value

        return wrapper

    return decorate


def forget() -> None:
    """Every kept answer dropped (a benchmark's cold solve: nothing kept from the runs before)."""
    for answers in _KEPT:
        answers.clear()
