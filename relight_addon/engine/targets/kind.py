"""The target-kind interface (engine/targets/__init__.py's docstring): ``Target``, the base of
every kind, and ``selection_rows``, the rows of a kind that selects patches."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["Target", "selection_rows"]


def selection_rows(patches, n_patches) -> sp.csr_matrix:
    """(k, P) CSR: row i selects patch ``patches[i]`` (weight 1)."""
    patches = np.asarray(patches, dtype=np.int64).reshape(-1)
    k = len(patches)
    return sp.csr_matrix((np.ones(k), patches, np.arange(k + 1)), shape=(k, n_patches))


class Target:
    """A target of some kind (engine/targets' docstring): subclasses set ``kind`` and ``unit`` and give
    ``rows``, ``values`` and, when they differ from the defaults, ``region`` and ``shown``."""

    kind = ""
    unit = "W/m^2"
    values: np.ndarray

    def rows(self, n_patches) -> sp.csr_matrix:
        raise NotImplementedError

    @property
    def region(self) -> np.ndarray:
        return np.full(len(self.values), -1, dtype=np.int64)

    def shown(self) -> np.ndarray:
        return np.asarray(self.values, dtype=np.float64)

    @classmethod
    def from_scene(cls, faces, patches, F=None):
        """This kind's target of a scene (FaceSet ``faces`` meshed into ``patches``), or None."""
        return None
