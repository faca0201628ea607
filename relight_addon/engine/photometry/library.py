"""A fixture library: luminaires with a name, a measured distribution, rated lumens and watts (no bpy).

A *fixture* is one luminaire type of a catalogue: its light distribution (an LM-63 or EULUMDAT
file, read by lm63.py / eulumdat.py), its name (LM-63 ``[LUMCAT]`` catalogue number and
``[LUMINAIRE]`` description; EULUMDAT's luminaire name), its rated lumens (the file's lumens field,
else the flux of its candela) and its input watts. ``load_library`` reads a folder of .ies and
.ldt files, or the library the project ships (``BUILTIN``: relight_addon/fixtures/).

The built-in library is generated here from closed-form distributions (``builtin_photometry``)
and written by lm63.write_lm63; the committed files are exactly what ``write_builtin`` writes
(tests/test_fixture_library.py). Each table is absolute: its candela are scaled so that the flux
Cycles renders from it (Photometry.flux_lm: the table as Cycles interpolates it, integrated over
the sphere) is the rated lumens, so a fixture at 100 % gives its rated lumens in Cycles and in
Relight's photometry alike.

A folder with a file Relight cannot read is refused, naming the file and its line (docs/reliability.md,
"Fixture libraries": a catalogue whose one file is skipped would offer a different set of
fixtures than the user chose without the user knowing; the fix, moving the file out, is theirs).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .distribution import TYPE_C, CyclesProfile, Photometry, PhotometryError
from .lm63 import parse_lm63, write_lm63
from .eulumdat import parse_eulumdat
from ..units import TINY

__all__ = ["Fixture", "BUILTIN", "BUILTIN_DIR", "load_library", "builtin_photometry", "write_builtin", "SPECS"]

#: the name that chooses the library the project ships
BUILTIN = "builtin"
#: where its files are (relight_addon/fixtures/)
BUILTIN_DIR = Path(__file__).resolve().parents[2] / "fixtures"
#: the file extensions a library folder's fixtures have
EXTENSIONS = (".ies", ".ldt")
#: the built-in tables' angles (degrees): vertical every 2.5, horizontal every 15 for asymmetric ones
V_STEP, H_STEP = 2.5, 15.0


@dataclass(frozen=True)
class Fixture:
    """One luminaire type: ``name`` (its catalogue number), ``description``, its distribution
    (``photometry``; ``profile``: as Cycles renders it), rated ``lumens`` and input ``watts``,
    ``aimable`` (a track or gimbal fixture: offered aimed at the targets, else along its mounting
    surface's normal), its LM-63 text ``lm63`` (what Blender's IES node holds) and ``source`` (its file)."""

    name: str
    description: str
    photometry: Photometry
    profile: CyclesProfile
    lumens: float
    watts: float
    aimable: bool
    lm63: str
    source: str

    @property
    def symmetric(self) -> bool:
        """Its distribution is the same in every C plane."""
        c = self.photometry.candela
        return bool(np.all(np.abs(c - c[:1]) <= 1e-9 * max(float(c.max()), TINY)))


# -- the built-in library's closed forms ------------------------------------------------------

def _lobe(v, h, axis_v, axis_h, m):
    """max(0, d . a)^m: a cosine-power lobe about the direction (axis_v, axis_h) (degrees, type C)."""
    vr, hr = np.radians(v), np.radians(h)
    av, ah = math.radians(axis_v), math.radians(axis_h)
    d = np.stack([np.sin(vr) * np.cos(hr), np.sin(vr) * np.sin(hr), -np.cos(vr)])
    a = np.array([math.sin(av) * math.cos(ah), math.sin(av) * math.sin(ah), -math.cos(av)])
    return np.maximum(np.tensordot(a, d, axes=1), 0.0) ** m


def _narrow(v, h):
    return _lobe(v, h, 0.0, 0.0, 30.0)


def _wide(v, h):
    return _lobe(v, h, 0.0, 0.0, 1.5)


def _batwing(v, h):
    """cos v (0.15 + sin^2 v) below the horizontal: its peak at asin(sqrt(1.85 / 3)) = 51.8 degrees, the nadir dimmer."""
    c = np.cos(np.radians(v))
    return np.where(c > 0, c * (0.15 + np.sin(np.radians(v)) ** 2), 0.0)


def _washer(v, h):
    """A lobe 35 degrees off the nadir towards C0 (a wall washer's throw), none above the horizontal."""
    return _lobe(v, h, 35.0, 0.0, 6.0) * (np.asarray(v) <= 90.0)


def _uplight(v, h):
    """A wall sconce's asymmetric up-throw: a lobe 130 degrees from its -Z towards C0."""
    return _lobe(v, h, 130.0, 0.0, 4.0)


#: the built-in fixtures: (file stem, [LUMCAT], [LUMINAIRE], closed form, rated lumens, input watts, aimable, symmetric)
SPECS = (
    ("relight-narrow-downlight", "RL-DN15", "Narrow downlight (cos^30 beam, 24 degrees to half peak)", _narrow,
     800.0, 9.0, True, True),
    ("relight-wide-downlight", "RL-DW90", "Wide downlight (cos^1.5, 102 degrees to half peak)", _wide,
     1500.0, 14.0, False, True),
    ("relight-batwing", "RL-BW", "Batwing (cos v (0.15 + sin^2 v), peak at 52 degrees)", _batwing,
     2500.0, 24.0, False, True),
    ("relight-wall-washer", "RL-WW35", "Wall washer (cos^6 lobe 35 degrees towards C0)", _washer,
     1200.0, 12.0, False, False),
    ("relight-asymmetric-uplight", "RL-UP130", "Asymmetric uplight (cos^4 lobe 130 degrees towards C0: wall mounted)",
     _uplight, 1000.0, 11.0, False, False),
)


def builtin_photometry(spec) -> Photometry:
    """The absolute Photometry of one SPECS entry: its closed form tabulated (type C; v every V_STEP
    over 0..180, h 0 alone when symmetric, else every H_STEP over 0..360), scaled so that the flux
    Cycles renders from the table is the rated lumens."""
    stem, lumcat, luminaire, form, lumens, watts, aimable, symmetric = spec
    v = np.arange(0.0, 180.0 + 0.5 * V_STEP, V_STEP)
    h = np.array([0.0]) if symmetric else np.arange(0.0, 360.0 + 0.5 * H_STEP, H_STEP)
    hh, vv = np.meshgrid(h, v, indexing="ij")
    shape = form(vv, hh)
    keywords = {"TEST": "Relight closed form", "MANUFAC": "Relight", "LUMCAT": lumcat, "LUMINAIRE": luminaire,
                "OTHER": f"aimable={'yes' if aimable else 'no'}"}
    unit = Photometry(TYPE_C, v, h, shape, lumens=lumens, watts=watts, keywords=keywords)
    cd = np.round(shape * lumens / unit.flux_lm(), 4)  # (the digits written: the flux is the table's)
    return Photometry(TYPE_C, v, h, cd, lumens=lumens, watts=watts, keywords=keywords)


def builtin_text(spec) -> str:
    """The LM-63 text of one SPECS entry (lm63.write_lm63)."""
    return write_lm63(builtin_photometry(spec))


def write_builtin(folder=BUILTIN_DIR) -> list:
    """Write the built-in library's files into ``folder`` (tools: regenerate relight_addon/fixtures/); their paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for spec in SPECS:
        path = folder / f"{spec[0]}.ies"
        path.write_text(builtin_text(spec), encoding="utf-8", newline="\n")
        out.append(path)
    return out


# -- reading a library ------------------------------------------------------------------------

def _fixture(path: Path) -> Fixture:
    """The Fixture of one file (PhotometryError naming the file and its line)."""
    raw = path.read_bytes()
    ldt = path.suffix.lower() == ".ldt"
    if ldt:
        text = raw.decode("latin-1")
        ph = parse_eulumdat(text, path.name)
    else:
        ph = parse_lm63(raw, path.name)
    kw = ph.keywords
    name = kw.get("LUMCAT") or kw.get("LUMINAIRE") or path.stem
    lumens = ph.flux_lm()  # (its output at full power as Cycles renders it, whatever its lumens field says)
    if not lumens > 0:
        raise PhotometryError(f"{path.name}: its candela table is all zero: it gives no light")
    aimable = "AIMABLE=YES" in kw.get("OTHER", "").upper().replace(" ", "")
    if ldt or ph.photometric_type != TYPE_C:  # Blender's IES node reads LM-63 of type C (written by lm63.py)
        if ph.photometric_type != TYPE_C:
            raise PhotometryError(f"{path.name}: photometric type B is not offered as a fixture (its table is not "
                                  "written back for Blender's IES node): convert it to type C")
        lm63 = write_lm63(ph)
    else:
        lm63 = raw.decode("utf-8", errors="replace") if not isinstance(raw, str) else raw
    return Fixture(str(name), str(kw.get("LUMINAIRE", name)), ph, CyclesProfile.of(ph), float(lumens),
                   float(ph.watts), aimable, lm63, str(path))


_CACHE: dict = {}


def load_library(where) -> tuple:
    """The fixtures (a tuple, by file name) of ``where``: BUILTIN or a folder of .ies / .ldt files.
    PhotometryError (one line naming the cause, and the file and its line) for a folder that does
    not exist, holds no fixture file, or holds one Relight cannot read, or two fixtures of one name."""
    folder = BUILTIN_DIR if where == BUILTIN else Path(str(where)).expanduser()
    if not folder.is_dir():
        raise PhotometryError(f"fixtures: {str(where)!r} is no folder (give a folder of .ies / .ldt files, "
                              f"or {BUILTIN!r})")
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in EXTENSIONS)
    if not files:
        raise PhotometryError(f"fixtures: the folder {str(folder)!r} holds no .ies or .ldt file")
    key = (str(folder), tuple((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in files))
    if key not in _CACHE:
        out, names = [], {}
        for p in files:
            try:
                f = _fixture(p)
            except OSError as e:
                raise PhotometryError(f"fixtures: {p.name}: cannot be read ({e.strerror})") from None
            except PhotometryError as e:
                raise PhotometryError(f"fixtures: {e} (in {str(folder)!r}: fix the file or move it out of the "
                                      "folder)") from None
            if f.name in names:
                raise PhotometryError(f"fixtures: {p.name} and {names[f.name]} are both named {f.name!r} "
                                      "([LUMCAT]): give each fixture its own catalogue number")
            names[f.name] = p.name
            out.append(f)
        _CACHE.clear()
        _CACHE[key] = tuple(out)
    return _CACHE[key]
