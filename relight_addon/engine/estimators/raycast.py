"""Hemisphere ray casting (engine.formfactors): rays from every patch, cosine-distributed."""
from __future__ import annotations

from ..formfactors import compute_form_factors
from ..registry import ESTIMATORS


@ESTIMATORS.register("raycast", "Hemisphere Ray Casting",
                     "Rays from every patch, cosine-distributed over its hemisphere (Sobol), counted where they land")
def estimate(patches, options, progress=None, cancel=None, pairs=None):
    kw = {} if options.rays_per_patch is None else {"rays_per_patch": int(options.rays_per_patch)}
    return compute_form_factors(patches, seed=options.seed, threads=options.threads, progress=progress,
                                cancel=cancel, **kw)
