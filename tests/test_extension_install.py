"""The packaged extension installs, loads and uninstalls in Blender (bpy module).

Builds the linux-x64 zip with tools/build_extension.py (Blender's own blender_ext.py build +
validate; cached by an input hash) and installs it in a child process whose Blender user
directories point to a temporary directory and whose sys.path holds only bpy + numpy (as in
a Blender release), so scipy and embreex can only come from the extension's bundled wheels.
Downloading the wheels needs PyPI on first use; they are cached in ./wheels.
"""

import importlib.util
import json
import os
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import build_extension  # noqa: E402

CHILD = ROOT / "tests" / "compat" / "install_child.py"


@pytest.fixture(scope="module")
def linux_zip():
    if sysconfig.get_platform() != "linux-x86_64":
        pytest.skip(f"the install test installs the linux-x64 zip; this is {sysconfig.get_platform()}")
    out = ROOT / "build" / f"test-extension-bpy{build_extension.bpy_version_dir()}"
    zips = build_extension.build_extension(output_dir=out, staging_dir=out / "staging")
    return zips["linux-x64"]


def _isolated_pythonpath(tmp: Path) -> Path:
    """A directory holding only what a Blender release has on sys.path besides its scripts."""
    iso = tmp / "pythonpath"
    iso.mkdir()
    for name in ("bpy", "numpy"):
        spec = importlib.util.find_spec(name)
        pkg_dir = Path(next(iter(spec.submodule_search_locations)))
        (iso / name).symlink_to(pkg_dir)
        libs = pkg_dir.with_name(name + ".libs")
        if libs.exists():
            (iso / libs.name).symlink_to(libs)
    return iso


def test_zip_content_matches_manifest(linux_zip):
    """The linux zip has the manifest at its root next to __init__.py, the linux wheels for
    both Python versions and the pure-Python one, no wheels of other platforms, no numpy and no caches/tests."""
    with zipfile.ZipFile(linux_zip) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    assert "__init__.py" in names and "engine/scene.py" in names and "blender/ui/__init__.py" in names
    wheels = sorted(n for n in names if n.endswith(".whl"))
    # --split-platforms narrows platforms/wheels in a [build.generated] table, which Blender
    # applies over the top-level values when it reads the manifest.
    generated = manifest["build"]["generated"]
    assert generated["platforms"] == ["linux-x64"]
    assert sorted(w.removeprefix("./") for w in generated["wheels"]) == wheels
    assert {w.split("/")[-1].split("-")[0] for w in wheels} == {"scipy", "embreex", "threadpoolctl"}
    binary = [w for w in wheels if not w.endswith("-py3-none-any.whl")]  # (threadpoolctl: pure Python)
    assert {w.split("-")[2] for w in binary} == {"cp311", "cp313"}
    assert all("manylinux" in w for w in binary)
    assert not any("__pycache__" in n or n.endswith(".pyc") or n.startswith("tests/") for n in names)


def test_install_enable_prefs_wheels_uninstall(linux_zip, tmp_path):
    home = tmp_path / "home"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("BLENDER_", "PYTHON"))}
    env.update(
        HOME=str(home),
        BLENDER_USER_RESOURCES=str(home / "blender"),
        BLENDER_USER_CONFIG=str(home / "blender" / "config"),
        BLENDER_USER_SCRIPTS=str(home / "blender" / "scripts"),
        BLENDER_USER_DATAFILES=str(home / "blender" / "datafiles"),
        BLENDER_USER_EXTENSIONS=str(home / "blender" / "extensions"),
        PYTHONPATH=str(_isolated_pythonpath(tmp_path)),
        PYTHONNOUSERSITE="1",
    )
    proc = subprocess.run([sys.executable, "-S", str(CHILD), str(linux_zip)], env=env,
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    failure = f"child failed (exit {proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    assert lines, failure
    r = json.loads(lines[-1][len("RESULT "):])
    detail = json.dumps(r, indent=1)
    # Blender 4.2 (bpy 4.2.23) segfaults at interpreter exit after *uninstalling* an extension
    # whose PropertyGroup has a property with an update= callback (reproduced with a 10-line
    # extension; disabling is fine; bpy 5.0 is fine). That Blender bug is tolerated on 4.2
    # only, and only after the child reported everything (the RESULT line above).
    allowed_exits = {0, -11} if r["blender"].startswith("4.2") else {0}
    assert proc.returncode in allowed_exits, failure

    # Installed under the temporary user directory, never the real one.
    assert Path(r["repo_directory"]).is_relative_to(home), detail
    assert r["install_return"] == ["FINISHED"], detail
    # Importable as bl_ext.user_default.relight; the add-on found its package via __package__.
    assert r["module_loaded"] and r["addon_enabled"], detail
    assert Path(r["module_file"]).is_relative_to(home), detail
    assert r["ui_package_seen"] == "bl_ext.user_default.relight", detail
    # Preferences registered under the package name, with the documented defaults.
    assert r["prefs_idname"] == "bl_ext.user_default.relight", detail
    assert r["prefs"] == {"sidebar_tab": "Relight", "threads": 0}, detail
    assert r["prefs_threads_after_set"] == 3, detail
    # The bundled wheels are what it loads (only bpy+numpy are on the child's own path),
    # they work with the numpy Blender ships, and they compute right.
    assert "wheel_error" not in r, detail
    assert Path(r["scipy_file"]).is_relative_to(home), detail
    assert Path(r["embreex_file"]).is_relative_to(home), detail
    assert r["scipy"] == "1.17.1", detail
    assert r["scipy_solve"] == pytest.approx([1.0, 2.0], abs=1e-12), detail
    assert r["embree_prim_ids"] == [0, -1], detail
    assert r["embree_tfar"][0] == pytest.approx(1.0, abs=1e-6), detail
    # Uninstall removes it cleanly.
    assert r["uninstall_return"] == ["FINISHED"], detail
    assert not r["addon_enabled_after_uninstall"], detail
    assert not r["package_dir_exists_after_uninstall"], detail
