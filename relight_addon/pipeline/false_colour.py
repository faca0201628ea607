"""What the 3D Viewport shows of a stored result, per polygon, and the legend (no bpy).

Five views of the configuration shown (``MODES``), each a colour per base-mesh polygon that
blender/ui/display.py writes into the corner colour layer ``relight_display``:

- ``PREDICTED``: the predicted radiance B/pi x 2^EV (scene-linear; ``exposure`` in stops), what the
  ``relight_radiosity`` layer holds times the exposure, smoothed the same way;
- ``PAINTED``: what was painted: the painted radiosity's radiance T/pi x 2^EV on painted faces
  (an illuminance target's too: reflectance x lux / 683), UNPAINTED dark grey elsewhere;
- ``ILLUMINANCE`` (lx): the light arriving, E = (B - e) / reflectance per channel (B = e +
  reflectance x E), in lux (engine.units.illuminance_lux); a face with a channel reflecting less
  than MIN_REFLECTANCE_LUX is too dark to read it from (``unread``: NOT_SHOWN grey, never 0 lx);
- ``LUMINANCE`` (cd/m^2): engine.units.luminance_cd of the radiance B/pi (a light's face included);
- ``DIFFERENCE`` (%): 100 x (Y(B) - Y(T)) / Y(T) on painted faces, Y the Rec.709 luminance
  (engine.units.luminance_weighted): +10 % = predicted 10 % brighter than painted.

The last three are false colours: a fixed sequential scale (``SEQUENTIAL``, violet -> red) from 0 to
a maximum, linear or logarithmic over LOG_DECADES decades, or a diverging one (``DIVERGING``, blue
-> white -> red) from -max to +max for the difference; a value beyond the scale takes its end's
colour. The maximum is the user's, or automatic (``auto_max``): a round number (chart.nice_ceil) at
or above both the painted targets' largest value and the AUTO_PERCENTILE-th percentile of the
patches' values. Their colours are display values (sRGB-encoded: what the screen shows through the
Standard view transform); the natural views' are scene-linear radiance.

Per polygon, a value is the area-weighted mean of its patches' (StoredResult.polygon_weight_matrix);
a polygon counts as painted (or readable) when at least half its area is, the mean then over that part.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..engine.units import (MIN_REFLECTANCE_LUX, illuminance_lux, luminance_cd, luminance_weighted,
                            radiance_from_exitance)
from .chart import COLORS, _draw_text, _line, nice_ceil, text_width

__all__ = ["MODES", "FALSE_COLOUR", "UNITS", "NOT_SHOWN", "UNPAINTED", "View", "view", "patch_exitance", "patch_illuminance",
           "to_polygons", "relative_difference", "colours", "auto_max", "ticks", "position", "legend", "label"]

MODES = ("PREDICTED", "ILLUMINANCE", "LUMINANCE", "DIFFERENCE", "PAINTED")
#: the views shown in false colour (the scene's view transform set to Standard while they are)
FALSE_COLOUR = ("ILLUMINANCE", "LUMINANCE", "DIFFERENCE")
UNITS = {"ILLUMINANCE": "lx", "LUMINANCE": "cd/m²", "DIFFERENCE": "%", "PREDICTED": "W/(m² sr)",
         "PAINTED": "W/(m² sr)"}
#: a face the view has no value for (not painted, too dark to read): a grey no scale holds (display value)
NOT_SHOWN = (0.3, 0.3, 0.3)
#: the painted view's faces that are not painted (scene-linear: the natural views' colours)
UNPAINTED = (0.05, 0.05, 0.05)
#: the sequential scale, from 0 (or the log scale's bottom) to the maximum: (position, display sRGB)
SEQUENTIAL = ((0.0, (0.16, 0.0, 0.38)), (0.15, (0.1, 0.2, 0.85)), (0.32, (0.0, 0.62, 0.95)),
              (0.48, (0.05, 0.72, 0.32)), (0.62, (0.62, 0.84, 0.1)), (0.76, (1.0, 0.86, 0.0)),
              (0.89, (1.0, 0.48, 0.0)), (1.0, (0.88, 0.05, 0.05)))
#: the diverging scale of the difference, -max .. 0 .. +max (too dark: blue; as painted: white; too bright: red)
DIVERGING = ((0.0, (0.05, 0.22, 0.72)), (0.25, (0.42, 0.62, 0.95)), (0.5, (0.96, 0.96, 0.96)),
             (0.75, (0.98, 0.58, 0.42)), (1.0, (0.74, 0.07, 0.1)))
#: a logarithmic scale spans this many decades below its maximum
LOG_DECADES = 3
#: the automatic maximum is at least this percentile of the patches' values
AUTO_PERCENTILE = 95
#: a painted face counts (and an illuminance is read) where at least this share of its area is
MIN_SHARE = 0.5
#: a relative difference is taken against at least this share of the brightest painted luminance
#: (a face painted black: finite, and beyond any scale), and clipped to +-DIFFERENCE_CLIP %
DARK_PAINT = 1e-3
DIFFERENCE_CLIP = 1e6


@dataclass
class View:
    """One view of one configuration. ``colours`` (n_polygons, 3): display sRGB values in false colour
    (``display``), else scene-linear radiance; ``smooth``: to be shown per vertex as the radiosity layer
    is (the predicted view); ``values`` (n_polygons,) in ``unit`` and ``shown`` (n_polygons,) bool: the
    polygons it has a value for; ``vmax`` the scale's maximum used (``auto``: chosen automatically), ``log``,
    ``ticks`` (the legend's values)."""
    mode: str
    colours: np.ndarray
    display: bool
    smooth: bool
    unit: str
    values: np.ndarray = None
    shown: np.ndarray = None
    vmax: float = 0.0
    auto: bool = False
    log: bool = False
    ticks: list = field(default_factory=list)


# --- per patch, per polygon ----------------------------------------------------------------------

def patch_exitance(data, row) -> np.ndarray:
    """(P, 3) W/m^2: each patch's own exitance in kept configuration ``row`` (its light cells'; lamps
    have no patch)."""
    P = data.radiosity.shape[1]
    e = np.zeros((P, 3))
    cell_e = np.asarray(data.light_basis() @ np.asarray(data.exitance[row], dtype=np.float64))
    e[np.asarray(data.cell_patch)] = cell_e
    return e


def patch_illuminance(radiosity, exitance, reflectance) -> tuple:
    """(lux (P,), readable (P,) bool): the illuminance arriving at each patch, E = (B - e) /
    reflectance per channel (engine.units.illuminance_lux; a negative channel read as 0); 0 and
    not readable where a channel reflects less than MIN_REFLECTANCE_LUX."""
    B = np.asarray(radiosity, dtype=np.float64).reshape(-1, 3)
    rho = np.asarray(reflectance, dtype=np.float64).reshape(-1, 3)
    ok = np.all(rho >= MIN_REFLECTANCE_LUX, axis=1) & np.all(np.isfinite(B), axis=1)
    E = np.where(ok[:, None], (B - np.asarray(exitance, dtype=np.float64).reshape(-1, 3))
                 / np.where(ok[:, None], rho, 1.0), 0.0)
    return illuminance_lux(np.maximum(E, 0.0)), ok


def to_polygons(W, values, ok=None) -> tuple:
    """(per polygon values, counted (n_polygons,) bool): per-patch ``values`` (P,) or (P, k) averaged
    over each polygon's patches by area (``W``: StoredResult.polygon_weight_matrix), over those where
    ``ok`` (P,) bool only; a polygon counts where they hold at least MIN_SHARE of its area (0 elsewhere)."""
    v = np.asarray(values, dtype=np.float64)
    m = np.ones(W.shape[1]) if ok is None else np.asarray(ok, dtype=np.float64)
    share = np.asarray(W @ m).reshape(-1)
    total = np.asarray(W @ np.ones(W.shape[1])).reshape(-1)
    counted = (share > 0) & (share >= MIN_SHARE * total)
    mv = v * (m if v.ndim == 1 else m[:, None])
    out = np.asarray(W @ mv)
    den = np.where(counted, share, 1.0)
    out = np.where(counted if v.ndim == 1 else counted[:, None], out / (den if v.ndim == 1 else den[:, None]), 0.0)
    return out, counted


def relative_difference(predicted, painted) -> np.ndarray:
    """100 x (Y(predicted) - Y(painted)) / Y(painted) (%), Y = luminance_weighted of RGB rows (..., 3);
    Y(painted) taken as at least DARK_PAINT x the largest of them, the result clipped to
    +-DIFFERENCE_CLIP: finite for any finite input."""
    yp = luminance_weighted(predicted)
    yt = luminance_weighted(painted)
    top = float(np.max(yt)) if np.size(yt) else 0.0
    floor = max(DARK_PAINT * top, 1e-30)
    return np.clip(100.0 * (yp - yt) / np.maximum(yt, floor), -DIFFERENCE_CLIP, DIFFERENCE_CLIP)


# --- the scales ----------------------------------------------------------------------------------

def auto_max(values, targets=(), diverging=False) -> float:
    """The automatic maximum of a scale: a round number (chart.nice_ceil) at or above both the
    AUTO_PERCENTILE-th percentile of ``values`` (their magnitude for the diverging scale) and the
    largest of ``targets``; 1 when there is nothing to show."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = np.abs(v) if diverging else v
    v = v[np.isfinite(v)]
    t = np.asarray(targets, dtype=np.float64).reshape(-1)
    t = t[np.isfinite(t)]
    top = max(float(np.percentile(v, AUTO_PERCENTILE)) if len(v) else 0.0, float(t.max()) if len(t) else 0.0)
    return nice_ceil(top)


def position(values, vmax, log=False, diverging=False) -> np.ndarray:
    """Where ``values`` lie on the scale, 0 (its bottom) .. 1 (its top), clipped."""
    v = np.asarray(values, dtype=np.float64)
    vmax = float(vmax)
    if diverging:
        t = (v + vmax) / (2 * vmax)
    elif log:
        vmin = vmax / 10.0 ** LOG_DECADES
        t = np.log10(np.maximum(v, vmin) / vmin) / LOG_DECADES
    else:
        t = v / vmax
    return np.clip(np.nan_to_num(t, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)


def colours(values, vmax, log=False, diverging=False) -> np.ndarray:
    """(..., 3) display sRGB colours of ``values`` on the sequential (or diverging) scale to ``vmax``."""
    anchors = DIVERGING if diverging else SEQUENTIAL
    at = np.array([a for a, _ in anchors])
    rgb = np.array([c for _, c in anchors])
    t = position(values, vmax, log, diverging)
    return np.stack([np.interp(t, at, rgb[:, k]) for k in range(3)], axis=-1)


def _nice_step(step) -> bool:
    m = step / 10.0 ** math.floor(math.log10(step))
    return any(abs(m - n) < 1e-9 for n in (1.0, 2.0, 2.5, 5.0, 10.0))


def ticks(vmax, log=False, diverging=False) -> list:
    """The legend's values, bottom to top, evenly spaced on the scale from its bottom to ``vmax``
    (both included): 3 to 6 intervals of a round step where ``vmax`` allows (5, 4, 6 or 3 tried in
    that order), else 5; the decades below ``vmax`` on a log scale; -vmax, -vmax/2, 0, vmax/2, vmax
    on the diverging one."""
    vmax = float(vmax)
    if diverging:
        return [-vmax, -vmax / 2, 0.0, vmax / 2, vmax]
    if log:
        return [vmax / 10.0 ** k for k in range(LOG_DECADES, -1, -1)]
    n = next((n for n in (5, 4, 6, 3) if _nice_step(vmax / n)), 5)
    return [float(f"{vmax * k / n:.12g}") for k in range(n + 1)]


def label(value, signed=False) -> str:
    """A tick's text: 3 significant digits at most, thousands above 10000 as k."""
    v = float(value)
    if abs(v) >= 10000:
        text = f"{v / 1000:.3g}k"
    else:
        text = f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
        if "e" in text:
            text = f"{v:.6f}".rstrip("0").rstrip(".")
    return ("+" + text) if signed and v > 0 else text


def legend(vmax, log=False, diverging=False, size=120, scale=1) -> tuple:
    """The legend (a vertical colour bar, its top at ``vmax``, ticks and their values), a
    square ``size`` px image: (pixels (size, size, 4) float32, row 0 at the bottom; geometry in
    top-down pixels: ``bar`` [x0, y0, x1, y1], ``ticks`` [[value, y], ...]). The bar's row at a
    tick's y has that tick's colour (``colours``)."""
    s = max(1, int(scale))
    n = int(size)
    img = np.empty((n, n, 4), dtype=np.float32)
    img[:] = COLORS["background"]
    ch = 7 * s
    x0, x1 = 4 * s, 16 * s
    y0, y1 = ch // 2 + 3 * s, n - 1 - ch // 2 - 3 * s
    tv = ticks(vmax, log, diverging)
    vmin = tv[0]
    ys = np.arange(y0, y1 + 1)
    frac = (y1 - ys) / max(y1 - y0, 1)
    if log:
        row_values = vmin * 10.0 ** (frac * LOG_DECADES)
    else:
        row_values = vmin + frac * (float(vmax) - vmin)
    img[y0:y1 + 1, x0:x1 + 1, :3] = colours(row_values, vmax, log, diverging)[:, None, :]
    img[y0:y1 + 1, x0:x1 + 1, 3] = 1.0
    geometry = {"size": [n, n], "bar": [x0, y0, x1, y1], "ticks": []}
    for v in tv:
        y = int(round(y1 - float(position(v, vmax, log, diverging)) * (y1 - y0)))
        _line(img, x1 + 1, y, x1 + 3 * s, y, COLORS["axis"])
        text = label(v, signed=diverging)
        _draw_text(img, min(x1 + 5 * s, n - text_width(text, s)), y - ch // 2, text, COLORS["text"], s)
        geometry["ticks"].append([float(v), y])
    return img[::-1].copy(), geometry


# --- the views -----------------------------------------------------------------------------------

def _painted(data) -> tuple:
    """(painted radiosity T (P, 3) W/m^2, painted (P,) bool) of the stored targets."""
    P = data.radiosity.shape[1]
    T = np.zeros((P, 3))
    on = np.zeros(P, dtype=bool)
    tp = np.asarray(data.target_patch, dtype=np.int64)
    T[tp] = np.asarray(data.target_value, dtype=np.float64).reshape(-1, 3)
    on[tp] = True
    return T, on


def view(data, row, mode, exposure=0.0, vmax=0.0, log=False) -> View:
    """The ``mode`` view (MODES) of kept configuration ``row`` of ``data`` (a StoredResult):
    ``exposure`` (EV) for the natural views, ``vmax`` the false-colour scale's maximum (0 or less:
    automatic), ``log`` its logarithmic scale (not the difference's). ValueError when the result
    lacks what the view needs (a result stored before the reflectance was kept: no illuminance)."""
    if mode not in MODES:
        raise ValueError(f"unknown view {mode!r} (one of {', '.join(MODES)})")
    W = data.polygon_weight_matrix()
    B = np.asarray(data.radiosity[row], dtype=np.float64)
    gain = 2.0 ** float(exposure)
    unit = UNITS[mode]
    if mode == "PREDICTED":
        poly, _ = to_polygons(W, radiance_from_exitance(B))
        return View(mode, poly * gain, display=False, smooth=True, unit=unit)
    T, on = _painted(data)
    if mode == "PAINTED":
        poly, painted = to_polygons(W, radiance_from_exitance(T), on)
        col = np.where(painted[:, None], poly * gain, np.array(UNPAINTED))
        return View(mode, col, display=False, smooth=False, unit=unit, shown=painted)
    if mode == "ILLUMINANCE":
        if getattr(data, "patch_reflectance", None) is None:
            raise ValueError("this result was stored without the surfaces' reflectance: solve again to see "
                             "the illuminance")
        rho = np.asarray(data.patch_reflectance, dtype=np.float64)
        lux, ok = patch_illuminance(B, patch_exitance(data, row), rho)
        target_lux, target_ok = patch_illuminance(T, np.zeros_like(T), rho)
        values, shown = to_polygons(W, lux, ok)
        scale_values, targets = lux[ok], target_lux[on & target_ok]
    elif mode == "LUMINANCE":
        cd = luminance_cd(radiance_from_exitance(B))
        values, shown = to_polygons(W, cd)
        scale_values, targets = cd, luminance_cd(radiance_from_exitance(T[on]))
    else:  # DIFFERENCE
        log = False
        pred, painted = to_polygons(W, B, on)
        want, _ = to_polygons(W, T, on)
        values = np.where(painted, relative_difference(pred, want), 0.0)
        shown = painted
        scale_values, targets = relative_difference(B[on], T[on]), ()
    diverging = mode == "DIFFERENCE"
    auto = not (vmax > 0 and math.isfinite(vmax))
    top = auto_max(scale_values, targets, diverging) if auto else float(vmax)
    col = np.where(shown[:, None], colours(values, top, log, diverging), np.array(NOT_SHOWN))
    return View(mode, col, display=True, smooth=False, unit=unit, values=values, shown=shown, vmax=top,
                auto=auto, log=bool(log), ticks=ticks(top, log, diverging))

