"""Shared fixtures: a clean bpy state per test and in-process CLI runs."""
import hashlib
import json
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(ROOT, "sample_blends")
for _p in (ROOT, SAMPLES):  # the package, and sample_blends/generate.py as ``generate``
    if _p not in sys.path:
        sys.path.insert(0, _p)


#: the test tiers (issue 38): `make test` runs the tests none of these marks (about 10 min on 2
#: cores), `make test-all` every test (.ci/run: it, then the window test)
TIERS = {
    "cycles": "a Cycles closed loop: bakes or renders with Cycles and compares with the prediction",
    "compat": "runs another Blender (4.2 LTS, 4.5 LTS, 5.3 as bpy modules, each in its own venv)",
    "slow": "over about 20 s on 2 cores (a whole solve of an artist-sized scene, a subprocess of Blender)",
}


def pytest_configure(config):
    for name, why in TIERS.items():
        config.addinivalue_line("markers", f"{name}: {why}")


@pytest.fixture
def addon():
    """The add-on registered in the bpy session for the test (a factory scene after it)."""
    bpy = pytest.importorskip("bpy", reason="the add-on needs bpy (Blender as a Python module)")
    import relight_addon

    relight_addon.register()
    yield bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    relight_addon.unregister()


@pytest.fixture
def bpy_clean():
    """bpy reset to an empty factory scene before (and after) the test."""
    bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)


@pytest.fixture
def run_cli(bpy_clean, capsys):
    """Run ``cli.main(argv)`` in-process; returns (exit code, report dict or None, stderr)."""
    from relight_addon import cli

    def run(argv):
        capsys.readouterr()
        code = cli.main([str(a) for a in argv])
        err = capsys.readouterr().err
        report = None
        if "--report" in argv:
            path = str(argv[argv.index("--report") + 1])
            if code == 0 and os.path.exists(path):
                with open(path) as fh:
                    report = json.load(fh)
        return code, report, err

    return run


def file_digest(path):
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()
