"""What colour a light may have (issue 21; no bpy).

A light's exitance is an RGB triple, W/m^2 per channel. Fitted per channel (``free``: NNLS per
channel, the selections' own way), a light's colour is whatever the three fits give: a light of
(8.5, 0, 0) W/m^2 fits grey targets beside a cyan one, and no lighting designer hangs either. The
registered modes (engine/colours/, LIGHT_COLOURS) constrain it:

- ``white``: each light is a power p_j times white (1, 1, 1) (Blender's linear Rec.709 white);
- ``blackbody``: each light is a power times the blackbody colour of a temperature in the range
  the user sets (default 2,700-6,500 K), Blender's conversion (``blackbody_rec709``, the Blackbody
  node's and a Light's ``temperature_color``).

How the constrained problem is solved with the selections as they are (``ColourProblem``): with
each light's colour chi_j fixed, its light on the targets is p_j times the column
t_j = (chi_j0 T_0[:, j]; chi_j1 T_1[:, j]; chi_j2 T_2[:, j]) of the channels stacked (3m rows), and
the targets b stacked the same way: one channel. The selections see a problem whose channel 0 is
that stacked problem and whose channels 1 and 2 have no target (best_lights skips them: they fit
nothing); errors, norms and powers are the real problem's exactly (the same residual, stacked), so
every selection, its curve and its certificate are of the constrained problem. The configurations
come back as exitance p_j chi_j.

White fixes chi_j = 1. Blackbody gives each light, for the selection, the temperature at which it
alone fits the targets best (``solo_temperatures``: a light's best colour does not depend on the
others' much when the targets are of one colour), then every configuration found refits its
lights' temperatures one at a time on a grid of TEMPERATURE_STEPS (even in mired, the scale on
which equal steps look equal), its powers by NNLS, while its error drops (``fit``). The
certificate of blackbody lights is a relaxation (``relaxed_bound``): the every-light NNLS with each
light's colour anywhere in a cone that contains the blackbody colours of the range (its edges: a
thin band's hull around them in the chromaticity plane, checked to contain BLACKBODY_CHECKS
colours of the range); no set of blackbody lights of the range is below it.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.optimize as sopt
from .units import TINY, luminance_weighted

__all__ = ["blackbody_rec709", "temperature_grid", "ColourProblem", "colour_problem", "fit_colours", "fit_lights",
           "fit_columns", "lower_bounds_of", "temperature_of", "TEMPERATURE_STEPS"]

#: Cycles' blackbody fit (intern/cycles/kernel/tables.h, used by svm_math_blackbody_color_rec709
#: in kernel/svm/math_util.h): per temperature band, R and G = a / t + b t + c, B = ((a t + b) t + c) t + d
_BANDS = (965.0, 1167.0, 1449.0, 1902.0, 3315.0, 6365.0)
_R = ((1.61919106e+03, -2.05010916e-03, 5.02995757e+00), (2.48845471e+03, -1.11330907e-03, 3.22621544e+00),
      (3.34143193e+03, -4.86551192e-04, 1.76486769e+00), (4.09461742e+03, -1.27446582e-04, 7.25731635e-01),
      (4.67028036e+03, 2.91258199e-05, 1.26703442e-01), (4.59509185e+03, 2.87495649e-05, 1.50345020e-01),
      (3.78717450e+03, 9.35907826e-06, 3.99075871e-01))
_G = ((-4.88999748e+02, 6.04330754e-04, -7.55807526e-02), (-7.55994277e+02, 3.16730098e-04, 4.78306139e-01),
      (-1.02363977e+03, 1.20223470e-04, 9.36662319e-01), (-1.26571316e+03, 4.87340896e-06, 1.27054498e+00),
      (-1.42529332e+03, -4.01150431e-05, 1.43972784e+00), (-1.17554822e+03, -2.16378048e-05, 1.30408023e+00),
      (-5.00799571e+02, -4.59832026e-06, 1.09098763e+00))
_B = ((5.96945309e-11, -4.85742887e-08, -9.70622247e-05, -4.07936148e-03),
      (2.40430366e-11, 5.55021075e-08, -1.98503712e-04, 2.89312858e-02),
      (-1.40949732e-11, 1.89878968e-07, -3.56632824e-04, 9.10767778e-02),
      (-3.61460868e-11, 2.84822009e-07, -4.93211319e-04, 1.56723440e-01),
      (-1.97075738e-11, 1.75359352e-07, -2.50542825e-04, -2.22783266e-02),
      (-1.61997957e-13, -1.64216008e-08, 3.86216271e-04, -7.38077418e-01),
      (6.72650283e-13, -2.73078809e-08, 4.24098264e-04, -7.52335691e-01))
#: Blender's Blackbody node takes 800 K to 12,000 K; at 12,000 K and above, and below 800 K,
#: Cycles returns these colours
BLACKBODY_LIMITS = (800.0, 12000.0)
_HOT = np.array([0.8262954810464208, 0.9945080501520986, 1.566307710274283])
_COLD = np.array([5.413294490189271, -0.20319390035873933, -0.0822535242887164])

#: temperatures a blackbody light may take in a range, evenly spaced in mired (1e6 / K)
TEMPERATURE_STEPS = 33
#: colours of the range the relaxation's cone is checked to contain
BLACKBODY_CHECKS = 512
#: colours of the range the cone is built around (its edges: at most twice as many)
CONE_POINTS = 9
#: temperature refits of a configuration's lights, rounds over its lights at most
FIT_ROUNDS = 4


def blackbody_rec709(temperature) -> np.ndarray:
    """(..., 3) linear Rec.709 colour of a blackbody at ``temperature`` K, as Cycles computes it
    (Blender's Blackbody node; a Light's ``temperature_color``): luminance about 1, clamped at 0."""
    t0 = np.asarray(temperature, dtype=np.float64)
    t = np.clip(t0, *BLACKBODY_LIMITS)
    i = np.searchsorted(np.asarray(_BANDS), t, side="right")
    r, g, b = (np.asarray(x)[i] for x in (_R, _G, _B))
    rgb = np.stack([r[..., 0] / t + r[..., 1] * t + r[..., 2],
                    g[..., 0] / t + g[..., 1] * t + g[..., 2],
                    ((b[..., 0] * t + b[..., 1]) * t + b[..., 2]) * t + b[..., 3]], axis=-1)
    rgb = np.where((t0 >= BLACKBODY_LIMITS[1])[..., None], _HOT, rgb)  # (Cycles' ends)
    rgb = np.where((t0 < BLACKBODY_LIMITS[0])[..., None], _COLD, rgb)
    return np.maximum(rgb, 0.0)


def temperature_grid(t_min, t_max, steps=TEMPERATURE_STEPS) -> np.ndarray:
    """``steps`` temperatures (K) from t_min to t_max, even in mired."""
    if not (BLACKBODY_LIMITS[0] <= t_min <= t_max <= BLACKBODY_LIMITS[1]):
        raise ValueError(f"the blackbody range must lie within {BLACKBODY_LIMITS[0]:g}-{BLACKBODY_LIMITS[1]:g} K "
                         f"with its minimum at most its maximum, got {t_min:g}-{t_max:g} K")
    if t_min == t_max:
        return np.array([float(t_min)])
    return 1e6 / np.linspace(1e6 / t_min, 1e6 / t_max, int(steps))


def temperature_of(rgb, t_min, t_max) -> np.ndarray:
    """(k,) the temperature (K, of the range's grid) whose blackbody colour is nearest the
    chromaticity of each RGB row of ``rgb`` (k, 3) (the colour of a blackbody light, read back)."""
    grid = temperature_grid(t_min, t_max)
    chi = blackbody_rec709(grid)
    chi = chi / chi.sum(axis=1, keepdims=True)
    rgb = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    c = rgb / np.maximum(rgb.sum(axis=1, keepdims=True), TINY)
    return grid[np.argmin(((c[:, None, :] - chi[None]) ** 2).sum(axis=2), axis=1)]


def stacked(columns, colours) -> np.ndarray:
    """(3m, k): the lights' light on the targets per unit power, channels stacked: colours (k, 3)
    times their transfer ``columns`` (3 arrays (m, k))."""
    return np.vstack([columns[c] * colours[:, c][None, :] for c in range(3)])


def _nnls(A, y, upper=None):
    from .best_lights import _bounded  # (best_lights' NNLS, with its fallback; bounded least squares)

    return _bounded(A, y, upper)


def power_upper(upper, colours):
    """(k,) the largest power p of lights of colours ``colours`` (k, 3) (strength p chi) whose strength
    per channel is bounded by ``upper`` (k,) (inf: none): upper / luminance(chi), the rated flux
    bounding the light's luminance; None when ``upper`` is None."""
    if upper is None:
        return None
    lum = luminance_weighted(colours)
    u = np.asarray(upper, dtype=np.float64)
    return np.where(lum > 0, u / np.where(lum > 0, lum, 1.0), u / np.maximum(np.max(colours, axis=1), TINY))


def fit_colours(columns, b, colours, temperatures=None, t_range=None, upper=None):
    """The best exitance (k, 3) >= 0 of lights whose colours are fixed (``colours`` (k, 3)) or,
    with ``temperatures`` (k,) K and ``t_range``, blackbody lights whose temperatures are refitted
    one light at a time while the error drops (FIT_ROUNDS rounds at most): the light's best
    temperature of the range's grid with the others' light fixed (every temperature at once: the
    best non-negative multiple of its column), then every power again by NNLS, kept when the error
    drops. Their transfer ``columns`` (3 arrays (m, k)), the targets ``b`` (m, 3); ``upper`` (k,) their
    largest strength per channel (inf: none; ``power_upper`` of each colour tried). Returns
    (exitance, error, temperatures or None)."""
    y = np.asarray(b, dtype=np.float64).T.reshape(-1)
    colours = np.array(colours, dtype=np.float64, copy=True).reshape(-1, 3)

    def solve(chi):
        A = stacked(columns, chi)
        p = _nnls(A, y, power_upper(upper, chi)) if A.shape[1] else np.zeros(0)
        return p, float(np.linalg.norm(A @ p - y)), A

    p, err, A = solve(colours)
    if temperatures is None or len(p) == 0:
        return p[:, None] * colours, err, None
    temps = np.array(temperatures, dtype=np.float64, copy=True)
    grid = temperature_grid(*t_range)
    chis = blackbody_rec709(grid)  # (g, 3)
    for _ in range(FIT_ROUNDS):
        moved = False
        for j in range(len(temps)):
            r = y - A @ p + A[:, j] * p[j]  # the residual without light j
            C = np.vstack([columns[c][:, j][:, None] * chis[:, c][None, :] for c in range(3)])  # (3m, g)
            h, d = C.T @ r, np.einsum("ij,ij->j", C, C)
            gain = np.where(d > 0, np.maximum(h, 0.0) ** 2 / np.where(d > 0, d, 1.0), 0.0)
            g = int(np.argmax(gain))
            if grid[g] == temps[j]:
                continue
            trial = colours.copy()
            trial[j] = chis[g]
            pt, et, At = solve(trial)
            if et < err * (1 - 1e-12):
                p, err, A, colours, temps[j], moved = pt, et, At, trial, grid[g], True
        if not moved:
            break
    return p[:, None] * colours, err, temps


class ColourProblem:
    """An InverseProblem seen with its lights' colours fixed (the module docstring): channel 0
    the stacked problem, channels 1 and 2 without a target; everything else is the problem's."""

    def __init__(self, problem, colours):
        self._problem = problem
        self.colours = np.asarray(colours, dtype=np.float64)
        Ts = stacked(problem.transfer, self.colours)
        self.transfer = [Ts, Ts, Ts]  # (one array: best_lights keeps one Gram matrix)
        y = np.asarray(problem.b_target, dtype=np.float64).T.reshape(-1)
        self.b_target = np.zeros((len(y), 3))
        self.b_target[:, 0] = y
        self.light_watts = np.asarray(problem.light_watts, dtype=np.float64) * self.colours.sum(axis=1)
        #: (n,) each light's largest power p (its strength p chi): its strength bound over the luminance
        #: of its colour (a fixture's rated lumens bound the luminance it gives, of any colour)
        self.light_upper = power_upper(getattr(problem, "light_upper", None), self.colours)
        self.target_norm = problem.target_norm

    def __getattr__(self, name):
        return getattr(self._problem, name)

    def exitance(self, e) -> np.ndarray:
        """The real exitance (n, 3) of a configuration (n, 3) of this view (its power in channel 0)."""
        e = np.asarray(e, dtype=np.float64).reshape(-1, 3)
        return e[:, :1] * self.colours

    def exitance_of(self, lights, e) -> np.ndarray:
        """The real exitance (k, 3) of the lights ``lights`` at this view's exitance ``e`` (k, 3)."""
        e = np.asarray(e, dtype=np.float64).reshape(-1, 3)
        return e[:, :1] * self.colours[np.asarray(lights, dtype=np.int64)]

    def start(self, e_x=None) -> np.ndarray:
        """The minimum-norm least-squares configuration of this view (n, 3), power in channel 0:
        the paper's selections start from it (the inverse solution of the constrained problem)."""
        from .solvers.common import default_rcond, lstsq_min_norm

        T = self.transfer[0]
        X, _ = lstsq_min_norm(T, self.b_target[:, :1], default_rcond(None, T.shape), "auto")
        out = np.zeros((T.shape[1], 3))
        out[:, 0] = X[:, 0]
        return out


    def real_bounds(self, bounds):
        """A certificate found on this view (best_lights.LowerBounds) with its every-light NNLS as
        the lights' exitance."""
        if bounds is None or getattr(bounds, "nnls_exitance", None) is None:
            return bounds
        return replace(bounds, nnls_exitance=self.exitance(bounds.nnls_exitance))


def colour_problem(problem, mode, ids=None, e=None) -> ColourProblem | None:
    """The view of ``problem`` for the light colour ``mode`` (a LIGHT_COLOURS instance), or None
    for free colours (the problem as it is); ``ids``, ``e``: a configuration whose lights keep
    their colours (the chromaticity of ``e`` (k, 3))."""
    if mode is None or mode.free:
        return None
    colours = np.array(mode.colours(problem), dtype=np.float64, copy=True)
    if ids is not None and len(ids):
        e = np.asarray(e, dtype=np.float64).reshape(-1, 3)
        on = e.sum(axis=1) > 0
        colours[np.asarray(ids, dtype=np.int64)[on]] = e[on] / e[on].mean(axis=1, keepdims=True)
    return ColourProblem(problem, colours)


def fit_lights(problem, ids, e=None):
    """The best non-negative exitance (k, 3) of the lights ``ids`` on the problem's T and its
    error (W/m^2), of the problem's light colour (NNLS per channel for free colours; ``e``: the
    configuration's exitance, whose colours a refit starts from)."""
    ids = np.asarray(ids, dtype=np.int64)
    return fit_columns(problem, [t[:, ids] for t in problem.transfer], e, ids)


def fit_columns(problem, columns, e=None, ids=None, refit=True, upper=None):
    """fit_lights for lights of transfer ``columns`` (3 arrays (m, k)) (a refined lamp's, not yet
    a light of the problem); ``e`` or else ``ids`` give the colours a refit starts from;
    ``refit`` False: those colours kept (their powers fitted only). ``upper`` (k,): the lights'
    largest strength per channel (default: the problem's ``light_upper`` of ``ids``; none without)."""
    b = problem.b_target
    mode = problem.colour
    if upper is None and ids is not None and getattr(problem, "light_upper", None) is not None:
        upper = np.asarray(problem.light_upper, dtype=np.float64)[np.asarray(ids, dtype=np.int64)]
    if mode is None or mode.free:
        return fit_per_channel(columns, b, upper)
    k = columns[0].shape[1]
    if e is not None and np.all(np.asarray(e).sum(axis=1) > 0):
        colours = np.asarray(e, dtype=np.float64)
    elif ids is not None:
        colours = mode.colours(problem)[np.asarray(ids, dtype=np.int64)]
    else:
        colours = np.ones((k, 3))
    return mode.fit(columns, b, colours, refit, upper)


def fit_per_channel(columns, b, upper=None):
    """(exitance (k, 3), error W/m^2): NNLS per channel of lights of transfer ``columns`` (3 arrays
    (m, k)) on the targets ``b`` (m, 3): free colours' fit; ``upper`` (k,) bounds each channel."""
    x = np.stack([_nnls(columns[c], b[:, c], upper) for c in range(3)], axis=1)
    return x, channel_error(columns, x, b)


def channel_error(columns, e, b) -> float:
    """Eq. 1 (W/m^2) of lights of transfer ``columns`` (3 arrays (m, k)) at exitance ``e`` (k, 3)."""
    return float(np.linalg.norm(np.stack([columns[c] @ e[:, c] for c in range(3)], axis=1) - b))


def lower_bounds_of(problem, k_max):
    """The certificate (best_lights.LowerBounds) of the problem's lights of its light colour."""
    from .best_lights import lower_bounds

    view = colour_problem(problem, problem.colour)
    if view is None:
        return lower_bounds(problem.transfer, problem.b_target, k_max)
    return problem.colour.certificate(problem, view, None, k_max)


def _solo_terms(problem) -> tuple:
    """(U, S) (n, 3): per light and channel, t_c . b_c and ||t_c||^2 of its column (what a light
    alone fits: solo_temperatures, solo_colours)."""
    b = np.asarray(problem.b_target, dtype=np.float64)
    T = problem.transfer
    return (np.stack([T[c].T @ b[:, c] for c in range(3)], axis=1),
            np.stack([np.einsum("ij,ij->j", T[c], T[c]) for c in range(3)], axis=1))


def solo_temperatures(problem, grid) -> np.ndarray:
    """(n,) per light, the temperature of ``grid`` at which it alone fits the targets best (the
    largest gain max(0, t . y)^2 / ||t||^2 of its stacked column t = (chi_c T_c[:, j])_c: with
    u_c = T_c^T y_c and s_c = ||T_c[:, j]||^2, t . y = u . chi and ||t||^2 = s . chi^2, every
    temperature at once)."""
    U, S = _solo_terms(problem)
    chis = blackbody_rec709(grid)  # (g, 3)
    h, d = U @ chis.T, S @ (chis * chis).T  # (n, g)
    gain = np.where(d > 0, np.maximum(h, 0.0) ** 2 / np.where(d > 0, d, 1.0), 0.0)
    return np.asarray(grid, dtype=np.float64)[np.argmax(gain, axis=1)]


def solo_colours(problem) -> np.ndarray:
    """(n, 3) per light, the colour it alone fits the targets best: per channel the best
    non-negative multiple of its column, max(0, t_c . b_c) / ||t_c||^2, normalised to a mean of 1
    (white for a light that reaches no target)."""
    h, d = _solo_terms(problem)
    x = np.where(d > 0, np.maximum(h, 0.0) / np.where(d > 0, d, 1.0), 0.0)
    m = x.mean(axis=1, keepdims=True)
    return np.where(m > 0, x / np.where(m > 0, m, 1.0), 1.0)


def cone_edges(t_min, t_max, checks=BLACKBODY_CHECKS, points=CONE_POINTS) -> np.ndarray:
    """(g, 3) colours whose non-negative combinations contain every blackbody colour of the range
    (the relaxation's cone). In the chromaticity plane (r + g + b = 1) the range's colours lie on a
    curve (Cycles' fit: nearly straight, piecewise); the cone's edges are the vertices of the convex
    hull of ``points`` colours of the range each moved by +-delta along the curve's normal, delta
    1.5 x the largest distance of ``checks`` colours of the range from the polyline through them
    (so the band around the polyline, which holds the curve, is inside; an edge may have a channel
    below 0 near the range's ends: a relaxation needs only to contain the colours). Checked: each of the
    ``checks`` colours is a non-negative combination of the edges (NNLS residual below 1e-9 of it);
    delta doubled until it is (ValueError after 20 doublings)."""
    from scipy.spatial import ConvexHull

    grid = temperature_grid(t_min, t_max, points)
    if len(grid) == 1:
        return blackbody_rec709(grid)

    def plane(rgb):  # chromaticity (r, b)
        c = rgb / rgb.sum(axis=1, keepdims=True)
        return c[:, [0, 2]]

    P = plane(blackbody_rec709(grid))
    fine_rgb = blackbody_rec709(temperature_grid(t_min, t_max, checks))
    Q = plane(fine_rgb)
    seg = P[1:] - P[:-1]
    rel = Q[:, None, :] - P[None, :-1, :]
    tt = np.clip((rel * seg[None]).sum(axis=2) / np.maximum((seg * seg).sum(axis=1), TINY)[None], 0.0, 1.0)
    dist = np.linalg.norm(rel - tt[..., None] * seg[None], axis=2).min(axis=1)
    tangent = np.gradient(P, axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), TINY)
    delta = 1.5 * float(dist.max()) + 1e-7
    for _ in range(20):
        pts = np.vstack([P + delta * normal, P - delta * normal])
        V = pts[ConvexHull(pts).vertices]
        E = np.stack([V[:, 0], 1.0 - V[:, 0] - V[:, 1], V[:, 1]], axis=1)
        if all(sopt.nnls(E.T, col)[1] <= 1e-9 * np.linalg.norm(col) for col in fine_rgb):
            return E
        delta *= 2.0
    raise ValueError(f"the blackbody colours of {t_min:g}-{t_max:g} K could not be enclosed in a cone")


#: the relaxation's stacked columns may take this many bytes at most (a coarser cone beyond)
RELAXATION_BYTES = 256 * 2 ** 20


class ConeColumns:
    """The relaxation's columns without building them (best_lights.DenseColumns' reads): column
    e n + j is light j's transfer columns (3 arrays (m, n)) times edge e's colour (edges (E, 3)),
    channels stacked (``stacked``)."""

    def __init__(self, transfer, edges):
        self.T = [np.asarray(t, dtype=np.float64) for t in transfer]
        self.edges = np.asarray(edges, dtype=np.float64)
        self.n, m = self.T[0].shape[1], self.T[0].shape[0]
        self.shape = (3 * m, len(self.edges) * self.n)

    def columns(self, idx) -> np.ndarray:
        e, j = np.divmod(np.asarray(idx, dtype=np.int64), self.n)
        return stacked([t[:, j] for t in self.T], self.edges[e])

    def norms(self) -> np.ndarray:
        sq = np.stack([np.einsum("ij,ij->j", t, t) for t in self.T], axis=1)  # (n, 3)
        return np.sqrt(self.edges ** 2 @ sq.T).reshape(-1)

    def correlation(self, y, x) -> np.ndarray:
        on = np.flatnonzero(x)
        r = (y - self.columns(on) @ x[on]).reshape(3, -1)
        G = np.stack([self.T[c].T @ r[c] for c in range(3)], axis=1)  # (n, 3)
        return (self.edges @ G.T).reshape(-1)

    def dense(self) -> np.ndarray:
        return self.columns(np.arange(self.shape[1]))


def relaxed_bound(problem, t_range, k_max) -> object:
    """best_lights.LowerBounds of blackbody lights of the range ``t_range`` (K): the every-light
    NNLS with each light's colour any non-negative combination of the cone's edges (cone_edges), a
    relaxation of every configuration of blackbody lights of the range, at any k (no exact
    entries). The cone is made coarser (fewer, wider edges) to keep the stacked columns within
    RELAXATION_BYTES; beyond even the coarsest, the free colours' certificate (a relaxation too)."""
    from .best_lights import BOUND_MARGIN, LowerBounds, _nnls_from

    y = np.asarray(problem.b_target, dtype=np.float64).T.reshape(-1)
    n = problem.n_lights
    edges = None
    for points in (CONE_POINTS, 5, 3, 2):
        edges = cone_edges(*t_range, points=points)
        if len(edges) * n * len(y) * 8 <= RELAXATION_BYTES:
            break
    else:
        from .best_lights import lower_bounds

        return lower_bounds(problem.transfer, problem.b_target, k_max, exhaustive_limit=0)
    cols = ConeColumns(problem.transfer, edges)
    # the NNLS on a working set grown from none (best_lights._nnls_from) of the columns built as it
    # asks for them: the optimum to the KKT tolerance of best_lights' certificates, where few are
    # active much faster than one NNLS over every light x edge (a view target's 2,823 rows x 8,932
    # columns, 100 active: 11.7 s)
    x = _nnls_from(cols, y, [], 1e-9 * cols.norms() * max(float(np.linalg.norm(y)), TINY))
    on = np.flatnonzero(x)
    err = float(np.linalg.norm(cols.columns(on) @ x[on] - y)) * (1 - BOUND_MARGIN)
    e = x.reshape(len(edges), n).T @ edges  # (n, 3): each light's colour in the cone (not a blackbody's)
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    k = np.arange(1, int(k_max) + 1)
    bound = np.full(len(k), err)
    return LowerBounds(k=k, bound=bound, relative=bound / norm, exact=np.zeros(len(k), dtype=bool), nnls=err,
                       nnls_relative=err / norm, optimum_lights=[None] * len(k), nnls_exitance=e)
