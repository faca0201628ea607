"""The .blend file and the files it reads (bpy): opening a .blend for the command line, the
external files an output must never replace, and the warning for a file saved by a newer Blender."""
from __future__ import annotations

import os

import bpy

from ..engine.scene import SceneError


class BlendFileError(SceneError):
    """The .blend file is missing or cannot be read."""


def open_blend(path: str):
    """Open ``path`` as the current Blender file (never writes it)."""
    if not os.path.isfile(path):
        raise BlendFileError(f"no such .blend file: {path}")
    try:
        with open(path, "rb") as fh:
            head = fh.read(7)
    except OSError as exc:
        raise BlendFileError(f"cannot read {path}: {exc.strerror}") from None
    # plain files start with BLENDER; compressed ones with the gzip or zstd magic
    if not (head.startswith(b"BLENDER") or head.startswith(b"\x1f\x8b") or head.startswith(b"\x28\xb5\x2f\xfd")):
        raise BlendFileError(f"{path} is not a .blend file")
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path), load_ui=False)
    except RuntimeError as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else "unknown error"
        raise BlendFileError(f"cannot open {path}: {msg}") from None


#: Blender's names of the data-blocks that read files (for messages)
_READERS = {"Image": "image", "VectorFont": "font", "Sound": "sound", "MovieClip": "movie clip", "Volume": "volume",
            "CacheFile": "cache file", "Text": "text", "Library": "library"}


def files_read() -> list:
    """[(what reads it, absolute path)] of every file the open .blend reads from disk: its libraries
    (direct and indirect) and every external file of its data-blocks (images, a World's HDRI among
    them, fonts, sounds, clips, volumes, caches; a linked data-block's paths resolved from its
    library). An output must never replace one."""
    out = []
    for lib in bpy.data.libraries:
        # (an indirect library's path too is relative to the open file: Blender remaps it when it reads it)
        out.append((f"the library {lib.name!r} it links from", os.path.normpath(bpy.path.abspath(lib.filepath))))
    for idb, paths in _file_paths():
        if isinstance(idb, bpy.types.Library):
            continue
        what = _READERS.get(type(idb).__name__, type(idb).__name__.lower())
        for p in paths:
            if p:
                out.append((f"the {what} {idb.name!r}", os.path.normpath(bpy.path.abspath(p, library=idb.library))))
    return out


def _file_paths():
    """[(data-block, its file paths)]: bpy.data.file_path_map (Blender 4.4+); before (4.2, and
    Debian's 4.3), the data-blocks that keep a ``filepath``."""
    fpm = getattr(bpy.data, "file_path_map", None)
    if fpm is not None:
        return list(fpm(include_libraries=False).items())
    return [(idb, {idb.filepath}) for kind in ("images", "fonts", "sounds", "movieclips", "volumes", "cache_files",
                                               "texts")
            for idb in getattr(bpy.data, kind, ()) if getattr(idb, "filepath", "") not in ("", "<builtin>")
            and getattr(idb, "source", "FILE") not in ("GENERATED", "VIEWER")]


def newer_file_warning() -> str | None:
    """The warning for a file saved by a newer Blender than this one (what this one does not know
    was dropped when it read the file, and a copy it saves will not have it), or None."""
    saved, this = tuple(bpy.data.version[:2]), tuple(bpy.app.version[:2])
    if not bpy.data.filepath or saved <= this:
        return None
    return (f"the file was saved by Blender {saved[0]}.{saved[1]}, newer than this one ({this[0]}.{this[1]}): what "
            f"{this[0]}.{this[1]} does not know was lost when it read the file, Relight solved what was left, and "
            f"a copy written by --out or a save here will not have it either")
