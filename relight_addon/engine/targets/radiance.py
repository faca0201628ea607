"""Painted radiance: faces painted with the radiosity they should have (W/m^2, each face's paint
read by engine.paint): one row per painted patch, selecting it."""
from __future__ import annotations

import numpy as np

from ..registry import TARGET_KINDS
from ..scene import patch_lux
from .kind import Target, selection_rows


@TARGET_KINDS.register("radiance", "Painted Radiance", "Faces painted with the radiosity they should have")
class PaintedRadiance(Target):
    """Patches ``patches`` (k,) asked for the radiosity ``values`` (k, 3) W/m^2."""

    kind = "radiance"
    unit = "W/m^2"

    def __init__(self, patches, values):
        self.patches = np.asarray(patches, dtype=np.int64).reshape(-1)
        self.values = np.asarray(values, dtype=np.float64).reshape(len(self.patches), 3)

    @classmethod
    def masked(cls, mask, radiosity) -> "PaintedRadiance":
        """The patches of ``mask`` (P,) bool at their rows of ``radiosity`` (P, 3) W/m^2."""
        mask = np.asarray(mask, dtype=bool).reshape(-1)
        return cls(np.flatnonzero(mask), np.asarray(radiosity, dtype=np.float64).reshape(len(mask), 3)[mask])

    def rows(self, n_patches):
        return selection_rows(self.patches, n_patches)

    @classmethod
    def from_scene(cls, faces, patches, F=None, kept=()):
        """The painted patches that are no illuminance target (engine/targets/illuminance.py)."""
        mask = np.asarray(patches.target, dtype=bool)
        lux = patch_lux(faces, patches)
        if lux is not None:
            mask = mask & ~(lux > 0)
        return cls.masked(mask, patches.target_radiosity) if mask.any() else None
