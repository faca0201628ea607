"""The polygon model: every polygon is a patch (polygons larger than the patch size are split:
quads into grids, other polygons' triangles into sub-triangles), and a light is a whole
polygon (all its patches share one exitance, as one material would make them)."""
from __future__ import annotations

import numpy as np

from ..lights import lights_from_groups
from ..registry import PATCH_MODELS
from ..scene import mesh_patches


@PATCH_MODELS.register("polygon", "Polygons",
                       "A patch per polygon (large ones split), a light per polygon: the artist's mesh as it is",
                       paint_independent=True)  # its patches do not depend on the paint (pipeline.prepared)
class PolygonModel:
    def __init__(self, options, default_max_patch_size=None):
        self.size = options.max_patch_size if options.max_patch_size is not None else default_max_patch_size

    def mesh(self, faces):
        return mesh_patches(faces, self.size)

    def lights(self, patches, mask):
        return lights_from_groups(patches, mask, patches.face, kind="polygon")

    @staticmethod
    def patches_per_light(patches, mask) -> float:
        """The mean number of patches a light holds (engine.cost: a light's direct light is
        computed patch by patch)."""
        return float(mask.sum()) / max(len(np.unique(patches.face[mask])), 1)
