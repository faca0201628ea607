"""Every painted face at three points of the curve, as Cycles renders the written file (issue 18).

The shipped staircase solved with ``--max-lights 10 --out``; in the written copy, four rows of the
stored curve (2, 3 (as many as the default answers with), 5 and 10 lights) are shown as the add-on's list does
(``results.apply_stored_point``), and Cycles bakes the 44 painted faces with the file's own
materials (Principled, roughness 1, Specular 0: Lambertian), World and light paths
(``cycles_reference.cycles_face_radiance``, only the painted faces baked). Each face's prediction
is what the artist is shown: the row's radiosity layer, B / pi per polygon.

Asserted per row: Cycles' own noise, and the signed (area-weighted) mean, the per-face mean and
the per-face max of (ours - Cycles) / Cycles within the bounds below. Measured: docs/validation.md
("Every painted face").
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="the Cycles reference needs bpy (Blender as a Python module)")

import cycles_reference as cr  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
STAIRCASE = ROOT / "sample_blends" / "staircase_targets.blend"
SAMPLES = 256
#: issue 18's bounds: per-face mean and max, signed (area-weighted mean)
FACE_MEAN, FACE_MAX, SIGNED = 0.02, 0.06, 0.01
NOISE = 0.02  # Cycles' per-face standard error at 256 samples, mean over the faces (measured 1.4 %)


@pytest.fixture(scope="module")
def curve(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("curve")
    rep, out = tmp / "report.json", tmp / "stair_lit.blend"
    r = subprocess.run([sys.executable, "-m", "relight_addon", "solve", str(STAIRCASE), "--report", str(rep),
                        "--out", str(out), "--max-lights", "10", "--seed", "1", "-q"],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    report = json.loads(rep.read_text())
    faces = {n: [i for i, t in enumerate(o["target"]) if t is not None] for n, o in report["objects"].items()}
    faces = {n: f for n, f in faces.items() if f}
    from relight_addon.blender import results

    rows = {}
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        data = results.load_result(bpy.context.scene)
        n = np.asarray(data.n_lights)
        # many: the solve's --max-lights (the list holds larger rows too: docs/validation.md gives them)
        picks = {"few": int(np.argmin(np.abs(n - 2))), "answer": int(np.argmin(np.abs(n - 3))),
                 "middle": int(np.argmin(np.abs(n - 5))),
                 "many": int(np.argmin(np.abs(n - 10)))}
        area = {name: cr.face_areas(bpy.data.objects[name]) for name in faces}
        for label, idx in picks.items():
            bpy.ops.wm.open_mainfile(filepath=str(out))
            scene = bpy.context.scene
            data = results.load_result(scene)
            results.apply_stored_point(scene, idx)
            poly_b = results.polygon_rows(data, np.asarray(data.radiosity[idx], dtype=np.float64))
            off = data.polygon_offset
            names = list(data.objects)
            shown = tmp / f"row_{label}.blend"  # saved and opened again, as a file the artist keeps
            bpy.ops.wm.save_as_mainfile(filepath=str(shown))
            bpy.ops.wm.open_mainfile(filepath=str(shown))
            baked = cr.cycles_face_radiance(samples=SAMPLES, seed=1, objects=[bpy.data.objects[k] for k in faces],
                                            keep_world=True, keep_materials=True, keep_light_paths=True, faces=faces)
            ours, got, noise, w = [], [], [], []
            for name, fl in faces.items():
                oi = names.index(name)
                ours.append(poly_b[off[oi]:off[oi + 1]][fl].sum(axis=1) / np.pi)
                got.append(baked[name].radiance[fl].sum(axis=1))
                noise.append(baked[name].rel_noise[fl].mean(axis=1))
                w.append(area[name][fl])
            ours, got, noise, w = map(np.concatenate, (ours, got, noise, w))
            rel = (ours - got) / got
            on = np.flatnonzero(np.any(np.asarray(data.exitance[idx]) > 0, axis=1))
            rows[label] = {"kinds": np.bincount(np.asarray(data.light_kind)[on]).tolist(), "n_lights": int(n[idx]), "faces": len(rel), "signed": float((rel * w).sum() / w.sum()),
                           "face_mean": float(np.abs(rel).mean()), "face_max": float(np.abs(rel).max()),
                           "noise": float(noise.mean())}
    finally:
        cr.reset_blender()
    return rows


@pytest.mark.parametrize("label", ["few", "answer", "middle", "many"])
def test_every_painted_face_at_three_points_of_the_curve(curve, label):
    row = curve[label]
    print(label, row)
    assert row["faces"] == 44
    assert row["noise"] < NOISE, row
    assert abs(row["signed"]) <= SIGNED, row
    assert row["face_mean"] <= FACE_MEAN, row
    assert row["face_max"] <= FACE_MAX, row


def test_the_three_points_are_different_configurations(curve):
    n = [curve[k]["n_lights"] for k in ("few", "answer", "middle", "many")]
    assert n == [2, 3, 5, 10], n  # 3: as many as the default solve answers with
