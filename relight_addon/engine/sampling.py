"""The sampling core of a PatchSet: its triangles, their area tables and one Embree scene.

A :class:`SceneSampler` is built once per solve and shared by everything that samples the
patches or casts rays between them: hemisphere ray casting (formfactors.py), the kernel
estimator's shadow rays (kernel_transfer.py) and, next, the lamps' shadow rays.

- Triangles: ``patch_triangles(patches)`` sorted by patch (stable), so that patch p's
  triangles are rows ``tstart[p] .. tstart[p] + tcount[p] - 1``; per triangle its edges
  ``e1``, ``e2`` (from vertex 0), ``cross`` (e1 x e2), area ``ta`` and unit normal ``tn``
  (zero for a degenerate triangle); per patch its area ``area``.
- Area tables: the within-patch area CDF of each triangle, ``cdf_lo`` .. ``cdf_hi`` (in
  [0, 1], exactly 1 at a patch's last triangle) and the global monotone search key
  ``key = tri_patch + cdf_hi``: a uniform u in [0, 1) picks triangle
  ``searchsorted(key, p + u, "right")`` of patch p with probability proportional to its area.
- Ray offset: ``offset`` = RAY_OFFSET x the scene's bounding-box diagonal, plus a few float32
  ulps of the largest coordinate. Ray origins are moved off their surface by it along the
  normal; sample points are taken on each triangle shrunk about its incentre so that its edges
  move inward by 2 x offset (``s_v0``, ``s_e1``, ``s_e2``): a point sampled within float32
  rounding of an edge could otherwise start behind the adjacent wall at a concave edge and leak
  out (seen on a 20,000-patch box).
- Queries (robust mode, float32 rays; embree releases the GIL, so threads may query at once):
  ``first_hit`` (the triangle each ray hits first, -1 for a miss), ``front_hit_patches`` (the
  patch whose front side a ray hits first; P for a miss or a back side) and ``visible`` (no
  triangle before a ray's end).

Also here, for every estimator that works in chunks: ``run_chunks`` (worker threads,
progress and cancellation between chunks) and :class:`Cancelled`.
"""
from __future__ import annotations

from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from concurrent.futures import TimeoutError as FutureTimeout

import numpy as np

from .coincident import Twins
from .rays import RAY_OFFSET
from .scene import PatchSet, SceneError, patch_triangles
from .units import TINY

__all__ = ["Cancelled", "SceneSampler", "run_cancellable", "run_chunks"]



class Cancelled(Exception):
    """The user cancelled the computation (``cancel()`` returned True)."""


def check_cancel(cancel, what="solve cancelled") -> None:
    """Cancelled(``what``) when ``cancel()`` says so (None: never)."""
    if cancel is not None and cancel():
        raise Cancelled(what)


class SceneSampler:
    """Triangle table, area tables, ray offset and Embree scene of a PatchSet (see the module
    docstring), built once and shared by the estimators of one solve."""

    def __init__(self, patches: PatchSet):
        self._triangles(patches)
        self._area_tables()
        self._shrunk_triangles(patches)
        self._ray_scene(patches)

    def _triangles(self, patches: PatchSet):
        """The triangle table, sorted by patch: vertices, edges, areas, normals; patch areas."""
        tv, tri_patch = patch_triangles(patches)
        P = patches.n_patches
        self.n_patches = P
        order = np.argsort(tri_patch, kind="stable")
        self.tv = tv = tv[order]
        self.tri_patch = tri_patch = tri_patch[order]
        self.tstart = np.searchsorted(tri_patch, np.arange(P), side="left")
        self.tcount = np.bincount(tri_patch, minlength=P)
        self.e1 = e1 = tv[:, 1] - tv[:, 0]
        self.e2 = e2 = tv[:, 2] - tv[:, 0]
        self.cross = cr = np.cross(e1, e2)
        self.ta = ta = 0.5 * np.linalg.norm(cr, axis=1)
        ok = ta > 0
        self.tn = np.zeros_like(cr)
        self.tn[ok] = cr[ok] / (2 * ta[ok, None])
        self.area = np.bincount(tri_patch, weights=ta, minlength=P)
        if np.any(self.area <= 0):
            raise SceneError("some patches have zero area")

    def _area_tables(self):
        """Per patch a cumulative-area table: the within-patch CDF at each triangle's ends."""
        ta, tri_patch = self.ta, self.tri_patch
        cum = np.cumsum(ta)
        before = np.concatenate([[0.0], cum])[self.tstart]  # area before each patch's first triangle
        self.cdf_hi = (cum - before[tri_patch]) / self.area[tri_patch]
        self.cdf_hi[np.r_[self.tstart[1:] - 1, len(ta) - 1]] = 1.0
        self.cdf_lo = np.concatenate([[0.0], self.cdf_hi[:-1]])
        self.cdf_lo[self.tstart] = 0.0
        self.key = tri_patch + self.cdf_hi  # global monotone search key

    def _shrunk_triangles(self, patches: PatchSet):
        """The ray offset, and each triangle shrunk about its incentre: edges moved inward by
        2 * offset (the shift, <= 2 * offset, is of the order of the normal offset)."""
        tv, ta = self.tv, self.ta
        lo, hi = tv.reshape(-1, 3).min(axis=0), tv.reshape(-1, 3).max(axis=0)
        diag = patches.ray_scale if patches.ray_scale is not None else \
            float(np.linalg.norm(hi - lo)) if patches.region is None else patches.region.diagonal
        self.offset = RAY_OFFSET * diag + 4 * np.finfo(np.float32).eps * float(np.abs(tv).max())
        el3 = np.stack([np.linalg.norm(tv[:, 2] - tv[:, 1], axis=1), np.linalg.norm(tv[:, 0] - tv[:, 2], axis=1),
                        np.linalg.norm(tv[:, 1] - tv[:, 0], axis=1)], axis=1)  # side opposite each vertex
        perim = np.maximum(el3.sum(axis=1), TINY)
        incentre = np.einsum("tk,tkj->tj", el3, tv) / perim[:, None]
        r_in = 2 * ta / perim
        shrink = 1 - np.minimum(0.5, 2 * self.offset / np.maximum(r_in, TINY))
        self.s_v0 = incentre + shrink[:, None] * (tv[:, 0] - incentre)
        self.s_e1 = self.e1 * shrink[:, None]
        self.s_e2 = self.e2 * shrink[:, None]

    def _ray_scene(self, patches: PatchSet):
        """The Embree scene: every triangle but those of the patches light passes through (work
        planes, PatchSet.passes: they occlude nothing and nothing sees them)."""
        from embreex import rtcore as rtc
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh

        # front-side test of a first hit: the hit triangle's normal; the extra last row (all
        # zero, receiving patch P) is what a miss (primID -1) picks up
        self._n_ext = np.concatenate([self.tn, np.zeros((1, 3))]).astype(np.float32)
        self._patch_ext = np.concatenate([self.tri_patch, [self.n_patches]])
        self._occluders = None
        if patches.passes is not None and np.any(patches.passes):
            self._occluders = np.flatnonzero(~np.asarray(patches.passes, dtype=bool)[self.tri_patch])
        self.scene = rtcs.EmbreeScene(rtc.EmbreeDevice(), robust=True)
        tv = self.tv if self._occluders is None else self.tv[self._occluders]
        self._mesh = TriangleMesh(self.scene, tv.astype(np.float32))
        # coincident triangles back to back: a ray hits the one facing it (engine.coincident)
        self._twins = Twins.of(self.tv, self.tn, self.ta, self.offset, self._own_hit, among=self._occluders)

    def first_hit(self, org, d) -> np.ndarray:
        """The (sorted) triangle each ray (origins, directions: (n, 3) float32) hits first, -1 for a
        miss; of coincident triangles back to back, the one facing the ray (engine.coincident)."""
        prim = self._own_hit(org, d)
        return prim if self._twins is None else self._twins.facing(org, d, prim)

    def _own_hit(self, org, d):
        """Embree's first hit, a sorted triangle (-1: a miss), of two coincident ones either."""
        prim = self.scene.run(org, d)
        if self._occluders is None:
            return prim
        prim = np.asarray(prim)
        return np.where(prim >= 0, self._occluders[np.maximum(prim, 0)], -1)

    def front_hit_patches(self, org, d) -> np.ndarray:
        """The patch whose front side each ray hits first; n_patches for a miss or a hit on a back side."""
        prim = np.asarray(self.first_hit(org, d))  # -1: miss -> the extra zero normal / patch P
        nh = np.take(self._n_ext, prim, axis=0)
        nh *= d
        back = nh[:, 0] + nh[:, 1]
        back += nh[:, 2]
        back = back >= 0  # a hit on a back side, or a miss
        dst = np.take(self._patch_ext, prim)
        dst[back] = self.n_patches
        return dst

    def visible(self, org, d, tfar) -> np.ndarray:
        """Per ray (origins, unit directions: (n, 3) float32, lengths tfar (n,)): True when no
        triangle lies on the ray before tfar (an Embree occlusion query)."""
        return np.asarray(self.scene.run(org, d, dists=tfar, query="OCCLUDED")) == -1


#: how often (s) run_chunks looks at ``cancel()`` while its chunks run
CANCEL_POLL = 0.02
#: how often (s) run_cancellable looks at ``cancel()`` while its call runs
CALL_POLL = 0.005


def run_cancellable(fn, cancel=None, what="cancelled"):
    """``fn()`` in a thread of its own while this one looks at ``cancel()`` every CALL_POLL s: on a
    cancel, Cancelled(``what``) at once, and ``fn`` ends in the background, its answer dropped (one
    LAPACK call cannot be interrupted: a channel's LU took 0.2-0.3 s on 2,305 patches, which Live's
    next stroke waited for when it came during a later answer's). ``fn`` must touch nothing but its
    own arrays. Without ``cancel``: ``fn()`` here."""
    if cancel is None:
        return fn()
    check_cancel(cancel, what)
    ex = ThreadPoolExecutor(max_workers=1)
    try:
        call = ex.submit(fn)
        while True:
            try:
                return call.result(timeout=CALL_POLL)
            except FutureTimeout:
                if cancel():
                    raise Cancelled(what) from None
    finally:
        ex.shutdown(wait=False)


def run_chunks(work, total, threads, stop, cancel=None, progress=None):
    """Run ``work(ci)`` for ci in range(total) on ``threads`` worker threads (in this thread when
    1), calling ``progress(done / total)`` and checking ``cancel()`` here between chunks: on
    cancel (Cancelled) or any error ``stop`` is set (work checks it) and the rest is dropped."""

    def check_cancel():
        if cancel is not None and cancel():
            stop.set()
            raise Cancelled("form-factor computation cancelled")

    check_cancel()
    done = 0
    if threads == 1 or total == 1:
        for ci in range(total):
            work(ci)
            done += 1
            if progress is not None:
                progress(done / total)
            check_cancel()
        return
    ex = ThreadPoolExecutor(max_workers=int(threads))
    pending = {ex.submit(work, ci) for ci in range(total)}
    try:
        while pending:
            finished, pending = wait(pending, timeout=CANCEL_POLL, return_when=FIRST_COMPLETED)
            for f in finished:
                f.result()
                done += 1
            if finished and progress is not None:
                progress(done / total)
            check_cancel()
    except BaseException:
        # (the chunks running end at their next look at ``stop``, in the background: a cancel is
        # not kept waiting for them; Live's next stroke starts meanwhile)
        stop.set()
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    ex.shutdown(wait=True)
