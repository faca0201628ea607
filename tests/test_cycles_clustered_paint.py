"""Paint on faces the adaptive model had clustered, answered from the prepared state, as Cycles
renders it (issue 37: "the patch model must not depend on where paint lies, or paint must map onto
the model that was prepared; state which, and measure what it costs in patches and in accuracy
against Cycles").

The shipped staircase (adaptive model, seed 3) is solved, then 12 unpainted faces that the model
had clustered with others are painted next to the paint (tests/test_prepared.py's stroke). Two
answers to that paint: Solve & Reduce from the prepared state (``PreparedScene.solve``: the paint
mapped onto the kept clusters, each touched cluster a target at its painted faces' mean, nothing
meshed again) and a cold solve (``jobs.run_solve``: the new paint meshed at the patch size). Each
is written into the staircase as the add-on writes it (``results.show_outcome``; the light paths
that show the prediction, as ``solve --out`` writes them), saved, opened again, and Cycles bakes the painted faces with the file's own materials, World and light paths
(``cycles_reference.cycles_face_radiance``).

Measured per answer, over the painted faces (area-weighted): the error Cycles shows against the
paint, sqrt(sum a |pi L - T|^2 / sum a |T|^2), which is what the artist sees; and the prediction
against Cycles (the engine's radiosity per face: its patches' area mean), signed and per face,
on the stroke's faces and on the rest. Asserted: the answer from the prepared state is within 5 %
of the cold solve's error as Cycles renders both (the issue's acceptance, with Cycles' noise
allowed for), and each answer's prediction holds in Cycles on the painted faces, the prepared
state's on the stroke's faces to a cluster's mean (what the mapping costs). Measured:
docs/validation.md ("Paint on clustered faces, as Cycles renders it").
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="the Cycles reference needs bpy (Blender as a Python module)")

import cycles_reference as cr  # noqa: E402
from test_prepared import _clustered_stroke  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STAIRCASE = ROOT / "sample_blends" / "staircase_targets.blend"
SAMPLES = 256
#: Cycles' per-face standard error at 256 samples (mean over the painted faces), at most
NOISE = 0.02
#: the answer from the prepared state, against the cold solve's, in Cycles' error (the issue's 5 %)
WITHIN = 1.05
#: the prediction against Cycles on the painted faces: signed (area-weighted) and per-face mean
#: (measured: the cold solve 0.1 % and 1.5 %; the answer from the prepared state on the faces it
#: meshes alone 1.2 % and 1.3 %)
SIGNED, FACE_MEAN = 0.02, 0.04
#: ... on the stroke's faces in the clusters they were mapped onto, where the prediction shown on
#: a face is its cluster's mean (measured: signed 5.4 %, per face 7.7 %, at most 24 %; the cold
#: solve, which meshes them alone, 0.6 % and 1.9 %)
SIGNED_CLUSTERED, FACE_MEAN_CLUSTERED = 0.08, 0.12


def _painted_polygons(faces):
    """{object name: polygon indices} of the painted faces of ``faces`` (a FaceSet)."""
    out = {}
    for f in np.flatnonzero(faces.target):
        if faces.face_index[f] >= 0:
            out.setdefault(faces.object_names[faces.face_object[f]], []).append(int(faces.face_index[f]))
    return out


def _rendered(outcome, faces, stroke, path):
    """The answer ``outcome`` written into the staircase, saved to ``path``, opened again and baked
    by Cycles: its measures (the module docstring)."""
    from relight_addon.blender import blend_files, export, light_paths, results
    from relight_addon.engine.scene import face_mean
    from relight_addon.pipeline.checks import face_areas

    blend_files.open_blend(str(STAIRCASE))
    exp = export.export_scene()
    results.show_outcome(bpy.context.scene, outcome, exp.fingerprints)
    # (the light paths that show the prediction, as ``solve --out`` writes them)
    block, _ = light_paths.assess_solve(bpy.context.scene, outcome)
    light_paths.match_light_paths(bpy.context.scene, block["max_reflectance"])
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    polys = _painted_polygons(faces)
    baked = cr.cycles_face_radiance(samples=SAMPLES, seed=1, objects=[bpy.data.objects[n] for n in polys],
                                    keep_world=True, keep_materials=True, keep_light_paths=True, faces=polys)
    ours = face_mean(outcome.patches, outcome.stored.radiosity[outcome.final_index])  # (F, 3) W/m^2
    area = face_areas(faces)
    rows = {"ours": [], "cycles": [], "target": [], "noise": [], "area": [], "stroke": []}
    stroked = set(stroke.tolist())
    for f in np.flatnonzero(faces.target):
        name, p = faces.object_names[faces.face_object[f]], int(faces.face_index[f])
        rows["ours"].append(ours[f])
        rows["cycles"].append(np.pi * baked[name].radiance[p])
        rows["target"].append(faces.target_radiosity[f])
        rows["noise"].append(float(np.mean(baked[name].rel_noise[p])))
        rows["area"].append(area[f])
        rows["stroke"].append(f in stroked)
    ours, cyc, tgt, noise, a, on = (np.asarray(rows[k]) for k in ("ours", "cycles", "target", "noise", "area",
                                                                     "stroke"))
    rel = (ours.sum(axis=1) - cyc.sum(axis=1)) / cyc.sum(axis=1)

    def err(x, sel):
        return float(np.sqrt((a[sel, None] * (x[sel] - tgt[sel]) ** 2).sum() / (a[sel, None] * tgt[sel] ** 2).sum()))

    every = np.ones(len(a), dtype=bool)
    return {"patches": int(outcome.patches.n_patches), "faces": int(len(a)), "stroke_faces": int(on.sum()),
            "cycles_error": err(cyc, every), "predicted_error": err(ours, every),
            "cycles_error_stroke": err(cyc, on), "predicted_error_stroke": err(ours, on),
            "signed": float((rel * a).sum() / a.sum()), "face_mean": float(np.abs(rel).mean()),
            "signed_stroke": float((rel[on] * a[on]).sum() / a[on].sum()),
            "face_mean_stroke": float(np.abs(rel[on]).mean()), "face_max_stroke": float(np.abs(rel[on]).max()),
            "signed_rest": float((rel[~on] * a[~on]).sum() / a[~on].sum()),
            "face_mean_rest": float(np.abs(rel[~on]).mean()), "face_max": float(np.abs(rel).max()),
            "noise": float(noise.mean()),
            "from_prepared_state": outcome.report.get("prepared", {}).get("from_prepared_state")}


@pytest.fixture(scope="module")
def answers(tmp_path_factory):
    from relight_addon.blender import blend_files, export
    from relight_addon.engine.options import JobOptions
    from relight_addon.pipeline import jobs, prepared

    tmp = tmp_path_factory.mktemp("clustered")
    try:
        blend_files.open_blend(str(STAIRCASE))
        exp = export.export_scene()
        options = JobOptions(seed=3).validate()
        size = exp.settings.get("max_patch_size")
        state = prepared.PreparedScene.prepare(exp.faces, options, size)
        state.solve(exp.faces)
        faces, stroke = _clustered_stroke(exp.faces, state.patches)
        warm = state.solve(faces)
        assert state.reason is None and warm.report["prepared"]["computed"]["rays cast"] == 0
        cold = jobs.run_solve(faces, options, default_max_patch_size=size)
        out = {"warm": _rendered(warm, faces, stroke, tmp / "warm.blend"),
               "cold": _rendered(cold, faces, stroke, tmp / "cold.blend")}
    finally:
        cr.reset_blender()
    print(out)
    return out


def test_paint_on_clustered_faces_renders_as_well_as_a_cold_solve(answers):
    warm, cold = answers["warm"], answers["cold"]
    assert warm["stroke_faces"] == cold["stroke_faces"] == 12
    assert warm["noise"] < NOISE and cold["noise"] < NOISE, answers
    # (the kept clusters: fewer patches than the cold mesh, which meshes the stroke at the patch size)
    assert warm["patches"] < cold["patches"], answers
    # as good as the cold solve in Cycles' render, within 5 % (and Cycles' noise on both)
    assert warm["cycles_error"] <= WITHIN * cold["cycles_error"] + 2 * NOISE * cold["cycles_error"], answers


@pytest.mark.parametrize("which", ["warm", "cold"])
def test_each_answers_prediction_holds_in_cycles_on_the_painted_faces(answers, which):
    """The prediction on the painted faces as Cycles renders them: on the faces each model meshes
    alone within SIGNED and FACE_MEAN; on the stroke's faces, mapped onto clusters by the
    prepared state, within SIGNED_CLUSTERED and FACE_MEAN_CLUSTERED: what mapping paint onto the
    kept clusters costs in the prediction shown (the answer itself renders as the cold one does)."""
    row = answers[which]
    assert abs(row["signed_rest"]) <= SIGNED and row["face_mean_rest"] <= FACE_MEAN, row
    signed, face_mean = (SIGNED_CLUSTERED, FACE_MEAN_CLUSTERED) if which == "warm" else (SIGNED, FACE_MEAN)
    assert abs(row["signed_stroke"]) <= signed and row["face_mean_stroke"] <= face_mean, row
