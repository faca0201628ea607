"""Units and shared constants come from engine/units.py (issue 38, item 6): no file repeats the
divisor floor 1e-300 (units.TINY) or the Rec.709 luminance weights (units.REC709_LUMINANCE).

The check covers the files listed in CHECKED. The list becomes the whole package (every .py
under relight_addon/ but engine/units.py) once the branches editing the other files are merged
and their literals replaced.
"""
from __future__ import annotations

import pathlib
import re

import pytest

from relight_addon.engine import units

ROOT = pathlib.Path(__file__).resolve().parent.parent / "relight_addon"

CHECKED = [
    "engine/kernel_transfer.py", "pipeline/chart.py", "engine/radiosity.py", "engine/formfactors.py",
    "engine/principled.py", "engine/view_radiance.py", "engine/sampling.py", "engine/world.py",
    "engine/estimators/*.py", "engine/patch_models/*.py", "engine/incidence.py", "engine/extent.py",
    "engine/geometry.py", "engine/bounces.py", "engine/closed_forms.py", "engine/plausibility.py",
    "pipeline/false_colour.py", "pipeline/polygons.py", "pipeline/viewing.py", "blender/ui/panels.py",
    "blender/ui/display.py", "blender/ui/operators.py",
]

LITERALS = {
    "units.TINY": re.compile(r"(?<![\w.])1e-300(?![\w.])"),
    "units.REC709_LUMINANCE": re.compile(r"(?<![\w.])0\.(2126|7152|0722)(?!\d)"),
}


def _files():
    files = sorted({p for pattern in CHECKED for p in ROOT.glob(pattern)})
    assert len(files) >= len(CHECKED)
    return files


def test_units_values():
    assert units.TINY == 1e-300
    assert sum(units.REC709_LUMINANCE) == pytest.approx(1.0)


def test_no_copied_constants():
    found = []
    for path in _files():
        for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for name, pattern in LITERALS.items():
                if pattern.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{no}: use {name}: {line.strip()}")
    assert not found, "\n".join(found)


def test_lamp_points_defined_once():
    """LAMP_POINTS (receiver points per patch of a lamp's irradiance) is candidate_lamps'; the
    others import it."""
    where = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*.py")
             if re.search(r"^LAMP_POINTS\s*=", p.read_text(encoding="utf-8"), re.M)]
    assert where == ["engine/candidate_lamps.py"]
