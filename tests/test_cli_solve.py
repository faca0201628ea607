"""The `solve` and `reduce` commands end to end on the sample scenes (in-process CLI).

References: the painted targets (e_x must reproduce them), the paper's stated properties
(direct-lighting mode starts from the scene's own configuration with zero error; power is
conserved by the distributions), and the input file (never modified)."""
import json
import math
import os

import numpy as np

import pytest

from conftest import SAMPLES, file_digest
from relight_scene import emitted, emitted_power


def test_solve_without_targets_exits_2_with_one_line(run_cli, tmp_path):
    scene = os.path.join(SAMPLES, "staircase.blend")
    before = file_digest(scene)
    code, report, err = run_cli(["solve", scene, "--report", tmp_path / "r.json"])
    assert code == 2 and report is None
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "no target" in lines[0]
    assert file_digest(scene) == before


def test_reduce_without_emitters_exits_2(run_cli, tmp_path):
    code, _, err = run_cli(["reduce", os.path.join(SAMPLES, "staircase.blend"), "--report", tmp_path / "r.json"])
    assert code == 2 and "no emitter" in err


def test_bad_option_values_exit_2(run_cli, tmp_path):
    scene = os.path.join(SAMPLES, "staircase_targets.blend")
    for extra in (["--selection", "magic"], ["--max-lights", "0"], ["--error-threshold", "nan"]):
        code, _, err = run_cli(["solve", scene, "--report", tmp_path / "r.json", *extra])
        assert code == 2 and len(err.strip().splitlines()) == 1, (extra, err)


@pytest.mark.parametrize("extra, words", [
    (["--tolerance", "0.2"], ["--tolerance", "least-power selection"]),
    (["--tolerance", "0.1"], ["--tolerance", "least-power selection"]),  # given, even at its default
    (["--refine-passes", "1", "--patch-model", "polygon"], ["--refine-passes", "adaptive patch model"]),
    (["--light-size", "0.5", "--patch-model", "polygon"], ["--light-size", "adaptive patch model"]),
    (["--distribution", "uniform"], ["--distribution", "distributes no power"]),
    (["--selection", "least-power", "--max-lights", "5"], ["--max-lights", "tolerance"]),
])
def test_an_option_the_chosen_methods_do_not_use_exits_2(run_cli, tmp_path, extra, words):
    """Issue 15.2: refused with one line naming the option and its method, before any work."""
    scene = os.path.join(SAMPLES, "staircase_targets.blend")
    code, _, err = run_cli(["solve", scene, "--report", tmp_path / "r.json", *extra])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1, (extra, err)
    assert lines[0].startswith("relight: error: ") and all(w in lines[0] for w in words), lines[0]
    assert not (tmp_path / "r.json").exists()


def test_reduce_refuses_the_inverse_only_options(run_cli, tmp_path):
    scene = os.path.join(SAMPLES, "cornell_box.blend")
    for extra in (["--refine-passes", "1"], ["--solver", "svd"]):
        code, _, err = run_cli(["reduce", scene, "--report", tmp_path / "r.json", *extra])
        assert code == 2 and len(err.strip().splitlines()) == 1 and "used only by solve" in err, (extra, err)


def test_least_power_from_the_cli_reports_its_tolerance(run_cli, tmp_path):
    scene = os.path.join(SAMPLES, "staircase_targets.blend")
    code, r, err = run_cli(["solve", scene, "--report", tmp_path / "r.json", "--selection", "least-power",
                            "--tolerance", "0.3", "--rays-per-patch", "512", "-q"])
    assert code == 0, err
    assert r["options"]["selection"] == "least-power" and r["options"]["tolerance"] == 0.3
    assert r["options"]["refine_passes"] == 0  # the adaptive model's, used
    code, r, err = run_cli(["solve", scene, "--report", tmp_path / "r2.json", "--rays-per-patch", "512", "-q"])
    assert code == 0 and r["options"]["tolerance"] is None  # greedy-swap: no tolerance listed


def test_reduce_cornell_direct_lighting_mode(run_cli, tmp_path):
    """Direct-lighting mode on the Cornell box with its light split into 3 x 3 faces: e_x is the
    scene's own light (error 0, no negatives); every step conserves the light's power per
    channel (the paper's EnergyConservation), and the final point has <= 3 light faces."""
    import bmesh
    import bpy

    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "cornell_box.blend"))
    light = bpy.data.objects["light"]
    bm = bmesh.new()
    bm.from_mesh(light.data)
    bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=2, use_grid_fill=True)
    bm.to_mesh(light.data)
    bm.free()
    scene = tmp_path / "cornell_9_lights.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene), copy=True)
    area = np.array([p.area for p in light.data.polygons])
    assert len(area) == 9
    code, r, err = run_cli(["reduce", scene, "--report", tmp_path / "r.json", "--rays-per-patch", "1024",
                            "--selection", "exitance-elimination"])
    assert code == 0, err
    assert r["command"] == "reduce" and r["inverse"]["n_candidates"] == 9
    assert r["curve"][0]["relative_error"] < 1e-10
    assert all(c["n_negative"] == 0 for c in r["curve"])
    assert [c["n_lights"] for c in r["curve"]] == list(range(9, 0, -1))
    fin = r["final"]
    assert fin["n_lights"] <= 3 and fin["n_negative"] == 0 and len(fin["lights"]) == fin["n_lights"]
    # power conserved: sum of exitance x area over the light faces = pi x radiance (50, 42.5, 30)
    # of the sample's material x the light's area, per channel (world area = mesh area here)
    e = np.array(r["objects"]["light"]["exitance"])
    world_area = np.array([li["area"] for li in fin["lights"]]).sum()
    np.testing.assert_allclose((e * area[:, None]).sum(axis=0),
                               math.pi * np.array([50.0, 42.5, 30.0]) * area.sum(), rtol=1e-6)
    assert world_area < area.sum() + 1e-9


def test_solve_out_file_reopens_with_its_curve(run_cli, tmp_path):
    import bpy

    import relight_addon

    scene = os.path.join(SAMPLES, "staircase_targets.blend")
    before = file_digest(scene)
    out = tmp_path / "out.blend"
    code, r, err = run_cli(["solve", scene, "--report", tmp_path / "r.json", "--out", out,
                            "--rays-per-patch", "1024"])
    assert code == 0, err
    assert file_digest(scene) == before
    # e_x reproduces the (feasible) painted targets
    assert r["inverse"]["relative_error"] < 1e-8 and r["inverse"]["n_negative"] > 0
    fin = r["final"]
    assert fin["n_negative"] == 0 and 1 <= fin["n_lights"] <= 3
    cells = [li for li in fin["lights"] if li["exitance"] is not None]  # surface lights; the others are lamps
    lamps = [li for li in fin["lights"] if li["exitance"] is None]
    assert all(li["kind"] in ("spot", "area", "point") for li in lamps)
    for light in cells:
        assert all(math.isfinite(x) and x >= 0 for x in light["exitance"])
    # reopen the copy with the add-on registered: the curve list is rebuilt from the file
    relight_addon.register()
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        s = bpy.context.scene
        assert len(s.relight.curve) >= 2
        row = s.relight.curve[s.relight.curve_index]
        assert row.n_lights == fin["n_lights"] and abs(row.error - fin["error"]) < 1e-6 * max(1, fin["error"])
        # the emitters object holds the reported lights: their power per channel, their area, and
        # every emitting triangle lies on (in front of) a polygon a reported light names
        em = emitted(s)
        if cells:
            assert em is not None and em["object"].name.startswith("Relight Emitters")
            power = np.sum([np.asarray(li["exitance"]) * li["area"] for li in cells], axis=0)
            np.testing.assert_allclose(emitted_power(s), power, rtol=1e-4)
            assert em["area"].sum() == pytest.approx(sum(li["area"] for li in cells), rel=1e-4)
            assert np.all(em["radiance"] >= 0)
        for li in cells:
            np.testing.assert_allclose(np.linalg.norm(li["normal"]), 1.0, rtol=1e-9)
            assert li["polygons"] and all(0 <= p < len(s.objects[li["object"]].data.polygons) for p in li["polygons"])
        # the lamps: Light objects of Relight's, each with its reported power per channel
        placed = {o.name: o for o in s.objects if o.type == "LIGHT" and o.get("relight_owner") == s["relight_result_id"]}
        assert sorted(placed) == sorted(li["object"] for li in lamps)
        for li in lamps:
            ld = placed[li["object"]].data
            np.testing.assert_allclose(np.array(ld.color) * ld.energy, li["strength"], rtol=1e-5)
    finally:
        relight_addon.unregister()


def test_cancelled_solve_raises_and_leaves_the_scene_as_it_was(bpy_clean):
    """ESC in the add-on sets the cancel flag the job polls; the job raises Cancelled before
    anything is written back (the operator only touches the scene after a finished job)."""
    import pytest

    from relight_addon.blender import blend_files, export
    from relight_addon.pipeline import jobs
    from relight_addon.engine.options import JobOptions

    blend_files.open_blend(os.path.join(SAMPLES, "staircase_targets.blend"))
    exp = export.export_scene()
    bpy = bpy_clean

    def state():
        return sorted((o.name, len(o.data.materials), sorted(a.name for a in o.data.attributes))
                      for o in bpy.context.scene.objects if o.type == "MESH"), sorted(m.name for m in bpy.data.materials)

    before = state()
    calls = {"n": 0}

    def cancel_after_a_while():
        calls["n"] += 1
        return calls["n"] > 3

    stages = []
    with pytest.raises(jobs.Cancelled):
        jobs.run_solve(exp.faces, JobOptions(rays_per_patch=1024), progress=lambda s, f: stages.append((s, f)),
                       cancel=cancel_after_a_while, **export.job_inputs(exp))
    assert calls["n"] > 3 and stages and all(0.0 <= f <= 1.0 for _, f in stages)
    assert state() == before


def test_scene_emitters_are_background_light_subtracted_from_the_targets(bpy_clean):
    """Targets painted at exactly the radiosity the Cornell box's own light gives them need no
    extra light: the solve keeps the scene's emitter as background, so e_x is ~0 and exact."""
    from relight_addon.blender import blend_files, export
    from relight_addon.pipeline import jobs
    from relight_addon.engine.options import JobOptions

    blend_files.open_blend(os.path.join(SAMPLES, "cornell_box.blend"))
    exp = export.export_scene()
    # a face, a patch; the same form factors for the forward job and the solve
    options = JobOptions(rays_per_patch=1024, max_patch_size=1.0, seed=3, patch_model="polygon", estimator="raycast")
    _, forward = jobs.run_radiosity(exp.faces, options, polygon_counts=exp.polygon_counts)
    faces = exp.faces
    floor = faces.object_names.index("floor")
    targets = np.flatnonzero(faces.face_object == floor)[:10]
    faces.target[targets] = True
    faces.target_radiosity[targets] = forward.face_radiosity[targets]
    out = jobs.run_solve(faces, options, polygon_counts=exp.polygon_counts)
    assert any("fixed background light" in w for w in out.warnings)
    light_exitance = math.pi * np.array([50.0, 42.5, 30.0])
    assert out.report["inverse"]["relative_error"] < 1e-9
    assert np.abs(out.inverse.exitance).max() < 1e-9 * light_exitance.max()


def test_the_certificate_is_relative_to_the_painted_targets_with_scene_light(run_cli, tmp_path):
    """A room whose own lamps give part of the painted light (lit_rooms.lamp_room): the
    certificate's relative bounds are of the painted targets' norm, like every relative error of
    the report, so none exceeds the error a configuration reached (they were of what the lights
    add to the lamps' light: 0.10 for the NNLS bound against a final 0.052). Without the lamp
    refinement: a refined lamp is not a candidate, and may go below the candidates' bound (with
    the default blackbody lights here the refined 3-light answer does, 0.065 against 0.071)."""
    import bpy

    import lit_rooms

    blend = tmp_path / "room.blend"
    lit_rooms.lamp_room(blend)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    lit_rooms.paint(bpy.data.objects["floor"], [j * 4 + i for j in range(1, 3) for i in range(0, 3)], (2.2, 2.0, 1.8))
    for name in ("floor", "wall_s", "wall_n", "wall_w", "wall_e"):
        bpy.data.objects[name]["relight_no_lights"] = True
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    code, r, err = run_cli(["solve", blend, "--report", tmp_path / "r.json", "--rays-per-patch", "512",
                            "--no-lamp-refinement"])
    assert code == 0, err
    assert sum(row["share"] for row in r["fixed_light"]) > 0.3  # the lamps give a good part of it
    cert = r["certificate"]
    best = min(c["relative_error"] for c in r["curve"])
    assert cert["nnls_relative_error"] <= best * (1 + 1e-9)
    for row, point in zip(cert["by_lights"], sorted(r["curve"], key=lambda c: c["n_lights"])):
        assert row["bound_relative_error"] <= point["relative_error"] * (1 + 1e-9) + 1e-12
    assert r["final"]["bound_relative_error"] <= r["final"]["relative_error"] * (1 + 1e-9)
    assert not any(f"below {cert['nnls_relative_error']:.3g}" in w and cert["nnls_relative_error"] >
                   r["final"]["relative_error"] for w in r["warnings"])


@pytest.mark.parametrize("colour", ["auto", "blackbody"])
def test_solve_keeps_the_lamps_of_an_earlier_report_and_finds_the_rest(run_cli, tmp_path, colour):
    """--keep (issue 20, items 3-4): the earlier answer's lamps held at their place and power (the
    scene's lamps in the copy and in the solve's fixed light), Max Lights more found around them,
    their error never below what the certificate allows for the rest. Blackbody lamps keep their
    Temperature (their power through it: colour x Power x its colour)."""
    import bpy

    scene = os.path.join(SAMPLES, "staircase_targets.blend")
    code, first, err = run_cli(["solve", scene, "--report", tmp_path / "r1.json", "-q", "--light-colour", colour])
    assert code == 0, err
    lamps = [li for li in first["final"]["lights"] if li.get("type") in ("spot", "point", "area")]
    assert lamps, "the first answer has no lamp to keep"
    code, again, err = run_cli(["solve", scene, "--report", tmp_path / "r2.json", "--keep", tmp_path / "r1.json",
                                "--max-lights", "2", "--out", tmp_path / "o2.blend", "-q"])
    assert code == 0, err
    fixed = {row["name"]: row for row in again["fixed_light"]}
    for li in lamps:
        name = f"{li['object']} (kept)"
        assert np.allclose(fixed[name]["power"], li["strength"], rtol=1e-6), (fixed[name], li["strength"])
    assert again["final"]["n_lights"] <= 2 and len(again["kept"]["lamps"]) == len(lamps)
    surface = len(first["final"]["lights"]) - len(lamps)
    assert (surface == 0) or any("surface light(s)" in w and "not kept" in w for w in again["warnings"])
    refined = (again["model"]["lamp_refinement"] or {}).get("lamps_refined", 0)
    for pt in again["curve"]:  # the certificate is of the rest, with the kept lamps on
        if pt["n_negative"] == 0 and pt["bound_relative_error"] is not None:
            # (of the candidate lights: a configuration holding a refined lamp, which is none, may go below)
            assert pt["relative_error"] >= pt["bound_relative_error"] * (1 - 1e-9) or refined, pt
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "o2.blend"))
    for li in lamps:
        ob = bpy.data.objects[f"{li['object']} (kept)"]
        assert np.allclose(ob.matrix_world.translation, li["location"], atol=1e-6)
        assert ob.data.energy == pytest.approx(li["energy"], rel=1e-6)
        if "temperature_K" in li and hasattr(ob.data, "use_temperature"):
            assert ob.data.use_temperature and ob.data.temperature == pytest.approx(li["temperature_K"], rel=1e-6)
        assert "relight_owner" not in ob and "relight_owner" not in ob.data  # the scene's own: no result removes it
    code, _, err = run_cli(["solve", scene, "--report", tmp_path / "r3.json", "--keep", tmp_path / "o2.blend"])
    assert code == 2 and err.count("\n") == 1 and "--keep" in err and "not JSON" in err, err
