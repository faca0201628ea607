"""Build the Relight Blender extension zips (one per platform) without a Blender binary.

    python tools/build_extension.py [--force] [--output-dir dist]

Steps:
1. download the wheels listed in blender_manifest.toml into ./wheels with pip
   (only the missing ones; ./wheels is git-ignored and acts as a cache);
2. stage build/extension/ = relight_addon/* + blender_manifest.toml + the listed wheels
   (in an extension the manifest sits next to __init__.py);
3. run Blender's own extension tool (bl_pkg/cli/blender_ext.py, shipped inside the bpy
   module) with ``build --split-platforms``, then ``validate`` every zip.

A stamp file in the output directory records a hash of all inputs, so an up-to-date
build is not redone (``--force`` rebuilds).
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"
PACKAGE_DIR = ROOT / "relight_addon"
WHEEL_DIR = ROOT / "wheels"
STAGING_DIR = ROOT / "build" / "extension"
OUTPUT_DIR = ROOT / "dist"
STAMP_NAME = ".relight-extension-inputs"
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.pyo", "*.blend1")


class BuildError(RuntimeError):
    """The extension could not be built; the message says why."""


def read_manifest(path: Path = MANIFEST) -> dict:
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def blender_ext_script() -> Path:
    """Path of Blender's extension CLI inside the installed bpy module (no bpy import)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the bpy module is not installed in this Python; run `make setup` first")
    for location in spec.submodule_search_locations:
        found = sorted(Path(location).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if found:
            return found[-1]
    raise BuildError("blender_ext.py not found inside the bpy module")


def wheel_download_args(filename: str) -> tuple[str, str | None, str | None]:
    """(requirement, python version, platform tag) that make pip fetch exactly ``filename``
    (None, None: a pure-Python wheel, py3-none-any)."""
    parts = filename[: -len(".whl")].split("-")
    if len(parts) not in (5, 6):
        raise BuildError(f"not a wheel file name: {filename}")
    dist, version, python_tag, platform_tag = parts[0], parts[1], parts[-3], parts[-1]
    if python_tag == "py3" and parts[-2] == "none" and platform_tag == "any":
        return f"{dist}=={version}", None, None
    if not (python_tag.startswith("cp3") and python_tag[3:].isdigit()):
        raise BuildError(f"unexpected Python tag {python_tag!r} in {filename}")
    python_version = f"3.{python_tag[3:]}"
    return f"{dist}=={version}", python_version, platform_tag.split(".")[-1]


def download_wheels(manifest: dict, wheel_dir: Path = WHEEL_DIR) -> list[Path]:
    """Ensure every wheel the manifest lists is in ``wheel_dir``; returns their paths."""
    wheel_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for rel in manifest.get("wheels", []):
        name = rel.rsplit("/", 1)[-1]
        target = wheel_dir / name
        if not target.exists():
            requirement, python_version, platform_tag = wheel_download_args(name)
            where = [] if python_version is None else ["--python-version", python_version,
                                                       "--platform", platform_tag]
            cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
                   "--only-binary=:all:", "--no-deps", *where, "--dest", str(wheel_dir), requirement]
            print("download:", name, flush=True)
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise BuildError(f"pip could not download {name}:\n{proc.stderr.strip()}")
            if not target.exists():
                raise BuildError(f"pip did not produce {name} (PyPI offers a different file for "
                                 f"{requirement} / Python {python_version} / {platform_tag}); "
                                 "update the wheels list in blender_manifest.toml")
        paths.append(target)
    return paths


def input_fingerprint(manifest_path: Path, wheels: list[Path]) -> str:
    """Hash of everything that goes into the zips (sources by content, wheels by name and size)."""
    h = hashlib.sha256()
    files = [manifest_path] + sorted(
        p for p in PACKAGE_DIR.rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"))
    for p in files:
        h.update(str(p.relative_to(ROOT)).encode())
        h.update(p.read_bytes())
    for w in wheels:
        h.update(f"{w.name}:{w.stat().st_size}".encode())
    h.update(blender_ext_script().read_bytes())
    return h.hexdigest()


def stage(manifest_path: Path, wheels: list[Path], staging_dir: Path = STAGING_DIR) -> Path:
    """Fresh staging dir laid out as the extension's source root."""
    if staging_dir.exists():
        shutil.rmtree(staging_dir)
    shutil.copytree(PACKAGE_DIR, staging_dir, ignore=IGNORE)
    shutil.copy2(manifest_path, staging_dir / "blender_manifest.toml")
    (staging_dir / "wheels").mkdir()
    for w in wheels:  # hard links: the wheels are large and read-only here
        try:
            os.link(w, staging_dir / "wheels" / w.name)
        except OSError:
            shutil.copy2(w, staging_dir / "wheels" / w.name)
    # The manifest's ./wheels/... paths must resolve inside the staged directory.
    for rel in read_manifest(staging_dir / "blender_manifest.toml").get("wheels", []):
        if not (staging_dir / rel).is_file():
            raise BuildError(f"manifest wheel {rel} does not resolve in {staging_dir}")
    return staging_dir


def bpy_version_dir() -> str:
    """Blender version of the installed bpy module, e.g. "5.0" (from its data dir, no bpy import)."""
    return blender_ext_script().parents[4].name


def run_blender_ext(*args: str) -> str:
    proc = subprocess.run([sys.executable, str(blender_ext_script()), *args],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError(f"blender_ext.py {args[0]} failed:\n{proc.stdout}{proc.stderr}".strip())
    return proc.stdout


def _shown(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def platform_zip_name(manifest: dict, platform: str) -> str:
    """File name blender_ext.py gives a --split-platforms zip."""
    return f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"


def build_extension(output_dir: Path = OUTPUT_DIR, force: bool = False,
                    manifest_path: Path = MANIFEST, staging_dir: Path = STAGING_DIR) -> dict[str, Path]:
    """Build and validate one zip per platform; returns {blender platform: zip path}.

    Skips the build when the zips exist and the inputs are unchanged since the last build.
    Concurrent builds into the same output directory wait for each other (file lock).
    """
    output_dir.mkdir(parents=True, exist_ok=True)
    with open(output_dir / ".relight-build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _build_locked(output_dir, force, manifest_path, staging_dir)


def _build_locked(output_dir: Path, force: bool, manifest_path: Path, staging_dir: Path) -> dict[str, Path]:
    manifest = read_manifest(manifest_path)
    wheels = download_wheels(manifest)
    zips = {p: output_dir / platform_zip_name(manifest, p) for p in manifest["platforms"]}
    stamp = output_dir / STAMP_NAME
    fingerprint = input_fingerprint(manifest_path, wheels)
    if (not force and stamp.exists() and stamp.read_text() == fingerprint
            and all(z.exists() for z in zips.values())):
        print("extension: up to date:", ", ".join(_shown(z) for z in zips.values()))
        return zips
    staging = stage(manifest_path, wheels, staging_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    stamp.unlink(missing_ok=True)
    for z in zips.values():
        z.unlink(missing_ok=True)
    run_blender_ext("build", "--source-dir", str(staging), "--output-dir", str(output_dir),
                    "--split-platforms")
    for platform, z in zips.items():
        if not z.exists():
            raise BuildError(f"blender_ext.py build did not write {z} for {platform}")
        run_blender_ext("validate", str(z))
        print("extension: built and validated", _shown(z))
    stamp.write_text(fingerprint)
    return zips


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", type=Path, default=OUTPUT_DIR)
    parser.add_argument("--force", action="store_true", help="rebuild even if up to date")
    parser.add_argument("--json", action="store_true", help="print {platform: zip} as JSON")
    args = parser.parse_args(argv)
    try:
        zips = build_extension(args.output_dir.resolve(), force=args.force)
    except BuildError as ex:
        print(f"build_extension: error: {ex}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({k: str(v) for k, v in zips.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
