"""Form factors by ray casting (embreex).

``F[i, j]`` is the fraction of the power leaving patch i (a Lambertian
emitter) that arrives first at the FRONT side of patch j. It is estimated by
shooting ``rays_per_patch`` rays from each patch i: origins uniform over the
patch's area (a triangle is chosen with probability proportional to its area),
directions cosine-weighted about the triangle's normal, and counting the
fraction whose first hit is the front side of j. Patches are one-sided: a hit
on a back side is absorbed and counts for no patch; a ray that leaves the
scene counts for none either, so row sums are < 1 in open scenes and ~1 in
closed ones.

Sampling (``sampling=``):
- ``"sobol"`` (default): per patch, the first N points of a 4-D Sobol
  sequence with a random digital shift (XOR) drawn per patch -- an unbiased
  randomised quasi-Monte Carlo rule, stratified jointly in the 4 dimensions
  (2 for the position on the patch, 2 for the direction).
- ``"stratified"``: a jittered k x k grid for the position and another for the
  direction (concentric map), paired by a random permutation; the N - k^2
  leftover rays are uniform random.
- ``"random"``: independent uniform samples (plain Monte Carlo).
Directions map the unit square to the disk with Shirley's concentric map and
lift it to the hemisphere (Malley), which gives a cosine-weighted density.
See docs/benchmarks.md ("Form factors") for the measured error per ray of the
three samplers, with and without reciprocity symmetrisation.

Storage: ``FormFactors.matrix`` is a dense float32 ndarray (P, P) when
P <= ``DENSE_LIMIT`` (6000, 144 MB), else a float32 scipy.sparse CSR matrix.

Determinism: rays are generated in fixed chunks of patches, each with its own
random stream ``np.random.default_rng([seed, chunk])``; the result is the
same for any thread count.

Cancellation: ``cancel()`` returning True makes ``compute_form_factors`` raise
:class:`Cancelled` (defined here).
"""
from __future__ import annotations

import os
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg  # noqa: F401  (sp.linalg.norm)
from scipy.stats import qmc

from .scene import PatchSet, SceneError

__all__ = [
    "QUALITY",
    "DEFAULT_RAYS_PER_PATCH",
    "DENSE_LIMIT",
    "SAMPLINGS",
    "Cancelled",
    "FormFactors",
    "compute_form_factors",
    "symmetrise",
]

#: rays per patch for each quality level; accuracy measured in docs/benchmarks.md
#: ("Form factors") and checked by tests/test_engine_formfactors.py.
QUALITY = {"draft": 1024, "default": 16384, "high": 262144}
DEFAULT_RAYS_PER_PATCH = QUALITY["default"]
#: dense float32 matrix up to this many patches, scipy.sparse CSR above.
DENSE_LIMIT = 6000
SAMPLINGS = ("sobol", "stratified", "random")
#: target number of rays per chunk (one chunk = a contiguous range of source patches).
CHUNK_RAYS = 1 << 17
#: origin offset along the normal, relative to the scene's bounding-box diagonal.
RAY_OFFSET = 1e-5


class Cancelled(Exception):
    """The user cancelled the form-factor computation."""


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
    symmetrised: bool = False

    @property
    def n_patches(self) -> int:
        return self.matrix.shape[0]

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


def symmetrise(matrix, area):
    """Enforce reciprocity: F_ij <- (A_i F_ij + A_j F_ji) / (2 A_i)."""
    area = np.asarray(area, dtype=np.float64)
    if sp.issparse(matrix):
        G = sp.diags(area) @ matrix.astype(np.float64)
        S = sp.diags(0.5 / area) @ (G + G.T)
        return S.astype(np.float32).tocsr()
    G = area[:, None] * np.asarray(matrix, dtype=np.float64)
    return ((G + G.T) * (0.5 / area)[:, None]).astype(np.float32)


class _Tracer:
    """Embree scene + per-triangle sampling data for a PatchSet (internal; the
    benchmark uses it to time raw embreex on the very same rays)."""

    def __init__(self, patches: PatchSet, rays_per_patch: int, seed: int, sampling: str):
        from embreex import rtcore as rtc
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        tv = np.asarray(patches.tri_vertices, dtype=np.float64)
        if tv.ndim != 3 or tv.shape[1:] != (3, 3) or len(tv) == 0:
            raise SceneError("the patch set has no triangles")
        if not np.all(np.isfinite(tv)):
            raise SceneError("the scene has NaN or infinite vertex coordinates")
        P = patches.n_patches
        tri_patch = np.asarray(patches.tri_patch, dtype=np.int64)
        if len(tri_patch) != len(tv) or tri_patch.min() < 0 or tri_patch.max() >= P:
            raise SceneError("tri_patch does not match the patches")
        self.P = P
        self.N = int(rays_per_patch)
        self.seed = int(seed)
        self.sampling = sampling

        # sort triangles by patch; per patch a cumulative-area table
        order = np.argsort(tri_patch, kind="stable")
        tv = tv[order]
        self.tri_patch = tri_patch[order]
        e1 = tv[:, 1] - tv[:, 0]
        e2 = tv[:, 2] - tv[:, 0]
        cr = np.cross(e1, e2)
        ta = 0.5 * np.linalg.norm(cr, axis=1)
        ok = ta > 0
        n = np.zeros_like(cr)
        n[ok] = cr[ok] / (2 * ta[ok, None])
        t = np.zeros_like(e1)
        el = np.linalg.norm(e1, axis=1)
        t[ok] = e1[ok] / el[ok, None]
        self.v0, self.e1, self.e2 = tv[:, 0], e1, e2
        self.n, self.t, self.b = n, t, np.cross(n, t)
        self.n32t = np.ascontiguousarray(n.T, dtype=np.float32)
        pa = np.bincount(self.tri_patch, weights=ta, minlength=P)
        if np.any(pa <= 0):
            raise SceneError("some patches have zero area")
        cum = np.cumsum(ta)
        start = np.searchsorted(self.tri_patch, np.arange(P), side="left")
        before = np.concatenate([[0.0], cum])[start]  # area before each patch's first triangle
        # within-patch CDF at each triangle's upper end, in (0, 1]
        self.cdf_hi = (cum - before[self.tri_patch]) / pa[self.tri_patch]
        self.cdf_hi[np.r_[start[1:] - 1, len(ta) - 1]] = 1.0
        self.cdf_lo = np.concatenate([[0.0], self.cdf_hi[:-1]])
        self.cdf_lo[start] = 0.0
        self.key = self.tri_patch + self.cdf_hi  # global monotone search key
        self.cdf_lo32 = self.cdf_lo.astype(np.float32)
        self.cdf_w32 = np.maximum(self.cdf_hi - self.cdf_lo, 1e-30).astype(np.float32)
        self.single = np.all(np.bincount(self.tri_patch, minlength=P) == 1)
        self.tri_of_patch = start  # valid when single

        lo, hi = tv.reshape(-1, 3).min(axis=0), tv.reshape(-1, 3).max(axis=0)
        diag = float(np.linalg.norm(hi - lo))
        self.offset = RAY_OFFSET * diag + 4 * np.finfo(np.float32).eps * float(np.abs(tv).max())

        # per triangle, component-major (18, T): origin base (v0 + offset n), e1, e2, t, b, n
        self.geo = np.ascontiguousarray(
            np.concatenate([(tv[:, 0] + self.offset * n).T, e1.T, e2.T, t.T, self.b.T, n.T]), dtype=np.float32)
        self.scene = rtcs.EmbreeScene(rtc.EmbreeDevice(), robust=True)
        self._mesh = TriangleMesh(self.scene, tv.astype(np.float32))
        # chunks: contiguous patch ranges of ~CHUNK_RAYS rays
        per = max(1, CHUNK_RAYS // self.N)
        self.chunks = [(p0, min(P, p0 + per)) for p0 in range(0, P, per)]
        if sampling == "sobol":
            m = int(np.ceil(np.log2(self.N))) if self.N > 1 else 0
            base = qmc.Sobol(d=4, scramble=False).random_base2(m)[: self.N]
            self.sobol = (base * 2.0**32).astype(np.uint64).astype(np.uint32)

    def unit_samples(self, ci: int) -> np.ndarray:
        """(n_patches_in_chunk * N, 4) float32 samples in (0, 1) for chunk ci."""
        p0, p1 = self.chunks[ci]
        k, N = p1 - p0, self.N
        rng = np.random.default_rng([self.seed, ci])
        if self.sampling == "sobol":
            shift = rng.integers(0, 2**32, size=(k, 1, 4), dtype=np.uint32)
            x = (self.sobol[None] ^ shift) >> np.uint32(8)  # 24 bits: exact in float32
            u = x.astype(np.float32)
            u *= np.float32(2.0**-24)
            u += np.float32(2.0**-25)  # cell midpoints, strictly inside (0, 1)
            return u.reshape(-1, 4)
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

    def rays(self, ci: int):
        """Origins (n,3) f32, directions (n,3) f32 and source patch (n,) of chunk ci."""
        p0, p1 = self.chunks[ci]
        u = self.unit_samples(ci)
        src = np.repeat(np.arange(p0, p1), self.N)
        u0, u1, u2, u3 = u.T
        if self.single:
            tri = self.tri_of_patch[src]
            s = u0
        else:
            tri = np.searchsorted(self.key, src + u0.astype(np.float64), side="right")
            np.minimum(tri, len(self.key) - 1, out=tri)
            lo = np.take(self.cdf_lo32, tri)
            s = np.clip((u0 - lo) / np.take(self.cdf_w32, tri), 0.0, 1.0)
        g = np.take(self.geo, tri, axis=1)  # (18, n): origin base, e1, e2, t, b, n
        # uniform point in the triangle
        su = np.sqrt(s)
        b2 = u1 * su
        b1 = su - b2
        out = np.empty((2, len(src), 3), dtype=np.float32)
        ot = out[0].T
        np.multiply(g[3:6], b1, out=ot)
        ot += g[0:3]
        ot += g[6:9] * b2
        # Shirley's concentric map of the unit square to the disk, lifted to the hemisphere
        a = 2.0 * u2 - 1.0
        b = 2.0 * u3 - 1.0
        first = np.abs(a) > np.abs(b)
        r = np.where(first, a, b)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.where(first, np.float32(np.pi / 4) * (b / a), np.float32(np.pi / 2) - np.float32(np.pi / 4) * (a / b))
        phi[~np.isfinite(phi)] = 0.0  # a = b = 0: r = 0, any angle
        dx = r * np.cos(phi)
        dy = r * np.sin(phi)
        dz = np.sqrt(np.maximum(np.float32(0.0), 1.0 - dx * dx - dy * dy))
        dt = out[1].T
        np.multiply(g[9:12], dx, out=dt)
        dt += g[12:15] * dy
        dt += g[15:18] * dz
        return out[0], out[1], src

    def trace(self, org, d) -> np.ndarray:
        return self.scene.run(org, d)

    def hits(self, ci: int):
        """Trace chunk ci: (source patch, receiving patch) of the rays that hit a front side."""
        org, d, src = self.rays(ci)
        prim = np.asarray(self.trace(org, d))
        hit = np.flatnonzero(prim >= 0)
        prim = prim[hit]
        nh = np.take(self.n32t, prim, axis=1)
        dh = d[hit].T
        front = (dh[0] * nh[0] + dh[1] * nh[1] + dh[2] * nh[2]) < 0
        return src[hit[front]], self.tri_patch[prim[front]]


def compute_form_factors(
    patches: PatchSet,
    rays_per_patch: int = DEFAULT_RAYS_PER_PATCH,
    seed: int = 0,
    threads: int | None = None,
    progress=None,
    cancel=None,
    sampling: str = "sobol",
    symmetrise_reciprocity: bool = False,
    dense_limit: int = DENSE_LIMIT,
) -> FormFactors:
    """Ray-cast form factors of ``patches`` (see the module docstring).

    ``rays_per_patch``: rays shot from every patch (see ``QUALITY``).
    ``seed``: results are reproducible for a seed, whatever ``threads``.
    ``threads``: worker threads (default ``os.cpu_count()``).
    ``progress(fraction)``: optional callback, called from the calling thread.
    ``cancel()``: optional; returning True aborts with :class:`Cancelled`.
    ``symmetrise_reciprocity``: replace F by (A_i F_ij + A_j F_ji) / (2 A_i)
    (off by default: it no longer guarantees row sums <= 1).
    """
    t0 = time.perf_counter()
    if isinstance(rays_per_patch, str):
        if rays_per_patch not in QUALITY:
            raise ValueError(f"unknown quality {rays_per_patch!r}; use one of {sorted(QUALITY)}")
        rays_per_patch = QUALITY[rays_per_patch]
    if not (isinstance(rays_per_patch, (int, np.integer)) and rays_per_patch >= 1):
        raise ValueError(f"rays per patch must be a positive integer, got {rays_per_patch!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"unknown sampling {sampling!r}; use one of {SAMPLINGS}")
    if threads is None:
        threads = os.cpu_count() or 1
    if not (isinstance(threads, (int, np.integer)) and threads >= 1):
        raise ValueError(f"threads must be a positive integer, got {threads!r}")

    tr = _Tracer(patches, int(rays_per_patch), seed, sampling)
    P, N = tr.P, tr.N
    dense = P <= dense_limit
    M = np.zeros((P, P), dtype=np.float32) if dense else None
    blocks = [None] * len(tr.chunks)
    stop = threading.Event()
    inv_n = 1.0 / N

    def work(ci):
        if stop.is_set():
            return ci
        src, dst = tr.hits(ci)
        p0, p1 = tr.chunks[ci]
        k = p1 - p0
        if dense:
            counts = np.bincount((src - p0) * P + dst, minlength=k * P)
            M[p0:p1] = (counts * inv_n).reshape(k, P)
        else:
            blk = sp.coo_matrix((np.full(len(src), inv_n, dtype=np.float32), (src - p0, dst)), shape=(k, P))
            blocks[ci] = blk.tocsr()  # sums duplicates
        return ci

    def check_cancel():
        if cancel is not None and cancel():
            stop.set()
            raise Cancelled("form-factor computation cancelled")

    check_cancel()
    total = len(tr.chunks)
    done = 0
    with ThreadPoolExecutor(max_workers=int(threads)) as ex:
        pending = {ex.submit(work, ci) for ci in range(total)}
        try:
            while pending:
                finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                for f in finished:
                    f.result()
                    done += 1
                if finished and progress is not None:
                    progress(done / total)
                check_cancel()
        except BaseException:
            stop.set()
            for f in pending:
                f.cancel()
            raise
    matrix = M if dense else sp.vstack(blocks, format="csr").astype(np.float32)
    if symmetrise_reciprocity:
        matrix = symmetrise(matrix, patches.area)
    data = matrix if dense else matrix.data
    if not np.all(np.isfinite(data)):
        raise SceneError("form factors contain NaN or infinite values (degenerate geometry?)")
    return FormFactors(
        matrix=matrix,
        rays_per_patch=N,
        n_rays=N * P,
        seconds=time.perf_counter() - t0,
        sampling=sampling,
        symmetrised=bool(symmetrise_reciprocity),
    )
