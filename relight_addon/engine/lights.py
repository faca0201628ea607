"""The light model: which patches may emit, and how they group into lights (no bpy).

A *candidate* is a patch that may become a light: ``candidate_mask`` is the one definition.
A *light* is a set of candidate patches that share one exitance (W/m^2): one patch (a light
cell), several cells (a group), or all the cells of a polygon. A :class:`LightSet` holds the
membership matrix ``basis`` (candidate patches x lights, 0/1); lights may overlap (the same
cell in a cell light, a 2x2 group and its polygon: multi-scale candidates), so the exitance
a patch emits is ``basis @ e``. The patch model (engine/patch_models/) builds the LightSet;
InverseProblem, the reduction, the stored result and the add-on all work per light.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .geometry import group_mean_basis, unit

__all__ = ["LightSet", "candidate_mask", "lights_from_groups", "KINDS"]

#: light kinds, the codes of ``LightSet.kind``
KINDS = ("cell", "group", "polygon")


def candidate_mask(patches, mode: str = "inverse") -> np.ndarray:
    """(P,) bool: the patches that may emit.

    inverse ("solve"): every patch that is not forbidden and not already emitting (the
    scene's own emitters stay fixed background light). direct ("reduce"): the scene's
    emitters (patches with a positive exitance in any channel).
    """
    emitting = np.any(patches.exitance > 0, axis=1)
    if mode == "direct":
        return emitting
    if mode != "inverse":
        raise ValueError(f"unknown mode {mode!r}; use 'inverse' or 'direct'")
    return ~patches.forbidden & ~emitting


@dataclass
class LightSet:
    """Lights over the candidate patches ``patches`` (|C|,) (ascending patch indices).

    basis: (|C|, n_lights) CSR 0/1, patch c belongs to light l. kind: (n_lights,) index into
    KINDS. area (m^2), center, normal: per light, area-weighted over its patches.
    """

    patches: np.ndarray
    basis: sp.csr_matrix
    kind: np.ndarray
    area: np.ndarray = field(default=None)
    center: np.ndarray = field(default=None)
    normal: np.ndarray = field(default=None)

    @property
    def n_lights(self) -> int:
        return int(self.basis.shape[1])

    def with_geometry(self, patch_set):
        a = patch_set.area[self.patches]
        self.area = np.asarray(self.basis.T @ a).reshape(-1)
        self.center = group_mean_basis(self.basis, patch_set.center[self.patches], a)
        self.normal = unit(group_mean_basis(self.basis, patch_set.normal[self.patches], a))
        return self

    def members(self, light) -> np.ndarray:
        """Patch indices of one light."""
        col = self.basis.tocsc()[:, light]
        return self.patches[col.indices]

    def patch_exitance(self, exitance, n_patches) -> np.ndarray:
        """(n_patches, 3) exitance the lights' ``exitance`` (n_lights, 3) put on the patches."""
        out = np.zeros((n_patches, 3))
        out[self.patches] = self.basis @ np.asarray(exitance, dtype=np.float64).reshape(-1, 3)
        return out


def lights_from_groups(patch_set, mask, groups, kind=0) -> LightSet:
    """One light per distinct value of ``groups`` (P,) over the patches in ``mask`` (P,) bool."""
    C = np.flatnonzero(mask)
    _, light_of = np.unique(np.asarray(groups)[C], return_inverse=True)
    light_of = light_of.reshape(-1)
    n = int(light_of.max()) + 1 if len(C) else 0
    basis = sp.csr_matrix((np.ones(len(C)), (np.arange(len(C)), light_of)), shape=(len(C), n))
    return LightSet(C, basis, np.full(n, kind, dtype=np.int8)).with_geometry(patch_set)
