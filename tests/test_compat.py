"""Compatibility runs: the small suite on Blender 4.2 LTS, the engine tests on Python 3.13 +
numpy 2.x, and Blender 5.2 when PyPI has it.

Each run happens in a side venv made by tests/compat/envs.py (`make compat-envs`; first
creation needs PyPI and takes about a minute, later runs reuse it) and a pytest subprocess
whose result must be a pass.

- bpy 4.2 LTS (bpy 4.2.23, Python 3.11, numpy 1.26.4 as Blender 4.2 ships): tests/compat/
  (the bpy API the add-on relies on; the CLI chain on a scene written by that Blender)
  + tests/test_extension_install.py (build with 4.2's own
  extension tool, install, enable, load the bundled wheels, uninstall).
- Python 3.13 + numpy 2.x + the bundled scipy/embreex: the pure engine tests
  (tests/test_engine_*.py), the closest available check of the Blender 5.1+ side.
- bpy 5.2 (Python 3.13, numpy 2.x): skipped while bpy 5.2 is not on PyPI.
"""

import os
import re
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "compat"))
import envs  # noqa: E402

BPY_SUITE = ["tests/compat", "tests/test_extension_install.py"]
PY313 = ["/root/.pyenv/versions/3.13.0/bin/python3.13", "python3.13"]


def _env(name):
    try:
        return envs.ensure_env(name)
    except envs.EnvUnavailable as ex:
        pytest.skip(str(ex))
    except subprocess.CalledProcessError as ex:
        pytest.fail(f"creating the {name} venv failed (PyPI needed on first run):\n{ex.stderr[-2000:]}")


def _run_suite(python, targets, timeout=1200):
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("BLENDER_", "PYTHON", "PYTEST_", "VIRTUAL_ENV"))}
    proc = subprocess.run([str(python), "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", *targets],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
    out = proc.stdout + proc.stderr
    counts = {k: int(n) for n, k in re.findall(r"(\d+) (passed|failed|skipped|error|errors)\b", out)}
    return proc.returncode, counts, out


def _python_info(python, code):
    return subprocess.run([str(python), "-c", code], capture_output=True, text=True,
                          check=True, timeout=120).stdout.strip()


def test_blender_42_lts_suite():
    py = _env("bpy42")
    assert _python_info(py, "import bpy; print(bpy.app.version_string)").startswith("4.2.")
    rc, counts, out = _run_suite(py, BPY_SUITE)
    assert rc == 0 and counts.get("passed", 0) >= 5, f"bpy 4.2 suite failed:\n{out[-6000:]}"
    if sysconfig.get_platform() == "linux-x86_64":
        assert counts.get("skipped", 0) == 0, f"unexpected skips on bpy 4.2:\n{out[-3000:]}"


ENGINE_IMPORT_CHECK = """
import importlib, pkgutil, relight_addon.engine as engine
names = [m.name for m in pkgutil.iter_modules(engine.__path__)]
for name in names:
    importlib.import_module("relight_addon.engine." + name)
print(len(names))
"""


def test_python313_numpy2_engine_suite():
    py = _env("py313")
    versions = _python_info(py, "import sys, numpy; print(sys.version_info[:2], numpy.__version__)")
    assert versions.startswith("(3, 13)") and " 2." in versions, versions
    # Every engine module imports on Python 3.13 + numpy 2 without deprecation warnings
    # (numpy 2 removed or deprecated many 1.x aliases).
    proc = subprocess.run([str(py), "-W", "error::DeprecationWarning", "-c", ENGINE_IMPORT_CHECK],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and int(proc.stdout.split()[-1]) >= 1, proc.stderr[-3000:]
    engine_tests = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_engine_*.py"))
    if not engine_tests:
        pytest.skip("engine modules import on Python 3.13/numpy 2, but no tests/test_engine_*.py exist yet")
    rc, counts, out = _run_suite(py, engine_tests)
    assert rc == 0 and counts.get("passed", 0) >= 1, f"engine tests failed on Python 3.13/numpy 2:\n{out[-6000:]}"


def test_blender_52_python313_suite():
    try:
        versions = envs.newest_bpy_versions()
    except (RuntimeError, subprocess.TimeoutExpired) as ex:
        pytest.skip(f"cannot ask PyPI which bpy versions exist: {ex}")
    def major_minor(v):
        return tuple(int(x) for x in re.findall(r"\d+", v)[:2])

    at_least_52 = [v for v in versions if major_minor(v) >= (5, 2)]
    if not at_least_52:
        pytest.skip(f"bpy 5.2 is not on PyPI (newest bpy there: {versions[0]}); the Python 3.13 + "
                    "numpy 2.x side is covered by test_python313_numpy2_engine_suite")
    envs.add_bpy_env("bpy52", at_least_52[-1], PY313, "numpy>=2,<2.7")
    py = _env("bpy52")
    engine_tests = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_engine_*.py"))
    rc, counts, out = _run_suite(py, BPY_SUITE + engine_tests)
    assert rc == 0 and counts.get("passed", 0) >= 5, f"bpy {at_least_52[-1]} suite failed:\n{out[-6000:]}"
