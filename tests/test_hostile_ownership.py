"""The hostile-input catalogue, part 3 (issue 35; docs/reliability.md): what Relight writes never
replaces or removes what the artist made. Outputs replace only regular files, and never a file the
scene reads; the contents of Relight's collections are checked for ownership before any removal;
what Relight writes is checked for drivers and keyframes that would override it; a kept report of
another scene is named. The harness is tests/test_hostile.py's (its scenes' helpers, its checks:
exit code or operator result, the one-line message, the input's bytes unchanged, no NaN or inf in
the report or the scene, the scene unchanged on refusal).
"""
from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from conftest import file_digest
from test_hostile import (RAYS, _grid, _library, _link, _mesh, _paint, _reset, _room, _save, addon,  # noqa: F401
                          assert_scene_finite, scene_cache, snapshot, strict_json)
from test_hostile_everyday import _error_line, _open_solved, _refused, _solve

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")


# ============================================================================ scenes

def _camera():
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.location = (0.5, 0.5, 0.9)
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    bpy.context.scene.render.resolution_x = bpy.context.scene.render.resolution_y = 32


def build(name, d):
    path = os.path.join(d, f"{name}.blend")
    _reset()
    if name == "room_camera":
        _room()
        _camera()
    else:
        raise KeyError(name)
    _save(path)
    _reset()
    return path


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    return scene_cache(tmp_path_factory, "ownership", build)


def _linked_scene(d, hdri="sky.hdr"):
    """scene.blend in ``d``: a painted floor, the ceiling linked from libs/lib.blend, and a World
    whose HDRI is textures/<hdri> (a file of its own). Returns (scene, library, HDRI) paths."""
    libs = os.path.join(d, "libs")
    os.makedirs(libs, exist_ok=True)
    lib = _library(libs)
    hdr = os.path.join(d, "textures", hdri)
    os.makedirs(os.path.dirname(hdr))
    with open(hdr, "wb") as fh:
        fh.write(b"#?RADIANCE\n")
    fv, ff = _grid(2)
    floor = _mesh("floor", fv, ff)
    floor["relight_no_lights"] = True
    _paint(floor)
    _link(lib, "lib_ceiling")
    world = bpy.data.worlds.new("sky")
    nt = world.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    img = bpy.data.images.new("sky.hdr", 4, 4, float_buffer=True)
    img.source, img.filepath = "FILE", f"//textures/{hdri}"
    env.image = img
    nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    bpy.context.scene.world = world
    _camera()
    path = _save(os.path.join(d, "scene.blend"))
    _reset()
    return path, lib, hdr


# ============================================================================ outputs: never what the scene reads

@pytest.mark.parametrize("option, target, message", [
    ("--out", "lib", "the library 'lib.blend' it links from"),  # issue 35, case 1
    ("--report", "lib", "the library 'lib.blend' it links from"),
    ("--out", "lib_spelled", "the library 'lib.blend' it links from"),  # the same file by another path
    ("--render", "hdr_png", "the image 'sky.hdr'"),  # an image the scene reads, named by --render
    ("--out", "hdr", "the image 'sky.hdr'"),  # the World's HDRI
])
def test_output_never_replaces_a_file_the_scene_reads(run_cli, tmp_path, option, target, message):
    """Case 1: `solve scene.blend --out lib.blend`, where the scene links its ceiling from lib.blend,
    saved the scene over the library (its link then broken). Refused before any work, exit 2, one
    line naming the file's role; the library, the HDRI and the input unchanged; nothing written."""
    scene, lib, hdr = _linked_scene(str(tmp_path), "sky.png" if target == "hdr_png" else "sky.hdr")
    path = {"lib": lib, "lib_spelled": os.path.join(tmp_path, "textures", "..", "libs", "lib.blend"),
            "hdr": hdr, "hdr_png": hdr}[target]
    digests = {p: file_digest(p) for p in (scene, lib, hdr)}
    argv = ["solve", scene, *RAYS]
    argv += ["--report", tmp_path / "r.json"] if option != "--report" else []
    code, _, err = _solve_argv(run_cli, argv + [option, path])
    assert code == 2, err
    line = _error_line(err)
    assert f"{option} " in line and "is a file the scene reads" in line and message in line, line
    assert {p: file_digest(p) for p in digests} == digests
    assert not (tmp_path / "r.json").exists()
    assert sorted(os.listdir(tmp_path)) == ["libs", "scene.blend", "textures"]
    bpy.ops.wm.open_mainfile(filepath=scene)  # the link still resolves
    assert bpy.data.objects["lib_ceiling"].library is not None and len(bpy.data.objects["lib_ceiling"].data.polygons) == 4


def _solve_argv(run_cli, argv):
    code, report, err = run_cli(argv)
    assert "Traceback" not in err, err
    return code, report, err


# ============================================================================ outputs: only regular files

def _special(kind, path, target=None):
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "device":  # a node of its own like /dev/full (never the system's), root only
        try:
            os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 7))
        except PermissionError:
            pytest.skip("making a device node needs root")
    elif kind == "symlink":
        with open(target, "w") as fh:
            fh.write("the artist's notes\n")
        os.symlink(target, path)
    return os.lstat(path)


@pytest.mark.parametrize("option, kind, message", [
    ("--report", "fifo", "it is a FIFO (named pipe), not a regular file"),  # issue 35, case 4
    ("--out", "fifo", "it is a FIFO (named pipe), not a regular file"),
    ("--render", "fifo", "it is a FIFO (named pipe), not a regular file"),
    ("--report", "device", "it is a character device, not a regular file"),  # as root: /dev/full
    ("--out", "device", "it is a character device, not a regular file"),
    ("--report", "symlink", "it is a symbolic link (to "),
    ("--out", "symlink", "it is a symbolic link (to "),
])
def test_output_replaces_only_a_regular_file(run_cli, scenes, tmp_path, option, kind, message):
    """Case 4: `--report` or `--out` naming a FIFO or a device node replaced it with a regular file
    (exit 0; as root, `--report /dev/full` would replace the system's device). Refused before any
    work: exit 2, one line; the node (or the link and its target) unchanged; nothing written."""
    name = {"--report": "r.json", "--out": "o.blend", "--render": "shot.png"}[option]
    path = str(tmp_path / name)
    target = str(tmp_path / "notes.txt")
    before = _special(kind, path, target)
    target_digest = file_digest(target) if kind == "symlink" else None
    argv = ["solve", scenes("room_camera"), *RAYS]
    argv += ["--report", tmp_path / "rep.json"] if option != "--report" else []
    code, _, err = _solve_argv(run_cli, argv + [option, path])
    assert code == 2, err
    line = _error_line(err)
    assert f"cannot write {option} {path}: " in line and message in line, line
    after = os.lstat(path)
    assert (after.st_mode, after.st_ino, after.st_rdev) == (before.st_mode, before.st_ino, before.st_rdev)
    if kind == "symlink":
        assert file_digest(target) == target_digest
    assert sorted(os.listdir(tmp_path)) == sorted([name] + (["notes.txt"] if kind == "symlink" else []))


def test_atomic_output_refuses_what_appeared_during_the_write(tmp_path):
    """The same rule where every output is written (pipeline.files.atomic_output): a FIFO made at the
    path while the output was being written is not replaced, and no temporary stays."""
    from relight_addon.pipeline.files import atomic_output

    path = str(tmp_path / "r.json")

    def write(tmp):
        with open(tmp, "w") as fh:
            fh.write("{}")
        os.mkfifo(path)

    with pytest.raises(OSError, match="it is a FIFO"):
        atomic_output(path, write)
    assert stat.S_ISFIFO(os.lstat(path).st_mode) and os.listdir(tmp_path) == ["r.json"]
