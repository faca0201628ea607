"""Closed-form form factors through the whole chain: .blend -> export -> engine -> report.

The sample files hold a black emitter (exitance pi W/m^2) and a grey receiver (reflectance
0.5), so the receiver's reported radiosity is exactly B_r = rho_r * F(r->e) * e; the reference
is Howell's closed form (engine.closed_forms). Default settings, 2% tolerance.
"""
import math
import os

import pytest

from conftest import SAMPLES

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
from relight_addon.engine import closed_forms as cf  # noqa: E402

import generate  # noqa: E402  (sample_blends/generate.py; conftest puts it on sys.path)


def reference(kind, param):
    if kind == "parallel":  # receiver and emitter param x param at distance 1
        return cf.parallel_rectangles(param, param, 1.0)
    if kind == "perpendicular":  # receiver width param, emitter height 1, common edge 1
        return cf.perpendicular_rectangles(1.0, param, 1.0)
    # disks: regular DISK_SIDES-gons; compare with disks of the same area
    n = generate.DISK_SIDES
    r_eq = param * math.sqrt(n * math.sin(2 * math.pi / n) / (2 * math.pi))
    return cf.coaxial_disks(r_eq, r_eq, 1.0)


# the extreme aspect ratios of each configuration (the 1.0 files are kept for manual runs)
@pytest.mark.parametrize("kind,param", [c for c in generate.CLOSED_FORM_CASES if c[1] != 1.0])
def test_receiver_radiosity_matches_closed_form(run_cli, tmp_path, kind, param):
    blend = os.path.join(SAMPLES, generate.closed_form_filename(kind, param))
    code, report, err = run_cli(["radiosity", blend, "--report", tmp_path / "r.json"])
    assert code == 0, err
    rows = report["objects"]["receiver"]["radiosity"]
    assert len(rows) == 1
    e = math.pi * generate.EMITTER_RADIANCE
    F = rows[0][0] / (generate.RECEIVER_REFLECTANCE * e)
    assert F == pytest.approx(reference(kind, param), rel=0.02)
    # the black emitter reflects nothing: its radiosity is its exitance
    assert report["objects"]["emitter"]["radiosity"][0] == pytest.approx([e] * 3, rel=1e-9)
    # grey: the three channels agree
    assert rows[0][1] == pytest.approx(rows[0][0], rel=1e-9)
