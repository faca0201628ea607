"""A scene's IES lamps read by the Blender layer (blender/ies_nodes.py, blender/lamps.py): what is
read as a photometric lamp, what stays named as not modelled, what is refused (a missing file, a
file Relight does not read: one line naming the lamp and the cause; the CLI exits 2), and `reduce`
counting a fixture as one of the scene's lights (its Power scaled, its distribution kept)."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")

import cycles_reference as cr  # noqa: E402
import photometric_fixtures as pf  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _floor():
    cr.reset_blender()
    bpy.context.scene.world = None
    grey = cr._material("grey", (0.5,) * 3, lambertian=True)
    v, f = cr.grid_quads((-1.0, -1.0, 0.0), (2.0, 0, 0), (0, 2.0, 0), 4, 4)
    return cr.add_mesh_object("floor", v, f, grey)


def _export():
    from relight_addon.blender import export
    return export.export_scene()


def test_an_ies_point_lamp_is_read_as_a_photometric_lamp_with_its_gain():
    from relight_addon.engine.lights.photometric import PHOTOMETRIC
    try:
        _floor()
        pf.ies_point_lamp(bpy, "fixture", (0, 0, 1.0), (0, 0, 0), pf.lm63_text("downlight"), 20.0, strength=2.0,
                          color=(1.0, 0.5, 0.25))
        exp = _export()
    finally:
        cr.reset_blender()
    (lamp,) = exp.faces.lamps
    assert lamp.kind is PHOTOMETRIC and lamp.profile is not None
    np.testing.assert_allclose(lamp.power, 20.0 * 2.0 * np.array([1.0, 0.5, 0.25]), rtol=1e-6)
    assert lamp.energy == 20.0
    assert not [w for w in exp.faces.warnings if "fixture" in w], exp.faces.warnings


def test_an_ies_spot_lamp_is_read_as_a_photometric_spot():
    from relight_addon.engine.lights.photometric_spot import PHOTOMETRIC_SPOT
    try:
        _floor()
        pf.ies_point_lamp(bpy, "fixture", (0, 0, 1.0), (0, 0, 0), pf.lm63_text("batwing"), 20.0, light_type="SPOT",
                          spot_size=1.2, spot_blend=0.3)
        exp = _export()
    finally:
        cr.reset_blender()
    (lamp,) = exp.faces.lamps
    assert lamp.kind is PHOTOMETRIC_SPOT and lamp.profile is not None
    assert lamp.spot_size == pytest.approx(1.2) and lamp.spot_blend == pytest.approx(0.3)


def test_an_area_lamps_ies_node_is_read_as_a_photometric_area_lamp():
    """An IES node on an Area lamp: engine/lights/photometric_area.py (its emission times the profile; its
    light against Cycles' in tests/test_cycles_photometric.py), its size read as an area lamp's."""
    from relight_addon.engine.lights.photometric_area import PHOTOMETRIC_AREA

    try:
        _floor()
        pf.ies_point_lamp(bpy, "fixture", (0, 0, 1.0), (0, 0, 0), pf.lm63_text("downlight"), 20.0,
                          light_type="AREA", shape="RECTANGLE", size=0.4, size_y=0.2)
        exp = _export()
    finally:
        cr.reset_blender()
    (lamp,) = exp.faces.lamps
    assert lamp.kind is PHOTOMETRIC_AREA and lamp.profile is not None
    assert (lamp.size_u, lamp.size_v) == pytest.approx((0.4, 0.2))
    assert not [w for w in exp.faces.warnings if "not modelled" in w], exp.faces.warnings


@pytest.mark.parametrize("setup", ["linked vector", "math node"])
def test_ies_trees_not_reduced_stay_named(setup):
    """An IES node whose Vector is linked (here the Geometry's Normal), or a Math node between the IES node
    and the Emission: read as a plain lamp, named in a warning as before."""
    try:
        _floor()
        ob = pf.ies_point_lamp(bpy, "fixture", (0, 0, 1.0), (0, 0, 0), pf.lm63_text("downlight"), 20.0)
        if setup == "linked vector":
            nt = ob.data.node_tree
            ies = next(n for n in nt.nodes if n.type == "TEX_IES")
            geo = nt.nodes.new("ShaderNodeNewGeometry")
            nt.links.new(geo.outputs["Normal"], ies.inputs["Vector"])
        else:
            nt = ob.data.node_tree
            ies = next(n for n in nt.nodes if n.type == "TEX_IES")
            em = next(n for n in nt.nodes if n.type == "EMISSION")
            m = nt.nodes.new("ShaderNodeMath")
            m.operation = "MULTIPLY"
            nt.links.new(ies.outputs["Fac"], m.inputs[0])
            nt.links.new(m.outputs[0], em.inputs["Strength"])
        exp = _export()
    finally:
        cr.reset_blender()
    assert exp.faces.lamps[0].profile is None
    assert any("'fixture'" in w and "light nodes" in w and "not modelled" in w for w in exp.faces.warnings)


@pytest.mark.parametrize("case, words", [
    ("missing", ["'fixture'", "nowhere.ies", "missing"]),
    ("type A", ["'fixture'", "line 6", "type A"]),
    ("truncated", ["'fixture'", "truncated"]),
])
def test_a_bad_ies_file_is_refused_naming_the_lamp(case, words, tmp_path):
    from relight_addon.engine.scene import SceneError
    text = pf.lm63_text("downlight")
    lines = text.split("\n")
    if case == "type A":
        at = lines.index("TILT=NONE") + 1  # (line 6 of the writer's file)
        f = lines[at].split()
        f[5] = "3"
        lines[at] = " ".join(f)
        text = "\n".join(lines)
    elif case == "truncated":
        text = "\n".join(lines[:12])
    try:
        _floor()
        pf.ies_point_lamp(bpy, "fixture", (0, 0, 1.0), (0, 0, 0), text, 20.0,
                          path=tmp_path / "nowhere.ies" if case == "missing" else None)
        with pytest.raises(SceneError) as e:
            _export()
    finally:
        cr.reset_blender()
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg


def _cli(*argv):
    return subprocess.run([sys.executable, "-m", "relight_addon", *map(str, argv), "--quiet"], cwd=ROOT,
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ROOT})


def test_the_cli_refuses_a_missing_ies_file_with_one_line(tmp_path):
    blend = tmp_path / "s.blend"
    try:
        _floor()
        pf.ies_point_lamp(bpy, "fixture", (0, 0, 1.0), (0, 0, 0), None, 20.0, path=tmp_path / "gone.ies")
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        cr.reset_blender()
    proc = _cli("radiosity", blend, "--report", tmp_path / "r.json")
    assert proc.returncode == 2, proc.stderr
    err = [ln for ln in proc.stderr.strip().splitlines() if ln.startswith("relight: error:")]
    assert len(err) == 1 and "'fixture'" in err[0] and "gone.ies" in err[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_reduce_counts_a_fixture_as_one_of_the_scenes_lights(tmp_path):
    """`reduce` on a floor lit by two fixtures, targets asking for the downlight's light alone where
    it shines: the fixtures are lights of the direct-lighting mode (kind "lamp"), and the answer's
    radiosity is the fixtures' light at their solved Power (no NaN)."""
    blend, report_path = tmp_path / "s.blend", tmp_path / "r.json"
    try:
        floor = _floor()
        pf.ies_point_lamp(bpy, "down", (-0.5, 0.0, 1.2), (0, 0, 0), pf.lm63_text("downlight"), 20.0)
        pf.ies_point_lamp(bpy, "bat", (0.5, 0.0, 1.2), (0, 0, 0), pf.lm63_text("batwing"), 20.0)
        me = floor.data
        layer = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
        col = np.zeros((len(me.loops), 4), dtype=np.float32)
        for p in me.polygons:
            col[p.loop_start:p.loop_start + p.loop_total] = (0.5, 0.5, 0.5, 1.0)
        layer.data.foreach_set("color", col.ravel())
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    finally:
        cr.reset_blender()
    proc = _cli("reduce", blend, "--report", report_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(report_path.read_text())
    names = {lt.get("object") for lt in report["final"]["lights"]}
    assert names & {"down", "bat"}, report["final"]["lights"]
    assert np.all(np.isfinite(np.asarray(report["objects"]["floor"]["radiosity"], dtype=float)))
