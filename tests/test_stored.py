"""The stored result (pipeline/stored.py): one owner of the layout kept in the .blend.

Evidence: a real solve of the shipped staircase, stored by the CLI's --out, read back from the
written file and compared with the report the same run wrote; and a stored light of a kind
this version cannot show refused before anything is written.
"""
import dataclasses
import os

import numpy as np
import pytest

from conftest import SAMPLES


@pytest.fixture
def solved(run_cli, tmp_path):
    out, rep = tmp_path / "out.blend", tmp_path / "r.json"
    code, report, err = run_cli(["solve", os.path.join(SAMPLES, "staircase_targets.blend"), "--report", rep,
                                 "--out", out, "--quiet"])
    assert code == 0, err
    return out, report


def test_stored_result_round_trips_and_matches_the_report(solved):
    import bpy

    from relight_addon.blender import results
    from relight_addon.pipeline.stored import StoredResult

    out, report = solved
    bpy.ops.wm.open_mainfile(filepath=str(out))
    data = results.load_result(bpy.context.scene)
    assert isinstance(data, StoredResult)
    # the whole curve, as the report lists it (float32 storage: 7 digits)
    np.testing.assert_allclose(data.curve_relative_error, [p["relative_error"] for p in report["curve"]], rtol=1e-6)
    assert list(data.curve_n_lights) == [p["n_lights"] for p in report["curve"]]
    k = int(np.searchsorted(data.point_index, int(data.final)))
    lit = np.flatnonzero(np.any(data.exitance[k] != 0, axis=1))
    assert len(lit) == report["final"]["n_lights"]
    kinds = results.LIGHT_KINDS.names()
    assert sorted(kinds[c] for c in data.light_kind[lit]) == sorted(li["kind"] for li in report["final"]["lights"])
    # pack/unpack is lossless on what was stored
    again = StoredResult.unpack(data.pack())
    _same_stored(data, again)


def _same_stored(a, b):
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype, f.name
            np.testing.assert_array_equal(x, y, err_msg=f.name)
        else:
            assert x == y and type(x) is type(y), f.name


def test_a_result_just_stored_reads_as_its_text_does():
    # results.store_result keeps what the StoredResult it packed reads as (as_stored) for load_result, which
    # then does not unpack the text: what it shows is what reading the text gives, field by field
    # (float32, JSON), from the solve's own float64 data
    import bpy

    from relight_addon.blender import preparation, results
    from relight_addon.engine.options import JobOptions
    from relight_addon.pipeline.stored import StoredResult

    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    job = preparation.SolveJob.export(bpy.context, JobOptions().validate())
    outcome = job.run()
    data, text, view = results.packed_result(outcome, job.exp.fingerprints)  # (as Live's worker packs it)
    assert data.exitance.dtype == np.float64  # (the solve's, not yet rounded)
    assert text == data.pack()
    _same_stored(view, StoredResult.unpack(text))
    results.store_result(bpy.context.scene, text, view)
    _same_stored(results.load_result(bpy.context.scene), StoredResult.unpack(text))


def test_a_light_kind_without_a_writer_is_refused_before_writing(solved):
    import bpy

    from relight_addon.blender import results
    from relight_addon.engine.scene import SceneError

    out, _ = solved
    bpy.ops.wm.open_mainfile(filepath=str(out))
    scene = bpy.context.scene
    data = results.load_result(scene)
    shown = int(scene["relight_shown"])
    bad = dataclasses.replace(data, light_kind=np.full_like(data.light_kind, 99))
    scene["relight_result"] = bad.pack()
    layer_before = {ob.name: ob.data.attributes.get("relight_radiosity") is not None
                    for ob in scene.objects if ob.type == "MESH"}
    with pytest.raises(SceneError, match="code 99"):
        results.apply_stored_point(scene, 0)
    with pytest.raises(SceneError, match="code 99"):
        results.make_area_lights(scene, shown)
    assert int(scene["relight_shown"]) == shown  # nothing was written
    assert layer_before == {ob.name: ob.data.attributes.get("relight_radiosity") is not None
                            for ob in scene.objects if ob.type == "MESH"}
