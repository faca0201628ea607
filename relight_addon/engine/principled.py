"""Cycles' Principled BSDF as an effective Lambertian reflectance (pure math, no bpy).

The radiosity engine treats every surface as Lambertian. A material that Cycles renders with a
specular layer (the Principled BSDF's default) reflects more light towards grazing directions
and less along the normal; what the radiosity transport needs is how much of the light falling
on the surface leaves it, over the hemisphere: the **white-furnace albedo**, the cosine-weighted
hemispherical average of the directional albedo R(mu) (the outgoing radiance along a direction
of cosine mu when the incident radiance is 1 from every direction)::

    rho = 2 * integral_0^1 R(mu) mu dmu          (per RGB channel)

This module rebuilds R(mu) as Cycles 4.2-5.0 shades the Principled BSDF (intern/cycles/kernel/
svm/closure.h, ``svm_node_closure_bsdf``, case CLOSURE_BSDF_PRINCIPLED_ID), from the layers'
equations; no Cycles table or code is copied: every integral is computed here by quadrature.

Dielectric specular layer (IOR, Specular IOR Level, Specular Tint, Roughness)
    - F0 = ((IOR - 1) / (IOR + 1))^2, scaled by 2 x Specular IOR Level when that is not 0.5;
      eta is the IOR giving that F0 (Level 0 -> F0 = 0, eta = 1: no specular closure at all).
    - GGX microfacets, alpha = Roughness^2, height-correlated Smith shadowing
      G2 = 1 / (1 + Lambda(i) + Lambda(o)), Lambda(mu) = (sqrt(1 + alpha^2 tan^2) - 1) / 2;
      Fresnel: "generalized Schlick" with the real dielectric curve,
      F(h) = mix(F0 x tint, 1, s(h)), s(h) = (F_dielectric(h.i, eta) - F0(eta)) / (1 - F0(eta)).
    - Multiple-scattering energy compensation (distribution "Multiscatter GGX", the default;
      ``microfacet_ggx_preserve_energy`` in kernel/closure/bsdf_microfacet.h, after Kulla &
      Conty 2017): with E(mu) the single-scattering albedo of the Fresnel-free lobe and E_avg
      its hemispherical average, Fss = mix(F0 x tint, 1, s_avg) the lobe's average Fresnel and
      Fms = Fss E_avg / (1 - Fss (1 - E_avg)), the lobe is scaled by 1 + Fms (1 - E) / E.
      Its directional albedo is therefore A(mu) = (1 + Fms (1 - E) / E) x E_F(mu), E_F the
      single-scattering albedo with the Fresnel term.
    - **Albedo scaling** (``closure_layering_weight`` in kernel/closure/bsdf_util.h): the layers
      under it (diffuse, subsurface) are weighted by 1 - max_rgb(A_est(mu) x (E + Fms (1 - E))),
      A_est = mix(F0 x tint, 1, s_est(mu)) Cycles' *estimate* of the lobe's albedo
      (``bsdf_microfacet_estimate_albedo``) read from a table of the mean of s(h) over the
      visible normals (``cycles_precompute.cpp``, ``ggx_gen_schlick_ior_s``), and the factor in
      brackets the energy-compensation "darkening" already applied to the lobe's weight.
    - E(mu) and E_avg are read, as Cycles does, from tables (32 x 32 and 32 entries) over
      (roughness, mu) with bilinear interpolation; s_est from a 16 x 16 x 16 table over
      (roughness, mu, F0^(1/4)). This module computes the same tables' entries (only those a
      material needs) by quadrature and interpolates them the same way, so its answer carries
      the same interpolation error as Cycles' render.

Diffuse: Base Color x (1 - Subsurface Weight) x the layering weight above: Lambert, or with
Diffuse Roughness > 0 Cycles' Oren-Nayar (Fujii's improved model with OpenPBR's
energy-preserving multiple-scattering term: ``oren_nayar_directional``).

Documented approximations (each returns a note naming what was assumed)
    - Metallic: the metal lobe (F82-tint Fresnel, Kutz et al. 2021: Schlick with F0 = Base Color
      minus b mu (1 - mu)^6, b from Specular Tint) is computed like the specular layer (its
      white-furnace albedo); it is *mixed* in (weight Metallic), not layered. Its glossy,
      mirror-like reflection is treated as diffuse.
    - Transmission: the Fresnel reflection of the glass lobe is kept (its estimated albedo);
      the light it transmits is treated as lost (it leaves through the other side).
    - Coat: layered like Cycles (coat albedo on top, lower layers scaled by 1 - coat albedo and
      by Coat Tint^(1/cos theta_t)); its glossy reflection treated as diffuse.
    - Sheen: ignored (Cycles reads its albedo from a fitted LTC table not rebuilt here; measured:
      it adds about 0.1 x weight x (Sheen Tint - Base Color) at Sheen Roughness 0.5).
    - Subsurface: treated as Lambert with Base Color (light spreading under the surface ignored;
      measured: Cycles' random walk reflects 0.02-0.03 less on a unit sphere).
    - Alpha < 1: the transparent part passes light through: treated as lost.
    - Thin film, anisotropy: ignored.
The emission of a Principled BSDF is attenuated by the coat (and sheen) only; the factor is
returned as ``emission``.

Every result is a function of mu only (the surface sees uniform white light): R(mu) is exact
for Cycles' model up to quadrature, and rho is its cosine-weighted mean. The GGX quadrature runs
once per roughness node (ROUGH_NODES, uniform in sqrt(roughness)) and is interpolated between
them, so that a scene of a thousand roughnesses costs what one of fifty does; with the quadrature's
own error this is within ~6e-4 on rho and ~1.2e-3 on R(1) (tests/test_engine_principled.py,
benchmarks/bench_materials.py). Checked against Cycles' white furnace in tests/test_cycles_materials.py (within 0.0022).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .units import TINY

__all__ = ["F0_from_ior", "ior_from_F0", "fresnel_dielectric", "hemispherical_fresnel", "PrincipledParams",
           "PrincipledAlbedo", "principled_albedo", "ggx_albedo", "oren_nayar_directional",
           "oren_nayar_albedo", "view_brdf", "lobes_brdf", "BRDFTable", "MU_NODES"]

#: VNDF quadrature resolution (points per axis of the unit square)
GRID_R, GRID_PHI = 48, 48
#: Gauss-Legendre nodes on mu in [0, 1] for the hemispherical averages
MU_NODES = 48
_MU_MIN = 1e-4  # Cycles' tables clamp mu and roughness to at least this


def F0_from_ior(ior):
    """Normal-incidence reflectance of a dielectric interface of relative index ``ior``."""
    ior = np.asarray(ior, dtype=np.float64)
    return ((ior - 1.0) / (ior + 1.0)) ** 2


def ior_from_F0(f0):
    """The relative index whose normal-incidence reflectance is ``f0`` (clamped to [0, 0.99])."""
    r = np.sqrt(np.clip(f0, 0.0, 0.99))
    return (1.0 + r) / (1.0 - r)


def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance at a dielectric interface of relative index ``eta`` for
    an incident cosine ``cos_i`` (1 on total internal reflection)."""
    c = np.abs(np.asarray(cos_i, dtype=np.float64))
    g2 = eta * eta - 1.0 + c * c
    if np.ndim(eta) == 0 and eta > 1.0:  # (into a denser medium: no total reflection, g > c >= 0, F finite)
        g = np.sqrt(g2)
        A = (g - c) / (g + c)
        B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        return 0.5 * A * A * (1.0 + B * B)
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        A = (g - c) / (g + c)
        B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        F = 0.5 * A * A * (1.0 + B * B)
    return np.where(g2 > 0, np.nan_to_num(F, nan=1.0), 1.0)


@lru_cache(maxsize=8)
def _gauss_nodes(n):
    x, w = np.polynomial.legendre.leggauss(n)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    x.flags.writeable = w.flags.writeable = False  # shared by every caller
    return x, w


def _gauss_mu(n=MU_NODES):
    """Gauss-Legendre nodes and weights on [0, 1] (computed once per n)."""
    return _gauss_nodes(int(n))


@lru_cache(maxsize=1024)
def hemispherical_fresnel(eta) -> float:
    """2 int_0^1 F(mu, eta) mu dmu: the dielectric's reflectance under uniform light."""
    mu, w = _gauss_mu(200)
    return float(np.sum(2.0 * mu * w * fresnel_dielectric(mu, float(eta))))


# ------------------------------------------------------------------ GGX integrals
def _lambda(alpha2, cos):
    cos2 = np.clip(cos * cos, TINY, 1.0)
    return 0.5 * (np.sqrt(1.0 + alpha2 * np.maximum(1.0 / cos2 - 1.0, 0.0)) - 1.0)


def _vndf_samples(rough: float, mus: tuple):
    """GGX's distribution of visible normals (Heitz 2018) for view cosines ``mus`` on the
    quadrature grid: (c = h.i, g w, valid w) per sample (n_mu, S), w the quadrature weight. A
    sample is valid when the reflected direction is above the surface; g = G2 / G1 =
    (1 + Lambda_i) / (1 + Lambda_i + Lambda_o), so that sum(g f(c) w) = int f(h) D G2 / (4 mu)
    dw_o, the single-scattering albedo of a lobe whose Fresnel term is f. Only the half of the
    grid with t1 > 0 is evaluated: phi -> pi - phi maps the grid onto itself and changes only
    the sign of the normal's y, which nothing here depends on."""
    alpha = max(rough, _MU_MIN) ** 2
    mu = np.asarray(mus, dtype=np.float64)[:, None]
    sin = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    # the view direction i = (sin, 0, mu); stretched: Vh = normalize(alpha sin, 0, mu)
    vx, vz = alpha * sin, mu
    n = np.sqrt(vx * vx + vz * vz)
    vx, vz = vx / n, vz / n
    # U1 = 1 - v^2 (midpoints in v, weight 2 v): smooth where sqrt(1 - U1) is not
    v = (np.arange(GRID_R) + 0.5) / GRID_R
    phi = 2.0 * np.pi * (np.arange(GRID_PHI) + 0.5) / GRID_PHI
    phi = phi[np.cos(phi) > 0]
    V, PHI = (a.ravel()[None, :] for a in np.meshgrid(v, phi, indexing="ij"))
    wq = 2.0 * V / (0.5 * GRID_PHI * np.sum(2.0 * v))
    r = np.sqrt(1.0 - V * V)
    t1, t2 = r * np.cos(PHI), r * np.sin(PHI)
    s = 0.5 * (1.0 + vz)
    t2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - t1 * t1, 0.0)) + s * t2
    tn = np.sqrt(np.maximum(1.0 - t1 * t1 - t2 * t2, 0.0))
    # T1 = (0, 1, 0), T2 = Vh x T1 = (-vz, 0, vx)
    nx = -vz * t2 + tn * vx
    ny = t1 + 0.0 * vx
    nz = vx * t2 + tn * vz
    hx, hy, hz = alpha * nx, alpha * ny, np.maximum(nz, 0.0)
    hn = np.sqrt(hx * hx + hy * hy + hz * hz)
    c = np.clip((sin * hx + mu * hz) / hn, 0.0, 1.0)  # h . i
    oz = 2.0 * c * hz / hn - mu  # reflected direction's cosine
    valid = oz > 0
    li = _lambda(alpha * alpha, mu)
    lo = _lambda(alpha * alpha, np.where(valid, oz, 1.0))
    g = np.where(valid, (1.0 + li) / (1.0 + li + lo), 0.0)
    return c, g * wq, valid * wq


#: the VNDF averages are kept as weights on C_NODES values of c = h.i (hat functions: any
#: Fresnel term f(c) is then one dot product), at ROUGH_NODES roughness nodes uniform in
#: sqrt(roughness) (dense near 0, where grazing views change fastest), computed once each and
#: read with 4-point Lagrange interpolation: within ~1e-3 of the direct quadrature at a view
#: (about its own quadrature error), ~1e-4 on an albedo, however many roughnesses a scene has
ROUGH_NODES, C_NODES = 49, 257
_C = np.linspace(0.0, 1.0, C_NODES)


@lru_cache(maxsize=4096)
def _vndf_node(i: int, mus: tuple):
    """(Wg, Wv) (n_mu, C_NODES): the samples' g w and valid w shared between the two c nodes
    around each sample, at roughness node ``i``."""
    c, gw, vw = _vndf_samples((i / (ROUGH_NODES - 1)) ** 2, mus)
    x = c * (C_NODES - 1)
    k = np.minimum(x.astype(np.int64), C_NODES - 2)
    t = x - k
    k = (k + C_NODES * np.arange(len(mus))[:, None]).ravel()
    size = len(mus) * C_NODES
    out = []
    for w in (gw, vw):
        w = np.broadcast_to(w, c.shape)
        W = np.bincount(k, (w * (1 - t)).ravel(), size) + np.bincount(k + 1, (w * t).ravel(), size)
        W = W.reshape(len(mus), C_NODES)
        W.flags.writeable = False  # shared by every caller
        out.append(W)
    return tuple(out)


@lru_cache(maxsize=4096)
def _node_terms(i: int, mus: tuple) -> dict:
    """The Fresnel-free terms at roughness node ``i`` (E, EB5, EB6: see _vndf_terms)."""
    Wg, _ = _vndf_node(i, mus)
    return {"E": Wg.sum(axis=1), "EB5": Wg @ (1.0 - _C) ** 5, "EB6": Wg @ (_C * (1.0 - _C) ** 6)}


@lru_cache(maxsize=1024)
def _fresnel_on_nodes(eta: float):
    """F_diel and s = (F_diel - F0) / (1 - F0) at the c nodes."""
    F = fresnel_dielectric(_C, eta)
    F0 = float(F0_from_ior(eta))
    return F, (np.clip((F - F0) / (1.0 - F0), 0.0, 1.0) if F0 < 1 else np.ones_like(F))


@lru_cache(maxsize=4096)
def _vndf_terms(rough: float, mus: tuple, eta: float | None = None, exponents: tuple = ()) -> dict:
    """Averages over GGX's visible normals for a view direction of cosine mu (each entry: an
    array over ``mus``; see _vndf_samples), interpolated between roughness nodes (4-point
    Lagrange in sqrt(roughness); every term is linear in the weights, so interpolating the terms
    is interpolating the weights).

    E: mean(valid g) (no Fresnel); EB5 / EB6: mean(valid g (1-c)^5) and mean(valid g c (1-c)^6),
    c = h.i (F82-tint terms); with ``eta``: EF mean(valid g F_diel), ES mean(valid g s),
    S mean(valid s) with s = (F_diel - F0) / (1 - F0); for each exponent p: Sp mean(valid (1-c)^p).
    """
    x = math.sqrt(min(max(rough, 0.0), 1.0)) * (ROUGH_NODES - 1)
    i = int(min(max(math.floor(x) - 1, 0), ROUGH_NODES - 4))
    t = x - i
    la = [math.prod((t - b) / (a - b) for b in range(4) if b != a) for a in range(4)]
    nodes = [_node_terms(i + a, mus) for a in range(4)]
    out = {k: sum(w * n[k] for w, n in zip(la, nodes)) for k in nodes[0]}
    if eta is not None or exponents:  # the weights themselves, for the Fresnel terms of this material
        W = [_vndf_node(i + a, mus) for a in range(4)]
        Wg = sum(w * n[0] for w, n in zip(la, W))
        Wv = sum(w * n[1] for w, n in zip(la, W))
        if eta is not None:
            F, sh = _fresnel_on_nodes(float(eta))
            out["EF"], out["ES"], out["S"] = Wg @ F, Wg @ sh, Wv @ sh
        for p in exponents:
            out[f"S{p}"] = Wv @ (1.0 - _C) ** p
    return out


def ggx_albedo(roughness: float, mu) -> np.ndarray:
    """Single-scattering directional albedo E(mu) of a Fresnel-free GGX lobe (alpha = roughness^2)."""
    mu = np.atleast_1d(np.asarray(mu, dtype=np.float64))
    return _vndf_terms(float(roughness), tuple(np.clip(mu, _MU_MIN, 1.0)))["E"]


# ------------------------------------------------------------------ Cycles' tables, rebuilt
def _axis(x, n):
    """Cycles' lookup_table_read: the two nodes around x in [0, 1] on n nodes and the weight."""
    if np.ndim(x) == 0:  # a roughness (Python's scalars: this runs for every material)
        x = min(max(float(x), 0.0), 1.0) * (n - 1)
        i0 = min(int(x), n - 1)
        return i0, min(i0 + 1, n - 1), x - i0
    x = np.clip(x, 0.0, 1.0) * (n - 1)
    i0 = np.minimum(np.floor(x).astype(int), n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    return i0, i1, x - i0


def _node(i, n, lo=_MU_MIN, hi=1.0):
    return float(np.clip(i / (n - 1), lo, hi))


def _ior_of_z(z):
    return float(ior_from_F0(z ** 4))


@lru_cache(maxsize=256)
def _E_row(ir: int) -> np.ndarray:
    """Table ggx_E (32 x 32): E at roughness node ``ir`` for the 32 mu nodes."""
    return _vndf_terms(_node(ir, 32), tuple(_node(j, 32) for j in range(32)))["E"]


@lru_cache(maxsize=256)
def _Eavg_node(ir: int) -> float:
    """Table ggx_Eavg (32): 2 int E(mu) mu dmu at roughness node ``ir``."""
    mu, w = _gauss_mu()
    return float(np.sum(2.0 * mu * w * _vndf_terms(_node(ir, 32), tuple(mu))["E"]))


def E_table(rough, mu):
    """Cycles' ggx_E(roughness, mu), bilinear on its 32 x 32 nodes."""
    mu = np.asarray(mu, dtype=np.float64)
    i0, i1, tx = _axis(rough, 32)
    j0, j1, ty = _axis(mu, 32)
    rows = [_E_row(int(i0)), _E_row(int(i1))]
    r = [(1 - ty) * row[j0] + ty * row[j1] for row in rows]
    return (1 - tx) * r[0] + tx * r[1]


def Eavg_table(rough) -> float:
    i0, i1, t = _axis(rough, 32)
    return float((1 - t) * _Eavg_node(int(i0)) + t * _Eavg_node(int(i1)))


@lru_cache(maxsize=1024)
def _s_ior_row(ir: int, iz: int) -> np.ndarray:
    """Table ggx_gen_schlick_ior_s (16^3) at roughness node ir, F0^(1/4) node iz: 16 mu nodes."""
    eta = _ior_of_z(_node(iz, 16, hi=0.99))
    return _vndf_terms(_node(ir, 16), tuple(_node(j, 16) for j in range(16)), eta)["S"]


@lru_cache(maxsize=1024)
def _s_pow_row(ir: int, iz: int) -> np.ndarray:
    """Table ggx_gen_schlick_s (16^3) at roughness node ir, exponent node iz (exponent
    5 (1 - z) / z): 16 mu nodes."""
    z = _node(iz, 16, hi=0.99)
    p = 5.0 * (1.0 - z) / z
    return _vndf_terms(_node(ir, 16), tuple(_node(j, 16) for j in range(16)), None, (p,))[f"S{p}"]


def _table3(row, rough, mu, z):
    mu = np.asarray(mu, dtype=np.float64)
    i0, i1, tx = _axis(rough, 16)
    j0, j1, ty = _axis(mu, 16)
    k0, k1, tz = _axis(z, 16)
    out = 0.0
    for k, wk in ((k0, 1 - tz), (k1, tz)):
        for i, wi in ((i0, 1 - tx), (i1, tx)):
            if wk == 0 or wi == 0:
                continue
            r = row(int(i), int(k))
            out = out + wk * wi * ((1 - ty) * r[j0] + ty * r[j1])
    return out


def s_ior_table(rough, mu, eta):
    """Cycles' estimate of the real-Fresnel interpolation weight (ggx_gen_schlick_ior_s)."""
    z = math.sqrt(abs((eta - 1.0) / (eta + 1.0)))
    return _table3(_s_ior_row, rough, mu, z)


def s_schlick5_table(rough, mu):
    """Cycles' estimate for Schlick's exponent 5 (ggx_gen_schlick_s read at z = 0.5)."""
    return _table3(_s_pow_row, rough, mu, 0.5)


# ------------------------------------------------------------------ lobes
def _fms(Fss, E_avg):
    return Fss * E_avg / (1.0 - Fss * (1.0 - E_avg))


@dataclass
class _Lobe:
    """A glossy lobe under uniform white light, per mu (rows) and channel (columns)."""

    albedo: np.ndarray  # (n_mu, 3): what it reflects
    layering: np.ndarray  # (n_mu, 3): what Cycles subtracts from the layers under it
    scale: np.ndarray = None  # (n_mu, 3): energy compensation on the single-scattering BRDF
    fresnel: tuple = None  # ("gs", f0 (3,), eta) | ("diel", eta) | ("f82", f0 (3,), b (3,))
    alpha: float = 0.0


def _dielectric_lobe(rough, eta, f0_rgb, mu, multiscatter, real_fresnel=False):
    """Specular (generalized Schlick on the real curve; ``real_fresnel``: the plain dielectric
    Fresnel, as the coat) reflection lobe."""
    mu = np.asarray(mu, dtype=np.float64)
    t = _vndf_terms(float(rough), tuple(mu), float(eta))
    F0r = float(F0_from_ior(eta))
    if real_fresnel:
        EF = np.repeat(t["EF"][:, None], 3, axis=1)
        est = np.repeat((F0r + (1 - F0r) * s_ior_table(rough, mu, eta))[:, None], 3, axis=1)
        Fss = np.full(3, hemispherical_fresnel(eta))
    else:
        f0 = np.clip(np.asarray(f0_rgb, dtype=np.float64), 0.0, 1.0)
        EF = f0[None, :] * t["E"][:, None] + (1 - f0[None, :]) * t["ES"][:, None]
        est = f0[None, :] + (1 - f0[None, :]) * s_ior_table(rough, mu, eta)[:, None]
        s_avg = np.clip((hemispherical_fresnel(eta) - F0r) / (1 - F0r), 0.0, 1.0) if F0r < 1 else 1.0
        Fss = f0 + (1 - f0) * s_avg
    fres = ("diel", float(eta)) if real_fresnel else ("gs", f0, float(eta))
    if not multiscatter:
        return _Lobe(EF, est, np.ones_like(EF), fres, max(rough, _MU_MIN) ** 2)
    E = np.clip(E_table(rough, mu), 1e-6, 1.0)[:, None]
    Fms = _fms(Fss, Eavg_table(rough))[None, :]
    scale = 1.0 + Fms * (1.0 - E) / E
    return _Lobe(EF * scale, est * (E + Fms * (1.0 - E)), scale, fres, max(rough, _MU_MIN) ** 2)


def f82_b(f0, tint):
    """F82-tint's b: Schlick(cos) - b cos (1 - cos)^6 equals Schlick x tint at cos = 1/7."""
    f0, tint = np.asarray(f0, dtype=np.float64), np.asarray(tint, dtype=np.float64)
    c = 1.0 / 7.0
    schlick = f0 + (1 - f0) * (1 - c) ** 5
    return schlick * (1 - tint) / (c * (1 - c) ** 6)


def _metal_lobe(rough, f0_rgb, tint_rgb, mu, multiscatter):
    mu = np.asarray(mu, dtype=np.float64)
    t = _vndf_terms(float(rough), tuple(mu))
    f0 = np.clip(np.asarray(f0_rgb, dtype=np.float64), 0.0, 1.0)
    b = f82_b(f0, np.minimum(tint_rgb, 1.0)) if not np.allclose(tint_rgb, 1.0) else np.zeros(3)
    EF = f0 * t["E"][:, None] + (1 - f0) * t["EB5"][:, None] - b * t["EB6"][:, None]
    est = f0 + (1 - f0) * s_schlick5_table(rough, mu)[:, None]
    fres = ("f82", f0, b)
    if not multiscatter:
        return _Lobe(EF, est, np.ones_like(EF), fres, max(rough, _MU_MIN) ** 2)
    # hemispherical averages: 2 int mu (1-mu)^5 = 1/21, 2 int mu^2 (1-mu)^6 = 1/126
    Fss = np.clip(f0 + (1 - f0) / 21.0 - b / 126.0, 0.0, 1.0)
    E = np.clip(E_table(rough, mu), 1e-6, 1.0)[:, None]
    Fms = _fms(Fss, Eavg_table(rough))[None, :]
    scale = 1.0 + Fms * (1.0 - E) / E
    return _Lobe(EF * scale, est * (E + Fms * (1.0 - E)), scale, fres, max(rough, _MU_MIN) ** 2)


# ------------------------------------------------------------------ rough diffuse
def _fujii_G(mu):
    """Fujii's improved Oren-Nayar: int over the hemisphere of cos_l t = G(theta) (the B term's
    directional albedo), theta = acos(mu)."""
    mu = np.clip(np.asarray(mu, dtype=np.float64), 1e-6, 1.0)
    sin = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    th = np.arccos(mu)
    return sin * (th - sin * mu) + 2.0 / 3.0 * (sin / mu) * (1.0 - sin ** 3) - 2.0 / 3.0 * sin


def oren_nayar_directional(color, sigma, mu) -> np.ndarray:
    """(n, 3) directional albedo of Cycles' rough diffuse (Diffuse Roughness / the Diffuse BSDF's
    Roughness sigma > 0): Fujii's improved Oren-Nayar (A = 1 / (pi + (pi/2 - 2/3) sigma),
    B = sigma A, E(mu) = A pi + B G(mu)) with OpenPBR's energy-preserving multiple-scattering
    term rho_ms (1 - E(v)) (1 - E(l)) / pi, rho_ms = c^2 E_avg / (1 - E_avg) / (1 - c (1 - E_avg)),
    E_avg ~ A pi + (2 pi - 5.6) / 3 B (the spec's fit), per unit closure weight; c = the colour
    clamped to [0, 1]. Integrated over l: E(v) + rho_ms (1 - E(v)) (1 - <E>), <E> the exact
    cosine-weighted mean of E."""
    mu = np.atleast_1d(np.asarray(mu, dtype=np.float64))
    sigma = float(np.clip(sigma, 0.0, 1.0))
    A = 1.0 / (np.pi + sigma * (np.pi / 2 - 2.0 / 3.0))
    B = sigma * A
    c = np.clip(np.asarray(color, dtype=np.float64), 0.0, 1.0)
    E_fit = A * np.pi + (2 * np.pi - 5.6) / 3.0 * B
    ms = c * c * (E_fit / (1.0 - E_fit)) / (1.0 - c * (1.0 - E_fit))
    x, w = _gauss_mu(200)
    E_mean = float(np.sum(2 * x * w * (A * np.pi + B * _fujii_G(x))))
    Ev = (A * np.pi + B * _fujii_G(mu))[:, None]
    return Ev + ms[None, :] * (1.0 - Ev) * (1.0 - E_mean)


def oren_nayar_albedo(color, sigma) -> np.ndarray:
    """(3,) white-furnace albedo of a Diffuse BSDF of colour ``color`` and roughness ``sigma``
    (Lambert, = colour, when sigma is 0)."""
    color = np.maximum(np.asarray(color, dtype=np.float64), 0.0)
    if sigma < 1e-5:
        return color.copy()
    mu, w = _gauss_mu()
    return color * np.sum((2 * mu * w)[:, None] * oren_nayar_directional(color, sigma, mu), axis=0)


# ------------------------------------------------------------------ the Principled BSDF
@dataclass(frozen=True)
class PrincipledParams:
    """The inputs of a Principled BSDF that change its albedo (Blender's names and defaults)."""

    base_color: tuple = (0.8, 0.8, 0.8)
    roughness: float = 0.5
    ior: float = 1.5
    specular_ior_level: float = 0.5
    specular_tint: tuple = (1.0, 1.0, 1.0)
    metallic: float = 0.0
    transmission: float = 0.0
    coat_weight: float = 0.0
    coat_roughness: float = 0.03
    coat_ior: float = 1.5
    coat_tint: tuple = (1.0, 1.0, 1.0)
    sheen_weight: float = 0.0
    subsurface_weight: float = 0.0
    alpha: float = 1.0
    thin_film_thickness: float = 0.0
    anisotropic: float = 0.0
    diffuse_roughness: float = 0.0
    multiscatter: bool = True  # distribution "MULTI_GGX" (the default) or "GGX"


@dataclass
class PrincipledAlbedo:
    albedo: np.ndarray  # (3,) white-furnace albedo: the effective Lambertian reflectance
    normal: np.ndarray  # (3,) R(mu = 1): what a bake (view along the normal) shows per unit irradiance x pi
    emission: np.ndarray  # (3,) factor on the emission's exitance (coat/sheen attenuation)
    specular: np.ndarray  # (3,) the glossy lobes' share of ``albedo``
    notes: list = field(default_factory=list)

    def directional(self, mu):
        """R(mu) (n, 3): outgoing radiance along cosine mu under uniform unit radiance."""
        return _directional(self._params, np.atleast_1d(np.asarray(mu, dtype=np.float64)))[0]


def _directional(p: PrincipledParams, mu, lobes: list | None = None):
    """(R(mu) (n,3), glossy share (n,3), emission factor (n,3), notes) for view cosines mu.
    ``lobes``: a list that receives the BSDF's closures at these mu, as (kind, weight (n,3),
    details): ("ggx", multiplier of the single-scattering BRDF, _Lobe) and ("diffuse", weight,
    (colour, sigma)), for ``view_brdf``."""
    layers = _Layers(p, np.clip(np.asarray(mu, dtype=np.float64), _MU_MIN, 1.0), lobes)
    layers.alpha()
    if p.sheen_weight > 0:
        layers.notes.append(f"sheen {p.sheen_weight:g}: ignored (Cycles' sheen adds about 0.1 x its weight x "
                            "(Sheen Tint - Base Color) at Sheen Roughness 0.5)")
    if p.coat_weight > 0:
        layers.coat()
    emission = layers.w.copy()
    layers.metal()
    layers.transmission()
    layers.specular()
    layers.diffuse()
    notes = layers.notes
    if p.subsurface_weight > 0:
        notes.append(f"subsurface {p.subsurface_weight:g}: treated as diffuse with Base Color (Cycles' random "
                     "walk reflects a few % less)")
    if p.thin_film_thickness > 0.1:
        notes.append("thin film: ignored")
    if p.anisotropic > 0:
        notes.append("anisotropy: ignored (isotropic roughness)")
    return layers.R, layers.gloss, emission, notes


class _Layers:
    """A Principled BSDF's layers from the top down at view cosines ``mu`` (n,), as Cycles
    stacks them: each adds its reflection to ``R`` (its glossy part to ``gloss`` too, its closure
    to ``lobes`` when given) and leaves ``w``, the weight of the layers still to come."""

    def __init__(self, p: PrincipledParams, mu, lobes):
        self.p, self.mu, self.lobes = p, mu, lobes
        n = len(mu)
        self.base = np.maximum(np.asarray(p.base_color, dtype=np.float64), 0.0)
        self.rough = float(np.clip(p.roughness, 0.0, 1.0))
        self.tint = np.maximum(np.asarray(p.specular_tint, dtype=np.float64), 0.0)
        self.w = np.ones((n, 3))  # the weight of the layers still to come
        self.R = np.zeros((n, 3))
        self.gloss = np.zeros((n, 3))
        self.notes = []

    def _glossy(self, weight, lobe, reflected):
        """A glossy lobe of ``weight`` x its BRDF reflecting ``reflected`` (n, 3)."""
        if self.lobes is not None:
            self.lobes.append(("ggx", weight, lobe))
        self.R += reflected
        self.gloss += reflected

    def alpha(self):
        alpha = float(np.clip(self.p.alpha, 0.0, 1.0))
        if alpha < 1.0:
            self.w *= alpha
            self.notes.append(f"alpha {alpha:g}: the transparent part lets light through, treated as lost")

    def coat(self):
        p, mu = self.p, self.mu
        cw = float(p.coat_weight)
        cior = max(float(p.coat_ior), 1.0)
        crough = float(np.clip(p.coat_roughness, 0.0, 1.0))
        if cior > 1.0:
            lobe = _dielectric_lobe(crough, cior, None, mu, True, real_fresnel=True)
            self._glossy(cw * self.w * lobe.scale, lobe, cw * self.w * lobe.albedo)
            self.w = self.w * np.clip(1.0 - cw * lobe.layering.max(axis=1, keepdims=True), 0.0, 1.0)
        ctint = np.maximum(np.asarray(p.coat_tint, dtype=np.float64), 0.0)
        if not np.allclose(ctint, 1.0):
            cos_t = np.sqrt(1.0 - (1.0 / cior) ** 2 * (1.0 - mu * mu))[:, None]
            self.w = self.w * (1.0 + cw * (ctint[None, :] ** (1.0 / cos_t) - 1.0))
        self.notes.append(f"coat {cw:g}: layered as Cycles does, its glossy reflection treated as diffuse")

    def metal(self):
        metallic = float(np.clip(self.p.metallic, 0.0, 1.0))
        if metallic > 0:
            lobe = _metal_lobe(self.rough, np.minimum(self.base, 1.0), self.tint, self.mu, self.p.multiscatter)
            self._glossy(metallic * self.w * lobe.scale, lobe, metallic * self.w * lobe.albedo)
            self.w = self.w * (1.0 - metallic)
            self.notes.append(f"metallic {metallic:g}: the metal's glossy reflection treated as diffuse with its "
                              "white-furnace albedo (F82-tint GGX)")

    def transmission(self):
        trans = float(np.clip(self.p.transmission, 0.0, 1.0))
        if trans > 0:
            ior = max(float(self.p.ior), 1e-5)
            eta = ior if ior >= 1 else 1.0 / ior
            if eta > 1.0:
                f0 = np.clip(F0_from_ior(ior) * self.tint, 0.0, 1.0)
                est = f0[None, :] + (1 - f0[None, :]) * s_ior_table(self.rough, self.mu, eta)[:, None]
                if self.lobes is not None:  # its reflection, scaled to reflect the estimated albedo
                    lobe = _dielectric_lobe(self.rough, eta, f0, self.mu, False)
                    self.lobes.append(("ggx", trans * self.w * est / np.maximum(lobe.albedo, 1e-9), lobe))
                self.R += trans * self.w * est
                self.gloss += trans * self.w * est
            self.w = self.w * (1.0 - trans)
            self.notes.append(f"transmission {trans:g}: its Fresnel reflection kept, the light it transmits "
                              "treated as lost")

    def specular(self):
        """The dielectric specular layer."""
        ior = max(float(self.p.ior), 1e-5)
        level = max(float(self.p.specular_ior_level), 0.0)
        f0 = float(F0_from_ior(ior))
        eta = ior
        if level != 0.5:
            f0 *= 2.0 * level
            eta = float(ior_from_F0(f0))
            if ior < 1.0:
                eta = 1.0 / eta
        if eta != 1.0:
            lobe = _dielectric_lobe(self.rough, eta, np.clip(f0 * self.tint, 0.0, 1.0), self.mu, self.p.multiscatter)
            self._glossy(self.w * lobe.scale, lobe, self.w * lobe.albedo)
            self.w = self.w * np.clip(1.0 - lobe.layering.max(axis=1, keepdims=True), 0.0, 1.0)

    def diffuse(self):
        """Diffuse and subsurface (both Base Color)."""
        w, base, lobes = self.w, self.base, self.lobes
        sigma = float(np.clip(self.p.diffuse_roughness, 0.0, 1.0))
        if sigma < 1e-5:
            self.R += w * base[None, :]
            if lobes is not None:
                lobes.append(("diffuse", w * base[None, :], (base, 0.0)))
        else:  # Oren-Nayar's weight is Base Color x (1 - subsurface) x w; the subsurface part stays Lambert
            ss = float(np.clip(self.p.subsurface_weight, 0.0, 1.0))
            self.R += w * base[None, :] * ((1.0 - ss) * oren_nayar_directional(base, sigma, self.mu) + ss)
            if lobes is not None:
                lobes.append(("diffuse", (1.0 - ss) * w * base[None, :], (base, sigma)))
                if ss > 0:
                    lobes.append(("diffuse", ss * w * base[None, :], (base, 0.0)))


# ------------------------------------------------------------------ view-dependent BRDF
#: lobes narrower than this (alpha = roughness^2) are widened when the BRDF is evaluated at a
#: few directions (patch centres): a mirror cannot be sampled that way
VIEW_ALPHA_MIN = 0.05


def _fresnel_eval(fres, c):
    c = np.clip(c, 0.0, 1.0)[..., None]
    if fres[0] == "gs":
        _, f0, eta = fres
        F0 = float(F0_from_ior(eta))
        s = np.clip((fresnel_dielectric(c, eta) - F0) / (1.0 - F0), 0.0, 1.0) if F0 < 1 else np.ones_like(c)
        return f0 + (1.0 - f0) * s
    if fres[0] == "diel":
        return np.repeat(fresnel_dielectric(c, fres[1]), 3, axis=-1)
    _, f0, b = fres
    return np.clip(f0 + (1.0 - f0) * (1.0 - c) ** 5 - b * c * (1.0 - c) ** 6, 0.0, 1.0)


def _ggx_eval(alpha, fres, v, l):
    """Single-scattering GGX BRDF f(l, v) (..., 3) for unit incident directions l (..., 3) and unit
    views v that broadcast against them ((3,), l's shape, or (n, 1, 3) against l (n, J, 3): a
    view's own terms computed once for its J directions), local frame (normal z); 0 below the
    horizon."""
    alpha = max(alpha, VIEW_ALPHA_MIN)
    a2 = alpha * alpha
    v = np.asarray(v, dtype=np.float64)
    mu_v = np.maximum(v[..., 2], _MU_MIN)
    mu_l = l[..., 2]
    ok = (mu_l > 0) & (v[..., 2] > 0)
    h = l + v
    h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), TINY)
    c_nh = np.clip(h[..., 2], 0.0, 1.0)
    D = a2 / (np.pi * ((1.0 - c_nh ** 2) + a2 * c_nh ** 2) ** 2)
    G2 = 1.0 / (1.0 + _lambda(a2, mu_v) + _lambda(a2, np.where(ok, mu_l, 1.0)))
    F = _fresnel_eval(fres, np.einsum("...j,...j->...", h, v))
    f = F * (D * G2 / (4.0 * mu_v * np.where(ok, mu_l, 1.0)))[..., None]
    return np.where(ok[..., None], f, 0.0)


def _oren_nayar_eval(color, sigma, v, l):
    """Cycles' rough diffuse BRDF (per unit weight), Fujii + OpenPBR multiple scattering; views v
    that broadcast against the directions l (as _ggx_eval's)."""
    mu_l = l[..., 2]
    v = np.asarray(v, dtype=np.float64)
    ok = (mu_l > 0) & (v[..., 2] > 0)
    if sigma < 1e-5:
        return np.where(ok[..., None], 1.0 / np.pi, 0.0) * np.ones(3)
    A = 1.0 / (np.pi + sigma * (np.pi / 2 - 2.0 / 3.0))
    B = sigma * A
    nv = np.maximum(v[..., 2], 0.0)
    t = np.einsum("...j,...j->...", l, v) - mu_l * nv
    t = np.where(t > 0, t / np.maximum(np.maximum(mu_l, nv), 1e-30), t)
    c = np.clip(np.asarray(color, dtype=np.float64), 0.0, 1.0)
    E_fit = A * np.pi + (2 * np.pi - 5.6) / 3.0 * B
    ms = c * c * (E_fit / (1.0 - E_fit)) / (1.0 - c * (1.0 - E_fit)) / np.pi
    Ev = A * np.pi + B * _fujii_G(np.maximum(nv, 1e-6))
    El = A * np.pi + B * _fujii_G(np.where(ok, mu_l, 1.0))
    f = (A + B * t)[..., None] + ms * ((1.0 - Ev) * (1.0 - El))[..., None]
    return np.where(ok[..., None], f, 0.0)


#: view cosines at which a material's layer weights are tabulated (BRDFTable)
VIEW_MU = np.linspace(_MU_MIN, 1.0, 65)


class BRDFTable:
    """A material's BSDF as Cycles evaluates it, for many (view, light) pairs at once: its
    closures (engine.principled._directional) with their weights tabulated over the view
    cosine (VIEW_MU, linear interpolation). ``lobes``: [(weight, "principled",
    PrincipledParams) | (weight, "diffuse", (colour (3,), roughness))] (a Mix/Add of BSDFs)."""

    def __init__(self, lobes):
        self.terms = []  # (kind, weight table (n_mu, 3), detail)
        for w, kind, d in lobes:
            if kind == "principled":
                closures = []
                _directional(d, VIEW_MU, closures)
                for k, weight, detail in closures:
                    self.terms.append((k, w * weight, detail))
            else:
                color, sigma = d
                color = np.maximum(np.asarray(color, dtype=np.float64), 0.0)
                self.terms.append(("diffuse", w * np.broadcast_to(color, (len(VIEW_MU), 3)), (color, float(sigma))))

    def __call__(self, v, l) -> np.ndarray:
        """(..., 3) f(l, v) (1/sr, without the cosine) for unit incident directions ``l`` (..., 3) in
        the surface's local frame (normal +z) and unit views ``v`` that broadcast against them
        ((3,), l's shape, or (n, 1, 3) for l (n, J, 3): each view's weights and terms once)."""
        l = np.asarray(l, dtype=np.float64)
        l = l[None] if l.ndim == 1 else l
        v = np.asarray(v, dtype=np.float64)
        mu = np.clip(v[..., 2], _MU_MIN, 1.0)
        out = np.zeros(np.broadcast_shapes(l.shape, v.shape))
        for kind, table, detail in self.terms:
            wt = np.stack([np.interp(mu, VIEW_MU, table[:, c]) for c in range(3)], axis=-1)
            if kind == "ggx":
                out += wt * _ggx_eval(detail.alpha, detail.fresnel, v, l)
            else:
                color, sigma = detail
                out += wt * _oren_nayar_eval(color, sigma, v, l)
        return out


def view_brdf(params: PrincipledParams, view, directions) -> np.ndarray:
    """(k, 3) the Principled BSDF f(l, v) as Cycles evaluates it (1/sr, without the cosine)
    for a view direction ``view`` and incident directions ``directions`` (k, 3), both unit
    vectors in the surface's local frame (normal = +z). The radiance seen along v under
    incident radiance L(l) is sum f(l, v) L(l) cos(l) dw. Glossy lobes narrower than
    VIEW_ALPHA_MIN are widened (evaluated at a few directions)."""
    v = np.asarray(view, dtype=np.float64)
    v = v / np.linalg.norm(v)
    lobes = []
    _directional(params, np.array([v[2]]), lobes)
    l = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    out = np.zeros((len(l), 3))
    for kind, weight, detail in lobes:
        if kind == "ggx":
            out += weight[0][None, :] * _ggx_eval(detail.alpha, detail.fresnel, v, l)
        else:
            color, sigma = detail
            out += weight[0][None, :] * _oren_nayar_eval(color, sigma, v, l)
    return out


def lobes_brdf(lobes, view, directions) -> np.ndarray:
    """(k, 3) sum of weight x BRDF over ``lobes`` [(weight, "principled", PrincipledParams) |
    (weight, "diffuse", (colour (3,), roughness))] (a material's Mix/Add of BSDFs), one view."""
    l = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    v = np.asarray(view, dtype=np.float64)
    v = v / np.linalg.norm(v)
    out = np.zeros((len(l), 3))
    for w, kind, d in lobes:
        if kind == "principled":
            out += w * view_brdf(d, v, l)
        else:
            color, sigma = d
            color = np.maximum(np.asarray(color, dtype=np.float64), 0.0)
            out += w * color[None, :] * _oren_nayar_eval(color, float(sigma), v, l)
    return out


@lru_cache(maxsize=1024)
def _albedo_cached(p: PrincipledParams):
    mu, wts = _gauss_mu()
    R, gloss, em, notes = _directional(p, np.append(mu, 1.0))  # the Gauss nodes and the normal at once
    R1, R, gloss, em = R[-1], R[:-1], gloss[:-1], em[:-1]
    wt = (2.0 * mu * wts)[:, None]
    return (np.sum(wt * R, axis=0), R1, np.sum(wt * em, axis=0), np.sum(wt * gloss, axis=0), tuple(notes))


def principled_albedo(params: PrincipledParams | None = None, **kw) -> PrincipledAlbedo:
    """The white-furnace albedo of a Principled BSDF (see the module docstring), per channel.

    ``principled_albedo(base_color=(0.5, 0.5, 0.5), roughness=0.5)`` or with a
    :class:`PrincipledParams`. Results are cached per parameter set.
    """
    p = params if params is not None else PrincipledParams(**{k: (tuple(float(x) for x in v)
                                                                  if isinstance(v, (list, tuple, np.ndarray)) else v)
                                                              for k, v in kw.items()})
    a, r1, em, gl, notes = _albedo_cached(p)
    out = PrincipledAlbedo(a.copy(), r1.copy(), em.copy(), gl.copy(), list(notes))
    out._params = p
    return out
