"""Artists' own files (issue 34): each corpus scene (tests/corpus/scenes.json), painted and
forbidden as an artist would (tests/corpus/paint/), solved with the defaults by the command line,
and reduced where it has emitters, as real processes.

What each run must hold: exit 0, no traceback and no library's message (only Relight's own
lines), a report of finite numbers, every final light either one a designer would hang or named in
a warning (engine/plausibility.py: its utilisation and luminance), and the cost estimate within
x 3 of the time measured. The files are not in the repository (tests/corpus/README.md): a scene
whose file is absent is skipped, naming where it was looked for."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip("bpy", reason="the corpus is painted and solved with bpy (Blender as a Python module)")

from relight_addon.engine.plausibility import MAX_LUMINANCE, MIN_UTILISATION  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HERE = os.path.join(ROOT, "tests", "corpus")
CORPUS = os.environ.get("RELIGHT_CORPUS") or os.path.join(os.path.dirname(ROOT), "shared", "corpus")
SCENES = json.load(open(os.path.join(HERE, "scenes.json")))["scenes"]
#: seconds a scene's solve may take here before the run is called a failure (issue 34: 60 s on 2
#: cores is the goal, docs/validation.md has the measured times; this bounds a hung run)
TIMEOUT = 900
#: the cost estimate must hold within this factor of the measured time (issue 34)
ESTIMATE_FACTOR = 3.0


def _run(args, timeout=TIMEOUT):
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    return p, time.perf_counter() - t0


def _painted(scene, tmp_path):
    src = os.path.join(CORPUS, scene["file"])
    if not os.path.exists(src):
        pytest.skip(f"{scene['name']}: {scene['file']} is not in {CORPUS} (the corpus files are not committed: "
                    "tests/corpus/README.md)")
    out = tmp_path / "painted.blend"
    p, _ = _run([os.path.join(HERE, scene["paint"]), src, str(out)], timeout=300)
    assert p.returncode == 0 and out.exists(), p.stdout[-2000:] + p.stderr[-2000:]
    return out


def _own_lines_only(stderr):
    """Relight's stderr holds its own lines (relight: ...) and Blender's read log, never a Python
    traceback or a library's warning."""
    assert "Traceback" not in stderr, stderr[-3000:]
    assert "RuntimeWarning" not in stderr and "DeprecationWarning" not in stderr, stderr[-3000:]


def _finite(obj):
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(_finite(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_finite(v) for v in obj)
    return True


@pytest.mark.parametrize("scene", SCENES, ids=[s["name"] for s in SCENES])
def test_an_artists_file_solves_with_a_sane_answer(scene, tmp_path):
    painted = _painted(scene, tmp_path)
    report = tmp_path / "report.json"
    p, seconds = _run(["-m", "relight_addon", "solve", str(painted), "--report", str(report),
                       "--out", str(tmp_path / "relit.blend")])
    _own_lines_only(p.stderr)
    assert p.returncode == 0, p.stderr[-2000:]
    r = json.loads(report.read_text())
    assert _finite(r)
    warned = " ".join(r["warnings"])
    for li in r["final"]["lights"]:
        sane = li.get("utilisation", 1.0) >= MIN_UTILISATION
        if li.get("exitance") is not None:
            from relight_addon.engine.units import luminance_cd, radiance_from_exitance

            sane &= float(luminance_cd(radiance_from_exitance(np.asarray(li["exitance"])))) <= MAX_LUMINANCE
        assert sane or f"{li['object']} ({li['kind']}" in warned, (li, r["warnings"])
    estimate = r["estimate"]["seconds"]
    assert seconds / ESTIMATE_FACTOR <= estimate + 5.0 and estimate <= ESTIMATE_FACTOR * seconds + 5.0, \
        (estimate, seconds)
    if scene.get("reduce"):
        p, _ = _run(["-m", "relight_addon", "reduce", str(painted), "--report", str(tmp_path / "reduce.json")])
        _own_lines_only(p.stderr)
        assert p.returncode == 0, p.stderr[-2000:]
        assert _finite(json.loads((tmp_path / "reduce.json").read_text()))
