"""Illuminance on work planes (Fill Selected in lx): a face asked for E_v lx is a target of
radiosity reflectance x E (engine.units.irradiance_from_lux: white light of that illuminance, the
export's ``target_radiosity``), one row per patch, selecting it; each object's rows are a region
of the least-power selection's uniformity goal."""
from __future__ import annotations

import numpy as np

from ..registry import TARGET_KINDS
from ..scene import patch_lux
from .kind import Target, selection_rows


@TARGET_KINDS.register("illuminance", "Illuminance", "Work-plane faces asked for an illuminance (lx)")
class Illuminance(Target):
    """Patches ``patches`` (k,) of objects ``objects`` (k,) asked for ``lux`` (k,) lx, as the
    radiosity ``values`` (k, 3) W/m^2 (their reflectance x lux / 683)."""

    kind = "illuminance"
    unit = "lx"

    def __init__(self, patches, values, lux, objects):
        self.patches = np.asarray(patches, dtype=np.int64).reshape(-1)
        self.values = np.asarray(values, dtype=np.float64).reshape(len(self.patches), 3)
        self.lux = np.asarray(lux, dtype=np.float64).reshape(len(self.patches))
        self.objects = np.asarray(objects, dtype=np.int64).reshape(len(self.patches))

    def rows(self, n_patches):
        return selection_rows(self.patches, n_patches)

    @property
    def region(self) -> np.ndarray:
        return self.objects.copy()

    def shown(self) -> np.ndarray:
        """(k, 3): the illuminance asked for (lx), in every channel (white light)."""
        return np.repeat(self.lux[:, None], 3, axis=1)

    @classmethod
    def from_scene(cls, faces, patches, F=None, kept=()):
        """The patches of faces with an illuminance target (FaceSet.target_lux > 0)."""
        lux = patch_lux(faces, patches)
        if lux is None:
            return None
        sel = np.flatnonzero(np.asarray(patches.target, dtype=bool) & (lux > 0))
        if len(sel) == 0:
            return None
        return cls(sel, patches.target_radiosity[sel], lux[sel], patches.object[sel])
