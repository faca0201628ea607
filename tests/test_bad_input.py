"""Bad input: exit code 2 with one line on stderr; odd but valid geometry gives finite results."""
import math
import os

import numpy as np
import pytest

from conftest import SAMPLES, file_digest

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")

LIGHT_SCENE = os.path.join(SAMPLES, "ff_parallel_0.5.blend")


def save_scene(bpy, path, objects):
    """objects: list of (name, verts, faces, emission radiance or None)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    for name, verts, faces, radiance in objects:
        me = bpy.data.meshes.new(name)
        me.from_pydata(verts, [], faces)
        if radiance is not None:
            m = bpy.data.materials.new(name)
            if bpy.app.version < (5, 0, 0):
                m.use_nodes = True
            p = next(n for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
            p.inputs["Emission Color"].default_value = (1, 1, 1, 1)
            p.inputs["Emission Strength"].default_value = radiance
            me.materials.append(m)
        ob = bpy.data.objects.new(name, me)
        bpy.context.scene.collection.objects.link(ob)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return str(path)


def assert_one_line_error(code, err, *words):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("relight: error:"), err
    for w in words:
        assert w in lines[0]


def test_missing_and_corrupt_files(run_cli, tmp_path):
    code, _, err = run_cli(["radiosity", tmp_path / "nope.blend", "--report", tmp_path / "r.json"])
    assert_one_line_error(code, err, "no such")
    bad = tmp_path / "bad.blend"
    bad.write_bytes(b"this is not a blend file at all")
    code, _, err = run_cli(["radiosity", bad, "--report", tmp_path / "r.json"])
    assert_one_line_error(code, err, "not a .blend")
    trunc = tmp_path / "trunc.blend"
    trunc.write_bytes(b"BLENDER-v404RENDH" + b"\0" * 20)
    code, _, err = run_cli(["radiosity", trunc, "--report", tmp_path / "r.json"])
    assert_one_line_error(code, err, "trunc.blend")
    assert not (tmp_path / "r.json").exists()


def test_bad_options(run_cli, tmp_path):
    for extra in (["--rays-per-patch", "0"], ["--max-patch-size", "-1"], ["--max-patch-size", "nan"], ["--bogus"]):
        code, _, err = run_cli(["radiosity", LIGHT_SCENE, "--report", tmp_path / "r.json", *extra])
        assert_one_line_error(code, err)
    code, _, err = run_cli(["radiosity", LIGHT_SCENE, "--report", tmp_path / "r.json", "--out", LIGHT_SCENE])
    assert_one_line_error(code, err, "input")


def test_empty_scene(run_cli, bpy_clean, tmp_path):
    path = save_scene(bpy_clean, tmp_path / "empty.blend", [])
    code, _, err = run_cli(["radiosity", path, "--report", tmp_path / "r.json"])
    assert_one_line_error(code, err, "no visible mesh")


def test_nan_coordinates(run_cli, bpy_clean, tmp_path):
    path = save_scene(bpy_clean, tmp_path / "nan.blend",
                      [("bad", [(0, 0, 0), (1, 0, 0), (math.nan, 1, 0)], [(0, 1, 2)], 1.0)])
    code, _, err = run_cli(["radiosity", path, "--report", tmp_path / "r.json"])
    assert_one_line_error(code, err, "NaN", "bad")


def test_no_emitter_is_a_documented_warning(run_cli, bpy_clean, tmp_path):
    path = save_scene(bpy_clean, tmp_path / "dark.blend", [("q", [(0, 0, 0), (1, 0, 0), (1, 1, 0)], [(0, 1, 2)], None)])
    code, report, err = run_cli(["radiosity", path, "--report", tmp_path / "r.json"])
    assert code == 0, err
    assert report["objects"]["q"]["radiosity"] == [[0.0, 0.0, 0.0]]
    assert any("no emitter" in w for w in report["warnings"])


def test_zero_area_and_non_manifold_faces(run_cli, bpy_clean, tmp_path):
    # a floor lit by a ceiling lamp; the floor mesh also holds a zero-area triangle and a
    # non-manifold fin (three faces on one edge); results stay finite, the degenerate face gets 0
    floor = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (3, 0, 0), (4, 0, 0),
             (0.5, 0.5, 0.5), (0.5, 0.5, -0.5)]
    faces = [(0, 1, 2, 3), (4, 5, 6), (0, 2, 7), (0, 2, 8)]
    lamp = [(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)]
    path = save_scene(bpy_clean, tmp_path / "odd.blend", [("floor", floor, faces, None), ("lamp", lamp, [(0, 1, 2, 3)], 1.0)])
    code, report, err = run_cli(["radiosity", path, "--report", tmp_path / "r.json", "--rays-per-patch", "256"])
    assert code == 0, err
    rows = np.array(report["objects"]["floor"]["radiosity"])
    assert rows.shape == (4, 3) and np.all(np.isfinite(rows))
    assert np.all(rows[1] == 0.0)  # zero-area triangle
    assert rows[0, 0] > 0.1  # the lit floor quad
    assert any("zero-area" in w for w in report["warnings"])


def test_input_never_modified(run_cli, tmp_path):
    before = (os.path.getmtime(LIGHT_SCENE), file_digest(LIGHT_SCENE))
    out = tmp_path / "out.blend"
    code, report, err = run_cli(["radiosity", LIGHT_SCENE, "--report", tmp_path / "r.json", "--out", out,
                                 "--rays-per-patch", "64"])
    assert code == 0, err
    assert out.exists()
    assert (os.path.getmtime(LIGHT_SCENE), file_digest(LIGHT_SCENE)) == before
