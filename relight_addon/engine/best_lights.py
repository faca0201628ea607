"""The best k-light configurations: sparse non-negative selection, a quality certificate,
and a least-power tolerance mode.

Everything here works on the transfer matrices of an :class:`~.inverse.InverseProblem`:
per channel c, ``b_P[:, c] = T[c] @ e[:, c]`` with T[c] (m targets x n lights) and the
exitance e (n, 3) in W/m^2; the error of a configuration is Eq. 1, the Frobenius norm of
``T e - b`` over the targets and the 3 channels. A configuration with k lights is a set S
of k lights (shared by the channels: a light is one face that emits) and a non-negative
exitance on them; for a fixed S the best exitance is NNLS per channel on ``T[c][:, S]``.
Choosing S is the hard part (best subset selection is NP-hard in general).

:func:`best_k_curve`
    For k = 1 .. k_max, the best configuration found with at most k lights:
    greedy pursuit (add one light at a time, each followed by an NNLS refit) then a local
    search that swaps one chosen light for an unchosen one while the error drops. Both
    phases screen all candidates at once with matrix work on the Gram matrices
    ``G = T^T T`` (rank-one updates of the inverse Gram matrix of the chosen set): per
    candidate a lower bound on the squared error of its exact NNLS refit (least squares
    with only the new light's sign constrained, or dual-feasible residuals), certified
    exact where the resulting fit is non-negative and satisfies the KKT conditions, and an
    achievable upper bound (the closed-form 1-D non-negative step along the new light). Only
    the candidates whose lower bound beats the best exact error found so far get an exact
    NNLS refit (branch and bound, at most ``max_exact`` per step), so with
    ``score="error"`` (the default) each addition is the one with the smallest *exact*
    error. ``score="correlation"`` instead takes the largest 1-D gain
    ``sum_c max(0, t_jc . r_c)^2 / ||t_jc||^2`` (the squared non-negative correlation
    with the residual, normalised), one refit per step: cheaper, worse on the staircase's
    greedy path (3 lights: 0.138 against 0.119), about as good after the swaps. The swap
    search runs from the greedy path and from the configuration kept for k - 1 plus an
    addition; for small problems the exhaustive optimum is a start too. The curve is
    monotone non-increasing in k and has no negative exitance. Among configurations whose
    errors agree within ``1e-9 ||b||`` the one with the smaller total power wins (see
    :func:`total_power`).

:func:`lower_bounds`
    A lower bound on the best possible error with k non-negative lights, for each k: the
    all-lights NNLS error (valid for every k) and, where the number of subsets of at most k
    of the n lights is at most ``exhaustive_limit``, the exact optimum by exhaustive search
    (all subsets at once from the Gram matrices, batched small eigen-solves).

:func:`least_power_within_tolerance`
    The tolerance mode after Castro, del Acebo and Sbert ("Heuristic-search-based light
    positioning according to irradiance intervals"): the least total power that keeps every
    target channel within a band around its painted value, a linear programme (HiGHS).

All functions are pure numpy/scipy; indices are the problem's lights (columns of T).
"""
from __future__ import annotations

import hashlib
import math
import time
import warnings as _warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.optimize as sopt
from .sampling import check_cancel
from .units import TINY

__all__ = [
    "SCORES",
    "KLightPoint",
    "LowerBounds",
    "ToleranceResult",
    "best_k_curve",
    "lower_bounds",
    "least_power_within_tolerance",
    "min_max_deviation",
    "total_power",
    "fit_lights",
    "curve_notes",
    "best_k_for_problem",
]

SCORES = ("error", "correlation")  # 'both' is also accepted by best_k_curve

#: errors within this fraction of ||b|| are "numerically equal" (then the least power wins)
EQUAL_ERROR_RTOL = 1e-9
#: relative margin taken off an exact/NNLS optimum so that rounding cannot lift a bound above
#: an error actually achieved
BOUND_MARGIN = 1e-9
#: and an absolute allowance (x ||b||) for the exhaustive search's squared errors, whose
#: ||b||^2 - ... cancels to about eps ||b||^2 (sqrt(eps) ||b|| on an error): in a closed room of
#: reflectance 1 - 1e-9 its optimum for 2 lights came out 1.5e-8 ||b|| above a pair greedy found
BOUND_ROUNDING = 1e-7


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------
def _as_transfer(T):
    """List of 3 float64 C-contiguous (m, n) arrays (channels with the same array share it)."""
    if isinstance(T, np.ndarray) and T.ndim == 2:
        T = [T, T, T]
    if len(T) != 3:
        raise ValueError("T must be a list of 3 (m, n) arrays (one per channel) or one (m, n) array")
    out, seen = [], {}
    for t in T:
        if id(t) not in seen:
            a = np.ascontiguousarray(t, dtype=np.float64)
            if a.ndim != 2:
                raise ValueError(f"each T[c] must be 2-D (m, n), got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError("T contains NaN or infinite values")
            seen[id(t)] = a
        out.append(seen[id(t)])
    if len({a.shape for a in out}) != 1:
        raise ValueError(f"the 3 transfer matrices differ in shape: {[a.shape for a in out]}")
    return out


#: digest of an (m, n) transfer array -> its Gram matrix T^T T (the last GRAMS_KEPT): the
#: certificate, the curve and the surface lights' curve of one problem share one per channel
#: (``gram``, ``column_subset``); keyed by content, so an array changed in place is computed anew
_GRAMS = {}
GRAMS_KEPT = 8


def _digest(t) -> bytes:
    """What keys an array by its content: sha256 of its bytes (processors' SHA extensions: 2 x
    blake2b's speed here, 1.2 against 2.4 ms on a Live stroke's 332 x 847 transfer, three or
    four a stroke) and its shape."""
    return hashlib.sha256(np.ascontiguousarray(t).view(np.uint8)).digest()[:16] + bytes(str(t.shape), "ascii")


def _keep(store, limit, key, value):
    """``value`` kept in ``store`` under ``key``, the oldest dropped beyond ``limit``; returned."""
    store[key] = value
    while len(store) > limit:
        del store[next(iter(store))]
    return value


def _keep_gram(key, G):
    G.setflags(write=False)
    return _keep(_GRAMS, GRAMS_KEPT, key, G)


def gram(t) -> np.ndarray:
    """T^T T of the (m, n) float64 array ``t`` (read-only: shared), computed once per content."""
    return _keyed_gram(t)[1]


def _keyed_gram(t) -> tuple:
    """(the digest of ``t``, gram(t))."""
    key = _digest(t)
    G = _GRAMS.get(key)
    # (np.dot takes BLAS's symmetric product for A^T A: 6.4 ms against matmul's 14.4 on a 204 x 849 T)
    return key, (G if G is not None else _keep_gram(key, np.dot(t.T, t)))


class GramRows:
    """T^T T of an (m, n) array ``t`` whose rows are computed when first indexed (``G[rows]``,
    ``G[rows, cols]``, ``G[np.ix_(rows, cols)]``), each row once: a Live stroke's quick search reads
    the rows of the few lights it tries, where the whole product (m small, n the candidates: 10-16
    ms of a 70-100 ms stroke on the 22k living room) reads every row. The rows are the gemm product
    T[:, rows]^T T, not syrk's (last bits may differ from ``gram``)."""

    def __init__(self, t):
        self.t = t
        n = t.shape[1]
        self.shape = (n, n)
        self._G = np.empty((n, n))
        self._have = np.zeros(n, dtype=bool)

    def __getitem__(self, key):
        rows = np.asarray(key[0] if isinstance(key, tuple) else key, dtype=np.int64).ravel()
        miss = ~self._have[rows]
        if miss.any():
            new = np.unique(rows[miss])
            self._G[new] = self.t[:, new].T @ self.t
            self._have[new] = True
        return self._G[key]

    def diagonal(self) -> np.ndarray:
        return np.einsum("ij,ij->j", self.t, self.t)


def column_subset(T, columns) -> list:
    """The 3 transfer matrices' ``columns`` (channels sharing an array still share one), their
    Gram matrices taken from the whole ones' when those are known (no new product)."""
    columns = np.asarray(columns, dtype=np.int64)
    out = {}
    for t in T:
        if id(t) not in out:
            sub = np.ascontiguousarray(t[:, columns], dtype=np.float64)
            G = _GRAMS.get(_digest(np.ascontiguousarray(t, dtype=np.float64)))
            if G is not None:
                _keep_gram(_digest(sub), np.ascontiguousarray(G[np.ix_(columns, columns)]))
            out[id(t)] = sub
    return [out[id(t)] for t in T]


def _as_targets(b, m):
    b = np.asarray(b, dtype=np.float64)
    if b.ndim == 1:
        b = np.repeat(b[:, None], 3, axis=1)
    if b.shape != (m, 3):
        raise ValueError(f"b must have shape ({m}, 3), got {b.shape}")
    if not np.all(np.isfinite(b)):
        raise ValueError("b contains NaN or infinite values")
    return b


def total_power(exitance, light_watts, lights=None):
    """Total emitted power (W) of a configuration: ``sum_j A_j sum_c e_jc``.

    exitance (k, 3) W/m^2 on the lights ``lights`` (k indices into light_watts), or (n, 3) on
    every light when ``lights`` is None. Summed over the 3 channels (radiometric W per
    channel, as the exitances are).
    """
    e = np.asarray(exitance, dtype=np.float64).reshape(-1, 3)
    a = np.asarray(light_watts, dtype=np.float64)
    if lights is not None:
        a = a[np.asarray(lights, dtype=np.int64)]
    if len(a) != len(e):
        raise ValueError(f"{len(e)} exitances for {len(a)} lights")
    return float((a * e.sum(axis=1)).sum())


def _nnls(A, y):
    """scipy's NNLS with a fallback to BVLS when the active-set loop does not converge."""
    try:
        x, _ = sopt.nnls(A, y, maxiter=max(50, 10 * A.shape[1]))
    except RuntimeError:
        x = sopt.lsq_linear(A, y, bounds=(0.0, np.inf), method="bvls").x
    if not np.all(np.isfinite(x)):
        raise ValueError("NNLS produced non-finite values")
    return np.maximum(x, 0.0)


#: a fit of k lights on m rows, m >= GRAM_FIT_ROWS x k and m k >= GRAM_FIT_SIZE, takes its NNLS on
#: the Cholesky factor of the lights' Gram matrix (``_nnls_normal``): measured on random columns,
#: scipy's NNLS on the columns themselves is faster below (m 60, k 8: 14 against 37 us; m 941,
#: k 8: 38 against 39 us; m 941, k 15: 89 against 47 us); a camera-view target's 941 rows
GRAM_FIT_ROWS = 4
GRAM_FIT_SIZE = 8192
#: the Gram factor is used when its smallest pivot^2 is above this share of the largest diagonal
#: entry (else the columns are nearly dependent, and the Gram's squared condition would cost digits)
GRAM_PIVOT = 1e-10
#: a Gram fit's squared error is ||y||^2 - 2 h.x + x.G x (no pass over the m rows) unless it is
#: below this share of ||y||^2 (a fit within 0.1 % of its targets: the sum cancels, the rows
#: give it); above, its rounding (~1e-14 ||y||^2) moves the error by less than 1e-11 ||y||, a
#: hundredth of EQUAL_ERROR_RTOL
GRAM_RESIDUAL = 1e-6
_TRTRS = sla.lapack.dtrtrs


def _nnls_normal(G, h, columns, y):
    """The NNLS of ``A x ~ y`` from the Gram matrix ``G`` = A^T A and ``h`` = A^T y: with G = L L^T,
    ||A x - y||^2 = ||L^T x - L^-1 h||^2 + a constant, so the NNLS of (L^T, L^-1 h), k x k instead of
    m x k, has the same optimum. ``_nnls(columns(), y)`` (``columns()``: A) when G is not safely
    positive definite."""
    try:
        L = np.linalg.cholesky(G)
    except np.linalg.LinAlgError:
        return _nnls(columns(), y)
    if not np.min(np.diag(L)) ** 2 > GRAM_PIVOT * max(float(np.max(np.diag(G))), TINY):
        return _nnls(columns(), y)
    return _nnls(L.T, _lower_solve(L, h))


def _lower_solve(L, h):
    """L^-1 h for a lower-triangular L (LAPACK's trtrs: scipy's solve_triangular without its
    checks, 20 us of each of a view target's thousands of fits)."""
    z, info = _TRTRS(L, h, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError("singular triangular factor")
    return z


def _bounded(A, y, upper=None):
    """The best ``x`` with 0 <= x <= ``upper`` (k,) of ``A x ~ y`` (bounded least squares: scipy's
    BVLS); NNLS (``_nnls``) when ``upper`` is None or has no finite entry."""
    if upper is None or not np.isfinite(upper).any():
        return _nnls(A, y)
    ub = np.asarray(upper, dtype=np.float64)
    x = sopt.lsq_linear(A, y, bounds=(np.zeros(len(ub)), ub), method="bvls").x
    if not np.all(np.isfinite(x)):
        raise ValueError("the bounded least squares produced non-finite values")
    return np.clip(x, 0.0, ub)


def checked_upper(upper, n):
    """``upper`` (n,) as float64, None when it is None or has no finite entry (no light bounded);
    ValueError on a bound that is NaN or not positive."""
    if upper is None:
        return None
    u = np.asarray(upper, dtype=np.float64).reshape(-1)
    if u.shape != (n,):
        raise ValueError(f"upper must have {n} entries (one per light), got {u.shape}")
    if np.isnan(u).any() or np.any(u <= 0):
        raise ValueError("a light's upper bound on its strength must be positive (inf: none)")
    return u if np.isfinite(u).any() else None


def _clipped_gain(g, d, u):
    """The decrease of a squared error along a column of squared norm ``d`` with correlation ``g``
    (t . residual) at its best multiple within [0, ``u``]: 2 beta g - beta^2 d, beta = clip(g / d)."""
    beta = np.clip(np.where(d > 0, g / np.where(d > 0, d, 1.0), 0.0), 0.0, u)
    return 2.0 * beta * g - beta * beta * d


#: the working-set NNLS (``_nnls_from``) adds at most this many violating lights per round
WORKING_SET_STEP = 16
#: the every-light NNLS of a problem with no earlier answer is the working set's from no light
#: when T has this many entries per channel (a view target's 941 rows x 812 lights, 86 of them
#: on: 22-39 ms against scipy's 65-75 ms over every light, the same error to 12 digits), scipy's
#: over every light below (a surface target's 60 rows)
WORKING_SET_SIZE = 1 << 18


class DenseColumns:
    """A matrix's columns as ``_nnls_from`` reads them (an implicit one: light_colour.ConeColumns)."""

    def __init__(self, A):
        self.A = A
        self.shape = A.shape

    def columns(self, idx) -> np.ndarray:
        return self.A[:, idx]

    def norms(self) -> np.ndarray:
        return np.linalg.norm(self.A, axis=0)

    def correlation(self, y, x) -> np.ndarray:
        """A^T (y - A x)."""
        return self.A.T @ (y - self.A @ x)

    def dense(self) -> np.ndarray:
        return self.A


def _nnls_from(A, y, start, tol):
    """NNLS of ``A x ~ y`` started from the columns ``start`` (an earlier, nearby problem's active
    set: a Live stroke's; none: a large problem's every-light NNLS, WORKING_SET_SIZE): scipy's NNLS
    on a working set of columns, grown by the columns that violate the optimality (KKT) conditions
    on the whole of A, ``a_j . (y - A x) > tol_j``, until none does; then x is the NNLS optimum over every column to that tolerance, as a cold NNLS is.
    A few small fits instead of one over every column (the living room: 3-4 x faster). ``A``: an
    array, or columns read as DenseColumns reads them."""
    A = DenseColumns(A) if isinstance(A, np.ndarray) else A
    n = A.shape[1]
    W = np.zeros(n, dtype=bool)
    W[np.asarray(start, dtype=np.int64)] = True
    scale = np.maximum(A.norms(), TINY)
    for _ in range(n):
        idx = np.flatnonzero(W)
        x = np.zeros(n)
        if len(idx):
            x[idx] = _nnls(A.columns(idx), y)
        g = A.correlation(y, x)
        viol = (g > tol) & ~W
        if not viol.any():
            return x
        top = np.flatnonzero(viol)[np.argsort(-(g[viol] / scale[viol]))[:WORKING_SET_STEP]]
        W[top] = True
    return _nnls(A.dense(), y)


def _inv_spd(M):
    """Inverse of a small symmetric positive (semi-)definite matrix; pseudo-inverse if singular."""
    if M.shape[0] == 0:
        return M.copy()
    try:
        c = sla.cho_factor(M, lower=True, check_finite=False)
        H = sla.cho_solve(c, np.eye(M.shape[0]), check_finite=False)
        if np.all(np.isfinite(H)) and np.all(np.diag(H) > 0):
            return H
    except (np.linalg.LinAlgError, ValueError):
        pass
    w, V = np.linalg.eigh(M)
    keep = w > 1e-12 * max(float(w.max()), TINY)
    return (V[:, keep] / w[keep]) @ V[:, keep].T


# ---------------------------------------------------------------------------------------------
# the configuration model
# ---------------------------------------------------------------------------------------------
@dataclass
class KLightPoint:
    """The best configuration found with at most ``k`` lights.

    Field names match :class:`~.reduction.CurvePoint` (n_lights, error, relative_error,
    n_negative, lights, exitance, changed) so a curve of these can stand for a reduction
    curve. lights: ascending indices of the lights that are on (every one has a positive
    channel); exitance (n_lights, 3) W/m^2, >= 0, NNLS per channel on those lights.
    error: Eq. 1 (W/m^2); relative_error = error / ||b|| (the error itself when b = 0).
    power: total power (W), see :func:`total_power`. source: which search gave it
    ('greedy', 'swap', 'fewer' = the configuration found for a smaller k was better,
    'none' = no light helps).
    """

    k: int
    n_lights: int
    error: float
    relative_error: float
    power: float
    lights: np.ndarray
    exitance: np.ndarray
    n_negative: int = 0
    changed: int = -1
    source: str = "greedy"


def _swap_unused(q, N, iN, MN, tolN, val, beta, kkt_ok):
    """swap_bounds' rows i in N (the channel does not use light i): adding j as in add_bounds;
    ``val``, ``beta``, ``kkt_ok`` filled in place."""
    g = q["corr"]
    cp = np.maximum(g, 0.0)
    bN = np.where(q["ok"], cp / q["perp"], 0.0)
    val[iN] = q["rls2"] - bN * cp
    beta[iN] = bN
    viol = g[N][:, None] - bN[None, :] * MN > tolN[:, None]  # (|N|, n)
    nviol = viol.sum(axis=0)
    for p_, i in enumerate(iN):  # KKT over l in N - {i}
        kkt_ok[i] = (nviol - viol[p_]) == 0


def _swap_used(q, d, N, ia, MN, tolN, val, beta, kkt_ok):
    """swap_bounds' rows i in A (the channel uses light i): downdate A by i, add j; ``val``,
    ``beta``, ``kkt_ok`` filled in place and the downdate's diagonal kept in q["Hd"]."""
    g = q["corr"]
    H, Z, x = q["H"], q["Z"], q["x"]
    Hd = np.diag(H).copy()
    Hd = np.where(Hd > 0, Hd, np.inf)
    pij = q["raw_perp"][None, :] + Z * Z / Hd[:, None]
    ok = pij > 1e-10 * np.maximum(d, TINY)[None, :]
    cij = np.maximum(g[None, :] + Z * (x / Hd)[:, None], 0.0)
    bA = np.where(ok, cij / np.where(ok, pij, 1.0), 0.0)
    val[ia] = (q["rls2"] + x * x / Hd)[:, None] - bA * cij
    beta[ia] = bA
    q["Hd"] = Hd
    if len(N):
        zN = Z[:, N]  # [i, l]: t_l . z_i
        gl = g[N][None, :] + (x / Hd)[:, None] * zN  # t_l . r without light i
        MNi = MN[None, :, :] + zN[:, :, None] * (Z / Hd[:, None])[:, None, :]  # [i, l, j]
        kkt = gl[:, :, None] - bA[:, None, :] * MNi
        kkt_ok[ia] = (kkt <= tolN[None, :, None]).all(axis=1)


class _Model:
    """Gram matrices, NNLS fits of light sets (cached), and the screening bounds."""

    def __init__(self, T, b, area, upper=None, lazy_gram=False):
        self.T = _as_transfer(T)
        m, n = self.T[0].shape
        self.m, self.n = m, n
        #: (n,) each light's largest strength per channel, or None: none bounded (a catalogue fixture's
        #: rated flux, LightKind.strength_upper). With bounds every fit is bounded least squares; the
        #: screening's lower bounds (of the unbounded NNLS: a relaxation) stay valid, none is taken as
        #: exact, and its achievable values take each step within the bound.
        self.upper = checked_upper(upper, n)
        self.b = _as_targets(b, m)
        self.area = np.ones(n) if area is None else np.asarray(area, dtype=np.float64).reshape(-1)
        if self.area.shape != (n,):
            raise ValueError(f"light_watts must have {n} entries, got {self.area.shape}")
        if not np.all(np.isfinite(self.area)) or np.any(self.area <= 0):
            raise ValueError("light areas (the power per unit strength) must be positive and finite")
        self.bb = (self.b * self.b).sum(axis=0)  # (3,)
        # the channels with a target: a channel whose targets are all 0 fits no light (NNLS: 0, its
        # error 0 whatever the lights) and is skipped (a colour-constrained problem has two such,
        # engine/light_colour.py)
        self.chans = tuple(c for c in range(3) if self.bb[c] > 0) or (0,)
        self.groups = {}  # id(T) -> channels sharing that matrix
        for c in self.chans:
            self.groups.setdefault(id(self.T[c]), []).append(c)
        self.G, self.d, digests = {}, {}, {}
        for key, chans in self.groups.items():  # (``lazy_gram``: GramRows, a row when read)
            if lazy_gram:
                digests[key], G = _digest(self.T[chans[0]]), GramRows(self.T[chans[0]])
                self.d[key] = G.diagonal()
            else:
                digests[key], G = _keyed_gram(self.T[chans[0]])
                self.d[key] = np.diag(G).copy()
            self.G[key] = G
        #: what the all-lights NNLS is a function of (_all_lights_nnls: the light colour's choice, the
        #: certificate and the report's each ask it of one problem)
        self.content = (tuple(digests[id(self.T[c])] for c in self.chans), _digest(self.b),
                        None if self.upper is None else self.upper.tobytes())
        self.h = np.stack([self.T[c].T @ self.b[:, c] if c in self.chans else np.zeros(n) for c in range(3)],
                          axis=1)  # (n, 3)
        self.norm = float(np.sqrt(self.bb.sum()))
        self.tol = EQUAL_ERROR_RTOL * max(self.norm, TINY)
        dsum = sum(self.d[id(self.T[c])] for c in self.chans)
        self.usable = dsum > 0  # lights that reach at least one target
        self._cache = {}
        self._gcache = {}
        self.n_fits = 0

    # -- exact fits ------------------------------------------------------------------------
    def fit(self, S):
        """(lights on (ascending), exitance (k, 3), per-channel squared error (3,), power)."""
        S = tuple(sorted(int(s) for s in S))
        if S in self._cache:
            return self._cache[S]
        idx = np.asarray(S, dtype=np.int64)
        e = np.zeros((len(S), 3))
        err2 = self.bb.copy()
        if len(S):
            self.n_fits += 1
            gram_fit = self.upper is None and self.m >= GRAM_FIT_ROWS * len(idx) and self.m * len(idx) >= GRAM_FIT_SIZE
            for c in self.chans:
                if gram_fit:
                    e[:, c], err2[c] = self._gram_fit(idx, c)
                    continue
                A = self.T[c][:, idx]
                e[:, c] = _bounded(A, self.b[:, c], None if self.upper is None else self.upper[idx])
                r = np.einsum("ij,j->i", A, e[:, c]) - self.b[:, c]
                err2[c] = float(np.dot(r, r))
        on = e.max(axis=1) > 0
        res = (idx[on], e[on], err2, total_power(e[on], self.area[idx[on]]))
        self._cache[S] = res
        return res

    def _gram_fit(self, idx, c):
        """(x, squared error) of channel c's NNLS on the lights ``idx`` from their Gram matrix: the
        m rows of T are read only when the fit needs them (_nnls_normal's fallback, GRAM_RESIDUAL):
        gathering k of T's columns over a view target's 941 rows was half of each fit's time."""
        G = self.G[id(self.T[c])][np.ix_(idx, idx)]
        h, y = self.h[idx, c], self.b[:, c]
        x = _nnls_normal(G, h, lambda: self.T[c][:, idx], y)
        r2 = float(self.bb[c] - 2.0 * (h @ x) + x @ (G @ x))
        if r2 < GRAM_RESIDUAL * self.bb[c]:
            r = self.T[c][:, idx] @ x - y
            r2 = float(r @ r)
        return x, r2

    def key(self, fit):
        return math.sqrt(max(float(fit[2].sum()), 0.0)), fit[3]

    def better(self, a, b):
        """Is fit a better than fit b (smaller error; within tolerance, less power; then fewer lights)?"""
        ea, pa = self.key(a)
        eb, pb = self.key(b)
        if ea < eb - self.tol:
            return True
        if ea > eb + self.tol:
            return False
        if pa < pb * (1 - 1e-9) - TINY:
            return True
        if pa > pb * (1 + 1e-9):
            return False
        return len(a[0]) < len(b[0])

    # -- screening ------------------------------------------------------------------------
    # Notation per channel c: S the chosen lights, e their NNLS exitance, A = the lights of S
    # with e_c > 0 (the channel's active set), N = S - A. On A the NNLS fit is the
    # least-squares fit (x = G_AA^-1 h_A), r its residual, H = G_AA^-1, Z = H G_A. (all
    # columns). Adding light j with coefficient beta_j = max(0, t_j . r) / ||t_j - P_A t_j||^2
    # (P_A: projection on A's columns) gives the least-squares fit on A + {j} with x_j >= 0;
    # it is *the* NNLS fit of S + {j} when its coefficients on A are >= 0 and the KKT
    # condition t_l . r' <= 0 holds for every l in N (then the value is exact). Otherwise the
    # value is not certified and the bound used is the least-squares fit over all of S + {j}
    # with only x_j >= 0 (a relaxation, so a lower bound). Removing light i from A is a
    # rank-one downdate of H (z_i = T_A H e_i, ||z_i||^2 = H_ii): the residual grows by
    # x_i^2 / H_ii, t_j . r changes by Z_ij x_i / H_ii, ||t_j - P t_j||^2 by Z_ij^2 / H_ii.

    def _gram_part(self, G, d, A):
        """The part of _channel that depends on T only, cached per (matrix, light set): the same
        sets recur (between the additions and the swaps, and across channels sharing T)."""
        key = (id(G), A.tobytes())
        got = self._gcache.get(key)
        if got is None:
            if len(A):
                GA = G[A]
                H = _inv_spd(G[np.ix_(A, A)])
                Z = H @ GA
                perp = d - np.einsum("ij,ij->j", GA, Z)
            else:
                GA = H = Z = None
                perp = d.copy()
            ok = perp > 1e-10 * np.maximum(d, TINY)
            got = (GA, H, Z, perp, ok, np.where(ok, perp, 1.0))
            if len(self._gcache) > 256:
                self._gcache.clear()
            self._gcache[key] = got
        return got

    def _channel(self, G, d, A, c):
        """Least-squares quantities of channel c on the light set A (see above)."""
        h = self.h[:, c]
        GA, H, Z, perp, ok, safe = self._gram_part(G, d, np.asarray(A, dtype=np.int64))
        if len(A):
            x = H @ h[A]
            rls2 = max(self.bb[c] - float(h[A] @ x), 0.0)
            corr = h - np.einsum("ij,i->j", GA, x)
        else:
            x = None
            rls2 = float(self.bb[c])
            corr = h.copy()
        return dict(GA=GA, H=H, Z=Z, x=x, perp=safe, raw_perp=perp, ok=ok, rls2=rls2, corr=corr)

    def _kkt_tol(self, d, c):
        return 1e-9 * np.sqrt(np.maximum(d, 0.0) * max(self.bb[c], TINY))

    def add_bounds(self, S, e, err2):
        """For every light j: (LB_j, UB_j, gain1_j) on the squared error of the NNLS fit of S + {j}.

        LB: exact where certified (see the notes above), else the relaxation bound. UB:
        exact where certified in every channel, else the current fit plus the best
        non-negative multiple of column j (achievable). gain1: that 1-D decrease,
        sum_c max(0, t_jc . rho_c)^2 / ||t_jc||^2 (the 'correlation' score).
        """
        n = self.n
        S = np.asarray(S, dtype=np.int64)
        LB = np.zeros(n)
        gain1 = np.zeros(n)
        exact_val = np.zeros(n)
        exact = np.ones(n, dtype=bool)
        for c in self.chans:
            key = id(self.T[c])
            G, d = self.G[key], self.d[key]
            act = e[:, c] > 0 if len(S) else np.zeros(0, dtype=bool)
            A, N = S[act], S[~act]
            q = self._channel(G, d, A, c)
            g = q["corr"]  # t_j . rho (rho: the NNLS residual = the LS residual on A)
            cp = np.maximum(g, 0.0)
            beta = np.where(q["ok"], cp / q["perp"], 0.0)
            val = q["rls2"] - beta * cp
            cert = np.ones(n, dtype=bool)
            if len(A):
                cert &= (q["x"][:, None] - beta[None, :] * q["Z"]).min(axis=0) >= 0
            if len(N):
                MN = G[N] - (q["GA"][:, N].T @ q["Z"] if len(A) else 0.0)  # (|N|, n): t_l . (t_j - P_A t_j)
                kkt = g[N][:, None] - beta[None, :] * MN
                cert &= (kkt <= self._kkt_tol(d[N], c)[:, None]).all(axis=0)
                qS = self._channel(G, d, S, c)  # the relaxation over all of S
                cS = np.maximum(qS["corr"], 0.0)
                lb = qS["rls2"] - np.where(qS["ok"], cS * cS / qS["perp"], 0.0)
                LB += np.where(cert, val, np.minimum(lb, val))
            else:
                LB += val
            exact &= cert
            exact_val += val
            gain1 += np.where(d > 0, cp * cp / np.where(d > 0, d, 1.0), 0.0)
        LB = np.maximum(LB, 0.0)
        if self.upper is not None:  # bounded: the current fit plus j's best multiple within its bound
            return LB, np.maximum(err2.sum() - self._bounded_gain(S, e), 0.0), gain1
        UB = np.where(exact, np.maximum(exact_val, 0.0), np.maximum(err2.sum() - gain1, 0.0))
        return LB, UB, gain1

    def _bounded_gain(self, S, e):
        """(n,) the decrease of the squared error of the fit ``e`` (k, 3) on S when light j is added at
        its best strength within [0, upper_j] per channel, the others kept (achievable)."""
        out = np.zeros(self.n)
        for c in self.chans:
            key = id(self.T[c])
            G, d = self.G[key], self.d[key]
            g = self.h[:, c] - (G[S].T @ e[:, c] if len(S) else 0.0)  # t_j . (b - T_S e)
            out += _clipped_gain(g, d, self.upper)
        return out

    def swap_bounds(self, S, e, err2, limit=np.inf, max_pairs=2048):
        """Swaps S[i] -> j whose lower bound on the squared error is <= limit.

        Returns (I, J, LB, UB) over those pairs (I: positions in S, J: light indices); bounds as
        in add_bounds. Per channel, the least-squares fit on A - {i} + {j} (x_j >= 0) has a
        residual r' orthogonal to those lights; when t_l . r' <= 0 for the other lights l of
        N (the KKT condition), r' is dual feasible for the NNLS of that set, so its value
        ||r'||^2 is a lower bound (and the NNLS value itself when the coefficients are also
        >= 0). Where the KKT condition fails, the relaxation over all of S is used. O(k^2 n)
        per channel for all pairs; the coefficient signs (exactness) only for the pairs
        within the limit, at most ``max_pairs`` of them (the smallest bounds).
        """
        S = np.asarray(S, dtype=np.int64)
        k, n = len(S), self.n
        cols = self.usable.copy()
        cols[S] = False
        chan = []
        LB0 = np.zeros((k, n))
        UB1 = np.zeros((k, n))
        for c in self.chans:
            lb, fit = self._swap_channel(S, e, c)
            LB0 += lb
            chan.append(fit)
            UB1 += self._swap_achievable(S, e[:, c], err2[c], c)
        LB0 = np.maximum(LB0, 0.0)
        I, J = np.nonzero((LB0 <= limit) & cols[None, :])
        if len(I) > max_pairs:  # the search refits pairs in increasing bound: keep the most promising
            keep = np.argpartition(LB0[I, J], max_pairs - 1)[:max_pairs]
            keep.sort()
            I, J = I[keep], J[keep]
        if len(I) == 0:
            return I, J, np.zeros(0), np.zeros(0)
        LB = LB0[I, J]
        if self.upper is not None:  # bounded: no swap's value is certified exact
            return I, J, LB, np.maximum(UB1[I, J], 0.0)
        exact, exact_val = self._swap_exact(chan, I, J, k)
        UB = np.where(exact, np.maximum(exact_val, 0.0), np.maximum(UB1[I, J], 0.0))
        return I, J, LB, UB

    def _swap_channel(self, S, e, c) -> tuple:
        """swap_bounds on channel c: (its (k, n) lower bounds, (c, q, A, ia, val, beta, kkt_ok): the
        channel's fit on its active lights A (positions ia in S), the least-squares values and
        multiples of j per swap, and where the KKT condition holds)."""
        k, n = len(S), self.n
        key = id(self.T[c])
        G, d = self.G[key], self.d[key]
        act = e[:, c] > 0
        A, N = S[act], S[~act]
        ia, iN = np.flatnonzero(act), np.flatnonzero(~act)
        q = self._channel(G, d, A, c)
        val = np.zeros((k, n))
        beta = np.zeros((k, n))
        kkt_ok = np.ones((k, n), dtype=bool)
        MN = tolN = None
        if len(N):  # rows i in N: the channel does not use light i; adding j as in add_bounds
            MN = G[N] - (q["GA"][:, N].T @ q["Z"] if len(A) else 0.0)  # t_l . (t_j - P_A t_j)
            tolN = self._kkt_tol(d[N], c)
            _swap_unused(q, N, iN, MN, tolN, val, beta, kkt_ok)
        if len(A):  # rows i in A: downdate A by i, add j
            _swap_used(q, d, N, ia, MN, tolN, val, beta, kkt_ok)
        if len(N) and not kkt_ok.all():
            lb = np.where(kkt_ok, val, np.minimum(self._swap_relaxation(G, d, S, c), val))
        else:
            lb = val
        return lb, (c, q, A, ia, val, beta, kkt_ok)

    def _swap_achievable(self, S, ec, err2c, c):
        """(k, n) achievable squared errors on channel c: drop light S[i] from the current fit
        (exitance ``ec``, squared error ``err2c``), best non-negative multiple of j."""
        key = id(self.T[c])
        G, d = self.G[key], self.d[key]
        gS = self.h[:, c] - np.einsum("ij,i->j", G[S], ec)  # t_j . rho
        rho_i2 = err2c + 2.0 * ec * gS[S] + ec * ec * d[S]
        gij = gS[None, :] + G[S] * ec[:, None]
        if self.upper is not None:
            return rho_i2[:, None] - _clipped_gain(gij, d[None, :], self.upper[None, :])
        return rho_i2[:, None] - np.where((d > 0)[None, :], np.maximum(gij, 0.0) ** 2
                                          / np.where(d > 0, d, 1.0)[None, :], 0.0)

    @staticmethod
    def _swap_exact(chan, I, J, k) -> tuple:
        """(exact (P,), value (P,)): the swaps (I, J) whose least-squares value is the NNLS value
        on every channel (the KKT condition holds and the coefficients are >= 0), and that value."""
        P = len(I)
        exact = np.ones(P, dtype=bool)
        exact_val = np.zeros(P)
        for c, q, A, ia, val, beta, kkt_ok in chan:
            cert = kkt_ok[I, J].copy()
            exact_val += val[I, J]
            if len(A):
                H, Z, x, Hd = q["H"], q["Z"], q["x"], q["Hd"]
                bt = beta[I, J]
                rowA = np.full(k, -1)
                rowA[ia] = np.arange(len(ia))
                a = rowA[I]  # position of S[i] in A, or -1
                t = np.flatnonzero((a >= 0) & cert)
                if len(t):  # coefficients on A - {i} after adding j: all >= 0?
                    ai = a[t]
                    Hr = H[ai] / Hd[ai][:, None]
                    Wd = Z[:, J[t]].T - Hr * Z[ai, J[t]][:, None]  # G_WW^-1 G_Wj on A - {i}
                    coef = (x[None, :] - Hr * x[ai][:, None]) - bt[t][:, None] * Wd
                    coef[np.arange(len(t)), ai] = 0.0
                    cert[t] = coef.min(axis=1) >= 0
                t = np.flatnonzero((a < 0) & cert)
                if len(t):
                    cert[t] = (x[None, :] - bt[t][:, None] * Z[:, J[t]].T).min(axis=1) >= 0
            exact &= cert
        return exact, exact_val

    def _swap_relaxation(self, G, d, S, c):
        """(k, n) lower bounds: least squares on S - {S[i]} + {j} with only x_j >= 0."""
        q = self._channel(G, d, S, c)
        H, Z, x = q["H"], q["Z"], q["x"]
        Hd = np.diag(H).copy()
        Hd = np.where(Hd > 0, Hd, np.inf)
        pij = q["raw_perp"][None, :] + Z * Z / Hd[:, None]
        ok = pij > 1e-10 * np.maximum(d, TINY)[None, :]
        cij = np.maximum(q["corr"][None, :] + Z * (x / Hd)[:, None], 0.0)
        rem = q["rls2"] + x * x / Hd
        return rem[:, None] - np.where(ok, cij * cij / np.where(ok, pij, 1.0), 0.0)


# ---------------------------------------------------------------------------------------------
# best_k_curve
# ---------------------------------------------------------------------------------------------
def _branch_and_bound(model, sets, LB, UB, current, max_exact):
    """Exact fits of candidate sets in increasing lower bound; stops when no later one can win.

    sets(i) -> the light set of candidate i; LB/UB (N,) squared-error bounds. Returns the best
    fit found (or None) and the number of exact fits made.
    """
    slack = 1e-12 * model.bb.sum() + 2.0 * model.tol * model.norm + model.tol ** 2
    ub_min = float(UB.min()) if len(UB) else np.inf
    cand = np.flatnonzero(LB <= ub_min + slack)
    order = cand[np.lexsort((cand, UB[cand], LB[cand]))]
    best, n = None, 0
    for i in order:
        if n >= max_exact:
            break
        if best is not None and LB[i] > best[2].sum() + slack:
            break
        f = model.fit(sets(i))
        n += 1
        if best is None or model.better(f, best):
            best = f
    return best, n


def _add_one(model, S, fit, score, max_exact):
    """The best set S + {j} by ``score``, or None when no light lowers the error."""
    lights, e_on, err2, _ = fit
    S = np.asarray(S, dtype=np.int64)
    e = np.zeros((len(S), 3))
    pos = {int(l): i for i, l in enumerate(S)}
    for l, row in zip(lights, e_on):
        e[pos[int(l)]] = row
    LB, UB, gain1 = model.add_bounds(S, e, err2)
    mask = model.usable.copy()
    mask[S] = False
    cand = np.flatnonzero(mask)
    if len(cand) == 0:
        return None
    if score == "correlation":
        gain = gain1[cand]
        gmax = float(gain.max())
        if not gmax > 0:
            return None
        # ties (numerically equal gains, e.g. duplicate lights): the exact fits decide (error, power)
        ties = cand[gain >= gmax - 1e-9 * max(gmax, model.tol * model.norm)][:max_exact]
        f = None
        for j in ties:
            fj = model.fit(np.append(S, j))
            if f is None or model.better(fj, f):
                f = fj
    else:
        best, _ = _branch_and_bound(model, lambda i: np.append(S, cand[i]), LB[cand], UB[cand], fit, max_exact)
        f = best
    if f is None or not model.better(f, fit):
        return None
    return f


def _swap_search(model, fit, max_rounds, max_exact, halt=None):
    """Best-improvement swaps (one light out, one in) while the error (then the power) drops.
    ``halt()`` returning True before a round: sampling.Cancelled."""
    rounds = 0
    while rounds < max_rounds:
        check_cancel(halt)
        S = np.asarray(fit[0], dtype=np.int64)
        if len(S) == 0:
            break
        E = math.sqrt(fit[2].sum())
        # only swaps whose bound does not exclude an improvement (or an equal error at less power)
        lim = (E + model.tol) ** 2 + 1e-12 * model.bb.sum()
        I, J, LB, UB = model.swap_bounds(S, fit[1], fit[2], lim)
        if len(I) == 0:
            break

        def sets(t, I=I, J=J, S=S):
            return np.append(np.delete(S, I[t]), J[t])

        best, _ = _branch_and_bound(model, sets, LB, UB, fit, max_exact)
        rounds += 1
        if best is None or not model.better(best, fit):
            break
        fit = best
    return fit, rounds


def fit_lights(T, b, lights, light_watts=None, upper=None):
    """NNLS per channel on a given set of lights (bounded least squares where ``upper`` (n,) bounds
    them): (lights on, exitance (k, 3), error, power)."""
    model = _Model(T, b, light_watts, upper)
    f = model.fit(lights)
    return f[0], f[1], math.sqrt(f[2].sum()), f[3]


def best_k_curve(T, b, k_max, light_watts=None, swap=True, score="error", seed=0, max_swap_rounds=None,
                 max_exact=24, restarts=0, initial=None, exhaustive_limit=20_000, swap_all=True, cancel=None,
                 progress=None, stats=None, _model=None, upper=None, halt=None):
    """The best configuration found with at most k lights, for k = 1 .. k_max.

    ``upper`` (n,): each light's largest strength per channel (inf: none; a catalogue fixture's
    rated flux): every fit is then bounded least squares (0 <= e <= upper), so a configuration
    that needs more light than its fixtures give takes more of them.

    T: list of 3 (m, n) transfer matrices (``problem.transfer``) or one (m, n) for all
    channels; b (m, 3) targets W/m^2 (``problem.b_target``); light_watts (n,) W per unit strength (the area for surface lights; for the
    power and the least-power tie-break; default 1).

    At every k the starts are the plain greedy path (one light added per step, each with an
    NNLS refit) and the chained configuration (the one kept for k - 1 plus greedy
    additions). ``score`` chooses the additions: 'error' (the candidate with the smallest
    exact NNLS error, found by branch and bound on the screening bounds, at most
    ``max_exact`` refits per step), 'correlation' (the largest non-negative 1-D gain on the
    residual, one refit), or 'both' (both greedy paths are starts). ``swap``: run the swap
    local search (best-improvement single swaps while the error, then the power, drops; at
    most ``max_swap_rounds`` per start, default 2 k + 10) from every distinct start
    (``swap_all``, the default) or from the best one only; without ``swap`` the curve is the
    best greedy path. ``restarts``: extra swap searches per k from random k-sets (seeded by
    ``seed``); 0 (the default) makes the result independent of the seed. ``initial``:
    optional light sets to start a swap search from as well, a list indexed by k - 1 or a
    dict {k: lights} (e.g. ``lower_bounds(...).optimum_lights``: the exact optima where the
    exhaustive search ran, which the curve then contains). ``exhaustive_limit``: for every k
    with at most that many subsets of at most k lights, the exact optimum (found by
    :func:`lower_bounds`' enumeration) is such a start too, so small problems get their
    optimum (0 turns it off). ``cancel()`` returning True stops after the current k (the
    list is then shorter); ``halt()`` returning True stops it within a swap search's round
    (sampling.Cancelled: no curve). ``progress(done, total)`` is called after every k. ``stats``:
    optional dict filled with counters.

    Returns a list of :class:`KLightPoint`, one per k (``point.k``), monotone
    non-increasing in error, every exitance >= 0. A point has fewer than k lights when no
    configuration found with k lights is better (``source='fewer'``) or when no light can
    lower the error (``source='none'``, e.g. b = 0: no light at all).
    """
    if score not in SCORES + ("both",):
        raise ValueError(f"unknown score {score!r}; choose one of {', '.join(SCORES + ('both',))}")
    model = _model or _Model(T, b, light_watts, upper)
    k_max = _checked_k_max(k_max, model.n)
    search = _KSearch(model, score, max(1, int(max_exact)), max_swap_rounds, swap_all, restarts,
                      np.random.default_rng(seed), initial, halt)
    empty = model.fit(())
    cur = empty  # chained configuration (at most k lights)
    curve = []
    if swap and exhaustive_limit:
        search.exact_sets = _exact_sets(model, k_max, exhaustive_limit)
    paths = {sc: empty for sc in (SCORES if score == "both" else (score,))}  # plain greedy paths
    for k in range(1, k_max + 1):
        cand, source = search.greedy(paths, k)
        if swap:
            cand, source = search.swaps(paths, cur, cand, source, k)
        cand, source = _no_worse_than_fewer(model, curve, cand, source, empty)
        cur = cand
        curve.append(_k_point(k, cand, source, model.norm if model.norm > 0 else 1.0))
        if progress is not None:
            progress(k, k_max)
        if cancel is not None and cancel():
            break
    _monotone(curve)
    search.report(stats)
    return curve


def _checked_k_max(k_max, n) -> int:
    """k_max as an int, at most ``n`` (ValueError below 1)."""
    k_max = int(k_max)
    if k_max < 1:
        raise ValueError(f"k_max must be at least 1, got {k_max}")
    return min(k_max, n)


def _exact_sets(model, k_max, exhaustive_limit) -> dict:
    """{k: the exact optimum's lights} for every k <= k_max with at most ``exhaustive_limit``
    subsets of at most k lights (_exhaustive's enumeration)."""
    k_exh = 0
    while k_exh < k_max and _n_subsets(model.n, k_exh + 1) <= exhaustive_limit:
        k_exh += 1
    if not k_exh:
        return {}
    return {s + 1: st for s, st in enumerate(_exhaustive(model, k_exh)[1])}


class _KSearch:
    """best_k_curve's search at one k: the greedy paths, then the swap searches from every start
    (the paths, the chained configuration, the exact optimum, the initial sets, random restarts)."""

    def __init__(self, model, score, max_exact, max_swap_rounds, swap_all, restarts, rng, initial, halt=None):
        self.model, self.score, self.max_exact, self.halt = model, score, max_exact, halt
        self.max_swap_rounds, self.swap_all, self.restarts = max_swap_rounds, swap_all, restarts
        self.rng, self.initial = rng, initial
        self.usable = np.flatnonzero(model.usable)
        self.exact_sets = {}
        self.counts = {"exact_fits": 0, "swap_rounds": 0, "restarts_won": 0}

    def report(self, stats):
        """The counters into ``stats`` (a dict, or None)."""
        self.counts["exact_fits"] = self.model.n_fits
        if stats is not None:
            stats.update(self.counts)

    def fill(self, fit, k, sc):
        """Add lights up to k (an addition can switch another light off under the refit)."""
        for _ in range(2 * k + 2):
            if len(fit[0]) >= k:
                break
            check_cancel(self.halt)
            nxt = _add_one(self.model, fit[0], fit, sc, self.max_exact)
            if nxt is None:
                break
            fit = nxt
        return fit

    def greedy(self, paths, k) -> tuple:
        """Every greedy path grown to k lights (``paths`` updated); (the best of them, "greedy")."""
        cand = None
        for sc in paths:
            paths[sc] = self.fill(paths[sc], k, sc)
            if cand is None or self.model.better(paths[sc], cand):
                cand = paths[sc]
        return cand, "greedy"

    def _swap(self, start, cand, source, rounds, won):
        """The swap search from ``start``: (cand, source) replaced by its result where better."""
        alt, r = _swap_search(self.model, start, rounds, self.max_exact, self.halt)
        self.counts["swap_rounds"] += r
        return (alt, won) if self.model.better(alt, cand) else (cand, source)

    def swaps(self, paths, cur, cand, source, k) -> tuple:
        """(cand, source) after the swap searches at k lights."""
        model = self.model
        starts = list(paths.values())
        if all(tuple(cur[0]) != tuple(f[0]) for f in paths.values()):
            chained = self.fill(cur, k, "error" if self.score == "both" else self.score)
            starts.append(chained)
            if model.better(chained, cand):
                cand, source = chained, "swap"
        if not self.swap_all:
            starts = [cand]  # the swap search from the best start only
        rounds = self.max_swap_rounds if self.max_swap_rounds is not None else 2 * k + 10
        seen = set()
        for f in starts:
            if not len(f[0]) or tuple(f[0]) in seen:
                continue
            seen.add(tuple(f[0]))
            cand, source = self._swap(f, cand, source, rounds, "swap")
        cand, source = self._given_starts(k, cand, source, rounds)
        return self._random_restarts(k, cand, source, rounds)

    def _given_starts(self, k, cand, source, rounds) -> tuple:
        """The swap search from the exact optimum at k and from the initial set of k lights."""
        starts = [self.exact_sets[k]] if k in self.exact_sets else []
        initial = self.initial
        if initial is not None:
            got = initial.get(k) if isinstance(initial, dict) else (initial[k - 1] if k <= len(initial) else None)
            if got is not None and 0 < len(got) <= k:
                starts.append(np.asarray(got, dtype=np.int64))
        for st in starts:
            won = "exhaustive" if k in self.exact_sets and st is starts[0] else "initial"
            cand, source = self._swap(self.model.fit(st), cand, source, rounds, won)
        return cand, source

    def _random_restarts(self, k, cand, source, rounds) -> tuple:
        for _ in range(max(0, int(self.restarts))):
            if len(self.usable) < k:
                break
            start = self.model.fit(self.rng.choice(self.usable, size=k, replace=False))
            before = cand
            cand, source = self._swap(start, cand, source, rounds, "swap")
            if cand is not before:
                self.counts["restarts_won"] += 1
        return cand, source


def _no_worse_than_fewer(model, curve, cand, source, empty) -> tuple:
    """(cand, source), or the configuration kept with fewer lights when it is better ("fewer"),
    or no light at all when the first candidate does not beat it ("none")."""
    prev = curve[-1] if curve else None
    if prev is not None and model.better(model.fit(prev.lights), cand):
        cand, source = model.fit(prev.lights), "fewer"
    elif prev is None and not model.better(cand, empty):
        cand, source = empty, "none"
    return cand, source


def _k_point(k, cand, source, norm) -> "KLightPoint":
    lights, e, err2, power = cand
    err = math.sqrt(max(float(err2.sum()), 0.0))
    if len(lights) == 0 and source != "none":
        source = "none"
    return KLightPoint(k=k, n_lights=len(lights), error=err, relative_error=err / norm, power=power,
                       lights=np.asarray(lights, dtype=np.int64).copy(), exitance=np.asarray(e).copy(),
                       n_negative=0, changed=-1, source=source)


def _monotone(curve):
    """The curve is monotone by construction (the k - 1 configuration is always a candidate); a
    point worse than the one before (a refit's rounding) takes its values."""
    for a, b_ in zip(curve, curve[1:]):
        if b_.error > a.error:  # cannot happen; guard against a refit's rounding
            b_.error, b_.relative_error, b_.power = a.error, a.relative_error, a.power
            b_.lights, b_.exitance, b_.n_lights, b_.source = a.lights.copy(), a.exitance.copy(), a.n_lights, "fewer"


def best_k_with_certificate(T, b, k_max, light_watts=None, exhaustive_limit=300_000, nnls_start=None, upper=None,
                            halt=None, lazy_gram=False, **kw):
    """The certificate first (lower_bounds: exact optima where the subsets are few enough), then
    best_k_curve seeded with those optimal sets: the curve is optimal wherever the certificate is
    exact, and the swap search starts from there above (best_k_curve enumerates nothing again:
    the certificate's enumeration reaches at least as far). ``initial`` (best_k_curve's: a list
    indexed by k - 1 or a dict {k: lights}, e.g. an earlier answer's curve) seeds the others;
    ``nnls_start``: lower_bounds'; ``halt``: lower_bounds' and best_k_curve's; ``lazy_gram``: the
    Gram matrices' rows computed as read (GramRows: a stroke's quick search). Returns (curve, bounds)."""
    model = _Model(T, b, light_watts, upper, lazy_gram)  # one for both (its Gram matrices, its fits)
    bounds = lower_bounds(T, b, k_max, exhaustive_limit=exhaustive_limit, nnls_start=nnls_start, _model=model,
                          halt=halt)
    given = kw.pop("initial", None) or {}
    starts = dict(given) if isinstance(given, dict) else {k + 1: st for k, st in enumerate(given)}
    starts.update({k + 1: st for k, st in enumerate(bounds.optimum_lights) if st is not None})
    kw["exhaustive_limit"] = 0
    return best_k_curve(T, b, k_max, light_watts, initial=starts or None, _model=model, halt=halt, **kw), bounds


def best_k_for_problem(problem, k_max, **kw):
    """best_k_curve on an InverseProblem: its transfer matrices, targets and light areas."""
    return best_k_curve(problem.transfer, problem.b_target, k_max, problem.light_watts, **kw)


# ---------------------------------------------------------------------------------------------
# lower bounds (the certificate)
# ---------------------------------------------------------------------------------------------
@dataclass
class LowerBounds:
    """Lower bounds on the best error with at most k non-negative lights, k = 1 .. k_max.

    bound[k-1] (W/m^2) is the certificate: no configuration of at most k lights with
    non-negative exitances has a smaller Eq.-1 error. exact[k-1] says that bound is the
    optimum itself (exhaustive search; ``optimum_lights[k-1]`` is then an optimal set), up to a
    relative margin BOUND_MARGIN and BOUND_ROUNDING x ||b|| taken off against rounding. nnls: the error of NNLS on all
    lights (valid for every k). relative = bound / ||b||.
    """

    k: np.ndarray
    bound: np.ndarray
    relative: np.ndarray
    exact: np.ndarray
    nnls: float
    nnls_relative: float
    optimum_lights: list = field(default_factory=list)
    seconds: float = 0.0
    nnls_exitance: np.ndarray = None  # (n, 3): the all-lights NNLS configuration the ``nnls`` bound is of

    def at(self, k):
        """Bound for k lights (k beyond k_max: the NNLS bound, valid for every k)."""
        if 1 <= k <= len(self.bound):
            return float(self.bound[k - 1])
        return self.nnls


def _n_subsets(n, k):
    return sum(math.comb(n, s) for s in range(1, k + 1))


def _rank_colex(C, binom):
    """Colex rank of sorted combinations C (N, s): sum_i binom(C[:, i], i + 1)."""
    r = np.zeros(len(C), dtype=np.int64)
    for i in range(C.shape[1]):
        r += binom[C[:, i], i + 1]
    return r


def _combinations_colex(n, s):
    """All s-subsets of range(n), sorted ascending within rows, in colex order (rank 0, 1, ...)."""
    if s == 1:
        return np.arange(n, dtype=np.int64)[:, None]
    prev = _combinations_colex(n, s - 1)
    blocks = []
    # colex order: grouped by the largest element c, then by the colex order of the rest
    for c in range(s - 1, n):
        rest = prev[prev[:, -1] < c]
        blocks.append(np.hstack([rest, np.full((len(rest), 1), c, dtype=np.int64)]))
    return np.vstack(blocks)


def _exhaustive(model, k_top, chunk=50000):
    """Exact best squared error for k = 1 .. k_top by enumerating every subset; (err2 list, sets)."""
    n = model.n
    binom = np.zeros((n + 1, k_top + 2), dtype=np.int64)
    for a in range(n + 1):
        for s in range(k_top + 2):
            binom[a, s] = math.comb(a, s)
    # g[s][c] (C(n, s),): best squared error of channel c with the lights of the s-subset (NNLS)
    g_prev = np.tile(model.bb, (1, 1))  # size 0: the empty set
    best_err2, best_sets = [], []
    for s in range(1, k_top + 1):
        C = _combinations_colex(n, s)
        N = len(C)
        g = np.empty((N, 3))
        for start in range(0, N, chunk):
            Cc = C[start:start + chunk]
            # NNLS on S = LS on S if it is feasible and S independent, else the best S - {i}
            sub = np.full((len(Cc), 3), np.inf)
            for i in range(s):
                rest = np.delete(Cc, i, axis=1)
                ridx = _rank_colex(rest, binom) if s > 1 else np.zeros(len(Cc), dtype=np.int64)
                sub = np.minimum(sub, g_prev[ridx])
            ls = np.full((len(Cc), 3), np.inf)
            for key, chans in model.groups.items():
                G = model.G[key]
                dg = np.sqrt(np.maximum(model.d[key][Cc], TINY))  # (N, s)
                if s == 2:  # closed form: Gn = [[1, rho], [rho, 1]], eigenvalues 1 -+ |rho|
                    rho = G[Cc[:, 0], Cc[:, 1]] / (dg[:, 0] * dg[:, 1])
                    det = 1.0 - rho * rho
                    indep = 1.0 - np.abs(rho) > 1e-10 * (1.0 + np.abs(rho))
                    det = np.where(indep, det, 1.0)
                elif s == 1:
                    w = np.ones((len(Cc), 1))
                    V = np.ones((len(Cc), 1, 1))
                    indep = np.ones(len(Cc), dtype=bool)
                else:
                    Gs = G[Cc[:, :, None], Cc[:, None, :]]  # (N, s, s)
                    w, V = np.linalg.eigh(Gs / dg[:, :, None] / dg[:, None, :])  # unit diagonal
                    indep = w[:, 0] > 1e-10 * w[:, -1]
                if s != 2:
                    winv = np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0), 0.0)
                for c in chans:
                    hs = model.h[Cc, c] / dg  # (N, s)
                    if s == 2:
                        xn = np.stack([hs[:, 0] - rho * hs[:, 1], hs[:, 1] - rho * hs[:, 0]], axis=1) / det[:, None]
                    else:
                        y = np.einsum("nij,ni->nj", V, hs) * winv
                        xn = np.einsum("nij,nj->ni", V, y)  # solution in normalised coordinates
                    feas = indep & np.all(xn >= 0, axis=1)
                    val = np.maximum(model.bb[c] - np.einsum("ni,ni->n", xn, hs), 0.0)
                    ls[:, c] = np.where(feas, val, np.inf)
            g[start:start + len(Cc)] = np.minimum(ls, sub)
        tot = g.sum(axis=1)
        i = int(np.argmin(tot))
        best_err2.append(float(tot[i]))
        best_sets.append(C[i].copy())
        g_prev = g
    return best_err2, best_sets


def lower_bounds(T, b, k_max, exhaustive_limit=300_000, nnls_start=None, _model=None, upper=None, halt=None):
    """Certificate: a lower bound on the best error with at most k non-negative lights, k = 1..k_max.

    The all-lights NNLS error bounds every k. For every k with at most ``exhaustive_limit``
    subsets of at most k lights (sum of C(n, s), s <= k), the exact optimum is found by
    enumerating them all, vectorised: for a set S, the per-channel NNLS optimum is the
    least-squares fit on S when that fit is non-negative (and S independent), otherwise
    the best over the subsets S - {i} (Caratheodory: an optimum is reached on an
    independent support), so every size reuses the previous size's table. The optimum's set
    is re-fitted with NNLS on T (not the Gram matrix) for the reported value. A bound for k
    is also a bound for fewer lights, so each k takes the largest valid bound of k..k_max.
    ``nnls_start``: an earlier, nearby problem's all-lights NNLS exitance (n, 3) (``nnls_exitance``
    of a Live stroke's bounds): its active lights start a working-set NNLS (``_nnls_from``),
    the same optimum, sooner. ``halt()`` returning True stops it (sampling.Cancelled) before each
    channel's all-lights NNLS (30-90 ms on the living room, holding the interpreter: Live's next
    stroke waited for the three when it came during a later answer's certificate). Returns a
    :class:`LowerBounds`.

    With bounds (``upper`` (n,), best_k_curve's), every configuration of k lights within them is a
    configuration of all the lights within them, so the all-lights *bounded* least squares bounds
    every k; the enumeration's optima are of the unbounded NNLS of each subset (a relaxation: a
    lower bound, no longer taken as exact), and each k takes the larger of the two.
    """
    t0 = time.perf_counter()
    model = _model or _Model(T, b, None, upper)  # (the lights' power plays no part in a bound)
    k_max = int(k_max)
    if k_max < 1:
        raise ValueError(f"k_max must be at least 1, got {k_max}")
    err2, e_nnls = _all_lights_nnls(model, nnls_start, halt)
    nnls_err = math.sqrt(max(err2.sum(), 0.0)) * (1 - BOUND_MARGIN)
    k_exh = 0
    while k_exh < min(k_max, model.n) and _n_subsets(model.n, k_exh + 1) <= exhaustive_limit:
        k_exh += 1
    bound = np.full(k_max, nnls_err)
    exact = np.zeros(k_max, dtype=bool)
    opt_sets = [None] * k_max
    if k_exh:
        errs, sets = _exhaustive(model, k_exh)
        for s in range(1, k_exh + 1):
            f = model.fit(sets[s - 1])  # accurate value on T for the optimal set
            val = min(math.sqrt(max(errs[s - 1], 0.0)), math.sqrt(f[2].sum()))
            bound[s - 1] = max(val * (1 - BOUND_MARGIN) - BOUND_ROUNDING * model.norm, nnls_err, 0.0)
            exact[s - 1] = model.upper is None
            opt_sets[s - 1] = f[0].copy()
    if model.n <= k_max:  # all lights allowed: NNLS is the optimum
        exact[model.n - 1:] = True
    _monotone_bounds(bound)
    norm = model.norm if model.norm > 0 else 1.0
    return LowerBounds(k=np.arange(1, k_max + 1), bound=bound, relative=bound / norm, exact=exact,
                       nnls=nnls_err, nnls_relative=nnls_err / norm, optimum_lights=opt_sets,
                       seconds=time.perf_counter() - t0, nnls_exitance=e_nnls)


#: _Model.content -> the all-lights NNLS computed cold (the last ALL_LIGHTS_KEPT)
_ALL_LIGHTS = {}
ALL_LIGHTS_KEPT = 4


def _all_lights_nnls(model, nnls_start=None, halt=None) -> tuple:
    """(squared error per channel (3,), exitance (n, 3)): the all-lights NNLS optimum, from
    ``nnls_start``'s active lights where given (lower_bounds); computed once per content (a view
    target's problem: 0.28 s, asked three times by a solve; a Live stroke's quick answer, from the
    earlier answer's lights, and its later answer's full search on the same problem: 30-90 ms).
    ``halt``: lower_bounds'."""
    kept = _ALL_LIGHTS.get(model.content)
    if kept is None:
        kept = _all_lights_nnls_of(model, nnls_start, halt)
        _keep(_ALL_LIGHTS, ALL_LIGHTS_KEPT, model.content, kept)
    return kept[0].copy(), kept[1].copy()


def _all_lights_nnls_of(model, nnls_start, halt=None) -> tuple:
    cols = np.flatnonzero(model.usable)
    err2 = model.bb.copy()
    e_nnls = np.zeros((model.n, 3))
    warm = nnls_start is not None and np.shape(nnls_start) == (model.n, 3)
    if len(cols):
        for c in model.chans:
            A = model.T[c][:, cols]
            check_cancel(halt)
            if model.upper is not None:
                x = _bounded(A, model.b[:, c], model.upper[cols])
            elif warm or A.size >= WORKING_SET_SIZE:  # (from the earlier answer's lights, or from none)
                on = np.flatnonzero(np.asarray(nnls_start)[cols, c] > 0) if warm else []
                d = model.d[id(model.T[c])][cols]
                x = _nnls_from(A, model.b[:, c], on, model._kkt_tol(d, c))
            else:
                x = _nnls(A, model.b[:, c])
            e_nnls[cols, c] = x
            r = A @ x - model.b[:, c]
            err2[c] = float(r @ r)
    return err2, e_nnls


def _monotone_bounds(bound):
    """In place: the optimum with at most k lights is at least the optimum with at most k' > k."""
    for i in range(len(bound) - 2, -1, -1):
        if bound[i + 1] > bound[i]:
            bound[i] = bound[i + 1]


def curve_notes(curve, bounds, target_norm, gap=0.1, k=None):
    """User messages about a curve point (default: the last): how far from optimal, and whether
    the targets can be met at all with non-negative lights (from the certificate)."""
    if not curve:
        return ["no configuration"]
    pt = curve[-1] if k is None else next((p for p in curve if p.k == k), curve[-1])
    norm = target_norm if target_norm > 0 else 1.0
    lb = bounds.at(pt.k)
    notes = []
    exact = pt.k <= len(bounds.exact) and bool(bounds.exact[pt.k - 1])
    if bounds.nnls / norm > gap:
        notes.append(f"no non-negative lights meet these targets: the best any number of lights can do is a "
                     f"relative error of {bounds.nnls / norm:.3g} (NNLS on every candidate); "
                     f"{pt.n_lights} light(s) give {pt.relative_error:.3g}")
    if pt.relative_error <= 1e-9:
        notes.append(f"{pt.n_lights} light(s) meet the targets (relative error {pt.relative_error:.2g})")
    elif exact and pt.error <= (lb + BOUND_ROUNDING * norm) / (1 - BOUND_MARGIN) * (1 + 1e-6) + 1e-12 * norm:
        notes.append(f"{pt.n_lights} light(s): optimal (exhaustive search), relative error {pt.relative_error:.3g}")
    else:
        notes.append(f"{pt.n_lights} light(s): relative error {pt.relative_error:.3g}; no configuration of at most "
                     f"{pt.k} non-negative lights is below {lb / norm:.3g}"
                     f"{' (exact optimum)' if exact else ''}")
    return notes


# ---------------------------------------------------------------------------------------------
# tolerance mode (linear programming)
# ---------------------------------------------------------------------------------------------
@dataclass
class ToleranceResult:
    """Least total power within a tolerance band.

    status: 'ok' (every target channel within the band), 'partial' (every target channel that
    a light reaches is within the band, but some targets no light reaches stay dark; see
    ``unreachable``), 'infeasible' (no non-negative
    configuration is; ``exitance`` is then the least-power configuration at the smallest
    reachable tolerance ``reachable_tolerance``) or 'failed' (the LP solver failed; see
    message). exitance (n, 3) W/m^2 >= 0 on every light (zero when unused); lights: indices
    of the lights used (any channel above ``1e-9`` of the largest exitance); max_deviation:
    max over target channels of |T e - b| / band_scale (band_scale = b, or the zero-target
    band for b = 0); power (W) = sum_j A_j sum_c e_jc; error: Eq. 1 of that configuration
    (over every target). unreachable: target rows that no light reaches while painted above 0
    (occluded); they are left out of the band (their deviation is 100 % whatever the lights)
    and named in the message.
    """

    status: str
    message: str
    tolerance: float
    exitance: np.ndarray
    lights: np.ndarray
    n_lights: int
    power: float
    max_deviation: float
    error: float
    relative_error: float
    reachable_tolerance: float | None = None
    zero_band: float = 0.0
    unreachable: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    seconds: float = 0.0
    reachable_uniformity: float | None = None  # the uniformity goal could not be met: the largest that is


def _band_scale(b, zero_band):
    """Per target channel, what the tolerance multiplies: b, or zero_band where b = 0."""
    return np.where(b > 0, b, zero_band)


def _default_zero_band(b):
    pos = b[b > 0]
    return float(pos.mean()) if len(pos) else 0.0


def _unreachable(model):
    """(m, 3) bool: target channels no light reaches (a zero row of T) that are painted above 0."""
    scale = max(float(np.abs(t).max()) for t in model.T) if model.T[0].size else 0.0
    zero = np.stack([np.abs(t).max(axis=1) <= 1e-12 * max(scale, TINY) if t.shape[1] else
                     np.ones(t.shape[0], dtype=bool) for t in model.T], axis=1)
    return zero & (model.b > 0)


def _deviation(model, e, scale, rows=None):
    dev = np.abs(np.stack([model.T[c] @ e[:, c] for c in range(3)], axis=1) - model.b)
    if rows is not None:
        dev = np.where(rows, dev, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(scale > 0, dev / np.where(scale > 0, scale, 1.0),
                       np.where(dev > 1e-12 * max(model.norm, TINY), np.inf, 0.0))
    return float(rel.max()) if rel.size else 0.0


def _lp_bounds(model) -> list:
    """Each light's bounds (0, its upper bound or None) in the programmes."""
    if model.upper is None:
        return [(0, None)] * model.n
    return [(0.0, float(u) if np.isfinite(u) else None) for u in model.upper]


def _lp_options():
    return {"presolve": True, "primal_feasibility_tolerance": 1e-9, "dual_feasibility_tolerance": 1e-9}


def min_max_deviation(T, b, zero_band=None, skip_unreachable=True, upper=None):
    """The smallest tolerance x such that non-negative lights keep |T e - b| <= x * scale on every
    target channel (scale = b, or ``zero_band`` W/m^2 where b = 0; default the mean of the positive
    target values), and such an exitance (n, 3). One LP per channel (the channels decouple).
    ``skip_unreachable``: leave out the target channels no light reaches (their deviation is 1
    whatever the lights). ``upper`` (n,): each light's largest strength per channel (inf: none)."""
    model = _Model(T, b, None, upper)
    zb = _default_zero_band(model.b) if zero_band is None else float(zero_band)
    scale = _band_scale(model.b, zb)
    rows = ~_unreachable(model) if skip_unreachable else np.ones(model.b.shape, dtype=bool)
    n = model.n
    e = np.zeros((n, 3))
    xs = []
    for c in range(3):
        keep = rows[:, c]
        if not keep.any():
            xs.append(0.0)
            continue
        w = scale[keep, c]
        t = model.T[c][keep]
        # variables [e (n), x]; min x s.t. T e - x w <= b, -T e - x w <= -b, e >= 0, x >= 0
        A = np.block([[t, -w[:, None]], [-t, -w[:, None]]])
        ub = np.concatenate([model.b[keep, c], -model.b[keep, c]])
        cost = np.zeros(n + 1)
        cost[-1] = 1.0
        res = sopt.linprog(cost, A_ub=A, b_ub=ub, bounds=_lp_bounds(model) + [(0, None)], method="highs",
                           options=_lp_options())
        if res.status != 0:
            # unbounded deviation: a target with scale 0 that every light reaching it must keep dark
            raise ValueError(f"the min-max deviation LP failed on channel {c}: {res.message}")
        e[:, c] = np.maximum(res.x[:n], 0.0)
        xs.append(float(res.x[-1]))
    return max(xs), e


def _uniformity_rows(t, regions, u):
    """(A_ub, b_ub) of the uniformity goal ``u`` on one channel's programme: per region (rows of
    ``t``, their reflectance, fixed light's radiosity and area), every row's irradiance
    E_i = (t_i e + bg_i) / rho_i at least u x the region's area-weighted mean irradiance."""
    A, ub = [], []
    for idx, rho, bg, area in regions:
        ti = t[idx] / rho[:, None]
        w = area / area.sum()
        mean_row, mean_bg = w @ ti, float(w @ (bg / rho))
        A.append(-(ti - u * mean_row[None, :]))
        ub.append(bg / rho - u * mean_bg)
    return np.vstack(A), np.concatenate(ub)


#: the reachable uniformity is found to this (bisection)
UNIFORMITY_STEP = 1e-3


def least_power_within_tolerance(T, b, light_watts, tolerance, zero_band=None, uniformity=None, upper=None):
    """Least total power keeping every target within +-tolerance of its painted value (an LP).

    minimise  sum_j A_j sum_c e_jc   (W)
    s.t.      |T[c] e_c - b_c| <= tolerance * s_c   per target and channel,   e >= 0,
    with s = b (a relative band: tolerance 0.05 is +-5 %) where b > 0, and, where b = 0 (a
    target painted black in that channel), the absolute band s = ``zero_band`` W/m^2
    (default: the mean of the positive target values, so +-5 % of a typical target). Solved
    per channel (they decouple) with scipy.optimize.linprog(method='highs'). A basic
    solution uses at most 2 m lights per channel; nothing limits the number of lights.

    Target channels no light reaches (zero rows of T) are left out of the constraints and named
    in the message. When no non-negative configuration satisfies the band, the result has status
    'infeasible', a message naming the smallest reachable tolerance (the min-max deviation
    LP), and the least-power configuration at that tolerance.

    ``uniformity`` (u, [per channel: [(target rows, their reflectance, fixed light's radiosity,
    area), ...] per region]): the goal U0 = E_min / E_mean >= u on the irradiance of each region,
    each channel's (a sufficient condition for the illuminance's: a luminance is a positive
    combination of the channels), as constraints of the same programme. When it cannot be met
    within the band, the largest reachable u (bisection, to UNIFORMITY_STEP) is used and said
    (``reachable_uniformity``). ``upper`` (n,): each light's largest strength per channel (inf: none),
    bounds of the programme's variables. Returns a ToleranceResult.
    """
    t0 = time.perf_counter()
    model = _Model(T, b, light_watts, upper)
    tol = float(tolerance)
    if not (np.isfinite(tol) and tol >= 0):
        raise ValueError(f"tolerance must be a non-negative number, got {tolerance}")
    zb = _default_zero_band(model.b) if zero_band is None else float(zero_band)
    if not (np.isfinite(zb) and zb >= 0):
        raise ValueError(f"zero_band must be a non-negative number (W/m^2), got {zero_band}")
    n = model.n
    prog = _BandProgramme(model, _band_scale(model.b, zb), _unreachable(model), uniformity)
    e, status, reach, x_used = _within_band(prog, tol, zb)
    goal, reach_u = prog.goal, None
    if e is not None and goal:  # the uniformity goal within that band, else the largest that holds
        e, reach_u = _with_uniformity(prog, e, x_used)
    if e is None:
        return ToleranceResult(status="failed", message=status, tolerance=tol, exitance=np.zeros((n, 3)),
                               lights=np.zeros(0, dtype=np.int64), n_lights=0, power=0.0,
                               max_deviation=float("nan"), error=float("nan"), relative_error=float("nan"),
                               reachable_tolerance=reach, zero_band=zb,
                               unreachable=np.flatnonzero(prog.unreach.any(1)), seconds=time.perf_counter() - t0)
    emax = float(e.max()) if e.size else 0.0
    on = e.max(axis=1) > 1e-9 * max(emax, TINY)
    e = np.where(on[:, None], e, 0.0)
    power = total_power(e, model.area)
    dev = _deviation(model, e, prog.scale, prog.rows)
    err = float(np.linalg.norm(np.stack([model.T[c] @ e[:, c] for c in range(3)], axis=1) - model.b))
    rel = err / model.norm if model.norm > 0 else err
    bad = np.flatnonzero(prog.unreach.any(axis=1))  # target rows no light reaches (painted above 0)
    status, msg = _band_message(prog, status, tol, reach, int(on.sum()), power, dev, bad)
    msg += _uniformity_message(goal, reach_u, x_used)
    return ToleranceResult(status=status, message=msg, tolerance=tol, exitance=e, lights=np.flatnonzero(on),
                           n_lights=int(on.sum()), power=power, max_deviation=dev, error=err, relative_error=rel,
                           reachable_tolerance=reach, zero_band=zb, unreachable=bad,
                           seconds=time.perf_counter() - t0, reachable_uniformity=reach_u)


class _BandProgramme:
    """least_power_within_tolerance's linear programmes: the least power within a band ``x`` x
    ``scale`` of the targets the lights reach (``unreach``: (m, 3) those they do not), and the
    uniformity goal (u, regions) or None."""

    def __init__(self, model, scale, unreach, uniformity):
        self.model, self.scale, self.unreach = model, scale, unreach
        self.rows = ~unreach
        self.goal, self.regions = (None, None) if uniformity is None else uniformity

    def solve(self, x, u=None):
        """(exitance (n, 3), "ok"), or (None, "infeasible" or the solver's failure)."""
        model, rows, scale, regions = self.model, self.rows, self.scale, self.regions
        u = self.goal if u is None else u
        e = np.zeros((model.n, 3))
        for c in range(3):
            keep = rows[:, c]
            if not keep.any():
                continue
            t = model.T[c][keep]
            lo = model.b[keep, c] - x * scale[keep, c]
            hi = model.b[keep, c] + x * scale[keep, c]
            A = np.vstack([t, -t])
            ub = np.concatenate([hi, -lo])
            if u and regions and regions[c]:
                Au, bu = _uniformity_rows(model.T[c], regions[c], u)
                A, ub = np.vstack([A, Au]), np.concatenate([ub, bu])
            res = sopt.linprog(model.area, A_ub=A, b_ub=ub, bounds=_lp_bounds(model), method="highs",
                               options=_lp_options())
            if res.status == 2:
                return None, "infeasible"
            if res.status != 0:
                return None, f"the LP solver failed on channel {c}: {res.message}"
            e[:, c] = np.maximum(res.x, 0.0)
        return e, "ok"


def _within_band(prog, tol, zb) -> tuple:
    """(exitance or None, status, the reachable tolerance or None, the band used): the band
    alone at ``tol``; when no non-negative lights can, at the smallest reachable tolerance (the
    min-max deviation programme), status 'infeasible'."""
    model = prog.model
    e, status = prog.solve(tol, 0.0)  # the band alone
    reach = None
    x_used = tol
    if e is None and status == "infeasible":
        reach, _ = min_max_deviation(model.T, model.b, zb, upper=model.upper)
        x = max(reach * (1 + 1e-7), reach + 1e-9, tol)
        e, st2 = prog.solve(x, 0.0)
        if e is None:  # a hair more room for the LP's tolerances
            x = x * (1 + 1e-4) + 1e-7
            e, st2 = prog.solve(x, 0.0)
        x_used = x
        status = "infeasible" if e is not None else st2
    return e, status, reach, x_used


def _with_uniformity(prog, e, x_used) -> tuple:
    """(exitance, the reachable uniformity or None): the goal within the band ``x_used``, else
    the largest that holds (bisection to UNIFORMITY_STEP; ``e`` kept when none does)."""
    goal = prog.goal
    reach_u = None
    eg, _ = prog.solve(x_used, goal)
    if eg is not None:
        e = eg
    else:
        lo_u, hi_u = 0.0, float(goal)
        while hi_u - lo_u > UNIFORMITY_STEP:
            mid = 0.5 * (lo_u + hi_u)
            lo_u, hi_u = (mid, hi_u) if prog.solve(x_used, mid)[0] is not None else (lo_u, mid)
        reach_u = lo_u
        if reach_u > 0:
            got = prog.solve(x_used, reach_u)[0]
            e = got if got is not None else e
    return e, reach_u


def _uniformity_message(goal, reach_u, x_used) -> str:
    """The uniformity goal's part of least_power_within_tolerance's message ("" without a goal)."""
    if goal and reach_u is not None:
        return (f"; the uniformity U0 >= {goal:.3g} cannot be met within the band (±{100 * x_used:.3g} %): "
                f"U0 >= {reach_u:.3g} is reachable (and kept)")
    elif goal:
        return f"; uniformity U0 >= {goal:.3g} met (every channel's irradiance, each illuminance region)"
    return ""


def _band_message(prog, status, tol, reach, n_on, power, dev, bad) -> tuple:
    """(status, message) of least_power_within_tolerance's result."""
    unreach, rows, b = prog.unreach, prog.rows, prog.model.b
    if unreach.any() and not (rows & (b > 0)).any():
        status = "infeasible"
        msg = "no candidate light reaches any painted target: every light stays off"
    elif status == "ok":
        status = "partial" if len(bad) else "ok"
        msg = (f"every target {'a light reaches ' if len(bad) else ''}within \u00b1{100 * tol:.3g} %: "
               f"{n_on} light(s), {power:.4g} W (largest deviation {100 * dev:.3g} %)")
    else:
        msg = (f"no non-negative lights keep every target within \u00b1{100 * tol:.3g} %; the closest is "
               f"\u00b1{100 * reach:.3g} % ({n_on} light(s), {power:.4g} W at that tolerance)")
    if len(bad):
        msg += (f"; {len(bad)} target(s) no candidate light reaches are left out (always dark): target rows "
                f"{bad[:20].tolist()}{' ...' if len(bad) > 20 else ''}")
    return status, msg
