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
                          assert_scene_finite, scene_cache, strict_json)
from test_hostile_everyday import _error_line, _refused, _solve

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
    elif name == "low_room":  # another scene: its ceiling at 0.5 m, below room_camera's lamps
        fv, ff = _grid(2)
        floor = _mesh("floor", fv, ff)
        floor["relight_no_lights"] = True
        _paint(floor)
        cv, cf = _grid(2, z=0.5, flip=True)
        _mesh("ceiling", cv, cf)
    elif name == "bounces_keyed":  # the scene's Total bounces keyframed at 0
        _room()
        scene = bpy.context.scene
        scene.render.engine = "CYCLES"
        scene.cycles.max_bounces = 0
        scene.cycles.keyframe_insert("max_bounces", frame=1)
    elif name in LAMP_SCENES:  # reduce: two lamps under the ceiling, one animated as named
        _room(paint=False)
        lamps = [_lamp("Key", (0.3, 0.5, 0.8), 20.0), _lamp("Fill", (0.7, 0.5, 0.8), 5.0)]
        LAMP_SCENES[name](lamps[0])
    else:
        raise KeyError(name)
    _save(path)
    _reset()
    return path


def _lamp(name, location, energy):
    ob = bpy.data.objects.new(name, bpy.data.lights.new(name, "POINT"))
    ob.data.energy = energy
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _driver(idb, path, expression):
    fc = idb.driver_add(path)
    fc.driver.type = "SCRIPTED"
    fc.driver.expression = expression
    return fc


def _keyframes(idb, path, values):
    for frame, v in enumerate(values, start=1):
        setattr(idb, path, v)
        idb.keyframe_insert(path, frame=frame)
    setattr(idb, path, values[0])


LAMP_SCENES = {
    "lamps": lambda key: None,
    "power_driven": lambda key: _driver(key.data, "energy", "20.0"),
    "colour_keyed": lambda key: _keyframes(key.data, "color", [(1.0, 1.0, 1.0), (1.0, 0.2, 0.2)]),
    "disable_keyed": lambda key: _keyframes(key, "hide_render", [False, True]),
}


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
    ceiling = bpy.data.objects["lib_ceiling"]
    assert ceiling.library is not None and len(ceiling.data.polygons) == 4


def test_output_never_replaces_an_indirect_library(run_cli, tmp_path):
    """Case 1, one level further: the scene instances a collection of sets/set.blend, which links
    the ceiling from libs/lib.blend (its path relative to set.blend, not to the scene). --out naming
    lib.blend is refused as well; both libraries unchanged."""
    d = str(tmp_path)
    os.makedirs(os.path.join(d, "libs"))
    lib = _library(os.path.join(d, "libs"))
    os.makedirs(os.path.join(d, "sets"))
    with bpy.data.libraries.load(lib, link=True, relative=True) as (_, dst):
        dst.objects = ["lib_ceiling"]
    coll = bpy.data.collections.new("set")
    coll.objects.link(dst.objects[0])
    bpy.context.scene.collection.children.link(coll)
    set_path = os.path.join(d, "sets", "set.blend")
    bpy.ops.wm.save_as_mainfile(filepath=set_path, relative_remap=True)
    _reset()
    with bpy.data.libraries.load(set_path, link=True, relative=True) as (_, dst):
        dst.collections = ["set"]
    inst = bpy.data.objects.new("set", None)
    inst.instance_type, inst.instance_collection = "COLLECTION", dst.collections[0]
    bpy.context.scene.collection.objects.link(inst)
    fv, ff = _grid(2)
    _paint(_mesh("floor", fv, ff))
    scene = _save(os.path.join(d, "scene.blend"))
    _reset()
    digests = {p: file_digest(p) for p in (scene, lib, set_path)}
    code, _, err = _solve_argv(run_cli, ["solve", scene, "--report", tmp_path / "r.json", "--out", lib, *RAYS])
    assert code == 2, err
    line = _error_line(err)
    assert "is a file the scene reads (the library 'lib.blend' it links from)" in line, line
    assert {p: file_digest(p) for p in digests} == digests and not (tmp_path / "r.json").exists()


def test_render_never_replaces_a_linked_objects_texture(run_cli, tmp_path):
    """Case 1, an image of a library: libs/lib.blend's ceiling has a texture libs/tex.png (its path
    relative to the library). --render naming it is refused; the picture and the library unchanged."""
    libs = tmp_path / "libs"
    libs.mkdir()
    tex = libs / "tex.png"
    tex.write_bytes(b"\x89PNG the artist's texture")
    _reset()
    mat = bpy.data.materials.new("plaster")
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = bpy.data.images.new("tex", 4, 4)
    node.image.source, node.image.filepath = "FILE", str(tex)
    cv, cf = _grid(2, z=1.0, flip=True)
    _mesh("lib_ceiling", cv, cf, material=mat)
    lib = str(libs / "lib.blend")
    bpy.ops.wm.save_as_mainfile(filepath=lib, relative_remap=True)
    _reset()
    fv, ff = _grid(2)
    _paint(_mesh("floor", fv, ff))
    _link(lib, "lib_ceiling")
    _camera()
    scene = _save(tmp_path / "scene.blend")
    _reset()
    digests = {p: file_digest(p) for p in (scene, lib, str(tex))}
    code, _, err = _solve_argv(run_cli, ["solve", scene, "--report", tmp_path / "r.json", "--render", tex, *RAYS])
    assert code == 2, err
    assert "--render " in _error_line(err) and "is a file the scene reads (the image 'tex')" in _error_line(err)
    assert {p: file_digest(p) for p in digests} == digests and not (tmp_path / "r.json").exists()


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


# ============================================================================ the lamps' collection: contents checked

def _open_placed(scenes):
    """room_camera solved in the add-on with point lamps and no cells: the answer is lamps Relight
    placed, in its collection "Relight Lamps". Returns (scene, the placed lamps)."""
    bpy.ops.wm.open_mainfile(filepath=scenes("room_camera"))
    s = bpy.context.scene.relight
    s.rays_per_patch, s.surface_lights, s.point_lamps = 256, False, True
    assert bpy.ops.relight.solve() == {"FINISHED"}
    scene = bpy.context.scene
    placed = [o for o in scene.objects if o.type == "LIGHT" and "relight_owner" in o]
    assert placed and all(c.name.startswith("Relight Lamps") for o in placed for c in o.users_collection)
    return scene, placed


def _artist_copy(ob, share_data=False):
    """What Shift-D (its own data) or Alt-D (``share_data``) makes: a copy in the same collections."""
    copy = ob.copy()
    if not share_data:
        copy.data = ob.data.copy()
    for coll in ob.users_collection:
        coll.objects.link(copy)
    return copy


def _lights(scene):
    return sorted(o.name for o in scene.objects if o.type == "LIGHT")


def test_a_renamed_relight_lamp_is_the_artists(addon, scenes):
    """Case 2: a Relight lamp the artist renamed is theirs (visibility.owner_of): the next row click
    deleted it with the "Relight Lamps" collection. It stays, in the scene, as they left it; the
    collection that holds it stays too (then theirs); Clear Results leaves it as well."""
    scene, placed = _open_placed(scenes)
    mine = placed[0]
    mine.name = "Key light"
    mine.location.x += 0.1
    bpy.context.view_layer.update()
    where = np.array(mine.matrix_world)
    k = scene.relight.curve_index
    assert bpy.ops.relight.apply_configuration(index=k) == {"FINISHED"}
    assert "Key light" in scene.objects and np.allclose(np.array(mine.matrix_world), where)
    assert [c.name for c in mine.users_collection] == ["Relight Lamps"]
    assert "relight_owner" not in mine.users_collection[0]  # the collection that holds it is the artist's now
    shown = [o for o in scene.objects if o.type == "LIGHT" and "relight_owner" in o and o.name != "Key light"]
    assert len(shown) == len(placed)  # the row's own lamps, shown again
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert _lights(scene) == ["Key light"] and mine.data is not None and mine.data.users == 1
    assert_scene_finite()


@pytest.mark.parametrize("share_data", [False, True], ids=["shift-d", "alt-d"])
def test_a_copy_of_a_relight_lamp_is_the_artists(addon, scenes, share_data):
    """Case 2: a Shift-D copy of a Relight lamp lands in Relight's collection: Clear Results orphaned
    it (the collection removed under it). It stays in the scene with its light (an Alt-D copy shares
    the data of Relight's lamp: the data stays with the copy)."""
    scene, placed = _open_placed(scenes)
    copy = _artist_copy(placed[0], share_data)
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert _lights(scene) == [copy.name] and copy.data is not None and copy.data.name in bpy.data.lights
    assert copy.users_collection and copy.users_collection[0].name in scene.collection.children
    assert not [o for o in bpy.data.objects if o.get("relight_owner") and o.name == o.get("relight_owner_name")]
    assert_scene_finite()


def test_make_area_lights_copies_the_lamps_as_edited(addon, scenes):
    """Case 3: Make Area Lights copied the solved records, not the lamp as the artist edited it
    (moved, another Power), and Clear Results then deleted the edited one: the edit was lost. The
    copies are the lamps as they are in the scene, and stay after Clear."""
    scene, placed = _open_placed(scenes)
    lamp = placed[0]
    lamp.location.x += 0.4
    lamp.data.energy *= 3.0
    lamp.data.color = (1.0, 0.5, 0.25)
    bpy.context.view_layer.update()
    edited = (np.array(lamp.matrix_world), lamp.data.energy, tuple(lamp.data.color), lamp.data.type)
    assert bpy.ops.relight.make_area_lights() == {"FINISHED"}
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    copies = [o for o in scene.objects if o.type == "LIGHT"]
    assert len(copies) == len(placed)
    copy = next(o for o in copies if o.data.type == edited[3] and np.allclose(o.matrix_world.translation,
                                                                              edited[0][:3, 3]))
    assert np.allclose(np.array(copy.matrix_world), edited[0])
    assert copy.data.energy == pytest.approx(edited[1]) and np.allclose(tuple(copy.data.color), edited[2])
    assert "relight_owner" not in copy and "relight_owner" not in copy.data
    assert_scene_finite()


def test_keep_lamps_then_the_same_row_places_no_twin(addon, scenes):
    """Case 5: after Keep Lamps, clicking the same row again recreated every Relight lamp beside its
    kept twin: twice the light the row predicts. The kept lamp stands for its lamp of that row: the
    scene's lights and their power are what the row predicts; Clear Results keeps the kept lamps."""
    scene, placed = _open_placed(scenes)
    power = sum(o.data.energy for o in placed)
    assert bpy.ops.relight.keep_lamps() == {"FINISHED"}
    kept = _lights(scene)
    assert len(kept) == len(placed) and all(n.endswith(" (kept)") for n in kept)
    k = scene.relight.curve_index
    assert bpy.ops.relight.apply_configuration(index=k) == {"FINISHED"}
    assert _lights(scene) == kept
    assert sum(o.data.energy for o in scene.objects if o.type == "LIGHT") == pytest.approx(power)
    scene.relight.curve_index = k  # a click on the list (its update callback applies the row)
    assert _lights(scene) == kept and scene.relight.apply_error == ""
    assert bpy.ops.relight.clear_results() == {"FINISHED"}
    assert _lights(scene) == kept
    assert_scene_finite()


def test_keep_lamps_then_a_moved_kept_lamp_is_named(addon, scenes):
    """Case 5, a kept lamp moved or given another Power (Keep Lamps invites it): a row is shown
    without a twin of it, and a warning names the kept lamp, since the row's prediction does not
    hold for the scene as it is (its lamps are the scene's now)."""
    scene, placed = _open_placed(scenes)
    assert bpy.ops.relight.keep_lamps() == {"FINISHED"}
    kept = _lights(scene)
    ob = bpy.data.objects[kept[0]]
    ob.location.x -= 0.2
    ob.data.energy *= 2
    bpy.context.view_layer.update()
    for j in range(len(scene.relight.curve)):
        from relight_addon.blender import results

        shown = results.apply_stored_point(scene, j)
        assert _lights(scene) == kept
        assert any("is kept as" in w and kept[0] in w and "Solve & Reduce" in w for w in shown["skipped"]), \
            shown["skipped"]
    assert_scene_finite()


# ============================================================================ what Relight writes: not overridden

@pytest.mark.parametrize("scene, option, message", [
    ("power_driven", "--out", "lamp 'Key': Power (a driver) would override what Relight sets there"),  # case 8
    ("power_driven", "--render", "lamp 'Key': Power (a driver) would override"),
    ("colour_keyed", "--out", "lamp 'Key': Color (keyframes) would override"),
    ("disable_keyed", "--out", "lamp 'Key': Disable in Renders (keyframes) would override"),
])
def test_reduce_refuses_lamps_whose_animation_overrides_it(run_cli, scenes, tmp_path, scene, option, message):
    """Case 8: `reduce --out` set a lamp's Power, but a driver on that Power overrode it when the copy
    was opened or rendered (keyframes alike, on its colour or on Disable in Renders). Refused before
    any work (exit 2, one line naming the lamp and the property); nothing written; input unchanged.
    Without --out or --render nothing is written on the lamps: the same scene is then reduced."""
    path = scenes(scene)
    before = file_digest(path)
    out = tmp_path / ("o.blend" if option == "--out" else "shot.png")
    code, _, err = _solve_argv(run_cli, ["reduce", path, "--report", tmp_path / "r.json", option, out, *RAYS])
    assert code == 2, err
    line = _error_line(err)
    assert message in line and "Delete Driver / Clear Keyframes" in line, line
    assert file_digest(path) == before and os.listdir(tmp_path) == []
    # without --out or --render nothing is written on the lamps: the same scene is reduced as it is
    code, _, err = _solve_argv(run_cli, ["reduce", path, "--report", tmp_path / "r.json", *RAYS])
    assert code == 0, err
    strict_json(tmp_path / "r.json")


@pytest.mark.parametrize("animate, message", [
    (lambda key: _driver(key.data, "energy", "20.0"), "lamp 'Key': Power (a driver)"),
    (lambda key: _keyframes(key, "hide_render", [False, True]), "lamp 'Key': Disable in Renders (keyframes)"),
], ids=["power-driver", "disable-keyframes"])
def test_apply_refuses_a_lamp_animated_after_the_reduction(addon, run_cli, scenes, tmp_path, animate, message):
    """Case 8 in the add-on: a reduce copy opened, the lamp given a driver or keyframes, then a row
    applied: refused before anything is written (the operator CANCELs with one line), scene unchanged."""
    out = tmp_path / "o.blend"
    code, _, err = _solve_argv(run_cli, ["reduce", scenes("lamps"), "--report", tmp_path / "r.json", "--out", out,
                                         *RAYS])
    assert code == 0, err
    bpy.ops.wm.open_mainfile(filepath=str(out))
    animate(bpy.data.objects["Key"])
    bpy.context.scene.frame_set(1)  # the animation evaluated, as opening the file does (the driver sets 20 W)
    for k in range(len(bpy.context.scene.relight.curve)):
        _refused(lambda: bpy.ops.relight.apply_configuration(index=k), message)


def test_out_names_light_paths_that_animation_overrides(run_cli, scenes, tmp_path):
    """Case 8, the scene's settings: --out sets the Cycles light paths the prediction needs (Total
    bounces 0 -> more), but keyframes on Total bounces set 0 again when the copy is opened or
    rendered. The copy's lights are right: warned (not refused), naming the setting."""
    code, report, err = _solve(run_cli, scenes("bounces_keyed"), tmp_path, out=True)
    assert code == 0, err
    assert "max_bounces" in report["render_settings"]["written"]["changed"]
    assert any("light paths are animated (cycles.max_bounces (keyframes))" in w for w in report["warnings"]), \
        report["warnings"]
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "out.blend"))
    assert bpy.context.scene.cycles.max_bounces == 0  # what the warning says: the animation wins
    assert_scene_finite()


# ============================================================================ --keep: a report of another scene

LAMPS_ONLY = ["--no-surface-lights", "--point-lamps"]


def test_keep_of_another_scenes_report_names_its_lamps(run_cli, scenes, tmp_path):
    """Case 10: `--keep` with a report of another scene wrote its lamps (above this room's ceiling)
    without a word, though they light no target. The solve runs (the lamps are kept as asked) and a
    warning names them: lighting no target, outside this scene's bounds, and the scene the report
    was solved for. Kept in its own scene, the same report gives no such warning."""
    first = tmp_path / "first.json"
    code, report, err = _solve_argv(run_cli, ["solve", scenes("room_camera"), "--report", first, *RAYS, *LAMPS_ONLY])
    assert code == 0, err
    lamps = [f"{li['object']} (kept)" for li in report["final"]["lights"] if li.get("type")]
    assert lamps and all(li["location"][2] > 0.5 for li in report["final"]["lights"])
    code, same, err = _solve(run_cli, scenes("room_camera"), tmp_path / "same", "--keep", first, "--max-lights", "1")
    assert code == 0, err
    assert not any("--keep" in w for w in same["warnings"]), same["warnings"]
    code, other, err = _solve(run_cli, scenes("low_room"), tmp_path / "other", "--keep", first, "--max-lights", "1",
                              out=True)
    assert code == 0, err
    notes = [w for w in other["warnings"] if w.startswith(f"--keep {first}")]
    assert len(notes) == 1, other["warnings"]
    note = notes[0]
    assert f"{len(lamps)} light no target" in note and f"{len(lamps)} lie outside this scene's bounds" in note, note
    assert all(repr(n) in note for n in lamps) and f"was solved for {scenes('room_camera')}, not this scene" in note
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "other" / "out.blend"))
    assert all(n in bpy.data.objects for n in lamps)  # kept, as asked
    from relight_addon.blender import results

    assert note in results.load_result(bpy.context.scene).meta["warnings"]  # the add-on shows it too
    assert_scene_finite()
