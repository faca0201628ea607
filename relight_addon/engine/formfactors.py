"""Form factors by ray casting (embreex).

``F[i, j]`` is the fraction of the power leaving patch i (a Lambertian
emitter) that arrives first at the FRONT side of patch j. It is estimated by
shooting ``rays_per_patch`` rays from each patch i: origins uniform over the
patch's area (a triangle is chosen with probability proportional to its area),
directions cosine-weighted about the triangle's normal, and counting the
fraction whose first hit is the front side of j. Patches are one-sided: a hit
on a back side is absorbed and counts for no patch; a ray that leaves the
scene counts for none either, so row sums are < 1 in open scenes and ~1 in
closed ones. A patch partly buried (inside a closed object, or behind a face coincident with it:
a wall where a slab runs into it, a flight's side against a wall) keeps its radiosity as its whole
area's mean, as a bake of the face shows it, but sends its light from its visible part only: its
column is divided by its visible share (``visible_fraction``: a point is buried when most of its
test rays reach back sides; a patch less visible than MIN_VISIBLE is left as it is). Without it
that light was lost (the staircase's walls and flights: 1.3 % of the rays in all, a patch up to
31 %). Every pair is then estimated from the rays of both its patches
(``reciprocity="weighted"``, the default; ``weigh_reciprocity``): the exchange
A_i F_ij = A_j F_ji weighted by the inverse variance of each side's count,
which favours the smaller patch (a small light cell seen by a large wall).

Sampling (``sampling=``):
- ``"sobol"`` (default): randomised quasi-Monte Carlo. The first N points of
  the 4-D Sobol sequence (2 dimensions for the position on the patch, 2 for
  the direction) are scrambled once (scipy's linear matrix scramble) and mapped
  once into a pool of copies (about POOL_RAYS rays' worth), each with its own
  random digital shift; the patches of a chunk use distinct copies, each patch turned about its normal by its own random angle. Both
  randomisations keep each patch's estimate unbiased and the point set
  stratified; reusing the mapped pool makes a ray cost two small matrix
  products (origin, direction) for patches of one triangle or two triangles
  of equal area (grid quads), and a per-ray triangle pick for other patches.
- ``"stratified"``: a jittered k x k grid for the position and another for the
  direction (concentric map), paired by a random permutation; the N - k^2
  leftover rays are uniform random.
- ``"random"``: independent uniform samples (plain Monte Carlo).
Directions map the unit square to the disk with Shirley's concentric map and
lift it to the hemisphere (Malley), which gives a cosine-weighted density.
See docs/benchmarks.md ("Form factors") for the measured error per ray of the
three samplers, with and without the reciprocity weighting.

Storage: ``FormFactors.matrix`` is a dense float32 ndarray (P, P) when
P <= ``DENSE_LIMIT`` (6000, 144 MB), else a float32 scipy.sparse CSR matrix.

Determinism: the Sobol pool is drawn from ``np.random.default_rng([seed, 1])``
and rays are generated in fixed chunks of patches, each with its own random
stream ``np.random.default_rng([seed, 0, chunk])``; the result is the same for
any thread count. Worker threads generate, trace (embree releases the GIL) and
count hits chunk by chunk, so ray generation of one chunk overlaps tracing of
another.

Kernel pairs: ``kernel_pairs=(receivers, sources)`` replaces those entries (and their
reciprocal ones) by the low-variance estimate of kernel_transfer.py (analytic
point-to-polygon kernel times shadow-ray visibility), for the transport that decides an
inverse solve: light cells to target patches. The rest of F stays ray cast.

Triangles, area tables, ray offset and the Embree scene are a SceneSampler's (sampling.py),
built once per call and shared with the kernel estimator.

Cancellation: ``cancel()`` returning True makes ``compute_form_factors`` raise
``sampling.Cancelled``.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401  (sp.linalg.norm)
from scipy.stats import qmc

from .kernel_transfer import _sample_patches, apply_kernel_pairs, kernel_form_factors, kernel_geometry
from .lamps import _tangents
from .rays import cosine_directions
from .sampling import SceneSampler, run_chunks
from .scene import PatchSet, SceneError

__all__ = [
    "QUALITY",
    "DENSE_LIMIT",
    "SAMPLINGS",
    "FormFactors",
    "compute_form_factors",
    "auto_rays_per_patch",
    "RAY_BUDGET",
    "KERNEL_RAY_BUDGET",
    "weigh_reciprocity",
]

#: rays per patch for each quality level; accuracy measured in docs/benchmarks.md
#: ("Form factors") and checked by tests/test_engine_formfactors.py.
QUALITY = {"draft": 1024, "default": 16384, "high": 262144}
#: total rays of the automatic quality: rays per patch = the power of two nearest to
#: RAY_BUDGET / patches, within [QUALITY["draft"], QUALITY["default"]]. Small scenes (a few
#: faces, e.g. the closed-form configurations) get the default 16384; the ~1500-patch
#: staircase gets 2048 (accuracy against rays per patch: docs/benchmarks.md).
RAY_BUDGET = 1 << 22
#: ... and with kernel pairs (compute_form_factors(kernel_pairs=...)), where the kernel estimate
#: replaces the light-to-target pairs that need the most rays and the hemisphere estimate serves
#: the rest of F (mostly the indirect light): half. The staircase's 943 adaptive patches then get
#: 2048 (measured against 4096: docs/benchmarks.md, "The staircase's mathematical phase").
KERNEL_RAY_BUDGET = RAY_BUDGET // 2
#: dense float32 matrix up to this many patches, scipy.sparse CSR above.
DENSE_LIMIT = 6000
#: ``visible_fraction``: stratified test points per patch and cosine-weighted rays per point
BURIED_POINTS = 36
BURIED_RAYS = 8
#: ... a patch less visible than this is left as it is (its visible share too uncertain to divide by)
MIN_VISIBLE = 0.5
#: ... a point is buried when at least this share of its rays reach back sides (not all: where the
#: enclosing object's face is coincident with another one, some rays hit that one's front)
BURIED_SHARE = 0.75
SAMPLINGS = ("sobol", "stratified", "random")
RECIPROCITY = ("weighted", "rays")
#: target number of rays per chunk (one chunk = a contiguous range of source patches, the unit
#: of work of a thread and of the random streams).
CHUNK_RAYS = 1 << 17
#: the Sobol point sets are pre-mapped for about this many rays (see _Tracer._sobol_pool).
POOL_RAYS = 1 << 17


@dataclass
class FormFactors:
    """Form factors of a PatchSet.

    ``matrix[i, j]``: fraction of the power leaving patch i that arrives at
    (the front of) patch j; float32, dense (P, P) ndarray when P <= DENSE_LIMIT,
    else scipy.sparse.csr_matrix.
    """

    matrix: object
    rays_per_patch: int
    n_rays: int
    seconds: float
    sampling: str = "sobol"
    reciprocity: str = "weighted"  # "weighted": weigh_reciprocity; "rays": each row from its own rays
    #: receiver x source pairs replaced by the kernel estimator (kernel_transfer.py), 0 if none
    kernel_pairs: int = 0
    #: (P,) each patch's visible share (``visible_fraction``; 1: nothing buried), None if not measured
    visible: object = None
    #: (P,) the factor each patch's column of F carries (``sending_scale``), None if not measured
    send: object = None
    #: the solve's SceneSampler (its one Embree scene), for the lamps' shadow rays (engine.lamps)
    sampler: object = field(default=None, repr=False, compare=False)
    #: (count, object indices) of the kernel's pairs left to the rays' estimate (non-finite: a
    #: receiver point on a source's edge), None when there is none
    kernel_unfit: object = None

    @property
    def n_patches(self) -> int:
        return self.matrix.shape[0]

    @property
    def emission_share(self):
        """(P,) the share of a patch's exitance that leaves it into the scene: its visible part
        where it is partly buried (1 / ``send``: F's columns carry the inverse, for the radiosity, a
        whole-area mean), None where nothing is buried or it was not measured."""
        if self.send is None or not np.any(np.asarray(self.send) != 1.0):
            return None
        return 1.0 / np.asarray(self.send, dtype=np.float64)

    @property
    def is_sparse(self) -> bool:
        return sp.issparse(self.matrix)

    def to_dense(self) -> np.ndarray:
        return self.matrix.toarray() if self.is_sparse else np.asarray(self.matrix)

    def row_sums(self) -> np.ndarray:
        """Per-patch sum_j F_ij (float64): ~1 in a closed scene, < 1 if rays escape."""
        return np.asarray(self.matrix.sum(axis=1, dtype=np.float64)).reshape(-1)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """F @ x for x of shape (P,) or (P, k), in float64."""
        return self.matrix @ np.asarray(x, dtype=np.float64)

    def reciprocity_error(self, area: np.ndarray, kind: str = "rms", threshold: float = 1e-3) -> float:
        """How far A_i F_ij is from A_j F_ji.

        With G = diag(area) F (the power-exchange matrix, symmetric for exact
        form factors):
        - ``kind="rms"``: ||G - G^T||_F / (sqrt(2) ||G||_F), the power-weighted RMS
          relative error of an entry (about the relative noise of one F_ij).
        - ``kind="max"``: max |G_ij - G_ji| / ((G_ij + G_ji) / 2) over the pairs
          whose smaller entry is at least ``threshold`` * max(G).
        """
        area = np.asarray(area, dtype=np.float64).reshape(-1)
        if len(area) != self.n_patches:
            raise ValueError(f"area has {len(area)} entries for {self.n_patches} patches")
        if kind not in ("rms", "max"):
            raise ValueError(f"unknown reciprocity error kind {kind!r}; use 'rms' or 'max'")
        if self.is_sparse:
            G = (sp.diags(area) @ self.matrix.astype(np.float64)).tocsr()
            GT = G.T.tocsr()
            if kind == "rms":
                gnorm = sp.linalg.norm(G)
                return float(sp.linalg.norm(G - GT) / (np.sqrt(2) * gnorm)) if gnorm > 0 else 0.0
            Gm = G.minimum(GT).tocoo()
            keep = Gm.data >= threshold * G.max()
            r, c = Gm.row[keep], Gm.col[keep]
            a = np.asarray(G[r, c]).reshape(-1)
            b = np.asarray(GT[r, c]).reshape(-1)
        else:
            G = area[:, None] * np.asarray(self.matrix, dtype=np.float64)
            if kind == "rms":
                gnorm = np.linalg.norm(G)
                return float(np.linalg.norm(G - G.T) / (np.sqrt(2) * gnorm)) if gnorm > 0 else 0.0
            keep = np.minimum(G, G.T) >= threshold * G.max()
            a, b = G[keep], G.T[keep]
        if len(a) == 0:
            return 0.0
        return float(np.max(np.abs(a - b) / (0.5 * (a + b))))


def weigh_reciprocity(matrix, area, rays_per_patch: int, passes=None):
    """Every pair's form factors from the rays of both of its patches.

    ``passes`` (P,) bool: the patches light passes through (work planes): no other patch's ray
    counts a hit on them, so the pair's second estimate is not there: their rows keep their own
    rays (combined with the zeros of the others' rows they were about 6 % low: CIE 171's area
    source over a work plane, tests/test_cie171.py), and the others are weighed among themselves.

    The power the pair exchanges, G_ij = A_i F_ij = A_j F_ji, is counted twice: by the rays of
    i (hits on j) and by the rays of j (hits on i). With N rays per patch, a count of F N hits
    has variance about F N, so the estimate from patch i has variance about A_i G / N: the
    smaller patch measures the exchange better. The two are combined by inverse variance,
    G = (F_ij + F_ji) / (1 / A_i + 1 / A_j), i.e. ``F_ij <- (F_ij + F_ji) A_j / (A_i + A_j)``
    (variance G / N * A_i A_j / (A_i + A_j): below either one; for equal areas the plain mean).

    Row sums: the rays' own row sum (the share of i's rays that reach a front face; exact, 1,
    in a closed scene) and the combined one are blended by their variances (R (1 - R) / N and
    sum_j F_ij A_j / (A_i + A_j) / N), capped at 1, and each row is scaled to that: no energy
    is created, and a closed scene keeps its row sums of 1 (to float32 rounding, never above:
    within 1.2e-7 below). Reciprocity then holds up to that scale (about 1 +- the row sum's
    noise).
    Dense (float32, by blocks of rows) or scipy.sparse CSR in, the same kind out.
    """
    a = np.asarray(area, dtype=np.float64)
    if passes is not None and np.any(passes):
        return _weigh_around(matrix, a, rays_per_patch, np.asarray(passes, dtype=bool))
    N = float(rays_per_patch)
    if sp.issparse(matrix):
        M = matrix.tocsr().astype(np.float32)
        raw = np.asarray(M.sum(axis=1), dtype=np.float64).ravel()
        S = (M + M.T).tocsr()
        rows = np.repeat(np.arange(S.shape[0]), np.diff(S.indptr))
        w = a[S.indices] / (a[rows] + a[S.indices])
        S.data = (S.data * w).astype(np.float32)
        comb = np.bincount(rows, weights=S.data, minlength=S.shape[0])
        var_comb = np.bincount(rows, weights=S.data * w, minlength=S.shape[0]) / N
        scale, target = _row_scale(raw, comb, var_comb, N)
        S.data = (S.data * scale[rows]).astype(np.float32)
        over = _over(np.bincount(rows, weights=S.data, minlength=S.shape[0]), target)
        S.data *= over[rows]
        return S
    M = np.asarray(matrix, dtype=np.float32)
    P = M.shape[0]
    raw = M.sum(axis=1, dtype=np.float64)
    out = np.empty_like(M)
    var_comb = np.empty(P)
    for r0 in range(0, P, 512):
        r1 = min(P, r0 + 512)
        w = (a[None, :] / (a[r0:r1, None] + a[None, :])).astype(np.float32)
        blk = np.add(M[r0:r1], M[:, r0:r1].T, out=out[r0:r1])
        blk *= w
        var_comb[r0:r1] = (blk * w).sum(axis=1, dtype=np.float64) / N
    comb = out.sum(axis=1, dtype=np.float64)
    scale, target = _row_scale(raw, comb, var_comb, N)
    out *= scale.astype(np.float32)[:, None]
    out *= _over(out.sum(axis=1, dtype=np.float64), target)[:, None]
    return out


def _weigh_around(matrix, area, rays_per_patch, passes):
    """weigh_reciprocity of the patches light does not pass through, among themselves; the rows of
    those it passes through as their rays counted them (their columns are zero: no ray sees them)."""
    keep = np.flatnonzero(~passes)
    if sp.issparse(matrix):
        M = matrix.tocsr().astype(np.float32)
        W = weigh_reciprocity(M[keep][:, keep], area[keep], rays_per_patch).tocoo()
        R = M[np.flatnonzero(passes)].tocoo()
        through = np.flatnonzero(passes)
        rows = np.concatenate([keep[W.row], through[R.row]])
        cols = np.concatenate([keep[W.col], R.col])
        data = np.concatenate([W.data, R.data]).astype(np.float32)
        return sp.csr_matrix((data, (rows, cols)), shape=M.shape, dtype=np.float32)
    out = np.array(matrix, dtype=np.float32)
    out[np.ix_(keep, keep)] = weigh_reciprocity(out[np.ix_(keep, keep)], area[keep], rays_per_patch)
    return out


def _row_scale(raw, comb, var_comb, N):
    """Per row: the blended row sum (see weigh_reciprocity) over the combined one, and that sum."""
    var_raw = np.clip(raw * (1 - raw), 0.0, None) / N
    total = var_raw + var_comb
    target = np.where(total > 0, (raw * var_comb + comb * var_raw) / np.where(total > 0, total, 1.0), raw)
    target = np.minimum(target, 1.0)
    return np.where(comb > 0, target / np.where(comb > 0, comb, 1.0), 0.0), target


def _over(sums, target):
    """float32 factors that bring rows whose float32 entries sum above their target just below it
    (a row sum above 1 would create energy where the reflectance is 1); 1 elsewhere."""
    over = sums > target
    f = np.ones(len(sums))
    f[over] = target[over] / sums[over] * (1 - 2.0**-23)
    return f.astype(np.float32)


class _Tracer:
    """Per-patch hemisphere sampling data for a PatchSet, on a SceneSampler's triangles and
    Embree scene (``sampler``: built here when not given; internal: the benchmark uses it to
    time raw embreex on the very same rays)."""

    def __init__(self, patches: PatchSet, rays_per_patch: int, seed: int, sampling: str,
                 sampler: SceneSampler | None = None):
        self.sampler = sm = SceneSampler(patches) if sampler is None else sampler
        if sm.n_patches != patches.n_patches:
            raise ValueError(f"the sampler has {sm.n_patches} patches, the patch set {patches.n_patches}")
        P = patches.n_patches
        self.P = P
        self.N = N = int(rays_per_patch)
        self.seed = int(seed)
        self.sampling = sampling

        # the sampler's triangles (sorted by patch), area tables and offset
        self.tri_patch = sm.tri_patch
        ta, n, pa, start = sm.ta, sm.tn, sm.area, sm.tstart
        # per triangle a tangent frame (t, b, n)
        ok = ta > 0
        t = np.zeros_like(sm.e1)
        el = np.linalg.norm(sm.e1, axis=1)
        t[ok] = sm.e1[ok] / el[ok, None]
        b = np.cross(n, t)
        self.key = sm.key
        self.cdf_lo32 = sm.cdf_lo.astype(np.float32)
        self.cdf_w32 = np.maximum(sm.cdf_hi - sm.cdf_lo, 1e-30).astype(np.float32)
        self.offset = sm.offset
        # origins on the shrunk triangles (see SceneSampler), moved off the surface by the offset
        e1, e2 = sm.s_e1, sm.s_e2
        base = sm.s_v0 + self.offset * n

        # per triangle, component-major (18, T): origin base (v0 + offset n), e1, e2, t, b, n
        self.geo = np.ascontiguousarray(np.concatenate([base.T, e1.T, e2.T, t.T, b.T, n.T]), dtype=np.float32)

        # Fast path (two matrix products per patch) for patches of one triangle, or of two
        # triangles of equal area, when N is a power of two. The Sobol points are sorted
        # by u0, so the first N/2 have u0 < 1/2 and the last N/2 u0 >= 1/2 (a (t, m, 4)-net
        # in base 2): for two equal triangles the halves go to the first and second
        # triangle, exactly as the per-ray path's pick by area would send them.
        # Rows of patch p, half h: origin = (1, b1, b2) @ pos[p, h], direction = local @ frame[p, h].
        ntri = np.bincount(self.tri_patch, minlength=P)
        kind = np.full(P, 2, dtype=np.int8)  # 0 one triangle, 1 two equal triangles, 2 per-ray path
        if N >= 2 and N & (N - 1) == 0:
            kind[ntri == 1] = 0
            two = np.flatnonzero(ntri == 2)
            kind[two[np.abs(ta[start[two]] - ta[start[two] + 1]) <= 1e-9 * pa[two]]] = 1
        second = np.where(kind == 1, start + 1, start)
        tri2 = np.stack([start, second], axis=1)  # (P, 2) triangle of each half
        self.kind = kind
        self.pos2 = np.stack([base[tri2], e1[tri2], e2[tri2]], axis=2).astype(np.float32)  # (P, 2, 3, 3)
        self.frame2 = np.stack([t[tri2], b[tri2], n[tri2]], axis=2)  # (P, 2, 3, 3) rows t, b, n

        # chunks: contiguous patch ranges of ~CHUNK_RAYS rays
        per = max(1, CHUNK_RAYS // N)
        self.chunks = [(p0, min(P, p0 + per)) for p0 in range(0, P, per)]
        if sampling == "sobol":
            self._sobol_pool(per)

    def _sobol_pool(self, per):
        """R randomised copies of the first N points of the 4-D Sobol sequence (one
        linear matrix scramble, scipy's ``qmc.Sobol(scramble=True)``, then an independent
        random digital shift per copy), each sorted by u0 and already mapped: position coefficients (1, b1, b2)
        for one triangle (s = u0) and for two equal triangles (s = 2 u0 mod 1), and the
        cosine-weighted local direction. Each patch of a chunk uses its own copy,
        turned about its normal by its own random angle."""
        N = self.N
        m = int(np.ceil(np.log2(N))) if N > 1 else 0
        R = max(per, min(self.P, max(1, POOL_RAYS // N)))
        rng = np.random.default_rng([self.seed, 1])
        base = qmc.Sobol(d=4, scramble=True, bits=32, seed=rng).random_base2(m)[:N]
        base = (base * 2.0**32).astype(np.uint64).astype(np.uint32)  # exact: 32-bit points
        # a base-2 net: exactly half of the points have u0 < 1/2; put those first
        base = base[np.argsort(base[:, 0] >> np.uint32(31), kind="stable")]
        shift = rng.integers(0, 2**32, size=(R, 1, 4), dtype=np.uint32)
        u = ((base[None] ^ shift) >> np.uint32(8)).astype(np.float32)  # 24 bits: exact in float32
        u *= np.float32(2.0**-24)
        u += np.float32(2.0**-25)  # cell midpoints, strictly inside (0, 1)
        flip = np.flatnonzero(shift[:, 0, 0] >> np.uint32(31))  # the shift swapped the halves
        u[flip] = np.roll(u[flip], N // 2, axis=1)
        u = u.reshape(-1, 4)
        self.pool_u = u[:, :2].reshape(R, N, 2)

        def coef(s):
            su = np.sqrt(s)
            b2 = su * u[:, 1]
            return np.stack([np.ones_like(su), su - b2, b2], axis=1).reshape(R, 2, N // 2 if N > 1 else 1, 3)

        if N >= 2 and N & (N - 1) == 0:
            self.pool_tri = coef(u[:, 0])
            self.pool_half = coef(np.clip(2 * u[:, 0] - (u[:, 0] >= 0.5), 0.0, 1.0))
        self.pool_dir = cosine_directions(u[:, 2], u[:, 3]).reshape(R, N, 3)
        self.R = R

    def unit_samples(self, ci: int, rng) -> np.ndarray:
        """(n_patches_in_chunk * N, 4) float32 samples in (0, 1) for chunk ci ("random", "stratified")."""
        p0, p1 = self.chunks[ci]
        k, N = p1 - p0, self.N
        if self.sampling == "random":
            return rng.random((k * N, 4), dtype=np.float32)
        # stratified: jittered g x g grids for position and direction, randomly paired
        g = int(np.sqrt(N))
        u = rng.random((k, N, 4))
        if g >= 2:
            ii, jj = np.divmod(np.arange(g * g), g)
            u[:, : g * g, 0] = (ii + u[:, : g * g, 0]) / g
            u[:, : g * g, 1] = (jj + u[:, : g * g, 1]) / g
            perm = np.argsort(rng.random((k, g * g)), axis=1)
            u[:, : g * g, 2] = (ii[perm] + u[:, : g * g, 2]) / g
            u[:, : g * g, 3] = (jj[perm] + u[:, : g * g, 3]) / g
        return np.clip(u, 2.0**-25, 1 - 2.0**-24).astype(np.float32).reshape(-1, 4)

    def _general(self, src, u0, u1, dloc, org, d):
        """Per-ray path (any patch): pick a triangle by area, a uniform point in it,
        and turn the local direction dloc (n, 3) into the triangle's frame."""
        tri = np.searchsorted(self.key, src + u0.astype(np.float64), side="right")
        np.minimum(tri, len(self.key) - 1, out=tri)
        lo = np.take(self.cdf_lo32, tri)
        s = np.clip((u0 - lo) / np.take(self.cdf_w32, tri), 0.0, 1.0)
        g = np.take(self.geo, tri, axis=1)  # (18, n): origin base, e1, e2, t, b, n
        su = np.sqrt(s)
        b2 = u1 * su
        b1 = su - b2
        ot = org.T
        np.multiply(g[3:6], b1, out=ot)
        ot += g[0:3]
        ot += g[6:9] * b2
        dt = d.T
        np.multiply(g[9:12], dloc[:, 0], out=dt)
        dt += g[12:15] * dloc[:, 1]
        dt += g[15:18] * dloc[:, 2]

    def rays(self, ci: int):
        """Origins (n,3) f32, directions (n,3) f32 and source patch (n,) of chunk ci
        (rays of patch p0 + j are rows j*N .. (j+1)*N - 1)."""
        p0, p1 = self.chunks[ci]
        k, N = p1 - p0, self.N
        rng = np.random.default_rng([self.seed, 0, ci])
        org = np.empty((k, N, 3), dtype=np.float32)
        d = np.empty((k, N, 3), dtype=np.float32)
        if self.sampling != "sobol":
            u = self.unit_samples(ci, rng)
            src = np.repeat(np.arange(p0, p1), N)
            self._general(src, u[:, 0], u[:, 1], cosine_directions(u[:, 2], u[:, 3]),
                          org.reshape(-1, 3), d.reshape(-1, 3))
            return org.reshape(-1, 3), d.reshape(-1, 3), src
        # Sobol: patch p0 + j uses pool copy off + j and a random turn about its normal
        off = int(rng.integers(0, self.R - k + 1))
        ang = rng.random(k) * (2 * np.pi)
        c, s = np.cos(ang), np.sin(ang)
        kind = self.kind[p0:p1]
        fast = np.flatnonzero(kind < 2)
        if len(fast):
            h = N // 2
            fr = self.frame2[p0:p1]  # (k, 2, 3, 3)
            cc, ss = c[:, None, None], s[:, None, None]
            frame = np.stack([cc * fr[:, :, 0] + ss * fr[:, :, 1], cc * fr[:, :, 1] - ss * fr[:, :, 0], fr[:, :, 2]],
                             axis=2).astype(np.float32)
            pdir = self.pool_dir[off: off + k].reshape(k, 2, h, 3)
            ptri, phalf = self.pool_tri[off: off + k], self.pool_half[off: off + k]
            if kind.max() == 0:
                coef = ptri
            elif kind.min() == 1:
                coef = phalf
            else:
                coef = np.where((kind == 1)[:, None, None, None], phalf, ptri)
            np.matmul(coef, self.pos2[p0:p1], out=org.reshape(k, 2, h, 3))
            np.matmul(pdir, frame, out=d.reshape(k, 2, h, 3))
        gen = np.flatnonzero(kind == 2)
        if len(gen):
            src = np.repeat(gen + p0, N)
            u = self.pool_u[off + gen].reshape(-1, 2)
            # local directions turned by the patch's angle; the per-ray path uses each triangle's frame
            dl = self.pool_dir[off + gen]
            cg, sg = c[gen, None].astype(np.float32), s[gen, None].astype(np.float32)
            dloc = np.empty_like(dl)
            dloc[..., 0] = cg * dl[..., 0] - sg * dl[..., 1]
            dloc[..., 1] = sg * dl[..., 0] + cg * dl[..., 1]
            dloc[..., 2] = dl[..., 2]
            og = np.empty((len(src), 3), dtype=np.float32)
            dg = np.empty((len(src), 3), dtype=np.float32)
            self._general(src, u[:, 0], u[:, 1], dloc.reshape(-1, 3), og, dg)
            org[gen] = og.reshape(-1, N, 3)
            d[gen] = dg.reshape(-1, N, 3)
        return org.reshape(-1, 3), d.reshape(-1, 3), None

    def trace(self, org, d) -> np.ndarray:
        return self.sampler.first_hit(org, d)

    def keys(self, ci: int) -> np.ndarray:
        """Trace chunk ci: per ray j * (P + 1) + receiving patch, for a ray of patch
        p0 + j; the receiver is P for a miss or a hit on a back side."""
        p0, p1 = self.chunks[ci]
        k, N, P = p1 - p0, self.N, self.P
        org, d, _ = self.rays(ci)
        dst = self.sampler.front_hit_patches(org, d)
        key = np.arange(0, k * (P + 1), P + 1).repeat(N)
        key += dst
        return key


def visible_fraction(patches: PatchSet, sampler: SceneSampler, seed: int = 0, points: int = BURIED_POINTS,
                     rays: int = BURIED_RAYS) -> np.ndarray:
    """(P,) the share of each patch's area that is not buried: of ``points`` stratified points
    (kernel_transfer._sample_patches), those from which BURIED_SHARE of ``rays`` cosine-weighted
    rays reach a back side are buried: they lie inside a closed object, or under a face coincident
    with the patch. A point under an open face (a card's back over a floor) is not, unless the card
    covers most of its hemisphere (a card that low is a slab to the light too). Deterministic for
    a seed."""
    P = patches.n_patches
    out = np.ones(P)
    g = kernel_geometry(patches, points, sampler)
    rng = np.random.default_rng([int(seed), 11])
    step = max(1, (1 << 18) // (points * rays))
    for p0 in range(0, P, step):
        s = np.arange(p0, min(P, p0 + step))
        y, ny = _sample_patches(g, s, points, rng)
        y = np.asarray(y, dtype=np.float64).reshape(-1, 3)
        ny = np.asarray(ny, dtype=np.float64).reshape(-1, 3)
        t1, t2 = _tangents(ny)
        u = rng.random((len(y), rays, 2))
        loc = cosine_directions(u[..., 0].ravel(), u[..., 1].ravel()).reshape(len(y), rays, 3).astype(np.float64)
        d = loc[..., 0:1] * t1[:, None] + loc[..., 1:2] * t2[:, None] + loc[..., 2:3] * ny[:, None]
        org = np.repeat(y + sampler.offset * ny, rays, axis=0).astype(np.float32)
        d = d.reshape(-1, 3).astype(np.float32)
        prim = np.asarray(sampler.first_hit(org, d))
        back = (prim >= 0) & (np.einsum("ij,ij->i", sampler.tn[np.maximum(prim, 0)], d) >= 0)
        buried = back.reshape(len(s), points, rays).mean(axis=2) >= BURIED_SHARE
        out[s] = 1.0 - buried.mean(axis=1)
    return out


def sending_scale(visible) -> np.ndarray:
    """(P,) the factor a patch's column of F carries: 1 / its visible share where it is partly
    buried (from MIN_VISIBLE up), 1 elsewhere."""
    v = np.asarray(visible, dtype=np.float64)
    part = (v >= MIN_VISIBLE) & (v < 1)
    return np.where(part, 1.0 / np.where(part, v, 1.0), 1.0)


def auto_rays_per_patch(n_patches: int, kernel: bool = False) -> int:
    """Rays per patch of the automatic quality (see RAY_BUDGET; KERNEL_RAY_BUDGET with kernel pairs)."""
    want = (KERNEL_RAY_BUDGET if kernel else RAY_BUDGET) / max(int(n_patches), 1)
    k = int(np.rint(np.log2(want)))
    return int(np.clip(2 ** k, QUALITY["draft"], QUALITY["default"]))


def pairs_then_sending_scale(matrix, area, send, rec=None, src=None, K=None, unscale=False):
    """The ray-cast ``matrix`` (float32, dense or CSR) with the kernel's pairs ``K`` (receivers
    ``rec`` x sources ``src``, kernel_transfer.apply_kernel_pairs; none when K is None), then every
    column scaled by the sending scale ``send`` of partly buried patches (a patch sends its light
    from its visible part: the module docstring), as compute_form_factors builds F. ``unscale``:
    ``matrix`` is a built F, its sending scale taken out first (pipeline.prepared adds a stroke's
    kernel rows to the prepared F this way)."""
    send = np.ones(matrix.shape[0]) if send is None else np.asarray(send, dtype=np.float64)
    dense = isinstance(matrix, np.ndarray)
    part = np.flatnonzero(send != 1.0)
    if unscale and len(part):
        inv = np.where(send > 0, 1.0 / np.where(send > 0, send, 1.0), 1.0)
        matrix = matrix.astype(np.float64) * inv[None, :] if dense else (matrix @ sp.diags(inv)).tocsr()
    elif K is not None and dense:
        matrix = matrix.copy() if unscale else matrix
    if K is not None:
        matrix = apply_kernel_pairs(matrix, area, rec, src, K)
    if len(part):
        if dense:
            matrix = np.asarray(matrix, dtype=np.float32) if matrix.dtype != np.float32 else matrix
            matrix[:, part] *= send[part].astype(np.float32)
        else:
            matrix = (matrix @ sp.diags(send.astype(np.float32))).tocsr()
    return matrix.astype(np.float32) if matrix.dtype != np.float32 else matrix


def compute_form_factors(
    patches: PatchSet,
    rays_per_patch: int | str | None = None,
    seed: int = 0,
    threads: int | None = None,
    progress=None,
    cancel=None,
    sampling: str = "sobol",
    reciprocity: str = "weighted",
    dense_limit: int = DENSE_LIMIT,
    kernel_pairs=None,
    kernel_options: dict | None = None,
) -> FormFactors:
    """Ray-cast form factors of ``patches`` (see the module docstring).

    ``rays_per_patch``: rays shot from every patch, a ``QUALITY`` name, or None for the
    automatic quality (``auto_rays_per_patch``: a budget of RAY_BUDGET rays in all, or
    KERNEL_RAY_BUDGET with ``kernel_pairs``).
    ``seed``: results are reproducible for a seed, whatever ``threads``.
    ``threads``: worker threads (default ``os.cpu_count()``).
    ``progress(fraction)``: optional callback, called from the calling thread.
    ``cancel()``: optional; returning True aborts with ``sampling.Cancelled``.
    ``reciprocity``: "weighted" (default) combines the rays of both patches of every pair
    (``weigh_reciprocity``); "rays": every row from its own patch's rays only.
    ``kernel_pairs=(receivers, sources)``: patch indices or masks; F[receivers, sources]
    and, by reciprocity, F[sources, receivers] are then replaced by the low-variance
    kernel estimate of kernel_transfer.kernel_form_factors (``kernel_options``: its
    keyword arguments; seed and threads are this call's), after any symmetrisation.
    Progress then runs to 0.5 for the rays and to 1 for the kernel pairs.
    """
    t0 = time.perf_counter()
    rays_per_patch, threads = _checked_options(patches, rays_per_patch, sampling, reciprocity, threads,
                                               kernel=kernel_pairs is not None)
    # one sampler (triangles, area tables, Embree scene) for the rays and the kernel pairs
    sampler = SceneSampler(patches)
    tr = _Tracer(patches, int(rays_per_patch), seed, sampling, sampler=sampler)
    P, N = tr.P, tr.N
    dense = P <= dense_limit
    ray_progress = (lambda f: progress(0.5 * f)) if kernel_pairs is not None and progress is not None else progress
    matrix = _ray_counts(tr, dense, threads, cancel, ray_progress)
    visible = visible_fraction(patches, sampler, seed)
    if reciprocity == "weighted":
        matrix = weigh_reciprocity(matrix, patches.area, N, passes=patches.passes)
    n_kernel = 0
    rec = src = K = unfit = None
    if kernel_pairs is not None:
        rec, src = kernel_pairs
        K = kernel_form_factors(patches, rec, src, seed=seed, threads=threads, cancel=cancel, sampler=sampler,
                                progress=None if progress is None else (lambda f: progress(0.5 + 0.5 * f)),
                                **(kernel_options or {}))
        n_kernel = K.size
        K, unfit = _finite_kernel(K, matrix, patches, rec, src)
    send = sending_scale(visible)
    matrix = pairs_then_sending_scale(matrix, patches.area, send, rec, src, K)
    if not np.all(np.isfinite(matrix if dense else matrix.data)):
        raise SceneError("form factors contain NaN or infinite values (degenerate geometry?)")
    return FormFactors(matrix=matrix, rays_per_patch=N, n_rays=N * P + P * BURIED_POINTS * BURIED_RAYS,
                       seconds=time.perf_counter() - t0, sampling=sampling, reciprocity=reciprocity,
                       kernel_pairs=int(n_kernel), visible=visible, send=send, sampler=sampler, kernel_unfit=unfit)


def _checked_options(patches, rays_per_patch, sampling, reciprocity, threads, kernel: bool) -> tuple:
    """compute_form_factors' options checked (ValueError naming the wrong one): (rays per patch,
    threads), the automatic quality and os.cpu_count() in place of None."""
    if rays_per_patch is None:
        rays_per_patch = auto_rays_per_patch(patches.n_patches, kernel=kernel)
    if isinstance(rays_per_patch, str):
        if rays_per_patch not in QUALITY:
            raise ValueError(f"unknown quality {rays_per_patch!r}; use one of {sorted(QUALITY)}")
        rays_per_patch = QUALITY[rays_per_patch]
    if not (isinstance(rays_per_patch, (int, np.integer)) and rays_per_patch >= 1):
        raise ValueError(f"rays per patch must be a positive integer, got {rays_per_patch!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"unknown sampling {sampling!r}; use one of {SAMPLINGS}")
    if reciprocity not in RECIPROCITY:
        raise ValueError(f"unknown reciprocity {reciprocity!r}; use one of {RECIPROCITY}")
    if threads is None:
        threads = os.cpu_count() or 1
    if not (isinstance(threads, (int, np.integer)) and threads >= 1):
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return rays_per_patch, threads


def _ray_counts(tr: "_Tracer", dense: bool, threads, cancel, progress):
    """F from the rays alone: each patch's hits per patch / its rays, float32, (P, P) dense or
    CSR; traced by chunks of patches (sampling.run_chunks)."""
    P, N = tr.P, tr.N
    M = np.zeros((P, P), dtype=np.float32) if dense else None
    blocks = [None] * len(tr.chunks)
    stop = threading.Event()
    inv_n = 1.0 / N

    def work(ci):
        if stop.is_set():
            return ci
        key = tr.keys(ci)
        p0, p1 = tr.chunks[ci]
        k = p1 - p0
        if dense:
            counts = np.bincount(key, minlength=k * (P + 1)).reshape(k, P + 1)[:, :P]
            np.multiply(counts, inv_n, out=M[p0:p1], casting="unsafe")
        else:
            key, cnt = np.unique(key, return_counts=True)
            row, col = np.divmod(key, P + 1)
            keep = col < P
            blocks[ci] = sp.csr_matrix(((cnt[keep] * inv_n).astype(np.float32), (row[keep], col[keep])), shape=(k, P))
        return ci

    run_chunks(work, len(tr.chunks), threads, stop, cancel, progress)
    return M if dense else sp.vstack(blocks, format="csr").astype(np.float32)


def _finite_kernel(K, matrix, patches, rec, src):
    """The kernel's pairs (receivers ``rec`` x sources ``src``) with any non-finite value (a
    receiver point on a source's edge or inside it: coincident or degenerate faces, collision
    helpers laid over a mesh) left to the rays' estimate; (K, None or (their count, their objects))."""
    bad = ~np.isfinite(K)
    if not bad.any():
        return K, None
    rec = np.flatnonzero(rec) if np.asarray(rec).dtype == bool else np.asarray(rec, dtype=np.int64)
    src = np.flatnonzero(src) if np.asarray(src).dtype == bool else np.asarray(src, dtype=np.int64)
    i, j = np.nonzero(bad)
    rays = matrix[rec[i], src[j]]
    K = K.copy()
    K[i, j] = np.asarray(rays, dtype=np.float64).reshape(-1)
    return K, (int(bad.sum()), np.unique(np.concatenate([patches.object[rec[i]], patches.object[src[j]]])))
