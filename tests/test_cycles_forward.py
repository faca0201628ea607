"""Forward radiosity against Cycles (issue "Radiosity engine", "Forward radiosity against Cycles").

Same scene, same units: sample_blends/cornell_box.blend (walls, floor and
ceiling are 8 x 8 grids of ~7 cm faces: 331 faces to compare); our radiosity from the
real command line (``python -m relight_addon radiosity ... --report``), Cycles'
per-face mean outgoing radiance from an image-texture bake with one UV cell
per face (tests/cycles_reference.py). Radiosity B (W/m^2) of a Lambertian
surface is pi times its outgoing radiance, so B/pi is compared with Cycles.

The Cycles bake pipeline itself is first checked against a closed form (a
receiver under a parallel square emitter). Measured numbers and the reasoning
behind the tolerances: docs/validation.md, "Radiosity vs Cycles".
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="Cycles reference needs bpy (Blender as a Python module)")

import cycles_reference as cr  # noqa: E402  (tests/ is on sys.path: pytest's rootdir-relative import)

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "sample_blends" / "cornell_box.blend"

# Settings and tolerances (measurements behind them: docs/validation.md, "Radiosity vs Cycles").
RAYS_PER_PATCH = 16384  # engine side (default meshing, ~1500 patches)
CYCLES_SAMPLES = 160
CELL_PX = 20  # 18 x 18 texels inside each face's UV cell
NOISE_MEAN_TOL = 0.01  # Cycles' own noise on a face mean, averaged over faces
MEAN_TOL = 0.02  # mean per-face relative error (issue's aim: 3 %)
BIAS_TOL = 0.01  # |mean signed relative error|
MAX_TOL = 0.06  # every face: error <= MAX_TOL + 3 x Cycles' noise on that face
DARK = 0.02  # faces darker than 2 % of their object's median: compared in absolute terms


def rel_error(ours, ref):
    """Per-face relative error |ours - ref|_1 / |ref|_1 over the RGB channels."""
    return np.abs(ours - ref).sum(axis=1) / ref.sum(axis=1)


@pytest.fixture(scope="module")
def cornell_comparison(tmp_path_factory):
    """Our report (real CLI, in a subprocess) and Cycles' per-face radiance of the sample box.

    The sample's walls, floor and ceiling are already 8 x 8 grids of ~7 cm faces.
    """
    if not CORNELL.exists():
        pytest.skip(f"{CORNELL} missing (make it with sample_blends/generate.py)")
    tmp = tmp_path_factory.mktemp("cycles_forward")
    report_path = tmp / "report.json"
    cmd = [sys.executable, "-m", "relight_addon", "radiosity", str(CORNELL), "--report", str(report_path),
           "--rays-per-patch", str(RAYS_PER_PATCH), "--seed", "1"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(report_path.read_text())
    try:  # the bake changes the open file (UVs, materials); the sample on disk is never saved
        # the sample's light lies 0.5 mm under the ceiling: its back's light, caught in the gap, is
        # not modelled (named in a warning: tests/test_cycles_emission.py), so Cycles' is left out
        cycles = cr.cycles_face_radiance(samples=CYCLES_SAMPLES, seed=1, cell_px=CELL_PX, blend_path=CORNELL,
                                         one_sided=True)
    finally:
        cr.reset_blender()
    yield report, cycles


def test_cycles_bake_matches_closed_form():
    """The reference itself: baked per-face radiance of a grey receiver under a black
    parallel square emitter equals albedo * L_e * F(point -> square), F in closed form,
    averaged over each face; and the noise estimate matches a second seed."""
    side, height, strength, albedo, n = 1.0, 0.5, 2.0, 0.6, 6
    try:
        recv = cr.build_parallel_emitter_scene(side, height, n, strength, albedo)
        me = recv.data
        cells = [np.array([me.vertices[i].co[:2] for i in p.vertices]) for p in me.polygons]
        a = cr.cycles_face_radiance(samples=16, seed=1, cell_px=24)
        b = cr.cycles_face_radiance(samples=16, seed=2, cell_px=24)
    finally:
        cr.reset_blender()
    g = (np.arange(40) + 0.5) / 40
    ref = []
    for c in cells:
        (x0, y0), (x1, y1) = c.min(axis=0), c.max(axis=0)
        X, Y = np.meshgrid(x0 + (x1 - x0) * g, y0 + (y1 - y0) * g)
        F = cr.rect_point_form_factor(X, Y, height, -side / 2, side / 2, -side / 2, side / 2)
        ref.append(albedo * strength * F.mean())  # radiance = albedo * (pi L_e F) / pi
    ref = np.asarray(ref)
    got = a["Receiver"].radiance
    assert np.allclose(a["Emitter"].radiance, strength, rtol=1e-4)  # emission is baked as radiance
    rel = np.abs(got / ref[:, None] - 1)
    assert rel.mean() < 0.005 and rel.max() < 0.015, (rel.mean(), rel.max())
    # Noise estimate vs the spread between two seeds (ratio ~1 if calibrated).
    spread = np.std(b["Receiver"].radiance - got) / np.sqrt(2)
    ratio = spread / a["Receiver"].std_error.mean()
    assert 0.6 < ratio < 1.6, ratio


def test_forward_radiosity_against_cycles(cornell_comparison):
    report, cycles = cornell_comparison
    assert report["units"]["radiosity"] == "W/m^2"
    assert any("'light'" in w and "back side" in w and "not modelled" in w for w in report["warnings"]), \
        report["warnings"]
    objects = report["objects"]
    assert set(cycles) == set(objects)
    errors, signed, noise, lines = [], [], [], []
    for name, cyc in cycles.items():
        ours = np.asarray(objects[name]["radiosity"], dtype=np.float64) / np.pi  # B/pi = radiance
        ref = cyc.radiance
        assert ours.shape == ref.shape and np.all(np.isfinite(ours))
        lum = ref.sum(axis=1)
        med = np.median(lum)
        if name == "light":  # emission-dominated: checks the units (B/pi vs Emission Color x Strength)
            assert np.allclose(ours, ref, rtol=0.01), (ours, ref)
            continue
        dark = lum < DARK * med  # floor under the blocks
        assert np.all(np.abs(ours[dark] - ref[dark]).sum(axis=1) < DARK * med), name
        use = ~dark
        e = rel_error(ours[use], ref[use])
        errors.append(e)
        signed.append((ours[use] - ref[use]).sum(axis=1) / lum[use])
        noise.append(cyc.std_error.sum(axis=1)[use] / lum[use])
        lines.append(f"{name}: faces {use.sum()} mean {e.mean():.4f} max {e.max():.4f} "
                     f"signed {signed[-1].mean():+.4f}")
    errors, signed, noise = map(np.concatenate, (errors, signed, noise))
    summary = (f"faces {len(errors)}: mean {errors.mean():.4f} max {errors.max():.4f} "
               f"signed {signed.mean():+.4f}; Cycles noise mean {noise.mean():.4f} max {noise.max():.4f}; "
               f"max(error - 3 noise) {(errors - 3 * noise).max():.4f}\n" + "\n".join(lines))
    print(summary)
    assert len(errors) >= 320, summary
    # The reference must be sharper than what is tested.
    assert noise.mean() < NOISE_MEAN_TOL, summary
    assert errors.mean() <= MEAN_TOL, summary
    assert abs(signed.mean()) <= BIAS_TOL, summary
    assert np.all(errors <= MAX_TOL + 3 * noise), summary
