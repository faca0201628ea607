"""Compatibility runs: the add-on from its zip on Blender 4.2 LTS, 4.5 LTS and 5.3 (the main
suite runs on 5.0), each as the bpy module from PyPI in a side venv.

Each run happens in a venv made by tests/compat/envs.py (`make compat-envs`; first creation
needs PyPI and takes 25-50 s per venv, later runs reuse it) and a pytest subprocess whose result
must be a pass, with no skip on linux-x64:

- tests/compat/ (the bpy API the add-on relies on; every shipped sample .blend opens; the CLI
  chain on a scene written by that Blender),
- tests/test_extension_install.py (build the zip with that Blender's own extension tool,
  install it, enable it, load the bundled wheels, uninstall),
- tests/test_addon_workflow.py (the add-on driven through its operators, from its zip, on the
  shipped staircase).

| run | Blender | Python | numpy | wheels used | time on 2 cores |
|---|---|---|---|---|---|
| bpy42 | 4.2.23 LTS | 3.11 | 1.26.4 | cp311 | ~35 s |
| bpy45 | 4.5.15 LTS | 3.11 | 1.26.4 | cp311 | ~30 s |
| bpy53 | 5.3.0 | 3.13 | 2.3.5 | cp313 | ~45 s, + the engine tests |

The bpy53 run also runs the pure engine tests (tests/test_engine_*.py) and imports every engine
module with DeprecationWarning as an error: the Python 3.13 + numpy 2 side of Blender 5.1+.
"""

import os
import re
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

pytestmark = pytest.mark.compat  # (other Blenders' runs: make test-all, not make test)

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests" / "compat"))
import envs  # noqa: E402

BPY_SUITE = ["tests/compat", "tests/test_extension_install.py", "tests/test_addon_workflow.py"]
ENGINE_TESTS = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "tests").glob("test_engine_*.py"))

RUNS = {  # venv -> (Blender version prefix, Python (major, minor), numpy major, extra test files)
    "bpy42": ("4.2.", (3, 11), 1, []),
    "bpy45": ("4.5.", (3, 11), 1, []),
    "bpy53": ("5.3.", (3, 13), 2, ENGINE_TESTS),
}


def _env(name):
    try:
        return envs.ensure_env(name)
    except envs.EnvUnavailable as ex:
        pytest.skip(str(ex))
    except subprocess.CalledProcessError as ex:
        pytest.fail(f"creating the {name} venv failed (PyPI needed on first run):\n{ex.stderr[-2000:]}")


def _clean_env():
    return {k: v for k, v in os.environ.items()
            if not k.startswith(("BLENDER_", "PYTHON", "PYTEST_", "VIRTUAL_ENV"))}


def _run_suite(python, targets, timeout=1500):
    proc = subprocess.run([str(python), "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", *targets],
                          cwd=ROOT, env=_clean_env(), capture_output=True, text=True, timeout=timeout)
    out = proc.stdout + proc.stderr
    counts = {k: int(n) for n, k in re.findall(r"(\d+) (passed|failed|skipped|error|errors)\b", out)}
    return proc.returncode, counts, out


def _python_info(python, code):
    return subprocess.run([str(python), "-c", code], capture_output=True, text=True, env=_clean_env(),
                          check=True, timeout=300).stdout.strip()


ENGINE_IMPORT_CHECK = """
import importlib, pkgutil, relight_addon.engine as engine
names = [m.name for m in pkgutil.walk_packages(engine.__path__, engine.__name__ + ".")]
for name in names:
    importlib.import_module(name)
print(len(names))
"""


@pytest.mark.parametrize("name", list(RUNS))
def test_blender_version_suite(name):
    version, python, numpy_major, extra = RUNS[name]
    py = _env(name)
    info = _python_info(py, "import sys, bpy, numpy; print(bpy.app.version_string, '|', "
                            "'%d.%d' % sys.version_info[:2], '|', numpy.__version__)")
    blender, pyver, npver = [s.strip() for s in info.splitlines()[-1].split("|")]
    assert blender.startswith(version) and pyver == "%d.%d" % python and npver.startswith(f"{numpy_major}."), info
    if extra:
        # every engine module imports without deprecation warnings (numpy 2 removed many 1.x aliases)
        proc = subprocess.run([str(py), "-W", "error::DeprecationWarning", "-c", ENGINE_IMPORT_CHECK],
                              cwd=ROOT, env=_clean_env(), capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0 and int(proc.stdout.split()[-1]) >= 1, proc.stderr[-3000:]
    rc, counts, out = _run_suite(py, BPY_SUITE + extra)
    assert rc == 0 and counts.get("passed", 0) >= 20, f"Blender {blender} suite failed:\n{out[-6000:]}"
    if sysconfig.get_platform() == "linux-x86_64":
        assert counts.get("skipped", 0) == 0, f"unexpected skips on Blender {blender}:\n{out[-3000:]}"
