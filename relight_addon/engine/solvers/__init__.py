"""Inverse solvers (see engine.registry): each module registers one in SOLVERS."""
from . import reduced, svd, nnls  # noqa: F401  (registration order = the order the UI lists them)
