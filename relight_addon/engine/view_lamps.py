"""Lamps' highlights seen by a camera: the reflection of a lamp's direct light through a glossy
BSDF towards the viewer (issue 40; no bpy).

The radiosity model takes a lamp's direct irradiance E into B as rho E (engine.lamps), so a pixel
that reads B sees the lamp's light Lambertian: rho E / pi. Cycles shows f(l, v) E, l the direction
to the lamp at the viewed point x and v towards the viewer. A pixel's radiance gains

    pi L_extra(x) = (pi f(l, v) - rho) E(x)   (W/m^2, the radiosity's units, per channel),

0 exactly on a Lambertian surface (f = rho / pi), a highlight on a glossy one. E(x) is the
lamp's kind's own irradiance at the point (``irradiance_at``, engine.lamps: inverse-square law,
cone, spread, with a shadow ray), per unit strength (the lamp's ``power``: 1 W per channel for a
candidate lamp, its own power for a scene lamp). A lamp with an extent (an area lamp, a point
lamp of radius > 0, a sun of angle > 0) is averaged over ``samples`` stratified lamp samples
per point, each with its own direction l (the highlight of an area lamp is its reflection, not a
point's): a relative noise about 1 / sqrt(samples) per point where the lamp is partly hidden or
the lobe varies across it, none for a delta lamp (one exact ray). Cost: one shadow ray per point
and lamp sample.
"""
from __future__ import annotations

import numpy as np

from .lamps import _far
from .principled import BRDFTable
from .view_radiance import _above, frames

__all__ = ["LAMP_VIEW_SAMPLES", "lamp_view_light", "brdf_tables"]

#: lamp samples per viewed point for a lamp with an extent (stratified on a 4 x 4 grid)
LAMP_VIEW_SAMPLES = 16


def _uniforms(rng, n, samples):
    """(samples, n, 2): for each point, ``samples`` jittered cells of a square grid of [0, 1)^2
    (a non-square count: strips along the first coordinate)."""
    g = int(np.sqrt(samples))
    out = np.empty((samples, n, 2))
    for s in range(samples):
        if g * g == samples:
            cell, size = np.array([s // g, s % g]) / g, np.array([1.0 / g, 1.0 / g])
        else:
            cell, size = np.array([s / samples, 0.0]), np.array([1.0 / samples, 1.0])
        out[s] = cell + rng.random((n, 2)) * size
    return out


def _lit(lamp, y, n, u, sampler, far):
    """(e (k,) irradiance per unit power with its shadow ray, w (k, 3) the unit directions to the
    lamp sample) at points y with normals n: the lamp kind's ``irradiance_at`` and, when it casts
    shadows, a shadow ray per lit point (as engine.lamps._irradiance_at)."""
    e, w, t, _ = lamp.kind.irradiance_at(lamp, y, n, u, far)
    e = np.array(e, dtype=np.float64)
    if lamp.cast_shadow:
        lit = np.flatnonzero(e > 0)
        if len(lit):
            o = (y[lit] + n[lit] * sampler.offset).astype(np.float32)
            ok = sampler.visible(o, w[lit].astype(np.float32),
                                 np.maximum(t[lit] - 2 * sampler.offset, 0.0).astype(np.float32))
            e[lit[~ok]] = 0.0
    return e, np.asarray(w, dtype=np.float64)


def brdf_tables(material_lobes, material) -> dict:
    """{m: engine.principled.BRDFTable of material_lobes[m]} for each material m of ``material``."""
    return {int(m): BRDFTable(material_lobes[int(m)]) for m in np.unique(material)}


def lamp_view_light(lamps, point, patch, view, normal, reflectance, material, material_lobes, sampler,
                    samples=LAMP_VIEW_SAMPLES, seed=0, tables=None, excess=None) -> np.ndarray:
    """(n, len(lamps), 3) pi L_extra = (pi f(l, v) - rho) E (W/m^2 per unit strength of each lamp,
    module docstring) at ``point`` (n, 3) on patches ``patch`` (n,), seen along ``view`` (n, 3)
    unit directions from the viewer to the points. ``normal``, ``reflectance`` (P, 3) and
    ``material`` (P,) are the patches' (``material_lobes``: each material's BSDFs,
    engine.principled.BRDFTable); ``sampler``: the scene's engine.sampling.SceneSampler (shadow
    rays). Deterministic for a seed. The caller passes glossy points only (a Lambertian one is 0).
    ``tables``: {material: its BRDFTable} of the points' materials, built by a caller that calls
    again (default: built here). ``excess(lamp)``: (n, 3) the albedo of the lamp's first reflection
    beyond rho at the points' patches that B holds (engine.incidence.lamp_albedo_excess: the
    problem's lamp_excess), taken off too: (pi f - rho - x) E, the BSDF giving the reflection itself."""
    point = np.asarray(point, dtype=np.float64).reshape(-1, 3)
    patch = np.asarray(patch, dtype=np.int64).reshape(-1)
    view = np.asarray(view, dtype=np.float64).reshape(-1, 3)
    n_pts = len(point)
    out = np.zeros((n_pts, len(lamps), 3))
    if n_pts == 0 or not lamps:
        return out
    normal = np.asarray(normal, dtype=np.float64)
    rho = np.asarray(reflectance, dtype=np.float64)[patch]
    mat = np.asarray(material, dtype=np.int64)[patch]
    nrm = normal[patch] / np.linalg.norm(normal[patch], axis=1, keepdims=True)
    # each point's local frame (its patch's) and its view towards the viewer, as view_rows takes them
    R = frames(normal[patch])  # (n, 3, 3)
    v_loc = _above(np.einsum("nab,nb->na", R, -view))
    if tables is None:
        tables = brdf_tables(material_lobes, mat)
    far = _far(sampler)
    for k, lamp in enumerate(lamps):
        ns = 1 if lamp.kind.samples_per_point(lamp) == 1 else int(samples)
        rng = np.random.default_rng([int(seed), k])
        acc = np.zeros((n_pts, 3))
        albedo = rho if excess is None else rho + excess(lamp)
        for u in _uniforms(rng, n_pts, ns):
            e, w = _lit(lamp, point, nrm, u, sampler, far)
            on = np.flatnonzero(e > 0)
            if not len(on):
                continue
            l_loc = _above(np.einsum("nab,nb->na", R[on], w[on]))
            f = np.empty((len(on), 3))
            for m, table in tables.items():
                sel = mat[on] == m
                if sel.any():
                    f[sel] = table(v_loc[on][sel], l_loc[sel])
            acc[on] += (np.pi * f - albedo[on]) * e[on, None]
        out[:, k, :] = acc / ns * np.asarray(lamp.power, dtype=np.float64)[None, :]
    return out
