"""Relight's radiosity engine: pure numpy/scipy/embreex, no bpy.

Modules
- scene: FaceSet / PatchSet data model, meshing into patches, per-face means.
- formfactors: form factors by ray casting with embreex.
- radiosity: forward solvers (Gauss-Seidel, direct).
- inverse: the inverse radiosity system (paper SVD formulation, reduced T formulation, NNLS).
- reduction: light-source reduction (selection procedures and energy-conservation distributions).
"""
