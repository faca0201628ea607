"""The error-curve chart of the Results panel, rasterised with numpy (no bpy here).

``render(...)`` draws relative error against number of lights, as the Results panel shows it:

- x: number of lights, logarithmic (1, 10, 100, ... labelled) when the curve spans more than
  ``LOG_X_ABOVE`` times its fewest, linear otherwise;
- y: relative error (Eq. 1 / ||b_P||), *linear* from 0, up to a rounded maximum of the curve
  (at most ``CLIP`` unless the shown configuration is above it; points above are drawn at the
  top edge). The exact e_x point (relative error ~1e-14) sits on the x axis instead of
  stretching a log axis over 14 decades;
- the curve in blue, segments between configurations with negative exitances in orange;
- the shown configuration: a yellow vertical line and a yellow dot;
- the best any non-negative lights can do, when the result holds it: the NNLS bound (one number,
  a dashed green line) or, per configuration, the lower bound for its number of lights (the
  solve's certificate, a green line);
- tick labels and axis titles in a built-in 5 x 7 pixel font.

The image is returned with row 0 at the bottom (Blender's pixel order), with a ``geometry`` dict
in top-down pixel coordinates (plot rectangle, marker and bound positions) for tests.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["render", "nice_ceil", "y_ticks", "x_ticks", "COLORS", "CLIP"]

#: the y axis ends at a rounded max of the curve, but not above this unless the shown point is
CLIP = 1.5
#: the lights axis is logarithmic when the most lights exceed the fewest by this factor
LOG_X_ABOVE = 40

COLORS = {
    "background": (0.075, 0.075, 0.095, 1.0),   # distinctive: the GUI test finds the chart by it
    "plot": (0.105, 0.105, 0.13, 1.0),
    "grid": (0.20, 0.20, 0.24, 1.0),
    "axis": (0.55, 0.55, 0.58, 1.0),
    "text": (0.80, 0.80, 0.82, 1.0),
    "curve": (0.35, 0.70, 1.00, 1.0),
    "negative": (1.00, 0.45, 0.25, 1.0),
    "marker": (1.00, 0.80, 0.10, 1.0),
    "bound": (0.40, 0.90, 0.40, 1.0),
}

# 5 x 7 glyphs: 7 rows of 5 columns ('#' = ink).
_GLYPHS = {
    '0': ('.###.', '#...#', '#..##', '#.#.#', '##..#', '#...#', '.###.'),
    '1': ('..#..', '.##..', '..#..', '..#..', '..#..', '..#..', '.###.'),
    '2': ('.###.', '#...#', '....#', '...#.', '..#..', '.#...', '#####'),
    '3': ('#####', '...#.', '..#..', '...#.', '....#', '#...#', '.###.'),
    '4': ('...#.', '..##.', '.#.#.', '#..#.', '#####', '...#.', '...#.'),
    '5': ('#####', '#....', '####.', '....#', '....#', '#...#', '.###.'),
    '6': ('..##.', '.#...', '#....', '####.', '#...#', '#...#', '.###.'),
    '7': ('#####', '....#', '...#.', '..#..', '.#...', '.#...', '.#...'),
    '8': ('.###.', '#...#', '#...#', '.###.', '#...#', '#...#', '.###.'),
    '9': ('.###.', '#...#', '#...#', '.####', '....#', '...#.', '.##..'),
    '.': ('.....', '.....', '.....', '.....', '.....', '.##..', '.##..'),
    '-': ('.....', '.....', '.....', '#####', '.....', '.....', '.....'),
    '+': ('.....', '..#..', '..#..', '#####', '..#..', '..#..', '.....'),
    ':': ('.....', '.##..', '.##..', '.....', '.##..', '.##..', '.....'),
    '(': ('...#.', '..#..', '.#...', '.#...', '.#...', '..#..', '...#.'),
    ')': ('.#...', '..#..', '...#.', '...#.', '...#.', '..#..', '.#...'),
    '/': ('.....', '....#', '...#.', '..#..', '.#...', '#....', '.....'),
    '=': ('.....', '.....', '#####', '.....', '#####', '.....', '.....'),
    ' ': ('.....', '.....', '.....', '.....', '.....', '.....', '.....'),
    'a': ('.....', '.....', '.###.', '....#', '.####', '#...#', '.####'),
    'b': ('#....', '#....', '#.##.', '##..#', '#...#', '#...#', '####.'),
    'c': ('.....', '.....', '.###.', '#....', '#....', '#...#', '.###.'),
    'd': ('....#', '....#', '.##.#', '#..##', '#...#', '#...#', '.####'),
    'e': ('.....', '.....', '.###.', '#...#', '#####', '#....', '.###.'),
    'f': ('..##.', '.#..#', '.#...', '###..', '.#...', '.#...', '.#...'),
    'g': ('.....', '.####', '#...#', '#...#', '.####', '....#', '.###.'),
    'h': ('#....', '#....', '#.##.', '##..#', '#...#', '#...#', '#...#'),
    'i': ('..#..', '.....', '.##..', '..#..', '..#..', '..#..', '.###.'),
    'k': ('#....', '#....', '#..#.', '#.#..', '##...', '#.#..', '#..#.'),
    'l': ('.##..', '..#..', '..#..', '..#..', '..#..', '..#..', '.###.'),
    'm': ('.....', '.....', '##.#.', '#.#.#', '#.#.#', '#...#', '#...#'),
    'n': ('.....', '.....', '#.##.', '##..#', '#...#', '#...#', '#...#'),
    'o': ('.....', '.....', '.###.', '#...#', '#...#', '#...#', '.###.'),
    'p': ('.....', '.....', '####.', '#...#', '####.', '#....', '#....'),
    'r': ('.....', '.....', '#.##.', '##..#', '#....', '#....', '#....'),
    's': ('.....', '.....', '.###.', '#....', '.###.', '....#', '####.'),
    't': ('.#...', '.#...', '###..', '.#...', '.#...', '.#..#', '..##.'),
    'u': ('.....', '.....', '#...#', '#...#', '#...#', '#..##', '.##.#'),
    'v': ('.....', '.....', '#...#', '#...#', '#...#', '.#.#.', '..#..'),
    'w': ('.....', '.....', '#...#', '#...#', '#.#.#', '#.#.#', '.#.#.'),
    'x': ('.....', '.....', '#...#', '.#.#.', '..#..', '.#.#.', '#...#'),
    'y': ('.....', '.....', '#...#', '#...#', '.####', '....#', '.###.'),
    'z': ('.....', '.....', '#####', '...#.', '..#..', '.#...', '#####'),
    'B': ('####.', '#...#', '#...#', '####.', '#...#', '#...#', '####.'),
    'E': ('#####', '#....', '#....', '####.', '#....', '#....', '#####'),
    'L': ('#....', '#....', '#....', '#....', '#....', '#....', '#####'),
    'N': ('#...#', '##..#', '#.#.#', '#..##', '#...#', '#...#', '#...#'),
    'S': ('.####', '#....', '#....', '.###.', '....#', '....#', '####.'),
}
_FONT = {c: np.array([[ch == "#" for ch in row] for row in g], dtype=bool) for c, g in _GLYPHS.items()}


def text_width(text: str, scale: int = 1) -> int:
    return max(len(text) * 6 - 1, 0) * scale


def _draw_text(img, x, y, text, color, scale=1):
    """Text with its top-left corner at (x, y) (top-down pixel coordinates); clipped."""
    h, w = img.shape[:2]
    for k, ch in enumerate(text):
        glyph = _FONT.get(ch) if ch in _FONT else _FONT.get(ch.lower(), _FONT[" "])
        if scale > 1:
            glyph = np.kron(glyph, np.ones((scale, scale), dtype=bool))
        gx, gy = x + 6 * scale * k, y
        gh, gw = glyph.shape
        x0, y0, x1, y1 = max(gx, 0), max(gy, 0), min(gx + gw, w), min(gy + gh, h)
        if x0 >= x1 or y0 >= y1:
            continue
        sub = glyph[y0 - gy:y1 - gy, x0 - gx:x1 - gx]
        img[y0:y1, x0:x1][sub] = color


def _line(img, x0, y0, x1, y1, color, width=1, dash=0):
    """A straight line between two points (top-down coordinates), ``width`` pixels thick,
    dashed with ``dash``-pixel dashes when dash > 0."""
    n = int(max(abs(x1 - x0), abs(y1 - y0))) + 1
    xs = np.rint(np.linspace(x0, x1, n)).astype(int)
    ys = np.rint(np.linspace(y0, y1, n)).astype(int)
    if dash > 0:
        keep = (np.arange(n) // dash) % 2 == 0
        xs, ys = xs[keep], ys[keep]
    h, w = img.shape[:2]
    lo = -((width - 1) // 2)
    for dx in range(lo, lo + width):
        for dy in range(lo, lo + width):
            xx, yy = xs + dx, ys + dy
            ok = (xx >= 0) & (xx < w) & (yy >= 0) & (yy < h)
            img[yy[ok], xx[ok]] = color


def _disc(img, cx, cy, r, color):
    h, w = img.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    img[(xx - cx) ** 2 + (yy - cy) ** 2 <= r * r + r] = color


def nice_ceil(v: float) -> float:
    """The smallest 'round' number >= v (mantissa in 1, 1.2, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10)."""
    if not v > 0 or not math.isfinite(v):
        return 1.0
    e = math.floor(math.log10(v))
    for m in (1, 1.2, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10):
        c = m * 10.0 ** e
        if c >= v * (1 - 1e-12):
            return c
    return 10.0 ** (e + 1)


def y_ticks(ymax: float) -> list[float]:
    """Tick values 0..ymax, 3 to 6 intervals of a round step."""
    for m in (0.01, 0.02, 0.025, 0.05, 0.1, 0.2, 0.25, 0.5, 1, 2, 2.5, 5, 10, 20, 25, 50, 100):
        step = m * 10.0 ** math.floor(math.log10(ymax) - 1) if ymax > 0 else 0.1
        if ymax / step <= 6 + 1e-9:
            n = int(math.floor(ymax / step + 1e-9))
            return [round(k * step, 12) for k in range(n + 1)]
    return [0.0, ymax]


def x_ticks(lo: float, hi: float, log: bool) -> tuple[list[float], list[float]]:
    """(labelled ticks, minor ticks) between lo and hi."""
    if log:
        major = [10.0 ** k for k in range(int(math.floor(math.log10(lo))), int(math.ceil(math.log10(hi))) + 1)
                 if lo <= 10.0 ** k <= hi]
        minor = [m * 10.0 ** k for k in range(int(math.floor(math.log10(lo))), int(math.ceil(math.log10(hi))) + 1)
                 for m in (2, 3, 4, 5, 6, 7, 8, 9) if lo <= m * 10.0 ** k <= hi]
        return major, minor
    span = hi - lo
    step = max(1, int(nice_ceil(span / 5))) if span > 0 else 1
    first = int(math.ceil(lo / step) * step)
    return [float(v) for v in range(first, int(hi) + 1, step)], []


def _fmt(v: float) -> str:
    if v == 0:
        return "0"
    if abs(v) >= 1000:
        return f"{v:.0f}"
    s = f"{v:.3f}".rstrip("0").rstrip(".")
    return s[1:] if s.startswith("0.") and len(s) > 4 else s


def render(n_lights, relative_error, n_negative=None, current=None, bound=None, bound_n_lights=None,
           size=(240, 192), scale=1):
    """The chart as (pixels (h, w, 4) float32, row 0 at the bottom; geometry dict).

    ``current``: index into the curve of the configuration shown; ``bound``: the best relative
    error non-negative lights can reach: one number (the NNLS bound), or an array aligned with the
    curve (per point, the bound for its number of lights; NaN = none), or None; ``bound_n_lights``:
    the NNLS bound's number of lights, if known. ``scale``: integer font/line scale (2 on high-DPI screens).
    """
    w, h = int(size[0]), int(size[1])
    s = max(1, int(scale))
    img = np.empty((h, w, 4), dtype=np.float32)
    img[:] = COLORS["background"]
    n_lights = np.asarray(n_lights, dtype=np.float64).reshape(-1)
    err = np.asarray(relative_error, dtype=np.float64).reshape(-1)
    neg = (np.zeros(len(n_lights), bool) if n_negative is None
           else np.asarray(n_negative).reshape(-1) > 0)
    ok = np.isfinite(err) & np.isfinite(n_lights)
    geometry = {"size": [w, h], "plot": None, "marker": None, "bound_y": None, "y_max": None,
                "x_log": None, "points": int(ok.sum())}
    if not ok.any():
        _draw_text(img, 4 * s, 4 * s, "no curve", COLORS["text"], s)
        return img[::-1].copy(), geometry
    cur_err = float(err[current]) if current is not None and 0 <= current < len(err) and ok[current] else None
    b = None if bound is None else np.asarray(bound, dtype=np.float64).reshape(-1)
    ymax, yt = _y_range(err[ok], cur_err, _shown_bound(b, current))
    xlo, xhi, log = _x_range(n_lights[ok])
    plot = _Plot(w, h, s, [_fmt(v) for v in yt], ymax, xlo, xhi, log)
    geometry.update(plot=[plot.x0, plot.y0, plot.x1, plot.y1], y_max=ymax, x_log=bool(log), x_range=[xlo, xhi])
    img[plot.y0:plot.y1 + 1, plot.x0:plot.x1 + 1] = COLORS["plot"]
    _draw_axes(img, plot, yt, *x_ticks(xlo, xhi, log))
    if b is not None and b.size == 1 and np.isfinite(b[0]):
        _draw_bound(img, plot, b[0], bound_n_lights, geometry)
    elif b is not None and b.size == len(n_lights):
        _draw_bounds(img, plot, n_lights, b, ok, current, geometry)
    _draw_curve(img, plot, n_lights, err, ok, neg)
    if cur_err is not None:  # the shown configuration
        mx, my = float(plot.px(n_lights[current])), float(plot.py(cur_err))
        _line(img, mx, plot.y0, mx, plot.y1, COLORS["marker"], width=s)
        _disc(img, mx, my, 3 * s, COLORS["marker"])
        geometry["marker"] = [mx, my]
    return img[::-1].copy(), geometry


def _shown_bound(b, current):
    """The bound the axis keeps in view of ``b`` (a 1-D array, or None): a single bound, or a
    per-point one's at the shown configuration; None when there is none (NaN)."""
    if b is None or not b.size:
        return None
    v = b[0] if b.size == 1 else b[current] if current is not None and 0 <= current < b.size else np.nan
    return float(v) if np.isfinite(v) else None


def _y_range(e_ok, cur_err, bound) -> tuple:
    """(the top of the y axis, its ticks): linear from 0; the top is a round number above the
    curve ``e_ok`` (its finite errors), clipped at CLIP unless the shown point or ``bound`` (a
    number: _shown_bound's) is above."""
    top = float(e_ok.max())
    if top > CLIP:
        top = max(CLIP * 2 / 3, cur_err * 1.05 if cur_err is not None else 0.0,
                  bound * 1.05 if bound is not None else 0.0)
        top = min(top, float(e_ok.max()))
    ymax = nice_ceil(max(top, 1e-6))
    yt = y_ticks(ymax)
    return max(ymax, yt[-1]), yt


def _x_range(n_ok) -> tuple:
    """(lowest, highest, logarithmic) of the lights axis over the curve's numbers of lights ``n_ok``."""
    xv = np.maximum(n_ok, 1.0)
    xlo, xhi = float(xv.min()), float(xv.max())
    log = xhi / xlo > LOG_X_ABOVE
    if log:
        xlo = 10.0 ** math.floor(math.log10(xlo) + 1e-9)
    elif xhi == xlo:
        xlo, xhi = xlo - 1, xhi + 1
    return xlo, xhi, log


class _Plot:
    """The layout (top-down pixels) of a w x h chart at font scale s: the plot rectangle x0..x1,
    y0..y1 (y1 the x axis) beside the y labels, and the maps px (lights) and py (error) into it."""

    def __init__(self, w, h, s, labels, ymax, xlo, xhi, log):
        self.w, self.s, self.ch, self.labels = w, s, 7 * s, labels
        left = max(text_width(t, s) for t in labels) + 5 * s
        self.x0, self.x1 = left, w - 6 * s
        self.y0, self.y1 = self.ch + 9 * s, h - self.ch - 6 * s  # plot top / bottom (y1 = the x axis)
        self.ymax, self.xlo, self.xhi, self.log = ymax, xlo, xhi, log

    def px(self, n):
        xlo, xhi = self.xlo, self.xhi
        n = np.maximum(np.asarray(n, dtype=np.float64), 1.0 if self.log else -np.inf)
        t = (np.log10(n) - math.log10(xlo)) / (math.log10(xhi) - math.log10(xlo)) if self.log \
            else (n - xlo) / (xhi - xlo)
        return self.x0 + 2 * self.s + t * (self.x1 - self.x0 - 4 * self.s)

    def py(self, e):
        e = np.clip(np.asarray(e, dtype=np.float64), 0.0, self.ymax)
        return self.y1 - e / self.ymax * (self.y1 - self.y0)


def _draw_axes(img, plot: _Plot, yt, xmaj, xmin_):
    """The grid, the ticks, their labels and the axis titles."""
    s, ch, w, x0, x1, y0, y1 = plot.s, plot.ch, plot.w, plot.x0, plot.x1, plot.y0, plot.y1
    for v, t in zip(yt, plot.labels):
        yy = float(plot.py(v))
        if v > 0:
            _line(img, x0 + 1, yy, x1, yy, COLORS["grid"])
        _line(img, x0 - 2 * s, yy, x0, yy, COLORS["axis"])
        _draw_text(img, x0 - 3 * s - text_width(t, s), int(round(yy)) - ch // 2, t, COLORS["text"], s)
    title = "lights"
    title_x = w - 2 * s - text_width(title, s)   # top right, beside the y title
    for v in xmin_:
        xx = float(plot.px(v))
        _line(img, xx, y1, xx, y1 + 2 * s, COLORS["axis"])
    for v in xmaj:
        xx = float(plot.px(v))
        if x0 < xx < x1:
            _line(img, xx, y0, xx, y1, COLORS["grid"])
        _line(img, xx, y1, xx, y1 + 3 * s, COLORS["axis"])
        t = _fmt(v)
        tx = int(round(xx - text_width(t, s) / 2))
        tx = min(max(tx, x0 - text_width(t, s) // 2), w - text_width(t, s))
        _draw_text(img, tx, y1 + 4 * s, t, COLORS["text"], s)
    _draw_text(img, 2 * s, 2 * s, "relative error", COLORS["text"], s)
    if title_x > 2 * s + text_width("relative error", s) + 6 * s:
        _draw_text(img, title_x, 2 * s, title, COLORS["text"], s)
    _line(img, x0, y0, x0, y1, COLORS["axis"])
    _line(img, x0, y1, x1, y1, COLORS["axis"])


BOUND_LABEL = "best possible"


def _draw_bound(img, plot: _Plot, bound, bound_n_lights, geometry):
    """The NNLS bound (one number): a dashed line, its label, a dot at its number of lights if known."""
    s = plot.s
    by = float(plot.py(bound))
    _line(img, plot.x0 + 1, by, plot.x1, by, COLORS["bound"], width=s, dash=4 * s)
    _draw_text(img, plot.x1 - text_width(BOUND_LABEL, s) - 2 * s, int(round(by)) - plot.ch - 2 * s, BOUND_LABEL,
               COLORS["bound"], s)
    geometry["bound_y"] = by
    if bound_n_lights is not None and bound_n_lights >= 1:
        _disc(img, float(plot.px(bound_n_lights)), by, 2 * s, COLORS["bound"])


def _draw_bounds(img, plot: _Plot, n_lights, b, ok, current, geometry):
    """The certificate: per configuration the lower bound of the error for its number of lights
    (``b`` aligned with the curve, NaN = none), a line with its legend in the top-right corner."""
    s = plot.s
    okb = ok & np.isfinite(b)
    idx = np.flatnonzero(okb)
    idx = idx[np.argsort(n_lights[idx], kind="stable")]
    if not len(idx):
        return
    bx, byy = plot.px(n_lights[idx]), plot.py(b[idx])
    for k in range(len(idx) - 1):
        _line(img, bx[k], byy[k], bx[k + 1], byy[k + 1], COLORS["bound"], width=max(1, s + (s == 1)))
    if len(idx) == 1:
        _disc(img, float(bx[0]), float(byy[0]), 2 * s, COLORS["bound"])
    # legend in the top-right corner (few lights have the large errors: it is the left
    # part of the plot that fills up)
    lx = plot.x1 - text_width(BOUND_LABEL, s) - 3 * s
    ly = plot.y0 + 3 * s
    _line(img, lx - 9 * s, ly + plot.ch // 2, lx - 3 * s, ly + plot.ch // 2, COLORS["bound"],
          width=max(1, s + (s == 1)))
    _draw_text(img, lx, ly, BOUND_LABEL, COLORS["bound"], s)
    if current is not None and 0 <= current < len(b) and okb[current]:
        geometry["bound_y"] = float(plot.py(b[current]))
    geometry["bound_points"] = int(len(idx))


def _draw_curve(img, plot: _Plot, n_lights, err, ok, neg):
    """The curve, sorted by number of lights; orange between configurations with negative exitances."""
    s = plot.s
    idx = np.flatnonzero(ok)
    order = idx[np.argsort(n_lights[idx], kind="stable")]
    xs, ys = plot.px(n_lights[order]), plot.py(err[order])
    for k in range(len(order) - 1):
        a, b = order[k], order[k + 1]
        color = COLORS["negative"] if (neg[a] or neg[b]) else COLORS["curve"]
        _line(img, xs[k], ys[k], xs[k + 1], ys[k + 1], color, width=max(1, s + (s == 1)))
    if len(order) == 1:
        _disc(img, float(xs[0]), float(ys[0]), 2 * s, COLORS["curve"])
