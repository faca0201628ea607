"""The `radiosity` command end to end, as a subprocess (what `make demo` runs)."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, SAMPLES, file_digest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")

CORNELL = os.path.join(SAMPLES, "cornell_box.blend")


def cli(*args):
    return subprocess.run([sys.executable, "-m", "relight_addon", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_cornell_report_copy_and_render(tmp_path):
    import generate

    before = file_digest(CORNELL)
    rep, out, png = tmp_path / "r.json", tmp_path / "o.blend", tmp_path / "o.png"
    p = cli("radiosity", CORNELL, "--report", rep, "--out", out, "--render", png,
            "--rays-per-patch", "256", "--render-samples", "1")
    assert p.returncode == 0, p.stderr
    assert file_digest(CORNELL) == before
    r = json.loads(rep.read_text())
    assert r["command"] == "radiosity"
    assert set(r["timings_s"]) >= {"export", "form_factors", "solve", "apply", "total"}
    assert r["scene"]["objects"] == 8 and r["scene"]["patches"] >= r["scene"]["faces"]
    # the emitter's radiosity is at least its exitance pi * L_e, plus a little reflected light
    light = np.array(r["objects"]["light"]["radiosity"][0])
    e = math.pi * np.array(generate.CORNELL_LIGHT_RADIANCE)
    assert np.all(light >= e) and np.all(light < 1.05 * e)
    # the red wall is red, the green wall green
    red = np.array(r["objects"]["red_wall"]["radiosity"]).mean(axis=0)
    green = np.array(r["objects"]["green_wall"]["radiosity"]).mean(axis=0)
    assert red[0] > 3 * red[1] and green[1] > 2 * green[0]
    # the copy holds relight_radiosity = B / pi, one row per polygon, the same as the report
    bpy.ops.wm.open_mainfile(filepath=str(out))
    ob = bpy.data.objects["light"]
    me = ob.data
    assert len(r["objects"]["light"]["radiosity"]) == len(me.polygons)
    a = me.color_attributes["relight_radiosity"]
    col = np.zeros(4 * len(me.loops), dtype=np.float32)
    a.data.foreach_get("color", col)
    assert col.reshape(-1, 4)[:, :3] == pytest.approx(np.tile(light / math.pi, (len(me.loops), 1)), rel=1e-5)
    for name, v in r["objects"].items():
        assert len(v["radiosity"]) == len(bpy.data.objects[name].data.polygons)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    img = bpy.data.images.load(str(png))
    assert tuple(img.size) == (256, 256)
    bpy.data.images.remove(img)


def test_bad_input_gives_exit_2_and_one_stderr_line(tmp_path):
    p = cli("radiosity", tmp_path / "missing.blend", "--report", tmp_path / "r.json")
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1 and "missing.blend" in p.stderr
    bad = tmp_path / "bad.blend"
    bad.write_bytes(b"BLENDER garbage")
    p = cli("radiosity", bad, "--report", tmp_path / "r.json")
    assert p.returncode == 2, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
