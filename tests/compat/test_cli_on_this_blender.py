"""The whole headless chain (.blend -> export -> engine -> report) on whichever bpy runs this
file, with the scene written by that same Blender (sample_blends/generate.py into a temporary
folder): the CLI path on each Blender of tests/test_compat.py, on a file that Blender wrote.

Reference: a black emitter (exitance pi W/m^2) facing a grey receiver (reflectance 0.5),
unit squares 1 m apart: B_r = rho_r * F * e with Howell's closed form F (engine.closed_forms).
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy", reason="this test writes a .blend with Blender's bpy module")

ROOT = Path(__file__).resolve().parents[2]
for p in (str(ROOT), str(ROOT / "sample_blends")):
    if p not in sys.path:
        sys.path.insert(0, p)

import generate  # noqa: E402  (sample_blends/generate.py)
from relight_addon.engine import closed_forms as cf  # noqa: E402


def test_cli_radiosity_parallel_squares_closed_form(tmp_path):
    generate.make_closed_form(str(tmp_path), "parallel", 1.0)
    blend = tmp_path / generate.closed_form_filename("parallel", 1.0)
    report_path = tmp_path / "report.json"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    proc = subprocess.run([sys.executable, "-m", "relight_addon", "radiosity", str(blend),
                           "--report", str(report_path)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(report_path.read_text())
    rows = report["objects"]["receiver"]["radiosity"]
    e = math.pi * generate.EMITTER_RADIANCE
    F = rows[0][0] / (generate.RECEIVER_REFLECTANCE * e)
    assert F == pytest.approx(cf.parallel_rectangles(1.0, 1.0, 1.0), rel=0.02)
    assert report["objects"]["emitter"]["radiosity"][0] == pytest.approx([e] * 3, rel=1e-9)
