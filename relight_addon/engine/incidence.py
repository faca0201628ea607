"""The first reflection of a small light, with the albedo its direction gives (pure math, no bpy).

The radiosity transport reflects the fraction rho of the light a patch receives, rho being the
material's white-furnace albedo (engine.principled): the right fraction when the light arrives
from every direction alike. The light of an emitter arrives from one direction. A Principled
BSDF's specular layer reflects more of light that arrives at grazing incidence (Fresnel) and
less of light from above, so the energy a patch j reflects of emitter k's light is

    R_j(mu_jk) F_jk e_k,     R(mu_i) = integral f(l_i, v) cos_v dv

(the directional-hemispherical reflectance for light incident at cosine mu_i; for Cycles'
layering: Base Color x (1 - mean specular albedo) + the specular albedo at mu_i, by
reciprocity of the glossy lobes). Its
cosine-weighted mean over mu_i is rho, so the correction has no effect on light from every
direction. The transport with it (the light's first reflection only; later reflections have
no single direction):

    B = A^-1 (e + D e),   D_jk = (R_j(mu_jk) - rho_j) F_jk  (k an emitter or candidate light)

Used by the solve (InverseProblem.first_bounce: T, the forward solves, the paper's substitution)
and the forward radiosity; left out of light_paths' bounce estimate, which counts D e as emitted
(it underestimates a bounce limit's loss by that first reflection's share, about 1 %).

``incidence_tables`` tabulates R(mu) per material (None for materials without a
direction-dependent albedo: Lambert, Base Color only); ``first_bounce_matrices`` builds D per
channel over the given source columns. Measured on the furnished room of
tests/test_cycles_principled.py (lights near the floor, light at grazing incidence on the
walls): +1 % on the targets, up to +3 %, where Cycles rendered 2.2 % brighter than the
prediction without it (docs/validation.md).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.sparse as sp

from .principled import _directional, oren_nayar_albedo, principled_albedo
from .units import TINY

__all__ = ["INCIDENCE_MU", "incidence_tables", "first_bounce_matrices", "lamp_incidence", "lamp_albedo_excess",
           "lamp_excess"]

#: incidence cosines of the tables (linear interpolation between them)
INCIDENCE_MU = np.linspace(0.0, 1.0, 41)
#: a table whose variation is below this (relative to its mean) is taken as constant (Lambert)
FLAT = 1e-6


@lru_cache(maxsize=1024)
def _glossy(params) -> np.ndarray:
    return _directional(params, INCIDENCE_MU)[1]


def incidence_tables(material_lobes) -> list:
    """Per material: R(mu) (len(INCIDENCE_MU), 3), the albedo for light incident at cosine mu, or
    None when it does not depend on mu (no glossy lobe). The glossy lobes reflect of light
    incident at mu what they send along mu under uniform light (reciprocity; engine.principled's
    glossy share G(mu)); the diffuse layer under them reflects its cosine-weighted mean whatever
    the incidence (Cycles weights it by the outgoing direction): R(mu) = rho + G(mu) - mean G,
    rho the white-furnace albedo. Checked against the BSDF integrated over the outgoing
    directions in tests/test_engine_incidence.py. Left out: Oren-Nayar's dependence on the
    incidence (Diffuse Roughness)."""
    out = []
    for lobes in material_lobes:
        G = np.zeros((len(INCIDENCE_MU), 3))
        rho = np.zeros(3)
        for w, kind, d in lobes:
            if kind == "principled":
                G += w * _glossy(d)
                rho += w * principled_albedo(d).albedo
            else:
                rho += w * np.asarray(oren_nayar_albedo(np.asarray(d[0], dtype=np.float64), float(d[1])), dtype=np.float64)
        span = G.max(axis=0) - G.min(axis=0)
        if np.all(span <= FLAT * np.maximum(np.abs(rho), 1e-12)):
            out.append(None)
            continue
        out.append(rho + G - _mean(G))
    return out


def _mean(table):
    """The cosine-weighted mean over incidences, 2 integral R(mu) mu dmu (3,)."""
    return 2 * np.trapz(table * INCIDENCE_MU[:, None], INCIDENCE_MU, axis=0)


#: about this many form-factor entries are turned into D entries at a time (bounds the memory)
CHUNK_ENTRIES = 1 << 20


def first_bounce_matrices(F, center, normal, material, tables, sources):
    """D per channel (3 sparse (P, P) CSC matrices sharing one index structure, float32, nonzero
    in the ``sources`` columns only), or None when no receiving material has a
    direction-dependent albedo. ``F`` (P, P) form factors (dense or sparse), ``material`` (P,)
    indexes ``tables`` (incidence_tables). D_jk = (R_j(mu_jk) - mean R_j) F_jk, the mean over
    incidences being rho_j. Work by chunks of source columns (CHUNK_ENTRIES)."""
    material = np.asarray(material, dtype=np.int64)
    glossy = np.array([t is not None for t in tables], dtype=bool)
    if not glossy.any() or not glossy[material].any():
        return None
    M = getattr(F, "matrix", F)
    P = M.shape[0]
    sources = np.sort(np.asarray(sources, dtype=np.int64))
    cols = sp.csc_matrix(M) if sp.issparse(M) else None
    # per material: R(mu) - mean R (the table's cosine-weighted mean is rho: zero on average)
    excess = {m: tables[m] - _mean(tables[m]) for m in np.flatnonzero(glossy)}
    per_col = np.diff(cols.indptr)[sources] if cols is not None else np.full(len(sources), P)
    bounds = np.searchsorted(np.cumsum(per_col), np.arange(CHUNK_ENTRIES, int(per_col.sum()), CHUNK_ENTRIES))
    rows, counts, data = [], np.zeros(P, dtype=np.int64), []
    for src in np.split(sources, np.unique(bounds) + 1):
        if len(src) == 0:
            continue
        blk = (cols[:, src] if cols is not None else sp.csc_matrix(np.asarray(M)[:, src])).tocoo()
        j, k, f = blk.row, src[blk.col], blk.data
        keep = glossy[material[j]] & (f > 0)
        j, k, f = j[keep], k[keep], f[keep]
        d = center[k] - center[j]
        d /= np.maximum(np.linalg.norm(d, axis=1), TINY)[:, None]
        mu = np.clip(np.einsum("ij,ij->i", d, normal[j]), 0.0, 1.0)
        vals = np.empty((len(j), 3), dtype=np.float32)
        for m in np.unique(material[j]):
            s_ = material[j] == m
            vals[s_] = np.stack([np.interp(mu[s_], INCIDENCE_MU, excess[m][:, c]) for c in range(3)], axis=1)
        vals *= f[:, None]
        order = np.lexsort((j, k))  # column-major (CSC)
        rows.append(j[order].astype(np.int32))
        data.append(vals[order])
        np.add.at(counts, k, 1)
    rows = np.concatenate(rows) if rows else np.zeros(0, np.int32)
    data = np.concatenate(data) if data else np.zeros((0, 3), np.float32)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32 if len(rows) < 2 ** 31 else np.int64)
    return [sp.csc_matrix((np.ascontiguousarray(data[:, c]), rows, indptr), shape=(P, P)) for c in range(3)]


def lamp_incidence(lamp, points, normals) -> np.ndarray:
    """(n,) the cosine at which a lamp's light arrives at ``points`` (n, 3) with unit ``normals``:
    from its position (a point, a spot, an area lamp: its centre), a sun from its direction."""
    return np.clip(np.einsum("ij,ij->i", lamp.kind.towards(lamp, points), normals), 0.0, 1.0)


def lamp_albedo_excess(lamp, center, normal, material, tables, patches=None) -> np.ndarray:
    """(len(patches), 3): R_j(mu_j) - rho_j, the albedo of the first reflection of ``lamp``'s light
    beyond the white-furnace albedo, at the patches ``patches`` (default all; mu_j the cosine at
    which its light arrives, ``lamp_incidence``); 0 for materials without a direction-dependent
    albedo."""
    j = np.arange(len(center)) if patches is None else np.asarray(patches, dtype=np.int64)
    out = np.zeros((len(j), 3))
    mat = np.asarray(material, dtype=np.int64)[j]
    mu = None
    for m in np.unique(mat):
        if tables[m] is None:
            continue
        mu = lamp_incidence(lamp, center[j], normal[j]) if mu is None else mu
        s_ = mat == m
        ex = tables[m] - _mean(tables[m])
        out[s_] = np.stack([np.interp(mu[s_], INCIDENCE_MU, ex[:, c]) for c in range(3)], axis=1)
    return out


def lamp_excess(lamps, H, center, normal, material, tables):
    """The first reflection of lamps' direct light with the albedo of its incidence: per channel a
    sparse (P, n) matrix (R_j(mu_jl) - rho_j) H_jl over the nonzeros of ``H`` (P, n) (each lamp's
    direct irradiance per unit strength; ``lamps`` its engine.lamps.Lamp per column, None for a
    column without one; ``lamp_albedo_excess``). None when no material has a direction-dependent
    albedo. The lamps' analogue of ``first_bounce_matrices``: B = A^-1 (rho H s + X s) for
    strengths s, X this matrix (InverseProblem's ``lamp_excess``)."""
    if not any(t is not None for t in tables):
        return None
    Hc = sp.csc_matrix(H, dtype=np.float64)
    data = np.zeros((Hc.nnz, 3))
    for l in range(Hc.shape[1]):
        lo, hi = Hc.indptr[l], Hc.indptr[l + 1]
        if hi > lo and lamps[l] is not None:
            data[lo:hi] = lamp_albedo_excess(lamps[l], center, normal, material, tables, Hc.indices[lo:hi])
    data *= Hc.data[:, None]
    return [sp.csc_matrix((data[:, c], Hc.indices, Hc.indptr), shape=Hc.shape) for c in range(3)]
