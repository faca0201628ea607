"""Outputs written whole or not at all (no bpy): the report (cli.py), the saved copy and the
rendered picture (blender/results.py)."""
from __future__ import annotations

import os
import uuid


def atomic_output(path: str, write) -> None:
    """``write(tmp)`` to a temporary of its own beside ``path`` (through a symbolic link, its
    target), then rename it to ``path``: the file is whole or absent, whatever stops the write
    (an error, Ctrl-C, SIGTERM), and two writers of one path never share a temporary; the
    temporary, and Blender's own ``tmp@``, never stay behind."""
    dest = os.path.realpath(path)
    d = os.path.dirname(dest)
    os.makedirs(d, exist_ok=True)
    base, ext = os.path.splitext(os.path.basename(dest))
    tmp = os.path.join(d, f".{base}.relight-{uuid.uuid4().hex[:12]}{ext}")
    try:
        write(tmp)
        if not os.path.isfile(tmp):
            raise RuntimeError(f"Error: nothing was written to {tmp}")
        os.replace(tmp, dest)
    finally:
        for leftover in (tmp, tmp + "@"):
            if os.path.exists(leftover):
                os.remove(leftover)
