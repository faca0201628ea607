"""Relight's radiosity engine: pure numpy/scipy/embreex, no bpy (docs/architecture.md).

Data and units
- units: the unit conversions and constants (pi, MAX_REFLECTANCE, 683 lm/W).
- scene: FaceSet / PatchSet data model, meshing building blocks, per-face means.
- geometry: triangle areas, group sums and means.
- lights/: the light model: a light is a source (LightKind, LightSet, candidate_mask; one
  file per kind).
- options: JobOptions and the defaults shared by the CLI and the add-on.
- registry: the registries of interchangeable methods (below).
- blas_threads: one BLAS thread for work of many small products (Live's re-solves).

Transport
- sampling: the one Embree scene of a solve and its queries, the chunk runner.
- formfactors: form factors by hemisphere ray casting (embreex).
- kernel_transfer: the analytic point-to-polygon kernel with shadow rays.
- radiosity: forward solvers (Gauss-Seidel, direct).
- incidence: the lights' first reflection at the albedo of its incidence.
- principled: Cycles' Principled BSDF (white-furnace albedo, evaluation).
- view_radiance: radiance along a view through the materials' BSDFs.
- bounces: the bounce limits Cycles needs.
- closed_forms: Howell's closed-form form factors (references).

Inverse lighting
- inverse: the inverse radiosity system (InverseProblem, solve_inverse).
- reduction: light-source reduction (the curve, stop criteria, Distributor).
- best_lights: Best k Lights (greedy pursuit with swaps) and its certificate.
- cost: memory and time estimate of a job; refusal before the work.

Registered methods (one file each): patch_models/, estimators/, solvers/ (common.py: what they
share), selections/, distributions/, lights/.
"""
