"""Units and shared constants come from engine/units.py (issue 38, item 6): no file repeats the
divisor floor 1e-300 (units.TINY) or the Rec.709 luminance weights (units.REC709_LUMINANCE).

The check covers every module of the package but engine/units.py, their owner.
"""
from __future__ import annotations

import pathlib
import re

import pytest

from relight_addon.engine import units

ROOT = pathlib.Path(__file__).resolve().parent.parent / "relight_addon"

LITERALS = {
    "units.TINY": re.compile(r"(?<![\w.])1e-300(?![\w.])"),
    "units.REC709_LUMINANCE": re.compile(r"(?<![\w.])0\.(2126|7152|0722)(?!\d)"),
}


def _files():
    files = sorted(p for p in ROOT.rglob("*.py") if p != ROOT / "engine" / "units.py")
    assert len(files) > 100
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
