"""EULUMDAT (.ldt) photometric files, read into the same Photometry as LM-63 (no bpy).

EULUMDAT's fixed lines (one value a line): 1 company, 2 type indicator, 3 symmetry Isym (0 none,
1 about the vertical axis, 2 about the plane C0-C180, 3 about C90-C270, 4 about both), 4 the number
Mc of C planes over the turn, 5 their spacing, 6 the number Ng of gamma angles, 7 their spacing,
8-12 report, luminaire name and number, file name, date, 13-15 the luminaire's length, width,
height (mm), 16-21 its luminous area (mm), 22 downward flux fraction, 23 light output ratio (%),
24 the conversion factor of the intensities, 25 the measurement's tilt, 26 the number n of lamp
sets, then per set (n lines each): 26a number of lamps, 26b their type, 26c their total flux
(lm), 26d colour, 26e rendering, 26f watts; 27 ten direct ratios; 28 the Mc C angles; 29 the Ng
gamma angles; 30 the intensities in cd per 1000 lamp lumens, the planes the symmetry needs
(Isym 0: all Mc; 1: one; 2: C0..C180; 3: C270..C90 through C0; 4: C0..C90), Ng values each.

C planes and gamma angles are LM-63 type C's horizontal and vertical angles (gamma 0 at the
nadir). The candela are the cd/klm x the conversion factor x the sets' flux / 1000; the planes
are written out as a symmetric type C set (0; 0..90; 0..180; or the whole turn with 360), so the
distribution renders in Blender (as LM-63 written by lm63.write_lm63) as the file means it.
"""
from __future__ import annotations

import math

import numpy as np

from .distribution import TYPE_C, Photometry, PhotometryError

__all__ = ["parse_eulumdat"]


class _Lines:
    def __init__(self, text, name):
        self.lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
        while self.lines and not self.lines[-1].strip():
            self.lines.pop()
        self.i = 0
        self.name = name

    def text(self, what) -> str:
        if self.i >= len(self.lines):
            raise PhotometryError(f"{self.name}: the file ends at line {len(self.lines)} before {what}: truncated")
        self.i += 1
        return self.lines[self.i - 1].strip()

    def number(self, what) -> float:
        t = self.text(what)
        try:
            x = float(t.replace(",", "."))
        except ValueError:
            raise PhotometryError(f"{self.name}: line {self.i}: {t!r} is not a number ({what})") from None
        if not math.isfinite(x):
            raise PhotometryError(f"{self.name}: line {self.i}: {t!r} is not a finite number ({what})")
        return x

    def integer(self, what, low=None, high=None) -> int:
        x = self.number(what)
        if x != int(x) or (low is not None and x < low) or (high is not None and x > high):
            rng = f" in {low}..{high}" if high is not None else (f", at least {low}" if low is not None else "")
            raise PhotometryError(f"{self.name}: line {self.i}: {what} is {x:g}, a whole number{rng} expected")
        return int(x)


def parse_eulumdat(text, name="EULUMDAT file") -> Photometry:
    """The Photometry of EULUMDAT ``text`` (str or bytes); ``name`` names it in the messages."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError:
            text = text.decode("latin-1")
    f = _Lines(text, name)
    company = f.text("the company")
    f.integer("the type indicator", 0, 3)
    isym = f.integer("the symmetry indicator Isym", 0, 4)
    mc = f.integer("the number of C planes", 1)
    f.number("the C planes' spacing")
    ng = f.integer("the number of gamma angles", 2)
    f.number("the gamma angles' spacing")
    f.text("the measurement report")
    luminaire = f.text("the luminaire's name")
    number = f.text("the luminaire's number")
    f.text("the file name")
    f.text("the date")
    dims = [f.number(w) / 1000.0 for w in ("the luminaire's length", "the luminaire's width",
                                           "the luminaire's height")]
    for w in ("the luminous area's length", "its width", "its height at C0", "at C90", "at C180", "at C270"):
        f.number(w)
    f.number("the downward flux fraction")
    f.number("the light output ratio")
    factor = f.number("the intensities' conversion factor")
    tilt = f.number("the tilt during measurement")
    n_sets = f.integer("the number of lamp sets", 1)
    n_lamps = [f.integer(f"the number of lamps of set {k + 1}") for k in range(n_sets)]
    for k in range(n_sets):
        f.text(f"the lamp type of set {k + 1}")
    flux = [f.number(f"the total flux of set {k + 1}") for k in range(n_sets)]
    for k in range(n_sets):
        f.text(f"the colour of set {k + 1}")
    for k in range(n_sets):
        f.text(f"the colour rendering of set {k + 1}")
    watts = [f.number(f"the watts of set {k + 1}") for k in range(n_sets)]
    for k in range(10):
        f.number(f"direct ratio {k + 1} of 10")
    c = np.array([f.number(f"C angle {k + 1} of {mc}") for k in range(mc)])
    c_line = f.i
    g = np.array([f.number(f"gamma angle {k + 1} of {ng}") for k in range(ng)])
    g_line = f.i
    if np.any(np.diff(c) <= 0) or c[0] < 0 or c[-1] >= 360:
        raise PhotometryError(f"{name}: line {c_line}: the C angles must increase within 0..360 (excluded)")
    if np.any(np.diff(g) <= 0) or g[0] < 0 or g[-1] > 180:
        raise PhotometryError(f"{name}: line {g_line}: the gamma angles must increase within 0..180")
    total = float(sum(flux))
    if total <= 0:
        raise PhotometryError(f"{name}: the lamps' flux is {total:g} lm: the intensities (cd per 1000 lm) "
                              "need a positive flux")
    # the planes stored: indices into c
    if isym == 0:
        planes = np.arange(mc)
    elif isym == 1:
        planes = np.array([0])
    elif isym == 2:
        planes = np.flatnonzero(c <= 180 + 1e-6)
    elif isym == 3:
        planes = np.concatenate([np.flatnonzero(c >= 270 - 1e-6), np.flatnonzero(c <= 90 + 1e-6)])
    else:
        planes = np.flatnonzero(c <= 90 + 1e-6)
    rows = np.zeros((len(planes), ng))
    for k in range(len(planes)):
        for j in range(ng):
            x = f.number(f"intensity {j + 1} of {ng} of C plane {c[planes[k]]:g}")
            if x < 0:
                raise PhotometryError(f"{name}: line {f.i}: a negative intensity ({x:g})")
            rows[k, j] = x
    cd_rows = rows * factor * total / 1000.0
    # a symmetric type C set of horizontal angles
    if isym == 1:
        h, table = np.array([0.0]), cd_rows[:1]
    elif isym in (2, 4):
        h, table = c[planes], cd_rows
    elif isym == 3:  # C270..C360 / C0..C90 -> the whole turn, mirrored about C90-C270
        by_angle = {float(c[p]) % 360.0: cd_rows[k] for k, p in enumerate(planes)}
        h = np.array(sorted({a % 360.0 for a in c}))
        table = np.array([by_angle.get(a, by_angle.get((540.0 - a) % 360.0)) for a in h])
        if any(t is None for t in table):
            raise PhotometryError(f"{name}: line {c_line}: the C angles are not symmetric about C90-C270")
        h, table = np.append(h, 360.0), np.vstack([table, table[:1]])
    else:
        h, table = np.append(c, 360.0), np.vstack([cd_rows, cd_rows[:1]])
    notes = []
    if tilt != 0:
        notes.append(f"it was measured tilted by {tilt:g} degrees: the intensities are used as given")
    lamps = int(sum(abs(n) for n in n_lamps))
    return Photometry(TYPE_C, g, h, table, lumens=total, n_lamps=max(lamps, 1), watts=float(sum(watts)),
                      size=tuple(dims), tilt="NONE",
                      keywords={"MANUFAC": company, "LUMINAIRE": luminaire, "LUMCAT": number},
                      notes=tuple(notes))
