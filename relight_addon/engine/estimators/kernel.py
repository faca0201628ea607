"""Hemisphere ray casting for the whole F, and for the transport that decides the answer -- from
the candidate light cells to the target patches, both directions by reciprocity -- the analytic
point-to-polygon (Lambert) kernel times shadow-ray visibility (engine.kernel_transfer; Baum et al.
1989, Wallace, Elmquist & Haines 1989): no noise where a light sees a target fully."""
from __future__ import annotations

from ..formfactors import compute_form_factors
from ..registry import ESTIMATORS


@ESTIMATORS.register("kernel", "Kernel for Lights to Targets",
                     "Hemisphere ray casting, and the analytic point-to-polygon kernel with shadow rays for the "
                     "transport from candidate lights to targets (low noise for small lights)", kernel_pairs=True)
def estimate(patches, options, progress=None, cancel=None, pairs=None):
    kw = {} if options.rays_per_patch is None else {"rays_per_patch": int(options.rays_per_patch)}
    return compute_form_factors(patches, seed=options.seed, threads=options.threads, progress=progress,
                                cancel=cancel, kernel_pairs=pairs, **kw)
