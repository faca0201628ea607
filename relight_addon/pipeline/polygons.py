"""Patches -> the artist's base-mesh polygons: the rows of the reports and of the scene (no bpy)."""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..engine.scene import FaceSet, PatchSet

__all__ = ["PolygonMap"]


class PolygonMap:
    """Patches -> base-mesh polygons: the reports' and the scene's rows.

    Every exported object's polygons are numbered globally (``offset[object] + polygon``);
    ``weights`` (n_polygons, P) CSR holds, per polygon, the area fractions of the patches its
    triangles lie on, so ``weights @ v`` is the area-weighted (power-conserving) mean of
    per-patch values over each polygon. Faces without a base polygon (face_index -1: made by a
    modifier, or instances) are left out; a polygon without area gets 0.
    """

    def __init__(self, faces: FaceSet, patches: PatchSet, polygon_counts=None):
        counts = []
        per_index = isinstance(polygon_counts, (list, tuple))
        if per_index and len(polygon_counts) != len(faces.object_names):
            raise ValueError(f"polygon_counts has {len(polygon_counts)} entries for {len(faces.object_names)} objects")
        for oi, name in enumerate(faces.object_names):
            if per_index:  # per object index: None = an unreported group (instances), no polygons
                n = 0 if polygon_counts[oi] is None else polygon_counts[oi]
            else:
                n = polygon_counts.get(name) if polygon_counts else None
            if n is None:
                idx = faces.face_index[(faces.face_object == oi) & (faces.face_index >= 0)]
                n = int(idx.max()) + 1 if len(idx) else 0
            counts.append(int(n))
        self.names = list(faces.object_names)
        #: indices of the objects the reports list (keyed by name): every one, except the
        #: unreported groups (None in a per-index ``polygon_counts``: instance groups)
        self.reported = [oi for oi in range(len(self.names))
                         if not (per_index and polygon_counts[oi] is None)]
        self.offset = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.n = int(self.offset[-1])
        face_pid = np.where(faces.face_index >= 0, self.offset[faces.face_object] + faces.face_index, -1)
        pid = face_pid[patches.tri_face]
        ok = pid >= 0
        ta = patches.tri_area[ok]
        A = sp.csr_matrix((ta, (pid[ok], patches.tri_patch[ok])), shape=(self.n, patches.n_patches))
        A.sum_duplicates()
        self.area = np.asarray(A.sum(axis=1)).reshape(-1)
        self.weights = (sp.diags(1.0 / np.where(self.area > 0, self.area, 1.0)) @ A).tocsr()
        self.pairs = A  # polygon x patch areas (m^2)

    def mean(self, patch_values) -> np.ndarray:
        """(n_polygons, k) area-weighted means of per-patch values (P, k)."""
        return np.asarray(self.weights @ np.asarray(patch_values, dtype=np.float64))

    def split(self, rows) -> dict:
        """Global polygon rows -> {object name: its rows}, for the reported objects (keys are
        unambiguous: real object names; groups without polygons are left out)."""
        out = {}
        for k in self.reported:  # real objects come first: a later group of the same name is left out
            out.setdefault(self.names[k], rows[self.offset[k]:self.offset[k + 1]])
        return out
