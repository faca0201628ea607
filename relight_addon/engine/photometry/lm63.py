"""IES LM-63 photometric files (1986 / 1991 / 1995 / 2002 / 2019 headers): read and written (no bpy).

The reader takes what Cycles' IES Texture node takes (distribution.py's docstring: the text after
the TILT= line) and refuses, naming the file's line and the cause, what it cannot render as the
file means it: photometric type A (3), a truncated file, a value that is not a number or not
finite, angles that do not increase or leave their range, negative candela, a horizontal set
Cycles would not turn into a whole turn. What Cycles ignores (the tilt, the lumens field for the
intensities, the luminous opening's size) is kept in ``Photometry`` and named in ``notes``.

The writer gives LM-63-2002 text of a type C ``Photometry`` (TILT=NONE; multipliers 1; the lumens
field the rated lumens, -1 for absolute photometry), which Blender's IES Texture node reads.
"""
from __future__ import annotations

import math
import re

import numpy as np

from .distribution import TYPE_A, TYPE_B, TYPE_C, CyclesProfile, Photometry, PhotometryError

__all__ = ["parse_lm63", "write_lm63"]

#: LM-63's unit types: 1 feet, 2 metres
FEET = 0.3048
#: photometric type names
TYPE_NAMES = {TYPE_C: "C", TYPE_B: "B", TYPE_A: "A"}


class _Tokens:
    """The numbers after the TILT= line, each with its line number (1-based)."""

    def __init__(self, lines, start, name):
        self.items = []
        self.name = name
        self.last_line = len(lines)
        for no in range(start, len(lines)):
            for tok in re.split(r"[\s,]+", lines[no].strip()):
                if tok:
                    self.items.append((no + 1, tok))
        self.i = 0

    def _next(self, what):
        if self.i >= len(self.items):
            raise PhotometryError(f"{self.name}: the file ends at line {self.last_line} before {what}: truncated")
        line, tok = self.items[self.i]
        self.i += 1
        return line, tok

    def number(self, what) -> tuple:
        line, tok = self._next(what)
        try:
            x = float(tok)
        except ValueError:
            raise PhotometryError(f"{self.name}: line {line}: {tok!r} is not a number ({what})") from None
        if not math.isfinite(x):
            raise PhotometryError(f"{self.name}: line {line}: {tok!r} is not a finite number ({what})")
        return x, line

    def integer(self, what, low=None) -> tuple:
        x, line = self.number(what)
        if x != int(x):
            raise PhotometryError(f"{self.name}: line {line}: {x:g} is not a whole number ({what})")
        if low is not None and x < low:
            raise PhotometryError(f"{self.name}: line {line}: {what} is {int(x)}, at least {low} expected")
        return int(x), line

    def numbers(self, n, what) -> tuple:
        vals, lines = [], []
        for k in range(n):
            x, line = self.number(f"{what} {k + 1} of {n}")
            vals.append(x)
            lines.append(line)
        return np.array(vals), lines

    def whole_line(self, n, what) -> None:
        """Check that the next n values are one line of exactly n (LM-63's two header lines)."""
        if self.i >= len(self.items):
            raise PhotometryError(f"{self.name}: the file ends at line {self.last_line} before {what}: truncated")
        line = self.items[self.i][0]
        k = sum(1 for ln, _ in self.items if ln == line)
        if k != n:
            raise PhotometryError(f"{self.name}: line {line}: {k} value(s) where LM-63 has {n} ({what}): a missing "
                                  "or extra field")

    def rest(self) -> int:
        return len(self.items) - self.i


def _increasing(values, lines, what, name, low, high):
    for k in range(len(values)):
        if not low - 1e-6 <= values[k] <= high + 1e-6:
            raise PhotometryError(f"{name}: line {lines[k]}: {what} {values[k]:g} is outside {low:g}..{high:g} degrees")
        if k and values[k] <= values[k - 1]:
            raise PhotometryError(f"{name}: line {lines[k]}: {what} {values[k]:g} does not increase (after "
                                  f"{values[k - 1]:g})")


def parse_lm63(text, name="IES file") -> Photometry:
    """The Photometry of LM-63 ``text`` (str or bytes); ``name`` names it in the messages."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            text = text.decode("latin-1")
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    tilt_at = next((i for i, ln in enumerate(lines) if ln.lstrip().upper().startswith("TILT=")), None)
    if tilt_at is None:
        raise PhotometryError(f"{name}: no TILT= line: not an IES LM-63 file")
    if tilt_at == 0 or not lines[tilt_at].startswith("TILT="):
        raise PhotometryError(f"{name}: line {tilt_at + 1}: the TILT= line must start a line after the first "
                              "(Blender's IES node looks for it there)")
    keywords = {}
    for ln in lines[:tilt_at]:
        m = re.match(r"\s*\[([^\]]+)\]\s*(.*)", ln)
        if m:
            keywords[m.group(1).strip().upper()] = (keywords.get(m.group(1).strip().upper(), "") + " " +
                                                    m.group(2).strip()).strip()
    tilt = lines[tilt_at][5:].strip()
    notes = []
    tok = _Tokens(lines, tilt_at + 1, name)
    if tilt.upper() == "INCLUDE":
        tok.integer("the lamp-to-luminaire geometry of the tilt", 1)
        n_tilt, _ = tok.integer("the number of tilt angles", 0)
        tok.numbers(n_tilt, "tilt angle")
        tok.numbers(n_tilt, "tilt multiplying factor")
        notes.append("its tilt data (TILT=INCLUDE) is not applied, as Blender's IES node does not apply it")
    elif tilt.upper() != "NONE":
        notes.append(f"its tilt file ({tilt!r}) is not applied, as Blender's IES node does not apply it")
    tok.whole_line(10, "lamps, lumens per lamp, candela multiplier, angles, photometric type, units, width, "
                       "length, height")
    n_lamps, _ = tok.integer("the number of lamps", 1)
    lumens, _ = tok.number("the lumens per lamp")
    multiplier, mline = tok.number("the candela multiplier")
    if multiplier < 0:
        raise PhotometryError(f"{name}: line {mline}: a negative candela multiplier ({multiplier:g})")
    n_v, _ = tok.integer("the number of vertical angles", 2)
    n_h, _ = tok.integer("the number of horizontal angles", 1)
    ptype, tline = tok.integer("the photometric type")
    if ptype == TYPE_A:
        raise PhotometryError(f"{name}: line {tline}: photometric type A (3) is not read (Relight reads types C "
                              "and B, as luminaires are measured for lighting design): convert the file to type C")
    if ptype not in (TYPE_C, TYPE_B):
        raise PhotometryError(f"{name}: line {tline}: photometric type {ptype} is none of C (1), B (2), A (3)")
    units, uline = tok.integer("the units type")
    if units not in (1, 2):
        raise PhotometryError(f"{name}: line {uline}: units type {units} is neither feet (1) nor metres (2)")
    size = tuple(tok.number(w)[0] * (FEET if units == 1 else 1.0) for w in ("the width", "the length", "the height"))
    tok.whole_line(3, "ballast factor, ballast-lamp photometric factor, input watts")
    ballast, bline = tok.number("the ballast factor")
    lamp_factor, lline = tok.number("the ballast-lamp photometric factor")
    for x, line, what in ((ballast, bline, "ballast factor"), (lamp_factor, lline, "ballast-lamp photometric factor")):
        if x < 0:
            raise PhotometryError(f"{name}: line {line}: a negative {what} ({x:g})")
    watts, _ = tok.number("the input watts")
    v, vlines = tok.numbers(n_v, "vertical angle")
    h, hlines = tok.numbers(n_h, "horizontal angle")
    if ptype == TYPE_C:
        _increasing(v, vlines, "vertical angle", name, 0.0, 180.0)
        _increasing(h, hlines, "horizontal angle", name, 0.0, 360.0)
    else:
        _increasing(v, vlines, "vertical angle", name, -90.0, 90.0)
        _increasing(h, hlines, "horizontal angle", name, -90.0, 90.0)
    cd = np.zeros((n_h, n_v))
    for i in range(n_h):
        row, rlines = tok.numbers(n_v, f"candela value of horizontal angle {h[i]:g}:")
        bad = np.flatnonzero(row < 0)
        if len(bad):
            raise PhotometryError(f"{name}: line {rlines[bad[0]]}: a negative candela value ({row[bad[0]]:g})")
        cd[i] = row
    if ptype == TYPE_C and abs(h[0] - 90.0) < 1e-4:
        notes.append(f"its horizontal angles {h[0]:g}..{h[-1]:g} are turned by 90 degrees (its C90 plane along the "
                     "lamp's C0), as Blender's IES node turns them")
    if tok.rest():
        notes.append(f"{tok.rest()} value(s) after its candela table are not read")
    ph = Photometry(ptype, v, h, cd * multiplier * ballast * lamp_factor,
                    lumens=float(lumens) * n_lamps if lumens > 0 else -1.0, n_lamps=n_lamps, watts=float(watts),
                    size=size, tilt=tilt, keywords=keywords, notes=tuple(notes))
    prof = CyclesProfile.of(ph)
    if ptype == TYPE_C and not (abs(float(prof.h[0])) < 1e-6 and abs(float(prof.h[-1]) - 2 * math.pi) < 1e-5):
        raise PhotometryError(f"{name}: line {hlines[-1]}: horizontal angles {h[0]:g}..{h[-1]:g} are no symmetric "
                              "set of type C (0; 0..90; 0..180; 0..360; 90..270): Blender's IES node would leave "
                              "the rest of the turn dark")
    return ph


def _numbers(values, per_line=10, fmt="{:.6g}") -> list:
    vals = [fmt.format(float(x)) for x in values]
    return [" ".join(vals[i:i + per_line]) for i in range(0, len(vals), per_line)] or [""]


def write_lm63(ph: Photometry, keywords=None) -> str:
    """LM-63-2002 text of the type C Photometry ``ph`` (its keywords, updated by ``keywords``)."""
    if ph.photometric_type != TYPE_C:
        raise PhotometryError(f"only type C distributions are written (this one is type {ph.photometric_type})")
    kw = {"TEST": "Relight", "MANUFAC": "Relight"}
    kw.update(ph.keywords)
    kw.update(keywords or {})
    out = ["IESNA:LM-63-2002"]
    out += [f"[{k}] {v}" for k, v in kw.items() if not k.startswith("_")]
    out.append("TILT=NONE")
    lumens = ph.lumens / max(ph.n_lamps, 1) if ph.lumens > 0 else -1
    w, ln, hgt = ph.size
    out.append(f"{ph.n_lamps} {lumens:.6g} 1 {len(ph.v_angles)} {len(ph.h_angles)} 1 2 {w:.6g} {ln:.6g} {hgt:.6g}")
    out.append(f"1 1 {ph.watts:.6g}")
    out += _numbers(ph.v_angles)
    out += _numbers(ph.h_angles)
    for row in ph.candela:
        out += _numbers(row, fmt="{:.7g}")
    return "\n".join(out) + "\n"
