"""Outputs written whole or not at all (no bpy): the report (cli.py), the saved copy and the
rendered picture (blender/results.py). An output only ever replaces a regular file: never a
FIFO, a device node (``/dev/full``, even as root), a socket, a directory or a symbolic link
(``not_regular``)."""
from __future__ import annotations

import os
import stat
import uuid

_KINDS = ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def not_regular(path: str) -> str | None:
    """What ``path`` is when it exists and is not a regular file ("a FIFO (named pipe)", "a symbolic
    link (to /x)", ...), else None (a regular file, or nothing there). The path itself is looked
    at, not what a symbolic link points to."""
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return None
    for test, kind in _KINDS:
        if test(mode):
            return f"{kind} (to {os.path.realpath(path)})" if test is stat.S_ISLNK else kind
    return None if stat.S_ISREG(mode) else "not a regular file"


def atomic_output(path: str, write) -> None:
    """``write(tmp)`` to a temporary of its own beside ``path``, then rename it to ``path``: the
    file is whole or absent, whatever stops the write (an error, Ctrl-C, SIGTERM), and two writers
    of one path never share a temporary; the temporary, and Blender's own ``tmp@``, never stay
    behind. Only a regular file (or nothing) is replaced: OSError when ``path`` is anything else
    (checked before the write and again before the rename)."""
    dest = os.path.join(os.path.realpath(os.path.dirname(os.path.abspath(path))), os.path.basename(path))

    def check():
        kind = not_regular(dest)
        if kind:
            raise OSError(f"cannot write {path}: it is {kind}, not a regular file, and Relight replaces only "
                          "regular files")

    check()
    d = os.path.dirname(dest)
    os.makedirs(d, exist_ok=True)
    base, ext = os.path.splitext(os.path.basename(dest))
    tmp = os.path.join(d, f".{base}.relight-{uuid.uuid4().hex[:12]}{ext}")
    try:
        write(tmp)
        if not os.path.isfile(tmp):
            raise RuntimeError(f"Error: nothing was written to {tmp}")
        check()
        os.replace(tmp, dest)
    finally:
        for leftover in (tmp, tmp + "@"):
            if os.path.exists(leftover):
                os.remove(leftover)
