"""Form factors of chosen (receiver, source) pairs with low variance: the analytic
point-to-polygon kernel times visibility from shadow rays (Baum, Rushmeier & Winget 1989,
"Improving radiosity solutions through the use of analytically determined form-factors";
Wallace, Elmquist & Haines 1989, "A ray tracing algorithm for progressive radiosity").

Hemisphere ray casting (formfactors.py) estimates F[r, s] by the fraction of N rays from r
that land on s: for a small or distant source (F of 0.001 to 0.01) that is a handful of
hits and a relative error of several per cent, which the inverse solve then turns into
wrong light intensities. Here, for the pairs that decide the answer (light cells to target
patches), F is integrated instead:

    F_rs = (1 / A_r) * integral over x in r of  F_pt(x, s) * V(x, s)  dA(x)

- ``F_pt(x, s)``: the form factor from the point x (normal n_x) to the source polygon, by
  Lambert's contour integral, per source triangle:
  ``F = -1/(2 pi) * sum_k angle_k * (n_x . unit(R_k x R_k+1))``, ``R_k`` = vertex k - x,
  ``angle_k = atan2(|R_k x R_k+1|, R_k . R_k+1)`` (exact for tiny angles). The triangle is
  first clipped to the half-space in front of x (the part behind x's tangent plane is cut
  away: the clipped polygon gains an edge in that plane) and counts only when x is in
  front of it (one-sided sources, as in formfactors.py). Double precision throughout.
- ``V(x, s)``: the visible fraction of s seen from x, weighted by the point-to-point kernel:
  ``sum_j w_j v_j / sum_j w_j`` over shadow rays from x to stratified points y_j on s
  (a jittered g x g grid over the source's area, triangles picked by area),
  ``w_j = cos_x cos_y / r^4`` (zero behind either surface), ``v_j`` from an Embree
  occlusion query (sampling.SceneSampler: the same triangles, Embree scene and ray offset as
  formfactors.py).
- Phase 1, every pair: the integral over the receiver is a quadrature (not Monte Carlo):
  each receiver triangle gets a collapsed (Duffy) Gauss rule, Gauss-Jacobi along the
  triangle's length and Gauss-Legendre across it, with about ``points_per_patch`` points
  per patch in all, shared among its triangles by area (a long thin triangle gets its
  points along its length). Every point is strictly inside its triangle (set in from the
  edges); the normal at a point is its own triangle's (a patch may be several non-coplanar
  triangles). Each point casts ``shadow_rays`` rays. A pair whose rays all reach the source
  gets the unoccluded integral exactly (no noise at all); a pair whose rays are all blocked
  gets 0.
- Phase 2, pairs in penumbra (some rays blocked, some not): a Gauss rule is no good across a
  shadow edge, so the pair's visible fraction is estimated again from ``penumbra_points``
  jittered receiver points (stratified over the receiver's area) with ``penumbra_rays`` rays
  each, as the ratio sum w v / sum w over all these rays, and multiplies the phase-1
  unoccluded integral (a ratio estimator: the kernel's variation is exact, only the
  visibility is sampled).
- Near pairs are refined in phase 1: when the receiver is large compared with the source's
  width (area / diameter) or with the gap between the two, the receiver's rule is made
  finer (level L: node spacing / 2^L, L <= MAX_LEVEL), and each point then casts
  ``shadow_rays / 4^L`` rays (at least 1), so the rays per pair stay about the same.
- Distant pairs get a coarse rule: when the gap between the patches exceeds COARSE_GAP x the
  receiver's diameter, a receiver triangle no larger than the node spacing gets one node,
  its centroid, instead of at least 2 x 2 (a patch clustered from many small triangles
  would otherwise get 4 nodes per triangle; on the staircase 37 % fewer kernel evaluations
  for a largest change of 0.3 % on the pairs above 1 % of their row's largest).
- A parallelogram source (a quad cell) wholly in front of the point is one contour of four
  edges: the diagonal's two terms of the two triangles cancel.
- Far pairs (centre distance > ``far_ratio`` x the larger patch diameter) use the
  point-to-point kernel ``a_t cos cos / (pi r^2)`` to each source triangle's centroid
  instead of the contour integral (relative error about (diameter / distance)^2 / 4).
- A receiver that crosses a (planar) source's plane gets its rule on the part in front of
  that plane only (the integrand jumps to 0 behind it; the source crossing the receiver's
  plane is handled exactly by the clipped contour integral).
- Pairs where one patch lies entirely behind the other's plane (planar patches) are 0
  without any work; a pair (r, r) is 0 (a patch's transfer to itself is left to the
  hemisphere estimate).

Errors: the receiver quadrature is deterministic (below 0.5 % on the closed-form
configurations of tests/test_engine_kernel_transfer.py at the default settings, 0.01 %
for small or distant sources); the noise is that of the visibility of pairs in penumbra.
An occluder that none of a pair's phase-1 rays meets (one covering a few per cent of the
pair's ray bundle or less) is missed: that pair is then taken as unoccluded.
Accuracy against time on the staircase and a furnished room: benchmarks/bench_kernel_transfer.py.

Determinism: every pair draws its samples from a stream of its own, keyed by the seed and the
two patches' geometry in scale-free steps (``_pair_keys``, ``_KeyedStream``: counter-based uniforms, a splitmix64 hash
of the key and the sample's place), so a pair's value does not depend on the other pairs asked for,
their order, the chunks or the thread count: a row drawn alone, or a source added, gives the
entries a draw of every pair gives (pipeline.prepared draws only a stroke's new pairs).
Worker threads evaluate the kernel (numpy) and trace the shadow rays (embree releases the
GIL) chunk by chunk.

Storage in a FormFactors matrix: ``apply_kernel_pairs`` writes F[r, s] and, by reciprocity,
F[s, r] = A_r F[r, s] / A_s (one estimate serves both directions).
"""
from __future__ import annotations

import copy
import math
import os
import threading
import time

import numpy as np
import scipy.sparse as sp
import scipy.special

from .sampling import SceneSampler, run_chunks
from .scene import PatchSet, SceneError, key_lengths, key_scale
from .units import TINY

__all__ = [
    "DEFAULT_POINTS_PER_PATCH",
    "DEFAULT_SHADOW_RAYS",
    "DEFAULT_PENUMBRA_POINTS",
    "DEFAULT_PENUMBRA_RAYS",
    "DEFAULT_FAR_RATIO",
    "MAX_LEVEL",
    "kernel_form_factors",
    "apply_kernel_pairs",
    "point_polygon_form_factor",
]

#: receiver quadrature points per patch (about: the rule is rounded per triangle).
DEFAULT_POINTS_PER_PATCH = 16
#: shadow rays per receiver point and source patch (phase 1: they find the pairs in penumbra).
DEFAULT_SHADOW_RAYS = 4
#: jittered receiver points of a pair in penumbra (phase 2), and rays from each: more points with
#: fewer rays each estimate the visible fraction better for the same rays (benchmarks/bench_kernel_transfer.py:
#: on the furnished room 100 x 2 gives 1.1 % where 64 x 4 gives 1.8 %, in less time).
DEFAULT_PENUMBRA_POINTS = 100
DEFAULT_PENUMBRA_RAYS = 2
#: pairs farther apart than this many times the larger patch diameter use the point kernel.
DEFAULT_FAR_RATIO = 10.0
#: the finest refinement level of near pairs (node spacing / 2^level).
MAX_LEVEL = 3
#: a near pair is refined when the receiver's diameter exceeds LEVEL_SPAN x the source's
#: width (area / diameter) or the gap between the patches: level = ceil(log2(ratio / span)).
LEVEL_SPAN = 4.0
#: a pair farther apart than this many receiver diameters (gap between the patches) uses the coarse rule.
COARSE_GAP = 2.0
#: at most this many Gauss nodes along either direction of one receiver triangle.
MAX_NODES = 24
#: the triangles gathered at once by the pairs' plane test (_signed_range): about 0.4 GB of temporaries.
RANGE_CHUNK_TRIANGLES = 1 << 21
#: the receiver triangles whose rules are made at once (_Geometry.make_receiver_rules): about 0.1 GB of temporaries.
RULE_CHUNK_TRIANGLES = 1 << 18
#: kernel evaluations (receiver point x source triangle) per work chunk.
CHUNK_EVALS = 1 << 15
#: at most about this many penumbra rays are generated at once (a batch within a work chunk:
#: it bounds the memory only, unlike formfactors.CHUNK_RAYS, the hemisphere casting's unit of work).
PENUMBRA_BATCH_RAYS = 1 << 18


# --------------------------------------------------------------------------------------
# the analytic kernel

def _dot(a, b):
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _cross(a, b):
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _edge_term(p, q, n):
    """angle(p, q) * n . unit(p x q), by atan2 (accurate for tiny angles); 0 for p || q."""
    c = _cross(p, q)
    cn = np.sqrt(_dot(c, c))
    ang = np.arctan2(cn, _dot(p, q))
    return ang * _dot(c, n) / np.where(cn > 0, cn, 1.0)


def _lambert(x, n, v, ns):
    """Point-to-triangle form factors, (E,): points x (E, 3) with unit normals n (E, 3),
    triangles v (E, 3, 3) with unit front normals ns (E, 3) (the winding's normal).

    The triangle is clipped to the half-space n . (y - x) > 0 (Sutherland-Hodgman, edge by
    edge: the clipped polygon's edges are the kept parts of the triangle's edges plus one
    edge in the plane, from the exit point to the entry point), then Lambert's formula.
    A point behind (or in) the triangle's plane gets 0. Triangles wholly in front of the
    point (the common case) skip the clipping.
    """
    out = np.zeros(len(x))
    front = _dot(x - v[:, 0], ns) > 0
    r = [v[:, k] - x for k in range(3)]
    ahead = [_dot(rk, n) > 0 for rk in r]
    whole = front & ahead[0] & ahead[1] & ahead[2]
    w = np.flatnonzero(whole)
    if len(w):
        out[w] = _contour([rk[w] for rk in r], n[w])
    c = np.flatnonzero(front & (ahead[0] | ahead[1] | ahead[2]) & ~whole)
    if len(c):
        out[c] = _clipped_contour([rk[c] for rk in r], n[c])
    return np.maximum(-out, 0.0) * (0.5 / np.pi)


def _contour(r, n):
    """Lambert's contour sum over a polygon wholly in front of the points: its vertices r[k]
    relative to the points ((E, 3) each, in winding order), the points' normals n."""
    return sum(_edge_term(r[k], r[(k + 1) % len(r)], n) for k in range(len(r)))


def _clipped_contour(r, n):
    """Lambert's contour sum over the part of the triangle (vertices r[k] relative to the
    points, (E, 3) each) in front of the points' planes (normals n)."""
    E = len(n)
    d = [_dot(rk, n) for rk in r]
    total = np.zeros(E)
    exit_p = np.zeros((E, 3))
    entry_p = np.zeros((E, 3))
    clipped = np.zeros(E, dtype=bool)
    for k in range(3):
        a, b = r[k], r[(k + 1) % 3]
        da, db = d[k], d[(k + 1) % 3]
        ina, inb = da > 0, db > 0
        leaves, enters = ina & ~inb, ~ina & inb
        cut = leaves | enters
        t = np.zeros(E)
        np.divide(da, da - db, out=t, where=cut)
        p = a + t[:, None] * (b - a)
        start = np.where(enters[:, None], p, a)
        end = np.where(leaves[:, None], p, b)
        total += np.where(ina | inb, _edge_term(start, end, n), 0.0)
        exit_p[leaves] = p[leaves]
        entry_p[enters] = p[enters]
        clipped |= leaves
    if clipped.any():
        total[clipped] += _edge_term(exit_p[clipped], entry_p[clipped], n[clipped])
    return total


def point_polygon_form_factor(x, n, polygon) -> float:
    """Form factor from a point x with unit normal n to a planar convex polygon (k, 3)
    (fan-triangulated; its front is the side its winding's normal points to), clipped to
    x's hemisphere. A convenience for tests and checks."""
    poly = np.asarray(polygon, dtype=np.float64).reshape(-1, 3)
    tris = np.stack([np.repeat(poly[:1], len(poly) - 2, axis=0), poly[1:-1], poly[2:]], axis=1)
    ns = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    ns /= np.linalg.norm(ns, axis=1)[:, None]
    k = len(tris)
    x = np.tile(np.asarray(x, dtype=np.float64).reshape(1, 3), (k, 1))
    n = np.tile(np.asarray(n, dtype=np.float64).reshape(1, 3), (k, 1))
    return float(_lambert(x, n, tris, ns).sum())


def _point_kernel(x, n, c, nc, a):
    """a cos_x cos_c / (pi r^2): the far-pair kernel from points x (normal n) to small
    areas a at c (normal nc); 0 behind either."""
    r = c - x
    r2 = _dot(r, r)
    cx = np.maximum(_dot(r, n), 0.0)
    cc = np.maximum(-_dot(r, nc), 0.0)
    return a * cx * cc / (np.pi * r2 * r2)


# --------------------------------------------------------------------------------------
# receiver quadrature

_RULES = {}


def _gauss(n):
    """Nodes/weights on [0, 1]: Gauss-Jacobi (weight xi, total 1/2) and Gauss-Legendre (total 1)."""
    if n not in _RULES:
        xj, wj = scipy.special.roots_jacobi(n, 0.0, 1.0)
        xl, wl = np.polynomial.legendre.leggauss(n)
        _RULES[n] = ((1 + xj) / 2, wj / 4, (1 + xl) / 2, wl / 2)
    return _RULES[n]


def _triangle_rule(v, h, coarse=False):
    """Collapsed Gauss rule on triangle v (3, 3) with node spacing about h: points (q, 3)
    and weights (q,) summing to the triangle's area. The collapsed vertex is the one
    opposite the shortest edge; n_xi nodes along the triangle's height from it (at least
    2), n_eta along the shortest edge (at least 2, or 1 for a sliver)."""
    e = np.array([np.linalg.norm(v[2] - v[1]), np.linalg.norm(v[0] - v[2]), np.linalg.norm(v[1] - v[0])])
    c = int(np.argmin(e))
    a, b, d = v[c], v[(c + 1) % 3], v[(c + 2) % 3]
    area = 0.5 * np.linalg.norm(np.cross(b - a, d - a))
    length = 2 * area / max(e[c], TINY)
    if coarse and length <= h and e[c] <= h:  # no larger than the node spacing: the centroid
        n_xi = n_eta = 1
    else:
        n_xi = int(min(MAX_NODES, max(2, math.ceil(length / h - 1e-9))))
        # across: at least 2 nodes, but 1 for a sliver (short edge < h / 4, e.g. a fan-triangulated disk)
        n_eta = 1 if e[c] < 0.25 * h else int(min(MAX_NODES, max(2, math.ceil(e[c] / h - 1e-9))))
    xi, wxi, _, _ = _gauss(n_xi)
    _, _, eta, weta = _gauss(n_eta)
    XI, ETA = np.meshgrid(xi, eta, indexing="ij")
    XI, ETA = XI.reshape(-1, 1), ETA.reshape(-1, 1)
    pts = (1 - XI) * a + XI * (1 - ETA) * b + XI * ETA * d
    w = (wxi[:, None] * weta[None, :]).reshape(-1) * (2 * area)
    return pts, w


def _triangle_rules(V, h, coarse=False):
    """``_triangle_rule`` on every triangle of V (n, 3, 3) at once: (points (q, 3), weights (q,),
    the triangle of each point (q,)), the triangles' points in their order and each triangle's in
    the order ``_triangle_rule`` gives them (the same numbers: a dense prop's thousands of small
    triangles per patch cost no Python loop)."""
    V = np.asarray(V, dtype=np.float64).reshape(-1, 3, 3)
    n = len(V)
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int64)
    e = np.stack([np.linalg.norm(V[:, 2] - V[:, 1], axis=1), np.linalg.norm(V[:, 0] - V[:, 2], axis=1),
                  np.linalg.norm(V[:, 1] - V[:, 0], axis=1)], axis=1)
    c = np.argmin(e, axis=1)
    rows = np.arange(n)
    a, b, d = V[rows, c], V[rows, (c + 1) % 3], V[rows, (c + 2) % 3]
    area = 0.5 * np.linalg.norm(np.cross(b - a, d - a), axis=1)
    ec = e[rows, c]
    length = 2 * area / np.maximum(ec, TINY)
    n_xi = np.minimum(MAX_NODES, np.maximum(2, np.ceil(length / h - 1e-9))).astype(np.int64)
    n_eta = np.where(ec < 0.25 * h, 1, np.minimum(MAX_NODES, np.maximum(2, np.ceil(ec / h - 1e-9)))).astype(np.int64)
    if coarse:
        small = (length <= h) & (ec <= h)
        n_xi, n_eta = np.where(small, 1, n_xi), np.where(small, 1, n_eta)
    pts = np.empty((int(np.sum(n_xi * n_eta)), 3))
    w = np.empty(len(pts))
    tri = np.repeat(rows, n_xi * n_eta)
    start = np.concatenate([[0], np.cumsum(n_xi * n_eta)[:-1]])
    for nx, ne in set(zip(n_xi.tolist(), n_eta.tolist())):
        sel = np.flatnonzero((n_xi == nx) & (n_eta == ne))
        xi, wxi, _, _ = _gauss(nx)
        _, _, eta, weta = _gauss(ne)
        XI, ETA = (g.reshape(-1) for g in np.meshgrid(xi, eta, indexing="ij"))
        q = (1 - XI)[None, :, None] * a[sel, None] + (XI * (1 - ETA))[None, :, None] * b[sel, None] \
            + (XI * ETA)[None, :, None] * d[sel, None]
        at = start[sel][:, None] + np.arange(nx * ne)[None, :]
        pts[at.reshape(-1)] = q.reshape(-1, 3)
        w[at.reshape(-1)] = ((wxi[:, None] * weta[None, :]).reshape(-1)[None, :] * (2 * area[sel])[:, None]).reshape(-1)
    return pts, w, tri


# --------------------------------------------------------------------------------------
# geometry

class _Geometry:
    """Per-patch kernel data of a PatchSet (centres, sizes, planes, parallelograms, receiver
    rules) on a SceneSampler's triangles, area tables and Embree scene (``sampler``: built
    here when not given)."""

    def __init__(self, patches: PatchSet, points_per_patch: int, sampler: SceneSampler | None = None):
        self.sampler = sm = SceneSampler(patches) if sampler is None else sampler
        P = patches.n_patches
        if sm.n_patches != P:
            raise ValueError(f"the sampler has {sm.n_patches} patches, the patch set {P}")
        self.P = P
        self.M = int(points_per_patch)
        # the sampler's triangles (sorted by patch), normals, areas and area tables
        self.tv = tv = sm.tv
        self.tri_patch = sm.tri_patch
        self.tstart, self.tcount = sm.tstart, sm.tcount
        self.tn, self.ta, self.area = sm.tn, sm.ta, sm.area
        self.cdf_lo, self.key = sm.cdf_lo, sm.key
        self.cdf_w = np.maximum(sm.cdf_hi - sm.cdf_lo, TINY)
        self.offset = sm.offset
        cr = sm.cross
        self.tc = tv.mean(axis=1)
        ta = self.ta
        self.center = np.stack([np.bincount(self.tri_patch, weights=self.tc[:, k] * ta, minlength=P)
                                for k in range(3)], axis=1) / self.area[:, None]
        rel = tv - self.center[self.tri_patch][:, None, :]
        rel *= rel  # (np.linalg.norm's squares and sum, in its order, without its temporaries)
        dist = np.sqrt(rel[..., 0] + rel[..., 1] + rel[..., 2]).max(axis=1)
        del rel
        self.radius = np.zeros(P)
        np.maximum.at(self.radius, self.tri_patch, dist)
        self.diam = 2 * self.radius
        self.width = self.area / np.maximum(self.diam, TINY)
        nsum = np.stack([np.bincount(self.tri_patch, weights=cr[:, k], minlength=P) for k in range(3)], axis=1)
        self.normal = nsum / np.maximum(np.linalg.norm(nsum, axis=1), TINY)[:, None]
        # planar: every triangle's normal is the patch's and every vertex lies in its plane
        tol = 1e-9 * np.maximum(self.diam, TINY)
        dn = np.linalg.norm(self.tn - self.normal[self.tri_patch], axis=1)
        off = np.abs(np.einsum("tkj,tj->tk", tv - self.center[self.tri_patch][:, None, :],
                               self.normal[self.tri_patch])).max(axis=1)
        bad = (dn > 1e-9) | (off > tol[self.tri_patch])
        self.planar = np.bincount(self.tri_patch, weights=bad.astype(float), minlength=P) == 0

        # source sample points on the shrunk triangles (see SceneSampler), with their normals
        self.tgeo = np.concatenate([sm.s_v0, sm.s_e1, sm.s_e2, self.tn], axis=1).astype(np.float32)
        self._parallelograms()
        self._rules = {}
        self._lock = threading.Lock()

    def _parallelograms(self):
        """Patches of two triangles that share an edge and make a planar parallelogram (grid
        cells, quads): ``para`` flags them, ``pgeo`` (P, 12) float32 holds origin, edge u,
        edge v (set in from the edges by 2 * offset) and the normal, ``quad`` (P, 4, 3) the outline."""
        P = self.P
        self.para = np.zeros(P, dtype=bool)
        self.pgeo = np.zeros((P, 12), dtype=np.float32)
        self.quad = np.zeros((P, 4, 3))  # a parallelogram patch's outline, in winding order
        two = np.flatnonzero((self.tcount == 2) & self.planar)
        if len(two) == 0:
            return
        t0 = self.tv[self.tstart[two]]  # (m, 3, 3)
        t1 = self.tv[self.tstart[two] + 1]
        tol = 1e-9 * self.diam[two]
        same = np.linalg.norm(t0[:, :, None, :] - t1[:, None, :, :], axis=3) <= tol[:, None, None]  # (m, 3, 3)
        shared0 = same.any(axis=2)  # vertices of t0 also in t1
        shared1 = same.any(axis=1)
        ok = (shared0.sum(axis=1) == 2) & (shared1.sum(axis=1) == 2)
        m = np.arange(len(two))
        i0 = np.argmin(shared0, axis=1)  # the vertex of t0 not in t1
        i1 = np.argmin(shared1, axis=1)
        o1, o2 = t0[m, i0], t1[m, i1]
        sv = t0[m, (i0 + 1) % 3], t0[m, (i0 + 2) % 3]  # the shared edge
        ok &= np.linalg.norm(o1 + o2 - sv[0] - sv[1], axis=1) <= tol
        eu, ev = sv[0] - o1, sv[1] - o1
        area = np.linalg.norm(np.cross(eu, ev), axis=1)
        ok &= area > 0
        area = np.where(area > 0, area, 1.0)
        ea = np.minimum(0.25, 2 * self.offset * np.linalg.norm(ev, axis=1) / area)
        eb = np.minimum(0.25, 2 * self.offset * np.linalg.norm(eu, axis=1) / area)
        org = o1 + ea[:, None] * eu + eb[:, None] * ev
        geo = np.concatenate([org, (1 - 2 * ea)[:, None] * eu, (1 - 2 * eb)[:, None] * ev,
                              self.normal[two]], axis=1)
        self.para[two[ok]] = True
        self.pgeo[two[ok]] = geo[ok]
        # the outline o1, shared vertex 0, o2, shared vertex 1 runs the way t0 winds
        self.quad[two[ok]] = np.stack([o1, sv[0], o2, sv[1]], axis=1)[ok]

    def receiver_points(self, r: int, level: int):
        """(points (q, 3), normals (q, 3), weights (q,) summing to 1) of receiver r at a level."""
        key = (int(r), int(level))
        got = self._rules.get(key)
        if got is None:
            self.make_receiver_rules([r], level)
            got = self._rules[key]
        return got

    def make_receiver_rules(self, receivers, level: int):
        """``receiver_points`` of the ``receivers`` at a level, those not made yet, made together
        (their triangles through one _triangle_rules by chunks of RULE_CHUNK_TRIANGLES: the same
        numbers as one receiver at a time, without a Python call per receiver: the 1M room's
        2,349)."""
        rs = np.array([r for r in dict.fromkeys(int(r) for r in receivers) if (r, int(level)) not in self._rules],
                      dtype=np.int64)
        if len(rs) == 0:
            return
        # node spacing: a patch of area A gets about M points (a triangle of area a gets
        # about 2 a / h^2 nodes, so h^2 = 2 A / M), then / 2^level
        h = np.sqrt(2 * self.area[rs] / max(self.M, 1)) / 2 ** max(level, 0)
        for first, end in _chunks(np.maximum(self.tcount[rs], 1), RULE_CHUNK_TRIANGLES):
            part = rs[first:end]
            cnt = self.tcount[part]
            ts = _ragged(self.tstart[part], cnt)
            owner = np.repeat(np.arange(len(part)), cnt)
            keep = self.ta[ts] > 0
            ts, owner = ts[keep], owner[keep]
            pts, wts, tri = _triangle_rules(self.tv[ts], h[first:end][owner], coarse=level < 0)
            own = owner[tri]
            nrm = np.asarray(self.tn[ts][tri], dtype=np.float64)
            wts = wts / self.area[part][own]
            cut = np.searchsorted(own, np.arange(len(part) + 1))
            with self._lock:
                for i, r in enumerate(part.tolist()):
                    self._rules[(r, int(level))] = (pts[cut[i]:cut[i + 1]], nrm[cut[i]:cut[i + 1]], wts[cut[i]:cut[i + 1]])


def kernel_geometry(patches: PatchSet, points_per_patch: int, sampler: SceneSampler | None = None) -> "_Geometry":
    """The kernel geometry of ``patches`` at ``points_per_patch``, built once per sampler (the
    lamp refinement asks for it at every evaluation: on a 260k-triangle room, 0.2 s each)."""
    if sampler is None:
        return _Geometry(patches, int(points_per_patch))
    cache = sampler.__dict__.setdefault("_kernel_geometry", {})
    key = int(points_per_patch)
    if key not in cache:
        if cache:  # only the receiver rules depend on the points: the rest is shared (on the 1M room, 1 s a geometry)
            cache[key] = _with_points(next(iter(cache.values())), key)
        else:
            cache[key] = _Geometry(patches, key, sampler=sampler)
    return cache[key]


def _with_points(g: _Geometry, points_per_patch: int) -> _Geometry:
    """A kernel geometry sharing ``g``'s arrays, with its own points per patch and receiver rules."""
    out = copy.copy(g)
    out.M = int(points_per_patch)
    out._rules = {}
    out._lock = threading.Lock()
    return out


def _clipped_receiver_points(g, r, level, s):
    """Receiver r's rule restricted to the part in front of planar source s's plane (the
    kernel is 0 behind it, a jump the Gauss rule would straddle); weights / A_r."""
    h = math.sqrt(2 * g.area[r] / max(g.M, 1)) / 2 ** max(level, 0)
    pts, nrm, wts = [], [], []
    for t in range(g.tstart[r], g.tstart[r] + g.tcount[r]):
        for part in _clip_triangle(g.tv[t], g.normal[s], g.center[s]):
            if np.linalg.norm(np.cross(part[1] - part[0], part[2] - part[0])) <= 0:
                continue
            p, w = _triangle_rule(part, h, coarse=level < 0)
            pts.append(p)
            wts.append(w)
            nrm.append(np.repeat(g.tn[t][None], len(p), axis=0))
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(pts), np.concatenate(nrm), np.concatenate(wts) / g.area[r]


def _ragged(starts, counts):
    """Concatenation of arange(s, s + c) for each (s, c)."""
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    ends = np.cumsum(counts)
    idx = np.arange(total, dtype=np.int64)
    return idx - np.repeat(ends - counts, counts) + np.repeat(np.asarray(starts, dtype=np.int64), counts)


def _chunks(weights, size) -> list:
    """[(first, end)]: contiguous ranges of the items of ``weights`` (> 0 in total), each of about
    ``size`` of their sum (an item heavier than that alone)."""
    cum = np.cumsum(weights)
    cuts = np.searchsorted(cum, np.arange(size, int(cum[-1]), size), side="left") + 1
    edges = np.unique(np.concatenate([[0], cuts, [len(cum)]]))
    return list(zip(edges[:-1], edges[1:]))


def _signed_range(g: _Geometry, a, b):
    """Per pair: (min, max) over patch b's vertices of the signed distance to planar patch
    a's plane (NaN where a is not planar), and the tolerance for 'in the plane'."""
    mn = np.full(len(a), np.nan)
    mx = np.full(len(a), np.nan)
    tol = 1e-9 * np.maximum(g.diam[a], g.diam[b])
    sel = np.flatnonzero(g.planar[a])
    if len(sel) == 0:
        return mn, mx, tol
    # a plane paired with patches of more than a quarter of the scene's triangles (every receiver
    # against a source: lights_direct_correction) is measured once against every triangle, in
    # order, and reduced per patch: no gather of the pairs' triangles (the same values)
    per_plane = np.bincount(a[sel], weights=g.tcount[b[sel]], minlength=g.P)
    whole = per_plane > 0.25 * len(g.tv)
    if whole.any():
        on = whole[a[sel]]
        for plane in np.flatnonzero(whole):
            lo, hi = _plane_range_per_patch(g, plane)
            part = sel[on & (a[sel] == plane)]
            mn[part], mx[part] = lo[b[part]], hi[b[part]]
        sel = sel[~on]
    # pairs in chunks of about RANGE_CHUNK_TRIANGLES of b's triangles (a dense receiver's
    # thousands, times every source: the 1M-triangle room's 246 sources would take 17 GB at once)
    for first, end in (_chunks(g.tcount[b[sel]], RANGE_CHUNK_TRIANGLES) if len(sel) else []):
        part = sel[first:end]
        ta, tb = a[part], b[part]
        cnt = g.tcount[tb]
        tri = _ragged(g.tstart[tb], cnt)
        pair = np.repeat(np.arange(len(part)), cnt)
        h = np.einsum("kij,kj->ki", g.tv[tri] - g.center[ta][pair][:, None, :], g.normal[ta][pair])
        lo = np.full(len(part), np.inf)
        hi = np.full(len(part), -np.inf)
        np.minimum.at(lo, pair, h.min(axis=1))
        np.maximum.at(hi, pair, h.max(axis=1))
        mn[part], mx[part] = lo, hi
    return mn, mx, tol


def _plane_range_per_patch(g: _Geometry, plane: int):
    """(P,) each patch's (min, max) over its vertices of the signed distance to patch
    ``plane``'s plane, by chunks of RANGE_CHUNK_TRIANGLES triangles (the sampler's triangles are
    sorted by patch)."""
    c, n = g.center[plane], g.normal[plane]
    tmin = np.empty(len(g.tv))
    tmax = np.empty(len(g.tv))
    for t0 in range(0, len(g.tv), RANGE_CHUNK_TRIANGLES):
        h = np.einsum("kij,j->ki", g.tv[t0:t0 + RANGE_CHUNK_TRIANGLES] - c, n)
        tmin[t0:t0 + len(h)] = h.min(axis=1)
        tmax[t0:t0 + len(h)] = h.max(axis=1)
    return np.minimum.reduceat(tmin, g.tstart), np.maximum.reduceat(tmax, g.tstart)


def _clip_triangle(v, n, p0):
    """The part of triangle v (3, 3) strictly in front of the plane n . (x - p0) = 0, as a
    list of 0 to 2 triangles."""
    d = (v - p0) @ n
    poly = []
    for k in range(3):
        a, b, da, db = v[k], v[(k + 1) % 3], d[k], d[(k + 1) % 3]
        if da > 0:
            poly.append(a)
        if (da > 0) != (db > 0):
            poly.append(a + (da / (da - db)) * (b - a))
    return [np.array([poly[0], poly[i], poly[i + 1]]) for i in range(1, len(poly) - 1)]


# --------------------------------------------------------------------------------------
# the estimator

def kernel_form_factors(
    patches: PatchSet,
    receivers,
    sources,
    points_per_patch: int = DEFAULT_POINTS_PER_PATCH,
    shadow_rays: int = DEFAULT_SHADOW_RAYS,
    seed: int = 0,
    threads: int | None = None,
    far_ratio: float = DEFAULT_FAR_RATIO,
    penumbra_points: int = DEFAULT_PENUMBRA_POINTS,
    penumbra_rays: int = DEFAULT_PENUMBRA_RAYS,
    cancel=None,
    progress=None,
    stats: dict | None = None,
    sampler: SceneSampler | None = None,
) -> np.ndarray:
    """F[receiver -> source] for every receiver x source pair, (len(receivers), len(sources)) float64.

    ``F[i, j]`` is the form factor from patch ``receivers[i]`` to patch ``sources[j]``: the
    fraction of the power leaving the receiver that reaches the front of the source, i.e.
    the gathering weight of B_r = E_r + rho_r sum_s F_rs B_s (see the module docstring).

    ``receivers``, ``sources``: patch indices (or boolean masks over the patches).
    ``points_per_patch``: receiver quadrature points per patch (about; phase 1);
    ``shadow_rays``: visibility rays per receiver point and source (phase 1; 0: no
    visibility at all, the unoccluded kernel). ``penumbra_points``, ``penumbra_rays``: the
    jittered receiver points of a pair found in penumbra and the rays from each (phase 2;
    penumbra_points is rounded to a square; 0: keep the phase-1 estimate).
    ``far_ratio``: pairs farther apart than far_ratio x the larger patch diameter use the
    point kernel (``inf``: never). ``seed``: reproducible for a seed, whatever ``threads``
    (default ``os.cpu_count()``). ``cancel()`` returning True raises sampling.Cancelled;
    ``progress(fraction)`` is called from the calling thread. ``stats``: an optional dict
    filled with counts (pairs, culled, far, pairs per level, clipped_receivers, kernel
    evaluations, rays, penumbra_pairs, seconds). ``sampler``: the SceneSampler of ``patches``
    to use (compute_form_factors passes the one its rays use; default: built here).

    Cost: about pairs x points x (source triangles) contour integrals and pairs x points x
    shadow_rays + penumbra pairs x penumbra_points x penumbra_rays rays; memory: a few
    arrays of len(receivers) x len(sources).
    """
    t_start = time.perf_counter()
    rec = _patch_indices(receivers, "receivers", patches.n_patches)
    src = _patch_indices(sources, "sources", patches.n_patches)
    threads = _checked_counts(points_per_patch, shadow_rays, penumbra_points, penumbra_rays, far_ratio, threads)
    out = np.zeros((len(rec), len(src)))
    info = {"pairs": 0, "culled": 0, "far": 0, "levels": [0] * (MAX_LEVEL + 1), "clipped_receivers": 0,
            "evaluations": 0, "rays": 0, "penumbra_pairs": 0}
    if len(rec) and len(src):
        g = kernel_geometry(patches, int(points_per_patch), sampler)
        pairs = _Pairs(g, rec, src, far_ratio, info)
        if len(pairs.pr):
            transfer = _PairTransfer(g, pairs, info, int(shadow_rays), int(penumbra_points), int(penumbra_rays), seed)
            out[pairs.ii, pairs.jj] = transfer.run(threads, cancel, progress, info)
    if stats is not None:
        stats.update(info, seconds=time.perf_counter() - t_start)
    return out


def _patch_indices(x, name, P):
    """Patch indices (int64) of ``x``: indices, or a boolean mask over the P patches."""
    x = np.asarray(x)
    if x.dtype == bool:
        if x.shape != (P,):
            raise ValueError(f"{name} mask must have {P} entries, got shape {x.shape}")
        return np.flatnonzero(x)
    x = x.astype(np.int64).reshape(-1)
    if len(x) and (x.min() < 0 or x.max() >= P):
        raise ValueError(f"{name} must be patch indices in [0, {P})")
    return x


def _checked_counts(points_per_patch, shadow_rays, penumbra_points, penumbra_rays, far_ratio, threads) -> int:
    """kernel_form_factors' counts checked (ValueError naming the wrong one); the threads to use."""
    if not (isinstance(points_per_patch, (int, np.integer)) and points_per_patch >= 1):
        raise ValueError(f"points per patch must be a positive integer, got {points_per_patch!r}")
    if not (isinstance(shadow_rays, (int, np.integer)) and shadow_rays >= 0):
        raise ValueError(f"shadow rays must be a non-negative integer, got {shadow_rays!r}")
    if not (isinstance(penumbra_points, (int, np.integer)) and penumbra_points >= 0):
        raise ValueError(f"penumbra points must be a non-negative integer, got {penumbra_points!r}")
    if not (isinstance(penumbra_rays, (int, np.integer)) and penumbra_rays >= 1):
        raise ValueError(f"penumbra rays must be a positive integer, got {penumbra_rays!r}")
    if not far_ratio > 0:
        raise ValueError(f"far ratio must be positive, got {far_ratio!r}")
    if threads is None:
        threads = os.cpu_count() or 1
    if not (isinstance(threads, (int, np.integer)) and threads >= 1):
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return threads


class _Pairs:
    """The receiver x source pairs that exchange light, receiver-major: ``ii``, ``jj`` their
    places in the output, ``pr``, ``ps`` their patches, ``straddle`` (the receiver crosses the
    source's plane), ``far`` (the point kernel), ``lev`` the receiver rule's level and
    ``rule_level`` (-1: the coarse rule). Fills info's pairs, culled, far, levels, coarse."""

    def __init__(self, g: _Geometry, rec, src, far_ratio, info: dict):
        # all pairs, receiver-major; drop (r, r) and pairs with one patch behind the other
        ii = np.repeat(np.arange(len(rec)), len(src))
        jj = np.tile(np.arange(len(src)), len(rec))
        pr, ps = rec[ii], src[jj]
        keep = pr != ps
        ii, jj, pr, ps = ii[keep], jj[keep], pr[keep], ps[keep]
        # one patch entirely in or behind the other's plane: 0. A receiver crossing the source's
        # plane: its rule is clipped to the source's front (the source crossing the receiver's
        # plane is clipped exactly by the contour integral).
        _, mx_sr, tol_sr = _signed_range(g, pr, ps)  # source vertices vs the receiver's plane
        mn_rs, mx_rs, tol_rs = _signed_range(g, ps, pr)  # receiver vertices vs the source's plane
        culled = (mx_sr <= tol_sr) | (mx_rs <= tol_rs)  # False where NaN (not planar)
        straddle = (mn_rs < -tol_rs) & (mx_rs > tol_rs)
        info["culled"] = int(culled.sum())
        ii, jj, pr, ps, straddle = ii[~culled], jj[~culled], pr[~culled], ps[~culled], straddle[~culled]
        dist = np.linalg.norm(g.center[pr] - g.center[ps], axis=1)
        far = dist > far_ratio * np.maximum(g.diam[pr], g.diam[ps])
        gap = np.maximum(dist - g.radius[pr] - g.radius[ps], 0.0)
        scale = np.maximum(gap, g.width[ps])
        with np.errstate(divide="ignore"):
            lev = np.ceil(np.log2(g.diam[pr] / (LEVEL_SPAN * np.maximum(scale, TINY))))
        lev = np.where(far, 0, np.clip(lev, 0, MAX_LEVEL)).astype(np.int64)
        info["pairs"] = int(len(pr))
        info["far"] = int(far.sum())
        info["levels"] = np.bincount(lev, minlength=MAX_LEVEL + 1).tolist()
        # the rule of a pair: its level, or -1 (coarse: one node per triangle no larger than the node
        # spacing) for a pair whose gap exceeds COARSE_GAP x the receiver's diameter
        rule_level = np.where((lev == 0) & (gap > COARSE_GAP * g.diam[pr]), -1, lev)
        info["coarse"] = int(np.count_nonzero(rule_level < 0))
        self.ii, self.jj, self.pr, self.ps, self.straddle = ii, jj, pr, ps, straddle
        self.far, self.lev, self.rule_level = far, lev, rule_level


def _receiver_rules(g: _Geometry, pairs: _Pairs, info: dict):
    """The receiver point sets of the pairs in one array: (X, N, W) the points, normals and
    weights, (pstart, pcount) each pair's range in them; a (receiver, level) rule is made once,
    a pair whose receiver crosses the source's plane has a rule of its own."""
    pr, ps, rule_level = pairs.pr, pairs.ps, pairs.rule_level
    need = np.unique(pr * (MAX_LEVEL + 2) + rule_level + 1)
    for L in np.unique(need % (MAX_LEVEL + 2)):  # the rules not made yet, a level at a time
        g.make_receiver_rules(need[need % (MAX_LEVEL + 2) == L] // (MAX_LEVEL + 2), int(L) - 1)
    sets = {}
    xs, ns, ws = [], [], []
    base = 0
    for k in need:
        r, L = divmod(int(k), MAX_LEVEL + 2)
        x, n, w = g.receiver_points(r, L - 1)
        sets[int(k)] = (base, len(x))
        xs.append(x)
        ns.append(n)
        ws.append(w)
        base += len(x)
    rule_key = pr * (MAX_LEVEL + 2) + rule_level + 1
    lookup = np.array([sets[int(k)] for k in need], dtype=np.int64)
    pos = np.searchsorted(need, rule_key)
    pstart, pcount = lookup[pos, 0], lookup[pos, 1]
    info["clipped_receivers"] = int(pairs.straddle.sum())
    for k in np.flatnonzero(pairs.straddle):
        x, n, w = _clipped_receiver_points(g, pr[k], rule_level[k], ps[k])
        pstart[k], pcount[k] = base, len(x)
        xs.append(x)
        ns.append(n)
        ws.append(w)
        base += len(x)
    return np.concatenate(xs), np.concatenate(ns), np.concatenate(ws), pstart, pcount


class _PairTransfer:
    """The pairs' form factors, computed by chunks (contiguous pair ranges of about
    CHUNK_EVALS kernel evaluations, each with its own random stream): ``chunk(ci)`` fills
    ``values``, ``partial`` (pairs found in penumbra) and ``rays`` of chunk ci."""

    def __init__(self, g: _Geometry, pairs: _Pairs, info: dict, shadow_rays: int, penumbra_points: int,
                 penumbra_rays: int, seed):
        self.g, self.pairs = g, pairs
        self.keys = _pair_keys(g, pairs.pr, pairs.ps, seed)
        self.X, self.N, self.W, self.pstart, self.pcount = _receiver_rules(g, pairs, info)
        evals = self.pcount * g.tcount[pairs.ps]
        info["evaluations"] = int(evals.sum())
        self.chunks = _chunks(evals, CHUNK_EVALS)
        self.values = np.zeros(len(pairs.pr))
        self.partial = np.zeros(len(pairs.pr), dtype=bool)
        self.rays = np.zeros(len(self.chunks), dtype=np.int64)
        self.stop = threading.Event()
        self.S = shadow_rays
        self.Q = int(round(math.sqrt(penumbra_points))) ** 2  # a square: a jittered grid
        self.K2 = penumbra_rays

    def run(self, threads, cancel, progress, info: dict) -> np.ndarray:
        """Every chunk (sampling.run_chunks); the pairs' form factors. Fills info's rays and penumbra_pairs."""
        run_chunks(self.chunk, len(self.chunks), threads, self.stop, cancel, progress)
        if not np.all(np.isfinite(self.values)):
            raise SceneError("kernel form factors contain NaN or infinite values (degenerate geometry?)")
        info["rays"] = int(self.rays.sum())
        info["penumbra_pairs"] = int(self.partial.sum())
        return self.values

    def chunk(self, ci):
        if self.stop.is_set():
            return ci
        a, b = self.chunks[ci]
        pp_pair, fpt, vis, unoccluded, n_rays = self._quadrature(a, b)
        if self.S > 0 and self.Q > 0:
            n_rays += self._penumbra(a, b, pp_pair, fpt, vis, unoccluded)
        self.rays[ci] = n_rays
        return ci

    def _quadrature(self, a, b):
        """Phase 1: the quadrature rule of every pair's receiver (at the pair's level), with
        shadow rays; values[a:b] and the unoccluded estimate kept for phase 2."""
        g, S = self.g, self.S
        cps, clev, cfar = self.pairs.ps[a:b], self.pairs.lev[a:b], self.pairs.far[a:b]
        npp = self.pcount[a:b]
        pp_pair = np.repeat(np.arange(b - a), npp)
        pp_pt = _ragged(self.pstart[a:b], npp)
        fpt = _source_kernel(g, self.X[pp_pt], self.N[pp_pt], cps[pp_pair], cfar[pp_pair])
        vis = np.ones(len(pp_pair))
        n_rays = 0
        if S > 0:
            for L in np.unique(clev):
                sel = np.flatnonzero((fpt > 0) & (clev[pp_pair] == L))
                if len(sel) == 0:
                    continue
                k = max(1, S >> (2 * int(L)))
                # each receiver point's rays on its pair's stream, at the point's place in its rule
                local = (pp_pt[sel] - self.pstart[a:b][pp_pair[sel]]).astype(np.uint64)
                rng = _KeyedStream(_mix(self.keys[a:b][pp_pair[sel]] ^ (local * _ODD1 + _TAG_PHASE1)))
                vis[sel], nr = _visibility(g, self.X[pp_pt[sel]], self.N[pp_pt[sel]], cps[pp_pair[sel]], k, rng)
                n_rays += nr
        self.values[a:b] = np.bincount(pp_pair, weights=self.W[pp_pt] * fpt * vis, minlength=b - a)
        unoccluded = np.bincount(pp_pair, weights=self.W[pp_pt] * fpt, minlength=b - a)
        return pp_pair, fpt, vis, unoccluded, n_rays

    def _penumbra(self, a, b, pp_pair, fpt, vis, unoccluded) -> int:
        """Phase 2: pairs partly in shadow (some visibility ray blocked, some not) again, with
        jittered receiver points (the Gauss rule is no good across a shadow edge); the rays cast."""
        Q, K2, cps = self.Q, self.K2, self.pairs.ps[a:b]
        live = fpt > 0
        vmin = np.ones(b - a)
        vmax = np.zeros(b - a)
        np.minimum.at(vmin, pp_pair[live], vis[live])
        np.maximum.at(vmax, pp_pair[live], vis[live])
        part = np.flatnonzero((vmin < 1) & (vmax > 0))
        self.partial[a + part] = True
        per = max(1, PENUMBRA_BATCH_RAYS // (Q * K2))
        n_rays = 0
        for q0 in range(0, len(part), per):
            sub = part[q0:q0 + per]
            key = self.keys[a + sub]
            x, n = _sample_patches(self.g, self.pairs.pr[a + sub], Q, _KeyedStream(_mix(key ^ _TAG_JITTER)))
            x, n = x.reshape(-1, 3), n.reshape(-1, 3)
            point = np.tile(np.arange(Q, dtype=np.uint64), len(sub))  # (the jittered point's place)
            rng = _KeyedStream(_mix(np.repeat(key, Q) ^ (point * _ODD1 + _TAG_PENUMBRA)))
            wv, ws, nr = _visibility(self.g, x, n, np.repeat(cps[sub], Q), K2, rng, sums=True)
            n_rays += nr
            # ratio estimate: the (accurate) unoccluded F of phase 1 times the visible
            # fraction of the point-to-point kernel over all the rays of the pair
            fv = wv.reshape(len(sub), Q).sum(axis=1)
            fs = ws.reshape(len(sub), Q).sum(axis=1)
            self.values[a + sub] = unoccluded[sub] * fv / np.where(fs > 0, fs, 1.0)
        return n_rays


_ODD1 = np.uint64(0x9E3779B97F4A7C15)  # (splitmix64's increment)
_ODD2 = np.uint64(0xD1B54A32D192ED03)
_TAG_PHASE1, _TAG_JITTER, _TAG_PENUMBRA = np.uint64(1), np.uint64(2), np.uint64(3)
with np.errstate(over="ignore"):
    _STEP = np.arange(1, 10, dtype=np.uint64) * _ODD2  # (a vertex coordinate's place in its triangle)


def _mix(x):
    """splitmix64's finaliser of uint64 ``x`` (elementwise, wrapping): a bijective hash."""
    x = np.asarray(x, dtype=np.uint64)
    with np.errstate(over="ignore"):  # (the multiplications wrap, as the hash means them to)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _patch_keys(g: _Geometry) -> np.ndarray:
    """(P,) uint64: a hash of each patch's triangles (their vertices in scale-free steps,
    scene.key_lengths, XORed over the patch's triangles: their order does not matter), the same
    for the same patch in another mesh or PatchSet, and in the scene scaled; kept on the geometry."""
    keys = getattr(g, "_patch_keys", None)
    if keys is None:
        bits = key_lengths(g.tv, key_scale(g.tv)).reshape(len(g.tv), 9).view(np.uint64)
        h = np.zeros(len(bits), dtype=np.uint64)
        for k in range(9):
            h = _mix(h ^ bits[:, k] ^ _STEP[k])
        keys = np.zeros(g.P, dtype=np.uint64)
        np.bitwise_xor.at(keys, g.tri_patch, h)
        g._patch_keys = keys = _mix(keys ^ g.tcount.astype(np.uint64))
    return keys


def _pair_keys(g: _Geometry, pr, ps, seed) -> np.ndarray:
    """(pairs,) uint64: each (receiver, source) pair's stream key, from the seed and the two patches'
    geometry (``_patch_keys``): a pair's samples are its own, whatever else is drawn with it."""
    keys = _patch_keys(g)
    s0 = _mix(np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF) ^ _ODD2)
    return _mix(_mix(keys[pr] ^ s0) ^ (keys[ps] * _ODD1))


class _KeyedStream:
    """Counter-based uniforms in place of a numpy Generator for ``_sample_patches``: row i of
    ``random((m, ...))`` is a hash of ``keys[i]`` and the value's place in the row, so a row's
    samples depend on its key alone (not on the rows drawn with it)."""

    def __init__(self, keys):
        self.keys = np.asarray(keys, dtype=np.uint64)

    def random(self, shape, dtype=np.float64):
        m, per = shape[0], int(np.prod(shape[1:], dtype=np.int64))
        if m != len(self.keys):
            raise ValueError(f"{m} rows asked of {len(self.keys)} keys")
        with np.errstate(over="ignore"):
            x = _mix(self.keys[:, None] + (np.arange(1, per + 1, dtype=np.uint64) * _ODD1)[None, :])
        if np.dtype(dtype) == np.float32:  # 24 bits: every value exact in float32, in [0, 1)
            u = (x >> np.uint64(40)).astype(np.float32) * np.float32(1.0 / (1 << 24))
        else:
            u = (x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))
        return u.reshape(shape)


def _source_kernel(g: _Geometry, x, n, s, far):
    """F_pt from points x (normals n) to source patches s, one source per point, (m,):
    the clipped contour integral per source triangle, or the point kernel where ``far``. A
    parallelogram source wholly in front of the point is one contour of four edges (the
    diagonal's two terms cancel)."""
    out = np.zeros(len(x))
    rest = np.ones(len(x), dtype=bool)
    q = np.flatnonzero(g.para[s] & ~far)
    if len(q):
        V, xq, nq = g.quad[s[q]], x[q], n[q]
        r = [V[:, k] - xq for k in range(4)]
        whole = _dot(xq - V[:, 0], g.normal[s[q]]) > 0
        for rk in r:
            whole &= _dot(rk, nq) > 0
        w = np.flatnonzero(whole)
        if len(w):
            out[q[w]] = np.maximum(-_contour([rk[w] for rk in r], nq[w]), 0.0) * (0.5 / np.pi)
            rest[q[w]] = False
    idx = np.flatnonzero(rest)
    if len(idx) == 0:
        return out
    s, far = s[idx], far[idx]
    ntri = g.tcount[s]
    ev = np.repeat(idx, ntri)
    tri = _ragged(g.tstart[s], ntri)
    kval = np.zeros(len(ev))
    fe = np.repeat(far, ntri)
    near = np.flatnonzero(~fe)
    if len(near):
        e, t = ev[near], tri[near]
        kval[near] = _lambert(x[e], n[e], g.tv[t], g.tn[t])
    fars = np.flatnonzero(fe)
    if len(fars):
        e, t = ev[fars], tri[fars]
        kval[fars] = _point_kernel(x[e], n[e], g.tc[t], g.tn[t], g.ta[t])
    out += np.bincount(ev, weights=kval, minlength=len(x))
    return out


def _sample_patches(g: _Geometry, s, k, rng):
    """k stratified points on each patch s[i] (float32): a jittered grid (k a square) or
    strata along the first coordinate. A parallelogram patch (two triangles, e.g. a grid
    cell) maps the grid affinely onto itself; any other patch picks triangles by area
    (the first coordinate through its area CDF). Points are set in from the edges by
    2 * offset. Returns points (m, k, 3) and their normals (m, k, 3)."""
    m = len(s)
    s = np.asarray(s, dtype=np.int64)
    gk = int(math.isqrt(k))
    u = rng.random((m, k, 2), dtype=np.float32)
    if gk * gk == k:
        ia, ib = np.divmod(np.arange(k, dtype=np.float32), np.float32(gk))
        u[..., 0] += ia
        u[..., 1] += ib
        u *= np.float32(1.0 / gk)
    else:  # strata along the first coordinate, the second random
        u[..., 0] += np.arange(k, dtype=np.float32)
        u[..., 0] *= np.float32(1.0 / k)
    # (u may round to 1.0 in float32: the far edge of the set-in patch, still inside)
    para = g.para[s]
    if para.all():  # the common case (grid cells): no per-sample gathers at all
        G = g.pgeo[s]
        y = G[:, None, 0:3] + u[..., 0:1] * G[:, None, 3:6]
        y += u[..., 1:2] * G[:, None, 6:9]
        return y, np.broadcast_to(G[:, None, 9:12], (m, k, 3))
    y = np.empty((m, k, 3), dtype=np.float32)
    ny = np.empty((m, k, 3), dtype=np.float32)
    ip = np.flatnonzero(para)
    if len(ip):
        G = g.pgeo[s[ip]]  # (mp, 12): origin, edge u, edge v, normal
        up = u[ip]
        yp = G[:, None, 0:3] + up[..., 0:1] * G[:, None, 3:6]
        yp += up[..., 1:2] * G[:, None, 6:9]
        y[ip] = yp
        ny[ip] = G[:, None, 9:12]
    ig = np.flatnonzero(~para)
    if len(ig):
        ug = u[ig].reshape(-1, 2).astype(np.float64)
        src = np.repeat(s[ig], k)
        tri = np.searchsorted(g.key, src + ug[:, 0], side="right")
        np.minimum(tri, len(g.key) - 1, out=tri)
        sv = np.clip((ug[:, 0] - g.cdf_lo[tri]) / g.cdf_w[tri], 0.0, 1.0)
        su = np.sqrt(sv)
        b2 = su * ug[:, 1]
        b1 = su - b2
        G = g.tgeo[tri]  # (n, 12): shrunk v0, e1, e2, normal
        yg = G[:, 0:3] + b1[:, None].astype(np.float32) * G[:, 3:6] + b2[:, None].astype(np.float32) * G[:, 6:9]
        y[ig] = yg.reshape(len(ig), k, 3)
        ny[ig] = G[:, 9:12].reshape(len(ig), k, 3)
    return y, ny


def _visibility(g: _Geometry, x, n, s, k, rng, sums=False):
    """Kernel-weighted visible fraction of source patch s[i] from point x[i] (normal n[i]),
    from k shadow rays each (stratified over the source). Returns (V (m,), rays), or with
    ``sums`` (sum w v (m,), sum w (m,), rays)."""
    m = len(x)
    y, ny = _sample_patches(g, s, k, rng)
    x32 = np.asarray(x, dtype=np.float32)
    n32 = np.asarray(n, dtype=np.float32)
    d = y - x32[:, None, :]
    r2 = np.einsum("mkj,mkj->mk", d, d)
    cx = np.einsum("mkj,mj->mk", d, n32)
    cy = np.einsum("mkj,mkj->mk", d, ny)
    np.maximum(cx, 0, out=cx)
    np.minimum(cy, 0, out=cy)
    r2 *= r2
    np.maximum(r2, np.float32(1e-30), out=r2)
    w = cx * -cy / r2  # (m, k)
    live = w > 0
    n_live = int(np.count_nonzero(live))
    vis = np.zeros((m, k), dtype=np.float32)
    if n_live:
        off = np.float32(g.offset)
        xo = x32 + off * n32
        if n_live > 0.8 * m * k:  # trace them all (a ray with w = 0 counts for nothing)
            org = np.repeat(xo, k, axis=0)
            dv = (y + off * ny).reshape(-1, 3)
            sel = None
        else:
            row, col = np.nonzero(live)
            org = xo[row]
            dv = y[row, col] + off * ny[row, col]
            sel = (row, col)
        dv -= org
        length = np.sqrt(np.einsum("ij,ij->i", dv, dv))
        dv /= np.maximum(length, np.float32(1e-30))[:, None]
        tfar = np.maximum(length - off, np.float32(0.5) * length)
        free = g.sampler.visible(org, dv, tfar)
        if sel is None:
            vis = free.reshape(m, k).astype(np.float32)
        else:
            vis[sel] = free
    wsum = w.sum(axis=1, dtype=np.float64)
    wvis = (w * vis).sum(axis=1, dtype=np.float64)
    if sums:
        return wvis, wsum, n_live
    V = np.where(wsum > 0, wvis / np.where(wsum > 0, wsum, 1.0), 1.0)
    return V, n_live


# --------------------------------------------------------------------------------------
#: ``lights_direct_correction``'s receiver points and shadow rays per pair and penumbra points
#: (kernel_form_factors' defaults; the living room's 18 lights on its 2305 patches: 3.4 s)
DIRECT_POINTS = 16
DIRECT_SHADOW_RAYS = 4
DIRECT_PENUMBRA_POINTS = 100


def lights_direct_correction(patches: PatchSet, F, lights, members, send=None, skip=None, seed: int = 0,
                             sampler: SceneSampler | None = None, cancel=None) -> np.ndarray:
    """(P, len(lights)) W/m^2 per unit exitance: the direct light of surface lights on every patch
    by the kernel (``kernel_form_factors``) minus what the ray-cast F gathers of it. ``members(j)``:
    light j's patches (all at its one exitance). ``send`` (P,): the factor F's columns carry
    (formfactors.sending_scale), taken out of them: the kernel gathers an emitter's light from its
    visible part already, as the problem's source does (InverseProblem.emission_share).
    ``skip``: receivers left as they are (0: their F entries are kernel
    estimates already, e.g. the targets of the estimator's kernel pairs)."""
    P = patches.n_patches
    own = [np.asarray(members(j), dtype=np.int64) for j in lights]
    src = np.unique(np.concatenate(own)) if own else np.zeros(0, dtype=np.int64)
    out = np.zeros((P, len(lights)))
    if len(src) == 0:
        return out
    K = kernel_form_factors(patches, np.arange(P), src, DIRECT_POINTS, DIRECT_SHADOW_RAYS, seed=seed,
                            sampler=sampler, cancel=cancel, penumbra_points=DIRECT_PENUMBRA_POINTS)
    cols = F[:, src]
    cols = cols.toarray() if sp.issparse(cols) else np.asarray(cols, dtype=np.float64)
    if send is not None:  # F's gather of the exitance that leaves a partly buried source
        cols = cols / np.asarray(send, dtype=np.float64)[src][None, :]
    D = K - cols
    if skip is not None:
        D[np.asarray(skip)] = 0.0
    where = {int(p): i for i, p in enumerate(src)}
    for k, members_k in enumerate(own):
        out[:, k] = D[:, [where[int(p)] for p in members_k]].sum(axis=1)
    return out


# storing the estimates in a form-factor matrix

#: a row the kernel's pairs bring above 1 + ROW_SLACK is scaled back to 1 (below it: the
#: estimators' noise in a closed scene)
ROW_SLACK = 0.01


def _within_unit_rows(F, ui, uj, val):
    """The kernel's values ``val`` at (ui, uj), scaled down in each row that they would bring above
    1 + ROW_SLACK (the share of a patch's light that reaches the scene is at most 1): coincident or
    overlapping faces (tiles laid on a wall, a decal on its own plane) are each seen whole by the
    point-to-polygon kernel, where the rays see one of them; the row's other entries are kept and
    the kernel's share takes what is left of 1."""
    P = F.shape[0]
    rows = np.unique(ui)
    if sp.issparse(F):
        Fr = F.tocsr()[rows]
        total = np.asarray(Fr.sum(axis=1), dtype=np.float64).ravel()
        old = np.asarray(F.tocsr()[ui, uj], dtype=np.float64).ravel()
    else:
        total = F[rows].sum(axis=1, dtype=np.float64)
        old = F[ui, uj].astype(np.float64)
    at = np.searchsorted(rows, ui)
    kept = total - np.bincount(at, weights=old, minlength=len(rows))
    new = np.bincount(at, weights=val, minlength=len(rows))
    over = kept + new > 1.0 + ROW_SLACK
    if not over.any():
        return val
    f = np.ones(len(rows))
    f[over] = np.clip(1.0 - kept[over], 0.0, None) / new[over] * (1 - 2.0 ** -20)
    return val * f[at]


def apply_kernel_pairs(F, area, rows, cols, values):
    """Replace F[rows, cols] by ``values`` (len(rows), len(cols)) (receiver x source form
    factors, e.g. from kernel_form_factors) and, by reciprocity, F[cols, rows] by
    A_r F_rs / A_s: one estimate serves both directions.

    ``F``: a FormFactors (its matrix is replaced) or a (P, P) matrix: a dense ndarray is
    modified in place, a scipy.sparse matrix is replaced by a new CSR matrix; the result
    is returned either way (same dtype). ``area``: (P,) patch areas (or a PatchSet).
    A pair estimated in both directions (a patch in both rows and cols) gets the mean of
    the two power estimates A_r F_rs. Diagonal entries (r, r) are left as they are. A row the
    values would bring above 1 + ROW_SLACK keeps its sum at 1 (``_within_unit_rows``).
    ``rows``, ``cols``: patch indices or boolean masks over the patches.
    """
    holder = None
    if hasattr(F, "matrix"):
        holder, F = F, F.matrix
    if hasattr(area, "area"):
        area = area.area
    area = np.asarray(area, dtype=np.float64).reshape(-1)
    P = F.shape[0]
    if F.shape != (P, P) or len(area) != P:
        raise ValueError(f"F must be (P, P) with P = len(area) = {len(area)}, got {F.shape}")
    rows, cols = np.asarray(rows), np.asarray(cols)
    rows = (np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.int64)).reshape(-1)
    cols = (np.flatnonzero(cols) if cols.dtype == bool else cols.astype(np.int64)).reshape(-1)
    values = np.asarray(values, dtype=np.float64).reshape(len(rows), len(cols))
    r = np.repeat(rows, len(cols))
    c = np.tile(cols, len(rows))
    G = area[r] * values.reshape(-1)  # power-exchange estimates A_r F_rs
    off = r != c
    r, c, G = r[off], c[off], G[off]
    # both directions of every pair, duplicates (pairs estimated twice) averaged
    i = np.concatenate([r, c])
    j = np.concatenate([c, r])
    key = i * P + j
    uk, inv = np.unique(key, return_inverse=True)
    gsum = np.bincount(inv, weights=np.concatenate([G, G]))
    cnt = np.bincount(inv)
    ui, uj = np.divmod(uk, P)
    val = gsum / cnt / area[ui]
    val = _within_unit_rows(F, ui, uj, val)
    if sp.issparse(F):
        dtype = F.dtype
        F = F.tocsr()
        mask = sp.csr_matrix((np.ones(len(ui)), (ui, uj)), shape=(P, P))
        new = sp.csr_matrix((val, (ui, uj)), shape=(P, P))
        F = (F - F.multiply(mask) + new).tocsr().astype(dtype)
        F.eliminate_zeros()
    else:
        F[ui, uj] = val
    if holder is not None:
        holder.matrix = F
        return holder
    return F
