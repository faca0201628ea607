"""The first reflection of a small light, with the albedo its direction gives (pure math, no bpy).

The radiosity transport reflects the fraction rho of the light a patch receives, rho being the
material's white-furnace albedo (engine.principled): the right fraction when the light arrives
from every direction alike. The light of an emitter arrives from one direction. A Principled
BSDF's specular layer reflects more of light that arrives at grazing incidence (Fresnel) and
less of light from above, so the energy a patch j reflects of emitter k's light is

    R_j(mu_jk) F_jk e_k,     R(mu_i) = integral f(l_i, v) cos_v dv

(the directional-hemispherical reflectance for light incident at cosine mu_i; for Cycles'
layering: Base Color x (1 - mean specular albedo) + the specular albedo at mu_i). Its
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

from .principled import BRDFTable

__all__ = ["INCIDENCE_MU", "incidence_tables", "first_bounce_matrices"]

#: incidence cosines of the tables (linear interpolation between them)
INCIDENCE_MU = np.linspace(0.0, 1.0, 41)
_N_MU, _N_PHI = 48, 96  # outgoing-direction quadrature
#: a table whose variation is below this (relative to its mean) is taken as constant (Lambert)
FLAT = 1e-4


def _outgoing():
    x, w = np.polynomial.legendre.leggauss(_N_MU)
    mu, wmu = (x + 1) / 2, w / 2
    phi = (np.arange(_N_PHI) + 0.5) * (2 * np.pi / _N_PHI)
    MU, PHI = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - MU ** 2)
    V = np.stack([s * np.cos(PHI), s * np.sin(PHI), MU], axis=-1).reshape(-1, 3)
    W = (wmu[:, None] * MU * (2 * np.pi / _N_PHI)).reshape(-1)
    return V, W


@lru_cache(maxsize=256)
def _table(lobes) -> np.ndarray | None:
    brdf = BRDFTable(lobes)
    V, W = _outgoing()
    rows = []
    for mu in np.maximum(INCIDENCE_MU, 0.01):
        l = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
        rows.append((brdf(V, np.broadcast_to(l, V.shape)) * W[:, None]).sum(axis=0))
    R = np.array(rows)
    mean = np.maximum(np.abs(R).mean(axis=0), 1e-12)
    if np.all((R.max(axis=0) - R.min(axis=0)) <= FLAT * mean):
        return None
    return R


def _hashable(lobes):
    return tuple((float(w), kind, d if kind == "principled" else (tuple(np.asarray(d[0], float).ravel()), float(d[1])))
                 for w, kind, d in lobes)


def incidence_tables(material_lobes) -> list:
    """Per material: R(mu) (len(INCIDENCE_MU), 3) for light incident at cosine mu, or None when it
    does not depend on mu (a Lambertian material). By quadrature over the outgoing directions:
    a lobe sharper than the quadrature loses a little (0.01 at Roughness 0.3), which
    ``first_bounce_matrices`` cancels by taking the excess over the table's own mean."""
    out = []
    for lobes in material_lobes:
        try:
            out.append(_table(_hashable(lobes)))
        except TypeError:  # parameters that cannot be hashed: not cached
            out.append(_table.__wrapped__(lobes))
    return out


def first_bounce_matrices(F, center, normal, material, tables, sources):
    """D per channel (3 sparse (P, P) CSR matrices, nonzero in the ``sources`` columns only), or
    None when no receiving material has a direction-dependent albedo. ``F`` (P, P) form factors
    (dense or sparse), ``material`` (P,) indexes ``tables`` (incidence_tables). D_jk =
    (R_j(mu_jk) - mean R_j) F_jk, the mean over incidences being rho_j."""
    material = np.asarray(material, dtype=np.int64)
    glossy = np.array([t is not None for t in tables], dtype=bool)
    if not glossy.any() or not glossy[material].any():
        return None
    M = getattr(F, "matrix", F)
    P = M.shape[0]
    sources = np.asarray(sources, dtype=np.int64)
    cols = sp.csc_matrix(M)[:, sources].tocoo() if sp.issparse(M) else sp.coo_matrix(np.asarray(M)[:, sources])
    j, k, f = cols.row, sources[cols.col], cols.data
    keep = glossy[material[j]] & (f > 0)
    j, k, f = j[keep], k[keep], f[keep]
    d = center[k] - center[j]
    d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    mu = np.clip(np.einsum("ij,ij->i", d, normal[j]), 0.0, 1.0)
    R = np.empty((len(j), 3))
    for m in np.unique(material[j]):
        s = material[j] == m
        R[s] = np.stack([np.interp(mu[s], INCIDENCE_MU, tables[m][:, c]) for c in range(3)], axis=1)
    # the excess over the table's cosine-weighted mean (the white-furnace albedo, rho, up to the
    # quadrature's loss on sharp lobes): zero on average over incidences, whatever that loss
    mean = {m: 2 * np.trapz(tables[m] * INCIDENCE_MU[:, None], INCIDENCE_MU, axis=0) for m in np.unique(material[j])}
    R -= np.stack([mean[int(m)] for m in material[j]]) if len(j) else 0.0
    vals = R * f[:, None]
    return [sp.csr_matrix((vals[:, c], (j, k)), shape=(P, P)) for c in range(3)]
