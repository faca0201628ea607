"""The radiance a surface shows along a view direction, from the radiosity solution and its
material's BSDF (pure math, no bpy).

The radiosity engine models every surface as Lambertian with its white-furnace albedo: B/pi is
the cosine-weighted mean of the radiance it sends over the hemisphere. A glossy material
(a Principled BSDF's specular layer) sends more towards the mirror directions of its incident
light and less elsewhere, so what one view shows differs from B/pi: a bake (every face viewed
along its normal) shows less than B/pi on a face lit at grazing incidence (measured: 8 % on a
red wall lit from the ceiling next to it) and more on one lit from straight above.

``view_radiance`` gathers a patch's incident light from the form factors: patch i receives
radiance B_j/pi from patch j over a cosine-weighted solid angle pi F_ij, so the radiance seen
along v is

    L_i(v) = e_i/pi + sum_j f_i(l_ij, v) F_ij B_j,

f_i the material's BSDF as Cycles evaluates it (engine.principled.lobes_brdf: the layering
weights at the view direction, the GGX lobes with their energy compensation) at the direction
l_ij of patch j's centre, e = B - rho F B the configuration's exitance. For a Lambertian
material f = rho/pi and L = B/pi exactly. Left out: the direction of the light leaving the
sources (each patch sends B_j/pi every way), the incidence dependence of the glossy albedo in
the transport (tried: a re-solve with A_s(mu_jk) per pair moved the measured errors the wrong
way once Cycles' Filter Glossy was off), and glossy lobes narrower than the patches seen
(engine.principled.VIEW_ALPHA_MIN).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .principled import lobes_brdf

__all__ = ["view_radiance"]


def _frame(n):
    n = n / np.linalg.norm(n)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(n, t1), n])  # rows: local x, y, z


def view_radiance(F, B, reflectance, center, normal, patches, material, material_lobes, view=None) -> np.ndarray:
    """(len(patches), 3) radiance (W m^-2 sr^-1) seen along ``view`` (world unit vectors
    (len(patches), 3); default: each patch's normal, what a bake shows) on ``patches``.

    ``F``: form factors (FormFactors or a (P, P) array / sparse matrix), ``B`` (P, 3) the
    radiosity solved with the Lambertian ``reflectance`` (P, 3), ``center`` and ``normal``
    (P, 3), ``material`` (P,) indexes ``material_lobes`` (each a material's BSDFs,
    engine.principled.lobes_brdf)."""
    M = getattr(F, "matrix", F)
    B = np.asarray(B, dtype=np.float64)
    rho = np.asarray(reflectance, dtype=np.float64)
    patches = np.asarray(patches, dtype=np.int64)
    e = B[patches] - rho[patches] * np.asarray(M[patches] @ B, dtype=np.float64)
    out = np.empty((len(patches), 3))
    rows = M[patches]
    rows = rows.tocsr() if sp.issparse(rows) else np.asarray(rows)
    for k, i in enumerate(patches):
        if sp.issparse(rows):
            js, fij = rows.indices[rows.indptr[k]:rows.indptr[k + 1]], rows.data[rows.indptr[k]:rows.indptr[k + 1]]
        else:
            js = np.flatnonzero(rows[k])
            fij = rows[k, js]
        R = _frame(normal[i])
        v = np.array([0.0, 0.0, 1.0]) if view is None else R @ np.asarray(view[k], dtype=np.float64)
        d = center[js] - center[i]
        d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
        f = lobes_brdf(material_lobes[material[i]], v, d @ R.T)
        out[k] = e[k] / np.pi + np.sum(f * (np.asarray(fij, dtype=np.float64)[:, None] * B[js]), axis=0)
    return out
