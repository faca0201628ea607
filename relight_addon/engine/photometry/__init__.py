"""Measured photometry: a luminaire's light distribution from its file, as Cycles renders it (no bpy).

- ``distribution.py``: Photometry (a file's angles and candela), CyclesProfile (the table as
  Cycles' IES Texture node evaluates it: its processing, angle conventions and interpolation).
- ``lm63.py``: IES LM-63 read (types C and B; type A refused) and written (type C, for Blender's
  IES node).
- ``eulumdat.py``: EULUMDAT (.ldt) read into the same Photometry.
- ``library.py``: fixture libraries (a folder of .ies / .ldt files, or the built-in one it generates:
  relight_addon/fixtures/), each fixture with its name, rated lumens and watts.

``read_photometry`` reads either by the file's extension (.ldt: EULUMDAT; else LM-63).
"""
from __future__ import annotations

from pathlib import Path

from .distribution import TYPE_A, TYPE_B, TYPE_C, CyclesProfile, Photometry, PhotometryError
from .eulumdat import parse_eulumdat
from .lm63 import parse_lm63, write_lm63

__all__ = ["CyclesProfile", "Photometry", "PhotometryError", "TYPE_A", "TYPE_B", "TYPE_C", "parse_eulumdat",
           "parse_lm63", "read_photometry", "write_lm63"]


def read_photometry(path) -> Photometry:
    """The Photometry of an LM-63 (.ies, any other extension) or EULUMDAT (.ldt) file (PhotometryError
    naming the file, and the line where its content is the cause)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise PhotometryError(f"{p.name}: cannot be read ({e.strerror or e})") from None
    return (parse_eulumdat if p.suffix.lower() == ".ldt" else parse_lm63)(data, p.name)
