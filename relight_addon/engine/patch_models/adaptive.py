"""The adaptive model: patches and lights that follow what the solve needs, not the topology.

Per face, a size (m):
- candidate faces (may emit): the *light size* ``light_size`` (default: the patch size);
- painted targets and the scene's emitters: the patch size;
- everything else (reflectors, occluders): the patch size x 2^(1 - level), level 1 at first
  (the patch size); ``refine`` raises it where the targets need it and lowers it (twice the
  patch size) where they do not.

A face larger than its size is split (quads into grids of bilinear sub-quads, other faces'
triangles into sub-triangles): each piece is a patch. A face about its size (longest edge between
half its size and its size) is a patch of its own. Faces much smaller than their size (longest
edge below half of it) are *clustered*: the faces of one object that share a key -- candidate / forbidden / target /
emitter status, reflectance, exitance, painted value, size, normal bucket (the nearest of 26
directions: a normal cone of about 30 degrees) and voxel of that size -- and are connected
through shared (welded) vertices form one patch. So a dense prop becomes a handful of patches,
and a patch never mixes painted with unpainted faces, different painted values, or candidate
with forbidden faces. Painted faces keep the resolution they were painted at (issue 18: the
error, the selection and the layer are the faces' own): they are clustered only below
TARGET_CLUSTER_BELOW of their size, in voxels of twice that.

Lights (multi-scale candidates, ``scales``): every candidate patch is a light cell; cells of
one object whose centres fall in one voxel of twice the light size and share a normal bucket
form a group (about 2 x 2 cells); all the cells of one polygon form a polygon light. Groups and
polygon lights of a single cell, and duplicates, are dropped. A group's transfer is the sum of
its cells' (InverseProblem's light basis).

Refinement (``refine``): the importance psi of every patch for the targets, the adjoint
solution A^T psi = w (w: the targets' area fractions; Smits, Arvo & Salesin 1992), times the
power it sends, A_j B_j, ranks the reflector patches; the highest are split (their faces go one
level finer) until they cover ``REFINE_SHARE`` of the total, and those of the lowest
``MERGE_SHARE`` are merged (their faces go one level coarser).
"""
from __future__ import annotations

import numpy as np
import scipy.optimize as sopt
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..geometry import group_sum, unit
from ..lights import LightSet, kind_code
from ..registry import PATCH_MODELS, Param
from ..extent import face_sizes, triangle_measures
from ..scene import SceneError, build_patches, check_size, default_max_patch_size, face_triangles, split_faces
from ..units import TINY

__all__ = ["AdaptiveModel", "DIRECTIONS", "normal_bucket"]

_d = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1) if (a, b, c) != (0, 0, 0)],
              dtype=np.float64)
#: the 26 directions of the normal buckets (cube faces, edges and corners)
DIRECTIONS = _d / np.linalg.norm(_d, axis=1, keepdims=True)
#: reflector levels: 0 (twice the patch size), 1 (the patch size: the start) .. MAX_LEVEL
START_LEVEL = 1
MAX_LEVEL = 3
#: ... and the merged ones the lowest share
MERGE_SHARE = 0.05
#: a refinement pass splits the most important reflector patches until they hold this share of
#: the total importance-weighted power of the splittable ones
REFINE_SHARE = 0.5
#: faces whose longest edge is below this fraction of their size are clustered; faces between
#: it and their size are patches of their own (as in the polygon model); larger faces are split
CLUSTER_BELOW = 0.5
#: painted faces are clustered only below this fraction of the patch size (in voxels of twice it):
#: the targets' rows are the faces as painted (issue 18), but a densely painted prop does not
#: make a patch of each of its faces
TARGET_CLUSTER_BELOW = 1.0 / 16
#: welding tolerance of vertices, relative to the scene's diagonal
WELD = 1e-7
#: the light kinds (engine/lights/) this model makes, finest first
SURFACE_SCALES = ("cell", "group", "polygon")


def normal_bucket(normals) -> np.ndarray:
    """Index of the nearest of the 26 DIRECTIONS of each normal (N, 3)."""
    return np.argmax(np.asarray(normals, dtype=np.float64) @ DIRECTIONS.T, axis=1)


def _ids(rows) -> np.ndarray:
    """A dense id per distinct row of ``rows`` (N, k), in sorted-row order (floats compared by
    their exact value). A lexicographic sort of the columns: much faster than np.unique(axis=0)."""
    rows = np.asarray(rows)
    if len(rows) == 0:
        return np.zeros(0, dtype=np.int64)
    rows = rows.reshape(len(rows), -1)
    if rows.dtype.kind == "f":
        rows = np.ascontiguousarray(rows + 0.0, dtype=np.float64).view(np.int64)  # +0.0: no -0.0
    order = np.lexsort(rows.T[::-1])
    s = rows[order]
    gid = np.concatenate([[0], np.cumsum(np.any(s[1:] != s[:-1], axis=1))])
    out = np.empty(len(rows), dtype=np.int64)
    out[order] = gid
    return out


@PATCH_MODELS.register("adaptive", "Adaptive",
                       "Small polygons clustered, candidate surfaces cut into light cells (cells, 2x2 groups, "
                       "whole polygons), reflectors refined where the targets need it",
                       params=(
                           Param("light_size", float, None, min=0.0, min_exclusive=True, unit="LENGTH",
                                 label="Light Size", ui="zero", none="the patch size",
                                 description="Size of the candidate lights' cells in metres"),
                           Param("refine_passes", int, 0, min=0, soft_max=8, label="Refine Passes", inverse_only=True,
                                 description="Importance-driven refinement passes after a first solve (0 = none; "
                                             "measured: docs/benchmarks.md)"),
                           Param("refine_tolerance", float, 0.02, min=0.0, soft_max=0.5, label="Refine Tolerance",
                                 inverse_only=True,
                                 description="Refinement stops when the predicted target radiosity moves less "
                                             "than this (relative)"),
                       ))
class AdaptiveModel:
    scales = SURFACE_SCALES

    def __init__(self, options, default_max_patch_size=None):
        self.patch_size = options.max_patch_size if options.max_patch_size is not None else default_max_patch_size
        self.light_size = getattr(options, "light_size", None)
        self.level = None  # per face, reflectors' refinement level (set on the first mesh)

    # -- patches -------------------------------------------------------------------------
    def _sizes(self, faces):
        if self.patch_size is None:
            self.patch_size = default_max_patch_size(faces)
        self.patch_size = check_size(self.patch_size)
        if self.light_size is None:
            self.light_size = self.patch_size
        self.light_size = check_size(self.light_size, "light size")
        emit = np.any(faces.exitance > 0, axis=1)
        cand = ~faces.forbidden & ~emit
        if self.level is None:
            self.level = np.full(faces.n_faces, START_LEVEL, dtype=np.int64)
        reflector = ~cand & ~faces.target & ~emit
        size = np.where(cand, self.light_size, self.patch_size)
        size = np.where(reflector, self.patch_size * 2.0 ** (1 - self.level), size)
        return face_sizes(faces, size), cand, emit, reflector

    def mesh(self, faces):
        size, cand, emit, reflector = self._sizes(faces)
        T, ok, face_edge = face_triangles(faces)
        tf = faces.triangle_face
        # much smaller than its size: clustered (never the scene's emitters: they are lamps the
        # direct-lighting mode reduces one polygon at a time)
        # painted faces keep the resolution they were painted at: clustered only when much smaller
        # still (TARGET_CLUSTER_BELOW), in voxels of that size
        below = np.where(faces.target, TARGET_CLUSTER_BELOW, CLUSTER_BELOW) * size
        small = (face_edge <= below) & ~emit
        whole = (face_edge <= size) & ~small  # about its size: a patch of its own
        # per face: area-weighted normal and centroid
        m = triangle_measures(faces)  # (the memory check's and the region's, not measured again)
        cr, ta, fa = m.cross, m.area, m.face_area
        normal = unit(group_sum(tf, cr, faces.n_faces))
        centroid = group_sum(tf, T.mean(axis=1), faces.n_faces, ta) / np.where(fa > 0, fa, 1.0)[:, None]
        lo = faces.vertices.min(axis=0)
        voxel = np.floor((centroid - lo) / np.where(faces.target, 2 * below, size)[:, None]).astype(np.int64)
        key = np.column_stack([
            faces.face_object, cand, faces.target, emit, faces.forbidden,
            _ids(faces.reflectance), _ids(faces.exitance), _ids(np.where(faces.target[:, None],
                                                                         faces.target_radiosity, 0.0)),
            _ids(size[:, None]), normal_bucket(normal), voxel])
        kid = _ids(key[small])
        # connected components among the small faces of one key, through welded vertices
        scale = float(np.linalg.norm(faces.vertices.max(axis=0) - lo))
        weld = _ids(np.rint((faces.vertices - lo) / (WELD * max(scale, TINY))).astype(np.int64))
        small_id = np.full(faces.n_faces, -1, dtype=np.int64)
        small_id[small] = np.arange(int(small.sum()))
        corner_tri = np.flatnonzero(small[tf] & ok)
        cf = small_id[tf[corner_tri]].repeat(3)
        cv = weld[faces.triangles[corner_tri].reshape(-1)]
        node = _ids(np.column_stack([kid[cf], cv]))
        ns, nn = int(small.sum()), int(node.max(initial=-1)) + 1
        G = sp.csr_matrix((np.ones(len(cf)), (cf, ns + node)), shape=(ns + nn, ns + nn))
        _, label = connected_components(G, directed=False)
        cluster = label[:ns]
        # triangles: small faces whole (one patch per cluster), faces about their size whole (one
        # patch each), larger faces split at their size
        sel = small[tf] & ok
        wsel = whole[tf] & ok
        st, sf, sl = split_faces(faces, T, np.flatnonzero(~small & ~whole), size)
        tri = np.concatenate([T[sel], T[wsel], st])
        face = np.concatenate([tf[sel], tf[wsel], sf])
        local = np.concatenate([np.zeros(int(wsel.sum()), dtype=np.int64), sl])
        n_cl = int(cluster.max(initial=-1)) + 1
        pkey = np.concatenate([cluster[small_id[tf[sel]]],
                               n_cl + face[int(sel.sum()):] * (int(local.max(initial=0)) + 1) + local])
        patches = build_patches(faces, tri, face, pkey, self.patch_size, light_size=self.light_size)
        patches.level = np.where(reflector[patches.face], self.level[patches.face], -1)
        return patches

    # -- lights --------------------------------------------------------------------------
    def lights(self, patches, mask, scales=None):
        scales = self.scales if scales is None else tuple(scales)
        for s in scales:
            if s not in SURFACE_SCALES:
                raise ValueError(f"unknown light scale {s!r}; use {', '.join(SURFACE_SCALES)}")
        C = np.flatnonzero(mask)
        nC = len(C)
        if not nC:
            raise SceneError("no candidate light: every face is forbidden")
        parts = []  # (member rows into C, light id within the part, kind)
        if "cell" in scales:
            parts.append((np.arange(nC), np.arange(nC), "cell"))
        group = None
        if "group" in scales:
            size = 2.0 * (patches.light_size or patches.max_patch_size)
            vox = np.floor((patches.center[C] - patches.center.min(axis=0)) / size).astype(np.int64)
            group = _ids(np.column_stack([patches.object[C], normal_bucket(patches.normal[C]), vox]))
            gsize = np.bincount(group)
            keep = gsize[group] >= 2 if "cell" in scales else np.ones(nC, bool)
            parts.append((np.flatnonzero(keep), _ids(group[keep][:, None]), "group"))
        if "polygon" in scales:
            poly = _ids(patches.face[C][:, None])
            psize = np.bincount(poly)
            keep = psize[poly] >= 2 if "cell" in scales else np.ones(nC, bool)
            if group is not None:  # a polygon that is exactly one group is already a light
                gmin = np.full(len(psize), np.iinfo(np.int64).max)
                gmax = np.full(len(psize), -1)
                np.minimum.at(gmin, poly, group)
                np.maximum.at(gmax, poly, group)
                same = (gmin == gmax) & (np.bincount(group, minlength=gmax.max() + 1)[np.maximum(gmax, 0)] == psize)
                keep &= ~same[poly]
            parts.append((np.flatnonzero(keep), _ids(poly[keep][:, None]), "polygon"))
        rows, cols, kinds = [], [], []
        n = 0
        for members, lid, kind in parts:
            if not len(members):
                continue
            rows.append(members)
            cols.append(n + lid)
            k = int(lid.max()) + 1
            kinds.append(np.full(k, kind_code(kind), dtype=np.int8))
            n += k
        basis = sp.csr_matrix((np.ones(sum(len(r) for r in rows)), (np.concatenate(rows), np.concatenate(cols))),
                              shape=(nC, n))
        lights = LightSet(C, basis, np.concatenate(kinds)).with_geometry(patches)
        # a canonical order (kind, then position): the same lights get the same indices after a
        # refinement of the reflectors
        q = np.rint(lights.center / (1e-6 * max(float(np.ptp(patches.center, axis=0).max()), TINY)))
        order = np.lexsort((lights.area, q[:, 2], q[:, 1], q[:, 0], lights.kind))
        return LightSet(C, basis[:, order].tocsr(), lights.kind[order], lights.area[order], lights.center[order],
                        lights.normal[order])

    # -- refinement ----------------------------------------------------------------------
    def refine(self, faces, patches, importance) -> bool:
        """Split the reflector patches of highest ``importance`` (P,) (psi_j A_j B_j) and merge
        those of lowest: their faces go one level finer / coarser. Returns False when nothing
        changed."""
        if self.level is None:  # the patches were meshed by another instance with the same options
            self._sizes(faces)
        refl = patches.level >= 0
        eta = np.where(refl, np.maximum(importance, 0.0), 0.0)
        total = eta.sum()
        if not total > 0:
            return False
        order = np.argsort(-eta, kind="stable")
        cum = np.cumsum(eta[order])
        split = order[:int(np.searchsorted(cum, REFINE_SHARE * total)) + 1]
        split = split[(eta[split] > 0) & (patches.level[split] < MAX_LEVEL)]
        low = order[cum > (1.0 - MERGE_SHARE) * total]
        merge = low[refl[low] & (patches.level[low] > 0)]
        before = self.level.copy()
        for sel, step in ((split, 1), (merge, -1)):
            if len(sel):
                f = np.unique(patches.tri_face[np.isin(patches.tri_patch, sel)])
                self.level[f] = np.clip(before[f] + step, 0, MAX_LEVEL)
        return bool(np.any(self.level != before))


def refinement_measure(problem, history: list):
    """Importance of every patch for the targets and the change of the predicted target
    radiosity since the previous model.

    The reference configuration is the best non-negative one (NNLS on T) of the first model;
    its lights keep their indices across refinements (the patch model's canonical light order),
    so ``T e`` on each new model says how much the targets' prediction moved: the relative change
    is returned (None on the first model). Importance psi solves A^T psi = w, w the targets'
    area fractions, and weights the power each patch sends: psi_j A_j B_j (summed over the
    channels), with B the radiosity of the reference configuration.
    """
    if not history:
        e_ref = np.stack([sopt.nnls(problem.transfer[c], problem.b_target[:, c],
                                    maxiter=50 * problem.n_lights)[0] for c in range(3)], axis=1)
    else:
        e_ref = history[0][0]
    pred = problem.target_radiosity_of(e_ref)
    change = None
    if history:
        prev = history[-1][1]
        change = float(np.linalg.norm(pred - prev) / max(np.linalg.norm(prev), TINY))
    history.append((e_ref, pred, change))
    facs = problem.factors()
    w = np.zeros(problem.n_patches)
    w[problem.targets] = problem.area[problem.targets] / problem.area[problem.targets].sum()
    B = problem.forward_radiosity(problem.patch_exitance(e_ref)) + problem.background_radiosity
    importance = np.zeros(problem.n_patches)
    for c in range(3):
        psi = facs[c].solve(w, trans=True)
        importance += psi * problem.area * B[:, c]
    return change, importance
