"""`make test-gui`: the Relight extension in a real Blender window, and the README's headless
usage in the real Blender binary.

    python tools/gui_test.py [--zip dist/relight-0.1.0-linux_x64.zip] [--out out/gui] [--no-docs]

Needs root and Debian's package mirror (first run): tools/gui_chroot.sh builds, once, a Debian
trixie chroot with Debian's blender (4.3.2), Xvfb, xdotool and ImageMagick, cached in
/var/cache/relight-gui/trixie (RELIGHT_GUI_ROOT). No python3-scipy there: the extension's
bundled wheels are what runs. Then, inside the chroot:

1. tests/gui/prep.py installs the linux zip the way Preferences > Install from Disk does;
2. tests/gui/driver.py drives the add-on in Blender's window under Xvfb with real clicks
   (sample_blends/staircase_targets.blend) and checks the scene after each step;
3. `blender -b SCENE --python-expr "import bpy; bpy.ops.relight.solve()"` (the installed
   extension) and `blender -b --python relight_addon/__main__.py -- solve ...` (the repository's
   package, with the extension's installed wheels on PYTHONPATH) run headless.

Fails on a failed check, a non-zero exit, or a "Traceback" / "Error" line in Blender's output.
Screenshots go to out/gui/; after a passing run a few of them, cropped, to docs/img/gui_*.png.
Exit codes: 0 passed, 1 failed, 3 cannot run here (the reason is printed on one line).
"""
from __future__ import annotations

import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CHROOT_SH = ROOT / "tools" / "gui_chroot.sh"
RUN = "/relight-gui-run"            # inside the chroot
DISPLAY = ":97"
SCREEN = (1600, 1000)
SCENE = "staircase_targets.blend"
DOCS = {  # screenshot -> (docs name, crop box (left, top, right, bottom), scale)
    "08_solved": ("gui_solved.png", (0, 40, 1340, 1000), 0.6),
    "11_results": ("gui_results.png", (1020, 60, 1340, 905), 1.0),
    "11a_false_colour": ("gui_false_colour.png", (0, 40, 1340, 1000), 0.6),
    "04_edit_mode": ("gui_edit_mode.png", (1020, 60, 1340, 700), 1.0),
    "13_large_solve_running": ("gui_progress.png", (1020, 60, 1340, 905), 1.0),
}
ERROR_RE = re.compile(r"Traceback|Error")
# harmless lines of a minbase chroot / Xvfb session (see /work/shared/gui-blender.md)
IGNORED = re.compile(r"^GUI-|could not get a list of mounted file-systems|ALSA|"
                     r"Failed to load ALSA|XDG_RUNTIME_DIR|libdecor|Xlib: *extension")


def sh(*args, check=True, **kw):
    return subprocess.run([str(a) for a in args], check=check, text=True, **kw)


def chroot_root() -> Path:
    return Path(sh(CHROOT_SH, "root", capture_output=True).stdout.strip())


def in_chroot(root, cmd, env=None, timeout=None, log=None):
    """Run a shell command inside the chroot; returns (returncode, output)."""
    envs = " ".join(f"{k}={v}" for k, v in (env or {}).items())
    full = ["chroot", str(root), "/usr/bin/env", "-i", "PATH=/usr/bin:/bin", "LANG=C.UTF-8",
            f"HOME={RUN}/home", *envs.split(), "bash", "-c", cmd]
    try:
        proc = subprocess.run(full, capture_output=True, text=True, timeout=timeout)
        out, code = proc.stdout + proc.stderr, proc.returncode
    except subprocess.TimeoutExpired as ex:
        out = (ex.stdout or b"").decode(errors="replace") if isinstance(ex.stdout, bytes) else (ex.stdout or "")
        out += f"\nGUI-TIMEOUT after {timeout} s"
        code = 124
    if log is not None:
        Path(log).write_text(out)
    return code, out


def error_lines(text):
    return [ln for ln in text.splitlines() if ERROR_RE.search(ln) and not IGNORED.search(ln)]


def stage(root: Path, zip_path: Path):
    run = root / RUN.lstrip("/")
    if run.exists():
        shutil.rmtree(run)
    (run / "out").mkdir(parents=True)
    (run / "home").mkdir()
    shutil.copy2(zip_path, run / "relight.zip")
    shutil.copy2(ROOT / "sample_blends" / SCENE, run / SCENE)
    for f in ("driver.py", "prep.py"):
        shutil.copy2(ROOT / "tests" / "gui" / f, run / f)
    shutil.copytree(ROOT / "relight_addon", run / "repo" / "relight_addon",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    return run


def headless(root, results, logs):
    """The README's two headless forms, in the chroot's real Blender binary."""
    # 1. the installed extension's operator, synchronous in blender -b
    code, out = in_chroot(root, f'cd {RUN} && blender -b {SCENE} --python-expr '
                                f'"import bpy; bpy.ops.relight.solve()"', timeout=900,
                          log=logs / "headless_operator.log")
    m = re.search(r"Relight: (\d+) lights, relative error ([0-9.e+-]+)", out)
    results.append(("blender -b SCENE --python-expr 'bpy.ops.relight.solve()'",
                    code == 0 and m is not None and not error_lines(out),
                    f"exit {code}; {m.group(0) if m else 'no Relight summary in the output'}"
                    + "".join(f"\n    {ln}" for ln in error_lines(out)[:5])))
    # 2. the repository's __main__.py, scipy/embreex from the extension's installed wheels
    site = sorted(glob.glob(str(root / RUN.lstrip("/") / "home/.config/blender/*/extensions/.local/lib/"
                                                         "python3*/site-packages")))
    pypath = site[-1].replace(str(root), "", 1) if site else ""
    code, out = in_chroot(root, f"cd {RUN} && blender -b --python repo/relight_addon/__main__.py -- solve "
                                f"{SCENE} --report out/headless_report.json --out out/headless_relit.blend",
                          env={"PYTHONPATH": pypath}, timeout=900, log=logs / "headless_main.log")
    report = root / RUN.lstrip("/") / "out" / "headless_report.json"
    final = json.loads(report.read_text())["final"] if report.exists() else None
    ok = code == 0 and final is not None and 1 <= final["n_lights"] <= 3 and not error_lines(out)
    results.append(("blender -b --python relight_addon/__main__.py -- solve", ok,
                    f"exit {code}; PYTHONPATH={pypath or '(no site dir found)'}; final "
                    + (f"{final['n_lights']} lights, relative error {final['relative_error']:.3g}" if final else "none")
                    + "".join(f"\n    {ln}" for ln in error_lines(out)[:5])))


def crop_to_docs(out: Path):
    try:
        from PIL import Image
    except ImportError:
        print("test-gui: Pillow missing, docs/img/gui_*.png not updated")
        return
    for name, (doc, box, scale) in DOCS.items():
        src = out / f"{name}.png"
        if not src.exists():
            continue
        img = Image.open(src).convert("RGB").crop(box)
        if scale != 1:
            img = img.resize((round(img.width * scale), round(img.height * scale)), Image.LANCZOS)
        img.save(ROOT / "docs" / "img" / doc, optimize=True)
        print(f"test-gui: docs/img/{doc} <- {src.relative_to(ROOT) if src.is_relative_to(ROOT) else src}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zip", type=Path, default=ROOT / "dist" / "relight-0.1.0-linux_x64.zip")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "gui")
    ap.add_argument("--no-docs", action="store_true", help="do not update docs/img/gui_*.png")
    ap.add_argument("--skip-headless", action="store_true")
    args = ap.parse_args(argv)

    why = sh(CHROOT_SH, "check", check=False, capture_output=True)
    if why.returncode != 0:
        print(f"test-gui: cannot run here: {why.stdout.strip() or why.stderr.strip()}")
        return 3
    if not args.zip.exists():
        print(f"test-gui: {args.zip} missing: run `make extension` first")
        return 1
    t0 = time.monotonic()
    sh(CHROOT_SH, "ensure")
    root = chroot_root()
    run = stage(root, args.zip)
    if args.out.exists():
        shutil.rmtree(args.out)
    args.out.mkdir(parents=True)
    checks, xvfb, result = [], None, {}
    sh(CHROOT_SH, "mount")
    try:
        code, out = in_chroot(root, f"cd {RUN} && blender -b --factory-startup --python prep.py -- {RUN}/relight.zip",
                              timeout=300, log=args.out / "prep.log")
        checks.append(("install the zip (Preferences > Install from Disk's operator)",
                       code == 0 and "GUI-PREP ok" in out, next((ln for ln in out.splitlines() if "GUI-PREP" in ln),
                                                               f"exit {code}")))
        xvfb = subprocess.Popen(["chroot", str(root), "Xvfb", DISPLAY, "-screen", "0", f"{SCREEN[0]}x{SCREEN[1]}x24",
                                 "-nolisten", "tcp"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(3)
        t_gui = time.monotonic()
        code, out = in_chroot(root, f"cd {RUN} && blender -p 0 0 {SCREEN[0]} {SCREEN[1]} {SCENE} "
                                    f"--python driver.py -- {RUN}/out", env={"DISPLAY": DISPLAY},
                              timeout=2400, log=args.out / "blender.log")
        gui_s = time.monotonic() - t_gui
        result_file = run / "out" / "result.json"
        result = json.loads(result_file.read_text()) if result_file.exists() else {"checks": []}
        for c in result["checks"]:
            checks.append((c["name"], c["status"] in ("pass", "xfail", "XPASS"), c["detail"], c["status"]))
        checks.append((f"the GUI session ends cleanly ({gui_s:.0f} s)", code == 0 and result.get("passed"),
                       f"exit {code}"))
        errs = error_lines(out)
        checks.append(("no Traceback / Error in Blender's output", not errs, "\n    ".join(errs[:12])))
        if not args.skip_headless:
            headless(root, checks, args.out)
    finally:
        if xvfb is not None:
            xvfb.terminate()
            try:
                xvfb.wait(timeout=10)
            except subprocess.TimeoutExpired:
                xvfb.kill()
        sh(CHROOT_SH, "umount", check=False)
        for f in sorted((run / "out").glob("*")):
            if f.is_file():
                shutil.copy2(f, args.out / f.name)

    failed = 0
    for c in checks:
        name, ok, detail = c[:3]
        status = c[3] if len(c) > 3 else ("pass" if ok else "FAIL")
        status = status if ok else "FAIL"
        failed += not ok
        print(f"  {status:5s} {name}" + (f": {detail}" if detail and (not ok or status != "pass") else ""))
    timings = result.get("timings", {})
    print(f"test-gui: {len(checks) - failed}/{len(checks)} checks passed in {time.monotonic() - t0:.0f} s "
          f"(timings {json.dumps(timings)}); screenshots in {args.out.relative_to(ROOT) if args.out.is_relative_to(ROOT) else args.out}")
    if not failed and not args.no_docs:
        crop_to_docs(args.out)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
