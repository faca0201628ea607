"""Options of a Relight job, with the engine's defaults (shared by the CLI and the add-on)."""
from __future__ import annotations

from dataclasses import asdict, dataclass

from .registry import DISTRIBUTIONS, ESTIMATORS, PATCH_MODELS, SELECTIONS, SOLVERS

DEFAULT_RAYS_PER_PATCH = 0  # 0 / None = automatic: engine.formfactors.auto_rays_per_patch
DEFAULT_SOLVER = "reduced"
DEFAULT_SELECTION = "greedy-swap"  # measured: docs/benchmarks.md "Best k lights"; the paper's is exitance-elimination
DEFAULT_DISTRIBUTION = "distance"  # the paper's choice (section 5)
DEFAULT_MAX_LIGHTS = 3
DEFAULT_PATCH_MODEL = "adaptive"  # the polygon model is the paper's (a patch per face)
DEFAULT_ESTIMATOR = "kernel"

#: configurations kept re-appliable in the .blend: every one up to this many lights, and
#: about STORE_LOG_POINTS log-spaced ones above (plus e_x and the final one); the chart and
#: the report keep the whole curve (the cost model counts their forward solves)
STORE_ALL_UP_TO = 32
STORE_LOG_POINTS = 40
#: intermediate (to-be-refined) models get this fraction of the rays
REFINE_RAY_FRACTION = 4


@dataclass
class JobOptions:
    rays_per_patch: int | None = None  # None or 0: automatic (formfactors.auto_rays_per_patch)
    max_patch_size: float | None = None  # None: scene diagonal / 20
    seed: int = 0
    threads: int | None = None  # None: every core
    solver: str = DEFAULT_SOLVER
    selection: str = DEFAULT_SELECTION
    distribution: str = DEFAULT_DISTRIBUTION
    max_lights: int | None = DEFAULT_MAX_LIGHTS  # stop criterion: number of lights
    error_threshold: float | None = None  # stop criterion: relative error (Eq. 1 / ||b_P||)
    tolerance: float | None = None  # least-power selection: every target within +-tolerance (relative)
    require_positive: bool = True  # stop criterion: no negatives
    patch_model: str = DEFAULT_PATCH_MODEL
    light_size: float | None = None  # None: the patch size (adaptive model's light cells)
    refine_passes: int = 0  # adaptive model: refinement passes after a first solve (measured: docs/benchmarks.md)
    refine_tolerance: float = 0.02  # ... stop when the predicted target radiosity moves less than this (relative)
    estimator: str = DEFAULT_ESTIMATOR

    def validate(self):
        for registry, name in ((SOLVERS, self.solver), (SELECTIONS, self.selection), (DISTRIBUTIONS, self.distribution),
                               (PATCH_MODELS, self.patch_model), (ESTIMATORS, self.estimator)):
            registry[name]  # ValueError naming the known methods
        if self.rays_per_patch == 0:
            self.rays_per_patch = None
        if self.rays_per_patch is not None and self.rays_per_patch < 1:
            raise ValueError("rays per patch must be at least 1 (0 = automatic)")
        if self.max_patch_size is not None and not self.max_patch_size > 0:
            raise ValueError("max patch size must be a positive length")
        if SELECTIONS[self.selection].get("needs_tolerance") and self.tolerance is None:
            raise ValueError(f"the {self.selection} selection needs a tolerance (e.g. 0.1 for +-10 %)")
        if self.tolerance is not None and not (self.tolerance >= 0 and self.tolerance < float("inf")):
            raise ValueError("the tolerance must be a non-negative number")
        if self.light_size is not None and not self.light_size > 0:
            raise ValueError("light size must be a positive length")
        if self.refine_passes < 0:
            raise ValueError("refine passes must be >= 0")
        if self.max_lights is not None and self.max_lights < 1:
            raise ValueError("max lights must be at least 1")
        if self.error_threshold is not None and not self.error_threshold >= 0:
            raise ValueError("the error threshold must be >= 0")
        return self

    def to_dict(self):
        return asdict(self)
