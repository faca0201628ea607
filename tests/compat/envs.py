"""Side virtual environments for the compatibility runs (used by tests/test_compat.py).

    python tests/compat/envs.py --create all|bpy42|bpy45|bpy53
    python tests/compat/envs.py --newest-bpy

- ``bpy42``: Blender 4.2 LTS as a module (bpy 4.2.23, the newest 4.2.x on PyPI), Python 3.11,
  numpy 1.26.4 (what Blender 4.2 ships; the bpy wheel itself leaves numpy unpinned),
  plus the scipy/embreex versions the extension bundles.
- ``bpy45``: Blender 4.5 LTS (bpy 4.5.15), Python 3.11, numpy 1.26.4.
- ``bpy53``: Blender 5.3 (bpy 5.3.0), Python 3.13, numpy 2.3.5 (bpy 5.3 requires numpy >= 2.2).

An environment is (re)built only when its requirement list changed (stamp file inside it).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Same versions the extension bundles (blender_manifest.toml wheels) and the main .venv uses.
_BUNDLED = ["scipy==1.17.1", "embreex==4.4.0.post1", "pytest==9.2.0"]

ENVS = {
    "bpy42": {
        "dir": ROOT / ".venv-bpy42",
        "python": ["/root/.pyenv/versions/3.11.7/bin/python3.11", "python3.11"],
        "requirements": ["bpy==4.2.23", "numpy==1.26.4", *_BUNDLED],
    },
    "bpy45": {
        "dir": ROOT / ".venv-bpy45",
        "python": ["/root/.pyenv/versions/3.11.7/bin/python3.11", "python3.11"],
        # Blender 4.5 LTS: still Python 3.11 and numpy 1.26
        "requirements": ["bpy==4.5.15", "numpy==1.26.4", *_BUNDLED],
    },
    "bpy53": {
        "dir": ROOT / ".venv-bpy53",
        "python": ["/root/.pyenv/versions/3.13.0/bin/python3.13", "python3.13"],
        # Blender 5.1+: Python 3.13 and numpy 2.x (the cp313 wheels of the extension)
        "requirements": ["bpy==5.3.0", "numpy==2.3.5", *_BUNDLED],
    },
}


def add_bpy_env(name: str, bpy_version: str, python_candidates: list[str], numpy: str) -> None:
    """Declare an environment for a bpy release found on PyPI at run time (e.g. bpy 5.2)."""
    ENVS[name] = {"dir": ROOT / f".venv-{name}", "python": python_candidates,
                  "requirements": [f"bpy=={bpy_version}", numpy, *_BUNDLED]}


class EnvUnavailable(RuntimeError):
    """The base interpreter for an environment is not installed (a reason to skip)."""


def base_python(name: str) -> str:
    for candidate in ENVS[name]["python"]:
        found = candidate if os.path.isabs(candidate) and os.access(candidate, os.X_OK) \
            else shutil.which(candidate) if not os.path.isabs(candidate) else None
        if found:
            return found
    raise EnvUnavailable(f"{name}: no interpreter found among {ENVS[name]['python']}")


def env_python(name: str) -> Path:
    return ENVS[name]["dir"] / "bin" / "python"


def ensure_env(name: str) -> Path:
    """Create or update environment ``name``; returns its python. Raises EnvUnavailable or
    CalledProcessError (pip output included) on failure."""
    spec = ENVS[name]
    base = base_python(name)
    reqs = spec["requirements"]
    stamp = spec["dir"] / (".relight-compat-" + hashlib.sha256("\n".join(reqs).encode()).hexdigest()[:16])
    py = env_python(name)
    if stamp.exists() and py.exists():
        return py
    if not py.exists():
        subprocess.run([base, "-m", "venv", str(spec["dir"])], check=True)
    proc = subprocess.run([str(py), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                           "--only-binary=:all:", *reqs], capture_output=True, text=True)
    if proc.returncode != 0:
        raise subprocess.CalledProcessError(proc.returncode, proc.args, proc.stdout, proc.stderr)
    for old in spec["dir"].glob(".relight-compat-*"):
        old.unlink()
    stamp.touch()
    return py


def newest_bpy_versions() -> list[str]:
    """bpy versions on PyPI for the newest Python here, newest first (one `pip index versions`
    look-up; pip lists only the versions with a wheel for the Python that runs it)."""
    try:
        python = base_python("bpy53")
    except EnvUnavailable:
        python = sys.executable
    proc = subprocess.run([python, "-m", "pip", "index", "versions", "bpy",
                           "--disable-pip-version-check"], capture_output=True, text=True, timeout=60)
    m = re.search(r"Available versions:\s*(.+)", proc.stdout)
    if proc.returncode != 0 or not m:
        raise RuntimeError(f"pip index versions bpy failed: {proc.stderr.strip()[-300:]}")
    return [v.strip() for v in m.group(1).split(",")]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="compatibility venvs")
    parser.add_argument("--create", choices=["all", *ENVS])
    parser.add_argument("--newest-bpy", action="store_true")
    args = parser.parse_args(argv)
    if args.newest_bpy:
        print(", ".join(newest_bpy_versions()[:5]))
    names = list(ENVS) if args.create == "all" else [args.create] if args.create else []
    status = 0
    for name in names:
        try:
            print(f"{name}: {ensure_env(name)}")
        except EnvUnavailable as ex:
            print(f"{name}: skipped: {ex}")
        except subprocess.CalledProcessError as ex:
            print(f"{name}: pip failed:\n{ex.stderr}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
