"""The radiance a surface shows along a view direction, from the radiosity solution and its
material's BSDF (pure math, no bpy).

The radiosity engine models every surface as Lambertian with its white-furnace albedo: B/pi is
the cosine-weighted mean of the radiance it sends over the hemisphere. A glossy material
(a Principled BSDF's specular layer) sends more towards the mirror directions of its incident
light and less elsewhere, so what one view shows differs from B/pi: a bake (every face viewed
along its normal) shows less than B/pi on a face lit at grazing incidence (measured: 8 % on a
red wall lit from the ceiling next to it) and more on one lit from straight above.

``view_radiance`` gathers a patch's incident light from the form factors: patch i receives
the radiance L_j(v_ji) that patch j sends towards it over a cosine-weighted solid angle
pi F_ij, so the radiance seen along v is

    L_i(v) = e_i/pi + sum_j f_i(l_ij, v) F_ij pi L_j(v_ji),

f_i the material's BSDF as Cycles evaluates it (engine.principled.BRDFTable: the layering
weights at the view direction, the GGX lobes with their energy compensation) at the direction
l_ij of patch j's centre, e = B - rho F B the configuration's exitance. A source sends its own
emission, its reflection of the emitters' light through its BSDF towards i (a wall lit at
grazing incidence by a ceiling lamp mirrors it down to the floor), and the rest of its light
as the Lambertian model does:

    L_j(v) = e_j/pi + sum_(k emits) f_j(l_jk, v) F_jk e_k + rho_j (H_j - sum_(k emits) F_jk e_k)/pi,

H_j = (F B)_j its irradiance. For Lambertian materials f = rho/pi and L = B/pi exactly. Left
out: the direction of light after two reflections, and glossy lobes narrower than the patches
seen (engine.principled.VIEW_ALPHA_MIN). Checked against Cycles bakes in
tests/test_cycles_principled.py (a floor under a lamp, a Cornell box, a furnished room;
docs/validation.md).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .principled import BRDFTable
from .units import TINY, radiance_from_exitance

__all__ = ["view_radiance", "view_rows", "HORIZON"]

#: smallest cosine of a source direction: a patch seen by i (F_ij > 0) may have its centre
#: behind i's plane (a large patch reaching under i); it is taken just above the horizon
HORIZON = 0.02
#: largest (target patch, source patch, emitter patch) triples for the sources' glossy reflection
MAX_PAIRS = 40_000_000


def frames(normal) -> np.ndarray:
    """(n, 3, 3): the local frame of each of the normals ``normal`` (n, 3) (or one (3,)), rows local x,
    y, z (z the unit normal; x across the world x axis, or the y axis for a normal near x)."""
    n = np.asarray(normal, dtype=np.float64).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    a = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return np.stack([t1, np.cross(n, t1), n], axis=1)


def view_radiance(F, B, reflectance, center, normal, patches, material, material_lobes, view=None,
                  source_glossy=True, max_pairs=MAX_PAIRS, exitance=None, lamp_light=None,
                  emission_share=None, direct_correction=None) -> np.ndarray:
    """(len(patches), 3) radiance (W m^-2 sr^-1) seen along ``view`` (world unit vectors
    (len(patches), 3); default: each patch's normal, what a bake shows) on ``patches``.

    ``F``: form factors (FormFactors or a (P, P) array / sparse matrix), ``B`` (P, 3) the
    radiosity solved with the Lambertian ``reflectance`` (P, 3), ``center`` and ``normal``
    (P, 3), ``material`` (P,) indexes ``material_lobes`` (each a material's BSDFs,
    engine.principled.BRDFTable). ``source_glossy``: the sources' reflection of the emitters'
    light through their own BSDF towards the patch (module docstring); skipped when
    patches x sources x emitters exceeds ``max_pairs``. ``exitance`` (P, 3): the emitters'
    exitance e; default B - rho F B (right when B was solved without engine.incidence's
    first-reflection term, which B - rho F B would count as emission). ``lamp_light``: [(towards
    (P, 3) unit world directions from each patch to a lamp, or None for light from every
    direction (the World), H (P, 3) its direct irradiance W/m^2)]: each lamp's light reflected
    through the patch's BSDF at its direction, f(l, v) H (the World's: rho H / pi).
    ``emission_share`` (P,): the share of an emitter's exitance that leaves it into the scene (its
    visible part where it is partly buried: InverseProblem.emission_share; F's columns carry the
    inverse), applied where it sends; a patch's own emission is seen whole. ``direct_correction``
    (P, P) sparse: per unit of emitter k's exitance, the direct irradiance the kernel estimator
    finds beyond F's gather (InverseProblem.emitter_direct_correction); the sources' glossy
    reflection of the emitters takes it (a ray-cast F entry between a source and a small bright
    cell near its horizon is noisy, and a grazing glossy lobe magnifies it)."""
    M = getattr(F, "matrix", F)
    B = np.asarray(B, dtype=np.float64)
    rho = np.asarray(reflectance, dtype=np.float64)
    material = np.asarray(material, dtype=np.int64)
    patches = np.asarray(patches, dtype=np.int64)
    FB = np.asarray(M @ B, dtype=np.float64)
    e_own = B - rho * FB if exitance is None else np.asarray(exitance, dtype=np.float64)  # what a patch shows
    e = e_own  # what it sends
    if emission_share is not None and exitance is not None:
        e = e * np.asarray(emission_share, dtype=np.float64).reshape(-1, 1)
    tables = {int(m): BRDFTable(material_lobes[m]) for m in np.unique(material)}
    frame_of = frames(normal)  # (P, 3, 3): rows local x, y, z
    E = np.flatnonzero(np.any(e > 1e-9 * max(float(e.max()), TINY), axis=1))
    rows = M[patches]
    rows = rows.tocsr() if sp.issparse(rows) else np.asarray(rows)
    nnz = rows.nnz if sp.issparse(rows) else int(np.count_nonzero(rows))
    sources = None
    if source_glossy and len(E) > 0 and nnz * len(E) <= max_pairs:
        sources = _GlossySources(M, E, e, e_own, rho, FB, B, center, frame_of, material, tables, direct_correction,
                                 lamp_light)
    out = np.empty((len(patches), 3))
    for k, i in enumerate(patches):
        js, fij = _row(rows, k)
        R = frame_of[i]
        v = np.array([0.0, 0.0, 1.0]) if view is None else R @ np.asarray(view[k], dtype=np.float64)
        d = center[js] - center[i]
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), TINY)
        f = tables[int(material[i])](v, _above(d @ R.T))
        src = radiance_from_exitance(B[js]) if sources is None else sources.towards(js, d)
        solid_angle = np.asarray(fij, dtype=np.float64)[:, None] * np.pi  # pi F_ij: j's projected solid angle
        out[k] = radiance_from_exitance(e_own[i]) + np.sum(f * (solid_angle * src), axis=0)
        for towards, H in lamp_light or ():
            if towards is None or np.any(H[i] > 0):
                out[k] += _lamp_seen(towards, H, i, rho, tables[int(material[i])], v, R)
    return out


def _lamp_seen(towards, H, i, rho, table, v, R):
    """(3,) the radiance along local ``v`` of patch i (frame R, BSDF table) reflecting a lamp's
    direct irradiance H[i] from world direction towards[i] (``towards`` None: the World's, from
    every direction, reflected Lambertian at reflectance rho[i])."""
    if towards is None:
        return radiance_from_exitance(rho[i] * H[i])
    return table(v, _above((R @ towards[i])[None, :]))[0] * H[i]


class _GlossySources:
    """The radiance sources send towards a patch: their emission, their reflection of the
    emitters' light (patches ``E``) through their own BSDF, and the rest of their light
    Lambertian (module docstring)."""

    def __init__(self, M, E, e, e_own, rho, FB, B, center, frames, material, tables, direct_correction, lamp_light):
        self.E, self.e, self.e_own, self.frames, self.material, self.tables = E, e, e_own, frames, material, tables
        FE = M[:, E]
        self.FE = (FE.toarray() if sp.issparse(FE) else np.asarray(FE)).astype(np.float64)  # (P, |E|)
        dE = center[None, E, :] - center[:, None, :]
        dE /= np.maximum(np.linalg.norm(dE, axis=2, keepdims=True), TINY)
        self.lE = _above(np.einsum("jab,jkb->jka", frames, dE))  # (P, |E|, 3) to each emitter, local
        H_direct = self.FE @ e[E]  # F's gather, what the Lambertian rest below takes out of F B
        self.XE = None
        if direct_correction is not None:
            XE = direct_correction[:, E]
            self.XE = (XE.toarray() if sp.issparse(XE) else np.asarray(XE)).astype(np.float64)
        # the rest of the light, sent Lambertian: what the emitters' light leaves of F B, and the
        # lamps' and the World's direct light (in B, not in F B)
        H_lamps = sum((np.asarray(H, dtype=np.float64) for _, H in lamp_light or ()), np.zeros_like(B))
        self.indirect = radiance_from_exitance(rho * (FB - H_direct + H_lamps))

    def towards(self, js, d):
        """(len(js), 3) the radiance sources ``js`` send along -d (d: unit world directions to them)."""
        E, e, material = self.E, self.e, self.material
        src = radiance_from_exitance(e[js]) + self.indirect[js]
        vj = _above(np.einsum("jab,jb->ja", self.frames[js], -d))  # towards i, in each source's frame
        for m in np.unique(material[js]):
            sel = np.flatnonzero(material[js] == m)
            g = self.tables[int(m)](vj[sel][:, None, :], self.lE[js[sel]])  # (n, nE, 3)
            src[sel] += np.einsum("jkc,jk,kc->jc", g, self.FE[js[sel]], e[E])
            if self.XE is not None:
                src[sel] += np.einsum("jkc,jk,kc->jc", g, self.XE[js[sel]], self.e_own[E])
        return src


def _row(rows, k):
    """(the patches j row k of F sees, F_kj) of ``rows`` (CSR or dense)."""
    if sp.issparse(rows):
        return rows.indices[rows.indptr[k]:rows.indptr[k + 1]], rows.data[rows.indptr[k]:rows.indptr[k + 1]]
    js = np.flatnonzero(rows[k])
    return js, rows[k, js]


def _above(loc):
    """Unit local directions lifted to at least HORIZON above the tangent plane."""
    loc = np.array(loc, dtype=np.float64)
    loc[..., 2] = np.maximum(loc[..., 2], HORIZON)
    return loc / np.linalg.norm(loc, axis=-1, keepdims=True)


#: a source patch whose centre lies within LOBE_REACH x the material's narrowest GGX alpha (plus the
#: patch's own angular radius) of a viewed point's mirror direction is read over its area (SourcePoints)
LOBE_REACH = 3.0
#: such a source is read at g x g points, g = ceil(its angular diameter / (alpha / 2)), 2 <= g <= MAX_SIDE
MAX_SIDE = 8


class _Midpoints:
    """An rng for kernel_transfer._sample_patches that puts each point at the middle of its stratum."""

    @staticmethod
    def random(shape, dtype=np.float64):
        return np.full(shape, 0.5, dtype=dtype)


class SourcePoints:
    """The g x g points of a patch at the middles of its strata (kernel_transfer._sample_patches: a
    grid cell's affine grid, any other patch's triangles by area), and the patches' areas: what
    view_rows reads a source near a glossy lobe at."""

    def __init__(self, patches, sampler):
        self.patches, self.sampler = patches, sampler
        self.area = np.asarray(sampler.area, dtype=np.float64)
        # g -> (slot (P,) of each patch's points in the store, -1 before they are made; points, normals,
        # how many stored): a patch's points are its own (the middles of its strata), made once
        self._kept = {}

    def __call__(self, s, g) -> tuple:
        """(points (len(s), g*g, 3), normals (len(s), g*g, 3)) of the patches ``s``."""
        from .kernel_transfer import _sample_patches, kernel_geometry

        s = np.asarray(s, dtype=np.int64)
        if g not in self._kept:
            self._kept[g] = [np.full(self.patches.n_patches, -1, dtype=np.int64), np.empty((0, g * g, 3)),
                             np.empty((0, g * g, 3)), 0]
        kept = self._kept[g]
        slot = kept[0]
        new = np.unique(s[slot[s] < 0])
        if len(new):
            y, ny = _sample_patches(kernel_geometry(self.patches, g * g, self.sampler), new, g * g, _Midpoints())
            n = kept[3]
            if n + len(new) > len(kept[1]):  # (the store doubles as it fills)
                size = max(2 * len(kept[1]), n + len(new))
                for a in (1, 2):
                    grown = np.empty((size, g * g, 3))
                    grown[:n] = kept[a][:n]
                    kept[a] = grown
            kept[1][n:n + len(new)] = y
            kept[2][n:n + len(new)] = ny
            slot[new] = np.arange(n, n + len(new))
            kept[3] = n + len(new)
        return kept[1][slot[s]], kept[2][slot[s]]


def _lobe_means(f, x, v_loc, R, js, l_loc, dist, table, alpha, sources):
    """``f`` (n, J, 3), the BSDF at the sources' centres, with each (point, source) pair near the
    lobe (LOBE_REACH) replaced by its mean over the source's points, weighted by their share of the
    form factor (cos at the point x cos at the source / r^2): the lobe integrated over the patch
    instead of read at its centre (a lobe about as wide as the patches' spacing is otherwise
    aliased: on a Roughness 0.25 table under 0.2 m patches the centres' sum of pi f F_ij ranged
    over 0.63-1.59 x the lobe's directional albedo from point to point)."""
    radius = np.sqrt(sources.area[js] / np.pi)[None, :] / np.maximum(dist, TINY)  # (n, J) angular radius
    mirror = v_loc * np.array([-1.0, -1.0, 1.0])
    ang = np.arccos(np.clip(np.einsum("njc,nc->nj", l_loc, mirror), -1.0, 1.0))
    near = ang < LOBE_REACH * alpha + radius
    side = np.clip(np.ceil(2.0 * radius / alpha), 2, MAX_SIDE).astype(np.int64)
    out = f.copy()
    for g in np.unique(side[near]):
        pn, jn = np.nonzero(near & (side == g))
        y, ny = sources(js[jn], int(g))  # (m, K, 3): each pair's source's points
        d = y - x[pn][:, None, :]  # (m, K, 3) from the point to each source point
        r2 = np.maximum(np.einsum("mkc,mkc->mk", d, d), TINY)
        d /= np.sqrt(r2)[..., None]
        loc = d @ R.T
        w = np.maximum(loc[..., 2], 0.0) * np.maximum(-np.einsum("mkc,mkc->mk", d, ny), 0.0) / r2
        w_sum = w.sum(axis=1, keepdims=True)
        keep = w_sum[:, 0] > 0
        fk = table(v_loc[pn][:, None, :], _above(loc))  # (m, K, 3)
        mean = np.einsum("mk,mkc->mc", w / np.where(w_sum > 0, w_sum, 1.0), fk)
        out[pn[keep], jn[keep]] = mean[keep]
    return out


def view_rows(F, reflectance, center, normal, patch, points, views, material, material_lobes, sources=None,
              tables=None):
    """The radiance seen along ``views`` (n, 3) unit world directions from the viewer at ``points``
    (n, 3) on patches ``patch`` (n,), as rows on the radiosity: (js, W), W (n, len(js), 3) the
    coefficients such that pi L_c = sum_j W[:, j, c] B[js[j], c] (pi times the radiance: W/m^2, the
    radiosity's units), per channel c.

    It is ``view_radiance`` without the sources' glossy reflection (source_glossy=False: every
    source sends B_j/pi), written linearly in B with e_i = B_i - rho_i (F B)_i:

        pi L_i(v) = B_i + sum_j (pi f_i(l_xj, v) - rho_i) F_ij B_j,

    l_xj the direction from the viewed point x (not the patch's centre: a highlight moves across a
    patch with the point) to source j's centre. A Lambertian patch (f = rho/pi) reads B_i alone.
    A lamp's direct light (in B_i, not in F B) is seen Lambertian here; its glossy reflection is
    added beyond these rows (engine.view_lamps, a view target's ``lamp_terms``). Every patch of ``patch`` is one
    patch (group the points by patch first); ``views`` point from the viewer to the surface.
    ``tables``: a dict the calls of one image share, material -> its BRDFTable (built once)."""
    M = getattr(F, "matrix", F)
    i = int(np.unique(np.asarray(patch, dtype=np.int64))[0]) if len(patch) else 0
    if np.any(np.asarray(patch) != i):
        raise ValueError("view_rows reads one patch at a time")
    if sp.issparse(M) and M.format == "csr":
        js, fij = _row(M, i)
    else:
        row = M[i]
        row = row.tocsr() if sp.issparse(row) else sp.csr_matrix(np.asarray(row).reshape(1, -1))
        js, fij = row.indices, row.data
    fij = np.asarray(fij, dtype=np.float64)
    keep = js != i
    js, fij = js[keep], fij[keep]
    n = len(points)
    R = frames(normal[i])[0]
    v_loc = _above(-np.asarray(views, dtype=np.float64) @ R.T)  # towards the viewer, local
    x = np.asarray(points, dtype=np.float64)
    d = center[js][None, :, :] - x[:, None, :]  # (n, J, 3)
    dist = np.linalg.norm(d, axis=2)
    d /= np.maximum(dist, TINY)[..., None]
    l_loc = _above(d @ R.T)
    tables = {} if tables is None else tables
    if int(material[i]) not in tables:
        tables[int(material[i])] = BRDFTable(material_lobes[int(material[i])])
    table = tables[int(material[i])]
    f = table(v_loc[:, None, :], l_loc)  # (n, J, 3)
    alpha = min([float(t.alpha) for kind, _, t in table.terms if kind == "ggx"] or [np.inf])
    if sources is not None and np.isfinite(alpha) and len(js):
        f = _lobe_means(f, x, v_loc, R, js, l_loc, dist, table, alpha, sources)
    rho = np.asarray(reflectance[i], dtype=np.float64)
    W = np.empty((n, len(js) + 1, 3))
    W[:, 0, :] = 1.0
    W[:, 1:, :] = (np.pi * f - rho[None, None, :]) * fij[None, :, None]
    return np.r_[i, js], W
