"""Scene data model of the radiosity engine: faces in, patches out.

No bpy here. export.py builds a :class:`FaceSet` from Blender meshes; the
engine meshes it into a :class:`PatchSet` (``mesh_patches``), computes form
factors on the patches and solves; per-face results are area-weighted means of
the face's patches (``face_mean``).

Units: lengths in metres, areas in m^2, radiosity and exitance in W/m^2,
reflectance is the linear-RGB diffuse albedo (0..1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .extent import decisive_region, face_sizes, is_beyond, quad_cells, triangle_measures
from .geometry import group_mean, group_sum, triangle_areas, triangle_cross, unit

__all__ = [
    "FaceSet",
    "PatchSet",
    "mesh_patches",
    "face_mean",
    "default_max_patch_size",
    "polygon_faceset",
    "loops_csr",
    "patch_triangles",
    "SceneError",
]


class SceneError(ValueError):
    """Bad input geometry or attributes; the message is meant for the user."""


@dataclass
class FaceSet:
    """World-space polygons with per-face attributes (what export.py exports).

    ``triangles`` is a triangulation of every face (Blender's loop triangles
    handle concave n-gons); ``triangle_face`` names the face of each triangle.
    The polygons' vertex loops, in polygon order (used to grid-split quads), are
    ``loop_vertices[loop_start[f]:loop_start[f] + loop_total[f]]`` (``face_loops``:
    the same as a list of lists).
    """

    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int64 vertex indices
    triangle_face: np.ndarray  # (T,) int64
    loop_vertices: np.ndarray  # (L,) int64
    loop_start: np.ndarray  # (F,) int64
    loop_total: np.ndarray  # (F,) int64
    face_object: np.ndarray  # (F,) int64 index into object_names
    face_index: np.ndarray  # (F,) int64 polygon index in the object's base mesh
    object_names: list
    reflectance: np.ndarray  # (F, 3) linear RGB albedo
    exitance: np.ndarray  # (F, 3) W/m^2
    target: np.ndarray = None  # (F,) bool
    target_radiosity: np.ndarray = None  # (F, 3) W/m^2, zeros where not a target
    forbidden: np.ndarray = None  # (F,) bool
    warnings: list = field(default_factory=list)
    #: optional (F,) lx: the faces' illuminance targets (0: none; such a face is a target of
    #: radiosity reflectance x lux / 683 in ``target_radiosity``)
    target_lux: np.ndarray = None
    #: optional (F,) bool: work-plane faces, which light passes through (they occlude nothing, no
    #: other face sees them: they reflect nothing into the scene; engine.sampling leaves them out
    #: of its ray scene)
    passes: np.ndarray = None
    #: optional: per face, an index into ``material_lobes`` (each material's BSDFs, the
    #: direction-dependent reflection of engine.incidence); None: every material is Lambertian
    face_material: np.ndarray = None
    material_lobes: list = None
    #: the scene's lamps (engine.lamps.Lamp, world space): fixed light that lights the faces directly
    lamps: list = field(default_factory=list)
    #: the World's radiance, an engine.world.EnvironmentMap (or a uniform (3,) W/(m^2 sr)), or None:
    #: fixed light from every direction that escapes the scene (engine.world.world_irradiance);
    #: ``world_name`` names it in the report
    world_radiance: object = None
    world_name: str = ""
    #: optional engine.targets.view.ViewSpec: pixels of the camera's image asked for a radiance
    view_target: object = None

    def __post_init__(self):
        self.loop_vertices = np.asarray(self.loop_vertices, dtype=np.int64).reshape(-1)
        self.loop_start = np.asarray(self.loop_start, dtype=np.int64).reshape(-1)
        self.loop_total = np.asarray(self.loop_total, dtype=np.int64).reshape(-1)
        F = len(self.loop_start)
        self.vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.triangles = np.asarray(self.triangles, dtype=np.int64).reshape(-1, 3)
        self.triangle_face = np.asarray(self.triangle_face, dtype=np.int64).reshape(-1)
        self.face_object = np.asarray(self.face_object, dtype=np.int64).reshape(F)
        self.face_index = np.asarray(self.face_index, dtype=np.int64).reshape(F)
        self.object_names = list(self.object_names)
        self.reflectance = np.asarray(self.reflectance, dtype=np.float64).reshape(F, 3)
        self.exitance = np.asarray(self.exitance, dtype=np.float64).reshape(F, 3)
        if self.target is None:
            self.target = np.zeros(F, dtype=bool)
        if self.target_radiosity is None:
            self.target_radiosity = np.zeros((F, 3))
        if self.forbidden is None:
            self.forbidden = np.zeros(F, dtype=bool)
        self.target = np.asarray(self.target, dtype=bool).reshape(F)
        self.target_radiosity = np.asarray(self.target_radiosity, dtype=np.float64).reshape(F, 3)
        self.forbidden = np.asarray(self.forbidden, dtype=bool).reshape(F)

    @property
    def n_faces(self) -> int:
        return len(self.loop_start)

    @property
    def face_loops(self) -> list:
        """Per face, its vertex indices in polygon order (a list of lists; prefer the arrays)."""
        lv = self.loop_vertices
        return [lv[s:s + n].tolist() for s, n in zip(self.loop_start, self.loop_total)]


def patch_triangles(patches) -> tuple:
    """(triangle vertices (T, 3, 3) float64, tri_patch (T,) int64) of a PatchSet, checked: finite,
    at least one triangle, every triangle on a patch (what the ray casters build on)."""
    tv = np.asarray(patches.tri_vertices, dtype=np.float64)
    if tv.ndim != 3 or tv.shape[1:] != (3, 3) or len(tv) == 0:
        raise SceneError("the patch set has no triangles")
    if not np.all(np.isfinite(tv)):
        raise SceneError("the scene has NaN or infinite vertex coordinates")
    tri_patch = np.asarray(patches.tri_patch, dtype=np.int64)
    if len(tri_patch) != len(tv) or tri_patch.min() < 0 or tri_patch.max() >= patches.n_patches:
        raise SceneError("tri_patch does not match the patches")
    return tv, tri_patch


def loops_csr(loops):
    """(loop_vertices, loop_start, loop_total) arrays from a list of vertex-index lists."""
    total = np.array([len(lp) for lp in loops], dtype=np.int64)
    verts = np.concatenate([np.asarray(lp, dtype=np.int64) for lp in loops]) if len(loops) else np.zeros(0, np.int64)
    return verts, np.concatenate([[0], np.cumsum(total)[:-1]]).astype(np.int64), total


@dataclass
class PatchSet:
    """Patches: the radiosity elements. Each patch is one or more triangles.

    All per-patch attributes are inherited from the face the patch came from.
    """

    tri_vertices: np.ndarray  # (T, 3, 3) float64 world-space triangles
    tri_patch: np.ndarray  # (T,) int64 patch of each triangle
    tri_face: np.ndarray  # (T,) int64 FaceSet face each triangle lies on
    area: np.ndarray  # (P,) m^2
    normal: np.ndarray  # (P, 3) unit normal (area-weighted over the patch's triangles)
    center: np.ndarray  # (P, 3) area-weighted centroid
    face: np.ndarray  # (P,) int64 the FaceSet face of the patch (of its first triangle when it spans several)
    object: np.ndarray  # (P,) int64 index into the FaceSet's object_names
    reflectance: np.ndarray  # (P, 3)
    exitance: np.ndarray  # (P, 3) W/m^2
    target: np.ndarray  # (P,) bool
    target_radiosity: np.ndarray  # (P, 3) W/m^2
    forbidden: np.ndarray  # (P,) bool
    n_faces: int
    max_patch_size: float
    light_size: float | None = None  # the adaptive model's light-cell size (m)
    passes: np.ndarray = None  # (P,) bool: light passes through it (FaceSet.passes), None: none does
    level: np.ndarray = None  # (P,) int, the adaptive model's refinement level of each patch
    #: the region that decides the answer (engine.extent.Region): the scale of every automatic length
    region: object = None
    #: the length the rays' offset is taken from (engine.sampling; None: the region's diagonal): a
    #: prepared solve repaints kept patches with the new paint's region and keeps this, so the rays
    #: and kernel rows it draws agree with those it kept (pipeline.prepared)
    ray_scale: float | None = None
    #: (P,) the illuminance (lx) asked of each patch, when it is not its face's (a prepared solve's
    #: paint mapped onto a kept cluster of faces: pipeline.prepared); None: its face's (``patch_lux``)
    target_lux: np.ndarray = None

    @property
    def n_patches(self) -> int:
        return len(self.area)

    @property
    def tri_area(self) -> np.ndarray:
        return triangle_areas(self.tri_vertices)

    def bounds(self):
        v = self.tri_vertices.reshape(-1, 3)
        return v.min(axis=0), v.max(axis=0)


def patch_lux(faces: FaceSet, patches: PatchSet) -> np.ndarray | None:
    """(P,) the illuminance (lx) asked of each patch: the patches' own (``target_lux``), else its
    face's (FaceSet.target_lux); None when no face is asked for one."""
    own = getattr(patches, "target_lux", None)  # (a patches-like object may have none)
    if own is not None:
        return own
    return None if faces is None or faces.target_lux is None else faces.target_lux[patches.face]


def default_max_patch_size(faces: FaceSet) -> float:
    """Default patch size: the diagonal of the region that decides the answer / 20
    (engine.extent: the targets and what they see, not a ground plane kilometres wide).

    A 0.55 m Cornell box then gets patches of about 4.8 cm (roughly 12 x 12 per
    wall); faces already smaller than that are kept whole.
    """
    if len(faces.vertices) == 0 or len(faces.triangles) == 0:
        raise SceneError("the scene has no geometry")
    size = decisive_region(faces).patch_size
    if not np.isfinite(size) or size <= 0:
        raise SceneError("the scene's geometry has no extent")
    return size


def _grid_quad(p, nu, nv):
    """Split a quad p[0..3] (polygon order) into nu x nv bilinear sub-quads.

    Returns an array (nu*nv, 2, 3, 3): two triangles per sub-quad.
    """
    u = np.linspace(0.0, 1.0, nu + 1)
    v = np.linspace(0.0, 1.0, nv + 1)
    U, V = np.meshgrid(u, v, indexing="ij")
    # bilinear: p0 (0,0), p1 (1,0), p2 (1,1), p3 (0,1)
    G = ((1 - U)[..., None] * (1 - V)[..., None] * p[0] + U[..., None] * (1 - V)[..., None] * p[1]
         + U[..., None] * V[..., None] * p[2] + (1 - U)[..., None] * V[..., None] * p[3])
    a = G[:-1, :-1].reshape(-1, 3)
    b = G[1:, :-1].reshape(-1, 3)
    c = G[1:, 1:].reshape(-1, 3)
    d = G[:-1, 1:].reshape(-1, 3)
    t1 = np.stack([a, b, c], axis=1)
    t2 = np.stack([a, c, d], axis=1)
    return np.stack([t1, t2], axis=1)


def _split_triangle(t, k):
    """Split triangle t (3, 3) into k*k congruent sub-triangles, (k*k, 3, 3)."""
    out = []
    a, b, c = t
    e1 = (b - a) / k
    e2 = (c - a) / k
    for i in range(k):
        for j in range(k - i):
            p = a + i * e1 + j * e2
            out.append((p, p + e1, p + e2))
            if j < k - i - 1:
                out.append((p + e1, p + e1 + e2, p + e2))
    return np.asarray(out)


def scene_scale(faces: FaceSet) -> float:
    """The bounding-box diagonal of the faces (m), after checking there is geometry to mesh."""
    V = faces.vertices
    if not np.all(np.isfinite(V)):
        raise SceneError("the scene has NaN or infinite vertex coordinates")
    if faces.n_faces == 0 or len(faces.triangles) == 0:
        raise SceneError("the scene has no faces")
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


#: the resolution of the scale-free keys that seed random streams (``key_lengths``): 2^-24 of the
#: scene's largest coordinate
KEY_STEPS = float(1 << 24)


def key_scale(tri_vertices) -> float:
    """The length unit of the keys that seed the random streams (engine.kernel_transfer's pairs,
    engine.candidate_lamps' lamps): the largest |coordinate| of the scene's triangles, the same
    for every paint and, x s, for the scene scaled by s."""
    s = float(np.abs(tri_vertices).max()) if len(tri_vertices) else 0.0
    return s if s > 0 and np.isfinite(s) else 1.0


def key_lengths(x, scale) -> np.ndarray:
    """int64: ``x`` (lengths) in steps of ``scale`` / KEY_STEPS, so the same scene in centimetres
    or kilometres draws the same samples (tests/test_scale.py); a rounding of the scaling moves a
    value across a step's edge with a probability of about 1e-8."""
    return np.rint(np.asarray(x, dtype=np.float64) * (KEY_STEPS / scale)).astype(np.int64)


def check_size(size, what="max patch size"):
    size = float(size)
    if not (size > 0 and np.isfinite(size)):
        raise SceneError(f"{what} must be a positive length, got {size}")
    return size


def face_triangles(faces: FaceSet):
    """World-space triangles (T, 3, 3), the non-degenerate ones (T,) bool, and per face its
    longest triangle edge (F,) m."""
    m = triangle_measures(faces)
    T = faces.vertices[faces.triangles]
    ok = m.area > (1e-10 * scene_scale(faces)) ** 2
    return T, ok, m.face_edge


def split_faces(faces: FaceSet, T, fids, size):
    """Split faces ``fids`` into sub-patches no larger than ``size[f]`` (m): a quad into an
    nu x nv grid of bilinear sub-quads (two triangles each), any other face's triangles into
    k x k sub-triangles. Returns (triangles (n, 3, 3), face (n,), local sub-patch index (n,));
    degenerate sub-triangles are dropped."""
    V = faces.vertices
    tf = faces.triangle_face
    region = decisive_region(faces)
    min_area = (1e-10 * scene_scale(faces)) ** 2
    tri_of = np.argsort(tf, kind="stable")
    starts = np.searchsorted(tf[tri_of], np.arange(faces.n_faces + 1))
    parts_t, parts_f, parts_l = [np.zeros((0, 3, 3))], [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for f in fids:
        s = float(size[f])
        if faces.loop_total[f] == 4:
            p = V[faces.loop_vertices[faces.loop_start[f]:faces.loop_start[f] + 4]]
            if is_beyond(region, p):  # a ground plane under the room: fine over the region only
                sub = quad_cells(region, p, s)
            else:
                nu = int(np.ceil(max(np.linalg.norm(p[1] - p[0]), np.linalg.norm(p[2] - p[3])) / s))
                nv = int(np.ceil(max(np.linalg.norm(p[3] - p[0]), np.linalg.norm(p[2] - p[1])) / s))
                sub = _grid_quad(p, max(nu, 1), max(nv, 1))  # (patches, 2, 3, 3)
            local = np.repeat(np.arange(len(sub)), 2)
            sub = sub.reshape(-1, 3, 3)
        else:
            subs = []
            for t in T[tri_of[starts[f]:starts[f + 1]]]:
                k = int(np.ceil(np.linalg.norm(t - np.roll(t, 1, axis=0), axis=1).max() / s))
                subs.append(_split_triangle(t, max(k, 1)))
            sub = np.concatenate(subs)
            local = np.arange(len(sub))
        keep = triangle_areas(sub) > min_area
        parts_t.append(sub[keep])
        parts_f.append(np.full(int(keep.sum()), f, dtype=np.int64))
        parts_l.append(local[keep])
    return np.concatenate(parts_t), np.concatenate(parts_f), np.concatenate(parts_l)


def build_patches(faces: FaceSet, tri, tri_face, key, max_patch_size, **extra) -> PatchSet:
    """A PatchSet from triangles (n, 3, 3) on faces ``tri_face`` (n,), one patch per distinct
    ``key`` (n,) int64, patches in key order. Per-patch attributes come from the face of the
    patch's first triangle: the patch model keeps faces that differ in them apart. Faces that
    got no triangle are counted in a warning."""
    made = np.zeros(faces.n_faces, dtype=bool)
    made[tri_face] = True
    degenerate = int(faces.n_faces - made.sum())
    if degenerate:
        faces.warnings.append(f"{degenerate} zero-area or degenerate face(s) ignored")
    if not made.any():
        raise SceneError("the scene has no face with a non-zero area")
    order = np.argsort(key, kind="stable")  # patches in key order, triangles contiguous
    uniq, first, tri_patch = np.unique(key[order], return_index=True, return_inverse=True)
    tri_vertices = tri[order]
    tri_patch = tri_patch.reshape(-1).astype(np.int64)
    tri_face = tri_face[order]
    patch_face = tri_face[first]
    area, normal, center = patch_geometry(tri_vertices, tri_patch, len(uniq))
    return PatchSet(
        tri_vertices=tri_vertices,
        tri_patch=tri_patch,
        tri_face=tri_face,
        area=area,
        normal=normal,
        center=center,
        face=patch_face,
        object=faces.face_object[patch_face].copy(),
        reflectance=faces.reflectance[patch_face].copy(),
        exitance=faces.exitance[patch_face].copy(),
        target=faces.target[patch_face].copy(),
        target_radiosity=faces.target_radiosity[patch_face].copy(),
        forbidden=faces.forbidden[patch_face].copy(),
        passes=None if faces.passes is None or not faces.passes.any() else faces.passes[patch_face].copy(),
        n_faces=faces.n_faces,
        max_patch_size=max_patch_size,
        region=decisive_region(faces),
        **extra,
    )


def mesh_patches(faces: FaceSet, max_patch_size: float | None = None) -> PatchSet:
    """Mesh faces into patches no larger than ``max_patch_size`` (metres): the polygon model.

    - A face whose edges are all <= max_patch_size is one patch (its triangles).
    - A larger quad is split into an nu x nv grid of bilinear sub-quads.
    - Any other larger face (triangle, n-gon, concave n-gon) has each of its
      triangles split into k x k sub-triangles, each a patch.
    Degenerate (zero-area) triangles are dropped; a face with no area left
    produces no patch and a warning in ``faces.warnings``.
    """
    scene_scale(faces)
    if max_patch_size is None:
        max_patch_size = default_max_patch_size(faces)
    max_patch_size = check_size(max_patch_size)
    T, ok, face_edge = face_triangles(faces)
    tf = faces.triangle_face
    size = face_sizes(faces, max_patch_size)
    whole = face_edge <= size
    sel = whole[tf] & ok  # faces kept whole (the common case, vectorised): one patch each
    st, sf, sl = split_faces(faces, T, np.flatnonzero(~whole), size)
    tri = np.concatenate([T[sel], st])
    face = np.concatenate([tf[sel], sf])
    local = np.concatenate([np.zeros(int(sel.sum()), dtype=np.int64), sl])
    return build_patches(faces, tri, face, face * (int(local.max(initial=0)) + 1) + local, max_patch_size)


def patch_geometry(tri_vertices, tri_patch, n_patches):
    """Per patch: area (m^2), unit normal (area-weighted over its triangles) and centroid."""
    cr = triangle_cross(tri_vertices)
    ta = 0.5 * np.linalg.norm(cr, axis=1)
    area = group_sum(tri_patch, ta, n_patches)
    normal = unit(group_sum(tri_patch, cr, n_patches))
    center = group_sum(tri_patch, tri_vertices.mean(axis=1), n_patches, ta) / area[:, None]
    return area, normal, center


def face_mean(patches: PatchSet, values: np.ndarray) -> np.ndarray:
    """Area-weighted mean of per-patch ``values`` (P,) or (P, k) over each face, through the
    triangles (a face may span several patches, a patch several faces).

    Faces with no patch (degenerate) get 0.
    """
    values = np.asarray(values, dtype=np.float64)
    return group_mean(patches.tri_face, values[patches.tri_patch], patches.n_faces, patches.tri_area)


def polygon_faceset(polygons, reflectance=0.5, exitance=0.0, object_names=None, face_object=None):
    """Build a FaceSet from a list of convex polygons given as (n, 3) vertex arrays.

    Convenience for engine tests and synthetic scenes (fan triangulation, so
    convex polygons only). ``reflectance`` and ``exitance`` are scalars, RGB
    triples or per-face arrays.
    """
    verts = []
    loops = []
    tris = []
    tri_face = []
    base = 0
    for f, poly in enumerate(polygons):
        poly = np.asarray(poly, dtype=np.float64).reshape(-1, 3)
        n = len(poly)
        verts.append(poly)
        loops.append(list(range(base, base + n)))
        for k in range(1, n - 1):
            tris.append((base, base + k, base + k + 1))
            tri_face.append(f)
        base += n
    F = len(polygons)

    def per_face(x):
        x = np.asarray(x, dtype=np.float64)
        if x.ndim == 0:
            return np.full((F, 3), float(x))
        if x.shape == (3,):
            return np.tile(x, (F, 1))
        if x.shape == (F,):
            return np.repeat(x[:, None], 3, axis=1)
        return x.reshape(F, 3)

    if object_names is None:
        object_names = ["polygons"]
    if face_object is None:
        face_object = np.zeros(F, dtype=np.int64)
    return FaceSet(
        vertices=np.concatenate(verts) if verts else np.zeros((0, 3)),
        triangles=np.asarray(tris, dtype=np.int64).reshape(-1, 3),
        triangle_face=np.asarray(tri_face, dtype=np.int64),
        **dict(zip(("loop_vertices", "loop_start", "loop_total"), loops_csr(loops))),
        face_object=face_object,
        face_index=np.arange(F),
        object_names=list(object_names),
        reflectance=per_face(reflectance),
        exitance=per_face(exitance),
    )
