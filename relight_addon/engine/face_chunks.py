"""The exported scene's faces as chunks of numpy arrays, one chunk per mesh (no bpy).

blender/meshes.py's Builder adds each evaluated mesh (and each mesh instance) as a chunk: its
world-space vertices, triangles and polygon loops, and per face its object, base-mesh polygon,
reflectance, exitance (front and back), target and forbidden state. engine/two_sided.py turns
faces (``flip_faces``) and gives the backs that the scene sees faces of their own
(``add_backs``) before blender/export.py concatenates the chunks into a FaceSet.

A chunk's local geometry (``geos``: the dict of blender/meshes.mesh_geometry, or the same keys
built by hand) holds, in its object's space: ``V`` (vertices), ``lt`` and ``lt_poly`` (the loop
triangles and their polygons), ``loop_vert``, ``loop_poly``, ``loop_start``, ``loop_total``,
``loop_edge`` and ``n_edges`` (the polygons' loops and edges), ``mat_index`` and ``slots``.
"""
from __future__ import annotations

import numpy as np

from .geometry import group_sum, triangle_areas
from .scene import SceneError

__all__ = ["MAX_COORDINATE", "FaceChunks", "check_near"]

#: metres: a vertex farther from the origin is refused (an infinite coordinate, stored as 3.4e38)
MAX_COORDINATE = 1e12


def check_near(V, name, origin):
    """SceneError when a vertex of ``V`` (n, 3) lies beyond MAX_COORDINATE from ``origin``."""
    far = float(np.abs(V).max()) if np.size(V) else 0.0
    if far > MAX_COORDINATE:
        raise SceneError(f"object {name!r} has a vertex {far:.3g} m from {origin}: an infinite coordinate? (Blender "
                         f"stores infinity as its largest number, 3.4e+38); Relight models scenes within "
                         f"{MAX_COORDINATE:.0e} m")



class FaceChunks:
    """Accumulates world-space faces of several meshes into FaceSet arrays, one chunk per mesh."""

    def __init__(self):
        self.verts, self.tris, self.tri_face = [], [], []
        self.loop_vert, self.loop_start, self.loop_total = [], [], []
        self.f_obj, self.f_idx, self.rho, self.e, self.tgt, self.tgt_b, self.forb = [], [], [], [], [], [], []
        self.lux = []  # per face: its illuminance target, lx (0: none)
        self.warnings = []
        self.f_mat = []  # per face: its material's index (blender/meshes.Builder.lobes)
        #: per chunk (one add_geometry()): its faces whose material has a linked emission (bool), its
        #: geometry (local arrays), world matrix and object name, and the back side's exitance (None:
        #: the front's)
        self.linked, self.geos, self.e_back = [], [], []
        self.base = []  # per chunk: its first vertex, face and loop
        self.names = []  # object names by object index (the warnings name objects)
        self.nf = self.nv = self.nl = 0

    def add_geometry(self, geo, matrix, name):
        """Start a chunk: the world-space vertices (``matrix``, a 4 x 4 world matrix), triangles
        and polygon loops of ``geo`` (see the module docstring); a negative-determinant
        transform reverses the winding. ``add_faces`` gives its faces' values next."""
        M = np.asarray(matrix, dtype=np.float64)
        if not np.all(np.isfinite(M)):
            raise SceneError(f"object {name!r} has a NaN or infinite transform (its location, rotation or scale, "
                             "or a parent's or a constraint's)")
        W = geo["V"] @ M[:3, :3].T + M[:3, 3]
        if not np.all(np.isfinite(W)):
            raise SceneError(f"object {name!r} has NaN or infinite vertex coordinates")
        check_near(W, name, "the origin")
        flip = np.linalg.det(M[:3, :3]) < 0
        lt = geo["lt"][:, ::-1] if flip else geo["lt"]
        nv, nf = self.nv, self.nf
        self.base.append((nv, nf, self.nl))
        self.verts.append(W)
        self.tris.append(lt + nv)
        self.tri_face.append(geo["lt_poly"] + nf)
        lv, lpoly, ls, lt_ = geo["loop_vert"], geo["loop_poly"], geo["loop_start"], geo["loop_total"]
        if flip:  # each polygon's loop reversed
            pos = np.arange(len(lv))
            lv = lv[ls[lpoly] + lt_[lpoly] - 1 - (pos - ls[lpoly])]
        self.loop_vert.append(lv + nv)
        self.loop_start.append(ls + self.nl)
        self.loop_total.append(lt_)
        self.nl += len(lv)
        self.geos.append((geo, M, name))

    def add_faces(self, oi, face_index, target, target_b, forbidden, lux, rho, e, linked, material):
        """The values of the faces of the chunk that ``add_geometry`` started: object index
        ``oi``, base-mesh polygon ``face_index`` (-1: none), target, target radiosity, forbidden,
        illuminance target (lx; None: none), reflectance, exitance, linked emission (bool) and
        material index, per face."""
        npoly = len(self.loop_start[-1])
        self.f_mat.append(material)
        self.linked.append(linked)
        self.e_back.append(None)
        self.rho.append(rho)
        self.e.append(e)
        self.f_obj.append(np.full(npoly, oi))
        self.f_idx.append(face_index)
        self.tgt.append(target)
        self.tgt_b.append(target_b)
        self.forb.append(forbidden)
        self.lux.append(np.zeros(npoly) if lux is None else lux)
        self.nf += npoly
        self.nv += len(self.verts[-1])

    def add_backs(self, chunk, faces, offset):
        """The back side of faces ``faces`` (bool, of chunk ``chunk``) as faces of their own: the
        same polygons with their winding reversed, set ``offset`` (m) behind the front along the
        vertex normals, emitting the chunk's back exitance and reflecting its reflectance; never
        targets or lights (forbidden), not reported (face_index -1)."""
        sel = np.flatnonzero(faces)
        if not len(sel):
            return 0
        nv0, nf0, nl0 = self.base[chunk]
        W = self.verts[chunk]
        ls, lt = self.loop_start[chunk][sel] - nl0, self.loop_total[chunk][sel]
        lpos = np.repeat(ls - np.cumsum(np.concatenate([[0], lt[:-1]])), lt) + np.arange(int(lt.sum()))
        lface = np.repeat(np.arange(len(sel)), lt)
        corners = self.loop_vert[chunk][lpos] - nv0  # chunk-local vertex of each loop of the chosen faces
        used, local = np.unique(corners, return_inverse=True)
        face_of = np.full(len(self.loop_start[chunk]), -1, dtype=np.int64)
        face_of[sel] = np.arange(len(sel))
        tri_sel = face_of[self.tri_face[chunk] - nf0] >= 0
        tri = self.tris[chunk][tri_sel] - nv0
        tv = W[tri]
        tn = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])  # area vectors of the front
        vn = np.zeros((len(W), 3))
        for k in range(3):
            np.add.at(vn, tri[:, k], tn)
        vn = vn[used]
        ln = np.linalg.norm(vn, axis=1)
        vn = vn / np.where(ln > 0, ln, 1.0)[:, None]
        remap = np.full(len(W), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        # each polygon's loop reversed: its normal points the other way
        start = np.concatenate([[0], np.cumsum(lt)[:-1]])
        pos = np.arange(len(lpos))
        rev = start[lface] + lt[lface] - 1 - (pos - start[lface])
        nv, nf = self.nv, self.nf
        self.verts.append(W[used] - offset * vn)
        self.tris.append(remap[tri][:, ::-1] + nv)
        self.tri_face.append(face_of[self.tri_face[chunk][tri_sel] - nf0] + nf)
        self.loop_vert.append(local[rev] + nv)
        self.loop_start.append(start + self.nl)
        self.loop_total.append(lt.copy())
        self.base.append((nv, nf, self.nl))
        self.nl += len(lpos)
        e_back = self.e[chunk] if self.e_back[chunk] is None else self.e_back[chunk]
        self.rho.append(self.rho[chunk][sel])
        self.e.append(e_back[sel])
        self.f_mat.append(self.f_mat[chunk][sel])
        self.f_obj.append(self.f_obj[chunk][sel])
        self.f_idx.append(np.full(len(sel), -1, dtype=np.int64))
        self.tgt.append(np.zeros(len(sel), dtype=bool))
        self.tgt_b.append(np.zeros((len(sel), 3)))
        self.lux.append(np.zeros(len(sel)))
        self.forb.append(np.ones(len(sel), dtype=bool))
        self.linked.append(np.zeros(len(sel), dtype=bool))
        self.geos.append(None)
        self.e_back.append(None)
        self.nf += len(sel)
        self.nv += len(used)
        return len(sel)

    def flip_faces(self, chunk, faces):
        """Turn faces ``faces`` (bool, of chunk ``chunk``) to face the other way: their triangles'
        winding and their polygons' loops reversed (the vertices stay; nothing else changes)."""
        nv0, nf0, nl0 = self.base[chunk]
        tsel = faces[self.tri_face[chunk] - nf0]
        self.tris[chunk][tsel] = self.tris[chunk][tsel][:, ::-1]
        sel = np.flatnonzero(faces)
        ls, lt = self.loop_start[chunk][sel] - nl0, self.loop_total[chunk][sel]
        first = np.repeat(ls, lt)
        pos = first + np.arange(int(lt.sum())) - np.repeat(np.cumsum(lt) - lt, lt)
        lv = self.loop_vert[chunk]
        lv[pos] = lv[2 * first + np.repeat(lt, lt) - 1 - pos]

    def face_areas(self, ci) -> np.ndarray:
        """(faces,) world-space areas (m^2) of the faces of chunk ``ci``."""
        nv0, nf0, _ = self.base[ci]
        return group_sum(self.tri_face[ci] - nf0, triangle_areas(self.verts[ci][self.tris[ci] - nv0]), len(self.e[ci]))
