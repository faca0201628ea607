"""Camera-view targets (issue 40): pixels of the scene camera's image painted with the radiance
the camera should see there (W m^-2 sr^-1, the render's units); unpainted pixels are free.

A painted pixel is a row of the inverse problem: its centre's ray hits patch i at point x, and
the radiance seen there is linear in the radiosity (engine.view_radiance.view_rows):

    pi L = B_i + sum_j (pi f_i(l_xj, v) - rho_i) F_ij B_j,

so a matte patch shows B_i / pi and a glossy one adds the reflection of what it sees through its
BSDF towards the camera: a light cell's highlight on a glossy table moves with the cell, and a
painted highlight pulls a cell to where its reflection lands. The rows are the same in every
channel (the target interface's): a glossy patch's coefficients are the mean of its channels'
(exact for a neutral specular layer over any diffuse colour when the layers' weights agree; the
largest relative spread is ``channel_spread``).

Lamps' highlights: B holds a lamp's direct light E as rho E, seen Lambertian; a glossy pixel shows
f(l, v) E, so each lamp adds (pi f(l, v) - rho) E to its glossy rows beyond B (engine.view_lamps:
the lamp's kind's irradiance at the point with a shadow ray, l towards the lamp; 0 exactly on a
matte patch, which has no such row). ``lamp_terms`` gives it per unit strength on the rows (at the
glossy tiles' mean points and directions, as their rows are evaluated): the inverse problem adds it
to the lamps' columns of T (InverseProblem.transfer, retarget; a refined lamp's column by
engine.lamp_refinement.Transport, for the lamp as it moved), so a painted highlight pulls a lamp to
where its reflection lands. The scene's own lamps' (``fixed_light``, the lamps of the faces the
target was built on) are subtracted from the targets with the rest of the fixed light; ``predict``,
``image`` and ``pixel_error`` add both at each pixel's own point. Left out: the highlights of the
World and of light cells' direct light beyond F's gather (a cell's reflection is the rows' own,
through F), the sources' own glossy reflection, pixels that see the World or a face's back (free,
counted in ``free``); the scene's lamps moved after the target was built (a prepared scene's
move_scene_light) keep their old highlights in the targets until the target is built again.

Rows are in W/m^2 (pi L: the radiosity's units, so they mix with painted and lux targets). A
patch seen by many pixels would give as many rows; pixels that share a row are one row of weight
sqrt(n) asking sqrt(n) x their mean (the least-squares problem unchanged, its values non-negative):
a matte patch's pixels all read B_i; a glossy patch's rows are evaluated on tiles of the image
(TILE_LOBE: a fraction of its lobe's width, about 13 pixels for Roughness 0.25 at 480 pixels over
a 57 degree view), its pixels in a tile sharing one row: the mean over them of the rows made on finer
tiles (PREDICT_LOBE's, each at its pixels' mean point and direction), which the radiance reported and
shown reads (made once, kept by the target). Then
||R B - t||^2 over the pixels is ||R' B - t'||^2 plus the constant ``offset`` (the spread of the
pixels that share a row, which no B changes): the same solution; the pixels' own error is
``pixel_error`` (the report's), not the rows'.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..by_content import digest
from ..first_reflection import incidence_of
from ..incidence import lamp_albedo_excess
from ..registry import TARGET_KINDS
from ..principled import VIEW_ALPHA_MIN, BRDFTable
from ..units import TINY
from ..view_lamps import LAMP_VIEW_SAMPLES, brdf_tables, lamp_view_light
from ..view_radiance import SourcePoints, view_rows
from .kind import Target, TargetAims

__all__ = ["Camera", "ViewSpec", "ViewTarget", "PixelHits", "cast_pixels", "predicted_image", "TILE_LOBE", "PREDICT_LOBE"]

#: the angle of the image tiles on which a glossy patch's rows are evaluated for the solve, relative
#: to its narrowest lobe's GGX alpha (Roughness^2, at least principled.VIEW_ALPHA_MIN): the pixels
#: of a patch in one tile share one row, the mean of their PREDICT_LOBE rows (a lobe is about 2 alpha
#: wide). 0.5: 13 pixels for Roughness 0.25 at 480 pixels over a 57 degree view; against each
#: pixel's own row 0.5 % mean, 2.2 % at the 95th percentile (tests/test_view_target.py), with 7 x
#: fewer rows than 0.15 (the solve's cost grows with the rows: docs/benchmarks.md)
TILE_LOBE = 0.5
#: the same for the radiance reported and shown (``predict``, ``predicted_image``: a forward
#: evaluation, no solve): finer, the pixels' error and the predicted image within 0.2 % of each
#: pixel's own row on average; a glossy patch's rows on them at its pixels' mean point and direction
PREDICT_LOBE = 0.15
#: a painted highlight (``highlight_mounts``): a painted pixel on a glossy patch at least this many
#: times the median of the painted glossy pixels; at most MAX_HIGHLIGHTS of them, HIGHLIGHT_SPACING
#: pixels apart, each a mounting position for the candidate lamps where its mirror ray lands
HIGHLIGHT_CONTRAST = 3.0
MAX_HIGHLIGHTS = 4
HIGHLIGHT_SPACING = 8
#: lamp samples a pixel (each of its rays) for a lamp with an extent in the radiance predicted and shown
#: (``predict``, ``image``: per pixel; the rows take engine.view_lamps.LAMP_VIEW_SAMPLES): 112,000 glossy
#: pixels of a 480 x 270 image x 16 samples took 5 s a 0.5 m area lamp, x 4 1.3 s (load 5 on 2 cores)
PIXEL_LAMP_SAMPLES = 4


@dataclass
class Camera:
    """A perspective camera: ``origin`` (3,), ``axes`` (3, 3) rows = the camera's right, up and
    back directions in world space (Blender's camera looks down its local -Z), the image ``width``
    x ``height`` pixels, ``half`` (2,): the image plane's half extent at distance 1 (x, y), ``shift``
    (2,): its centre's offset at distance 1 (Blender's Shift X/Y)."""

    origin: np.ndarray
    axes: np.ndarray
    width: int
    height: int
    half: np.ndarray
    shift: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self):
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        self.axes = np.asarray(self.axes, dtype=np.float64).reshape(3, 3)
        self.half = np.asarray(self.half, dtype=np.float64).reshape(2)
        self.shift = np.asarray(self.shift, dtype=np.float64).reshape(2)
        self.width, self.height = int(self.width), int(self.height)

    def directions(self, pixels, offset=(0.5, 0.5)) -> np.ndarray:
        """(n, 3) unit world directions through flat pixel indices ``pixels`` (row-major, row 0 at
        the top) at ``offset`` (x, y in [0, 1)) within each pixel ((n, 2) per pixel, or one pair)."""
        pixels = np.asarray(pixels, dtype=np.int64)
        off = np.broadcast_to(np.asarray(offset, dtype=np.float64), (len(pixels), 2))
        r, c = np.divmod(pixels, self.width)
        x = self.shift[0] + ((c + off[:, 0]) / self.width * 2 - 1) * self.half[0]
        y = self.shift[1] + (1 - (r + off[:, 1]) / self.height * 2) * self.half[1]
        d = x[:, None] * self.axes[0] + y[:, None] * self.axes[1] - self.axes[2]
        return d / np.linalg.norm(d, axis=1, keepdims=True)


@dataclass
class ViewSpec:
    """What the camera should see: ``radiance`` (H, W, 3) W m^-2 sr^-1 at the camera's working
    resolution (row 0 at the top), ``painted`` (H, W) bool (False: a free pixel); ``name`` says
    where it came from (the image's file)."""

    camera: Camera
    radiance: np.ndarray
    painted: np.ndarray
    name: str = ""

    def __post_init__(self):
        shape = (self.camera.height, self.camera.width)
        self.radiance = np.asarray(self.radiance, dtype=np.float64).reshape(shape + (3,))
        self.painted = np.asarray(self.painted, dtype=bool).reshape(shape)
        if not np.all(np.isfinite(self.radiance[self.painted])) or np.any(self.radiance[self.painted] < 0):
            raise ValueError(f"the view target {self.name!r} has negative or non-finite radiance in painted pixels")


@dataclass
class PixelHits:
    """The pixels whose ray hits a patch's front: ``pixel`` (n,) flat indices, ``patch`` (n,),
    ``point`` (n, 3), ``direction`` (n, 3) from the camera; ``missed`` and ``back``: how many
    asked pixels see nothing (the World) or a face's back."""

    pixel: np.ndarray
    patch: np.ndarray
    point: np.ndarray
    direction: np.ndarray
    missed: int = 0
    back: int = 0


def _sampler(F, patches):
    sampler = getattr(F, "sampler", None)
    if sampler is None:
        from ..sampling import SceneSampler
        sampler = SceneSampler(patches)
    return sampler


def highlight_mounts(spec, hits, want, alpha, sampler):
    """((m, 3) points, (m,) patches): where a lamp hangs to put a painted highlight where it is
    painted -- for each highlight (a painted pixel on a glossy patch at least HIGHLIGHT_CONTRAST x
    the median of the painted glossy pixels, the brightest first, at most MAX_HIGHLIGHTS of them
    HIGHLIGHT_SPACING pixels apart), the first surface the camera's ray meets after its mirror
    reflection about the patch's normal (the lobe's peak direction)."""
    glossy = np.flatnonzero(np.isfinite(alpha[hits.patch]))
    if not len(glossy):
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    bright = glossy[want[glossy] >= HIGHLIGHT_CONTRAST * np.median(want[glossy])]
    rows, cols = np.divmod(hits.pixel, spec.camera.width)
    chosen = []
    for k in bright[np.argsort(-want[bright], kind="stable")]:
        if all(np.hypot(rows[k] - rows[c], cols[k] - cols[c]) >= HIGHLIGHT_SPACING for c in chosen):
            chosen.append(k)
        if len(chosen) == MAX_HIGHLIGHTS:
            break
    if not chosen:
        return np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    chosen = np.asarray(chosen)
    n = sampler.tn[sampler.tstart[hits.patch[chosen]]]  # (the patch's first triangle's normal: a plane)
    d = hits.direction[chosen]
    r = d - 2 * np.einsum("ij,ij->i", d, n)[:, None] * n
    org = hits.point[chosen] + n * sampler.offset
    hit, front, tri, point = _first_surface(sampler, org, r)
    ok = front & (np.einsum("ij,ij->i", point - org, r) > 0)
    return point[ok], sampler.tri_patch[tri[ok]]


def _first_surface(sampler, org, d):
    """The first triangle each ray (origins ``org``, unit directions ``d``) meets: (hit (n,) bool, front
    (n,) bool: it meets the triangle's front, tri (n,) its sorted triangle (0 where none), point (n, 3)
    on its plane)."""
    prim = np.asarray(sampler.first_hit(org.astype(np.float32), d.astype(np.float32)))
    hit = prim >= 0
    tri = np.maximum(prim, 0)
    n = sampler.tn[tri]
    cos = np.einsum("ij,ij->i", n, d)
    t = np.einsum("ij,ij->i", sampler.tv[tri, 0] - org, n) / np.where(np.abs(cos) > TINY, cos, -1.0)
    return hit, hit & (cos < 0), tri, org + t[:, None] * d


def cast_pixels(camera: Camera, sampler, pixels, offset=(0.5, 0.5)) -> PixelHits:
    """The first hit of each pixel's ray (``sampler``: engine.sampling.SceneSampler)."""
    pixels = np.asarray(pixels, dtype=np.int64)
    d = camera.directions(pixels, offset)
    org = np.repeat(camera.origin[None, :], len(pixels), axis=0)
    hit, front, tri, point = _first_surface(sampler, org, d)
    return PixelHits(pixels[front], sampler.tri_patch[tri[front]], point[front], d[front],
                     missed=int(np.sum(~hit)), back=int(np.sum(hit & ~front)))


class MatteInterpolation:
    """A matte patch's radiance at a point from the patches' radiosities: its own B_i plus a
    gradient across it, the least-squares plane through the radiosities of the patches that share a
    corner with it on one surface (the same object, plane and material: a room's corner is not
    blended), B(x) = B_i + g_i . (x - c_i). Linear in B; the mean over the patch stays B_i (its centre
    is its centroid); Cycles shows the radiosity varying across a patch where B_i is its mean, and the
    pixels follow it. A patch that may emit (a candidate for lights: not forbidden, or the scene's own
    emitter) is seen as its own B_i and takes no part in its neighbours' gradients (an emitter's edge
    is sharp), as is a patch without two neighbours in different directions."""

    def __init__(self, sampler, patches, material):
        tv, tp = sampler.tv, sampler.tri_patch
        scale = max(float(np.ptp(tv.reshape(-1, 3), axis=0).max()), TINY)
        pos = np.round(tv.reshape(-1, 3) / (scale * 1e-6)).astype(np.int64)  # (3T, 3) the corners, quantised
        p = np.repeat(tp, 3)
        n_q = np.round(np.asarray(patches.normal, dtype=np.float64)[p] * 1e3).astype(np.int64)  # (one plane)
        may_emit = ~np.asarray(patches.forbidden, dtype=bool) | np.any(np.asarray(patches.exitance) > 0, axis=1)
        surface = np.stack([np.asarray(patches.object, dtype=np.int64)[p], np.asarray(material, dtype=np.int64)[p],
                            np.where(may_emit[p], p, -1)], 1)  # (an emitter: its own corners)
        _, vertex = np.unique(np.concatenate([pos, n_q, surface], axis=1), axis=0, return_inverse=True)
        vertex = vertex.reshape(-1)
        S = sp.csr_matrix((np.ones(len(p)), (p, vertex)), shape=(patches.n_patches, int(vertex.max()) + 1))
        self.near = (S @ S.T).tocsr()  # (P, P): patches sharing a corner
        self.may_emit = may_emit
        self.center = np.asarray(patches.center, dtype=np.float64)
        self.normal = np.asarray(patches.normal, dtype=np.float64)
        self._grad = {}

    def gradient(self, i) -> tuple:
        """(js (k,) the neighbours, G (3, k)): B's gradient on patch i is G (B_js - B_i); k = 0 for
        a patch seen as its own B_i."""
        if i not in self._grad:
            js = self.near.indices[self.near.indptr[i]:self.near.indptr[i + 1]]
            js = js[js != i] if not self.may_emit[i] else js[:0]
            G = np.zeros((3, 0))
            if len(js) >= 2:
                n = self.normal[i] / max(np.linalg.norm(self.normal[i]), TINY)
                a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
                t1 = np.cross(n, a)
                t1 /= np.linalg.norm(t1)
                T = np.stack([t1, np.cross(n, t1)])  # (2, 3) the plane's axes
                D = (self.center[js] - self.center[i]) @ T.T  # (k, 2)
                s = np.linalg.svd(D, compute_uv=False)
                if s[-1] > 1e-3 * s[0]:
                    G = T.T @ np.linalg.pinv(D)
            self._grad[i] = (js if G.shape[1] else js[:0], G)
        return self._grad[i]

    def rows(self, i, point) -> tuple:
        """(js, W (n, J)): the radiosity at ``point`` (n, 3) on patch i is W @ B[js]."""
        js, G = self.gradient(i)
        w = (np.asarray(point, dtype=np.float64) - self.center[i]) @ G  # (n, k)
        return np.r_[i, js], np.concatenate([1.0 - w.sum(axis=1, keepdims=True), w], axis=1)


def _narrowest(lobes) -> float:
    """A material's narrowest GGX alpha; inf for Lambert's BSDF (diffuse lobes of roughness 0), 1 for
    another BSDF without a GGX lobe (Oren-Nayar)."""
    if all(kind == "diffuse" and float(d[1]) == 0.0 for _, kind, d in lobes):
        return np.inf
    return min([float(d.alpha) for kind, _, d in BRDFTable(lobes).terms if kind == "ggx"] or [1.0])


def _patch_materials(faces, patches):
    """(material (P,) int, material_lobes, alpha (P,): the narrowest GGX alpha of each patch's
    material, inf where it is Lambertian)."""
    lobes = getattr(faces, "material_lobes", None)
    fm = getattr(faces, "face_material", None)
    if lobes is None or fm is None:
        P = patches.n_patches
        return np.zeros(P, dtype=np.int64), None, np.full(P, np.inf)
    material = np.asarray(fm, dtype=np.int64)[patches.face]
    return material, lobes, np.array([_narrowest(m) for m in lobes])[material]


def _tile(camera, alpha, lobe=None) -> int:
    """The side in pixels of the tiles a glossy patch's rows are evaluated on (``lobe`` of its
    alpha; default TILE_LOBE)."""
    pixel = 2 * camera.half[0] / camera.width  # (at distance 1: the pixel's angle near the centre)
    return max(1, int((TILE_LOBE if lobe is None else lobe) * max(alpha, VIEW_ALPHA_MIN) / pixel))


def _matte_side(n, exact) -> int:
    """The side in pixels of the tiles a matte patch's ``n`` pixels share a row on: half the patch's
    extent in the image for the solve (about 4 rows a patch: its gradient at half its size), 1 for
    the radiance predicted (``exact``: each pixel its own point)."""
    return 1 if exact else max(1, int(np.ceil(np.sqrt(n) / 2)))


def _tiles(pixels, width, side):
    """(n_tiles, tile (n,)): the image tiles of ``side`` pixels that ``pixels`` fall in."""
    n_cols = -(-width // side)
    r, c = np.divmod(pixels, width)
    tiles, tile = np.unique((r // side) * n_cols + c // side, return_inverse=True)
    return len(tiles), tile.reshape(-1)


def _pixel_blocks(hits, patches, F, faces, camera, lobe=None, interp=None, exact=False, kept=None, made=None,
                  fine=None):
    """Per patch seen: (patch, pixel positions in ``hits``, columns js, W (n_tiles, J, 3), tile (n,)):
    the rows of its pixels, pixel k's row W[tile[k]]. A glossy patch: the means over the pixels in each
    tile of ``lobe`` (_tile) of its rows on PREDICT_LOBE's tiles (``fine``); ``exact``: view_rows at
    the mean point and direction of its pixels in each tile of ``lobe``. A matte
    patch: the radiosity interpolated at its pixels' points (``interp``: MatteInterpolation; None:
    the patch's own B_i), their mean in tiles of _matte_side (``exact``: each pixel alone). With
    ``interp`` a glossy patch's B_i is interpolated too: at its tiles' mean points, or (``exact``) in
    one more block of the patch's pixels, each at its own point (the blocks of a patch add up).
    ``made`` (not ``exact``): filled with {(patch, its pixels' bytes): (js, W, tile)}, every block
    yielded; ``kept``: such blocks made before with the same camera, model, materials and
    arguments, taken again where a patch sees the same pixels (a Live stroke on the view target:
    the patches whose pixels it did not change). ``fine``: {(patch, its pixels' bytes): (js, W, tile)}
    of a glossy patch on PREDICT_LOBE's tiles, without the interpolation (what ``exact`` evaluates
    it on): not ``exact``, filled for each glossy patch evaluated (a dict of its own when None);
    ``exact``, taken from it where present."""
    if fine is None and not exact:
        fine = {}
    material, lobes, alpha = _patch_materials(faces, patches)
    sources = SourcePoints(patches, _sampler(F, patches)) if np.isfinite(alpha[hits.patch]).any() else None
    tables = {}  # (the materials' BRDF tables, built once for the image)
    order = np.argsort(hits.patch, kind="stable")
    cuts = np.flatnonzero(np.diff(hits.patch[order])) + 1
    for group in np.split(order, cuts) if len(order) else []:
        i = int(hits.patch[group[0]])
        key = (i, hits.pixel[group].tobytes()) if not exact or fine is not None else None
        if made is not None and not exact and kept is not None and key in kept:
            made[key] = kept[key]
            yield (i, group) + kept[key]
            continue
        for block in _patch_blocks(i, group, hits, patches, F, camera, lobe, interp, exact, material, lobes, alpha,
                                   sources, tables, fine, key):
            if made is not None and not exact:
                made[key] = block[2:]
            yield block


def _patch_blocks(i, group, hits, patches, F, camera, lobe, interp, exact, material, lobes, alpha, sources, tables,
                  fine=None, key=None):
    """_pixel_blocks' blocks of patch ``i`` seen by the pixels ``group`` of ``hits`` (``fine``, ``key``:
    its fine rows', _pixel_blocks')."""
    if np.isinf(alpha[i]):
        js, R = (np.array([i]), None) if interp is None else interp.rows(i, hits.point[group])
        if len(js) == 1:  # (its own B_i at every pixel: one row)
            yield i, group, js, np.ones((1, 1, 3)), np.zeros(len(group), dtype=np.int64)
            return
        n_tiles, tile = _tiles(hits.pixel[group], camera.width, _matte_side(len(group), exact))
        W = np.stack([np.bincount(tile, R[:, j], n_tiles) for j in range(len(js))], 1)
        W /= np.bincount(tile, minlength=n_tiles)[:, None]
        yield i, group, js, np.repeat(W[:, :, None], 3, axis=2), tile
        return
    if not exact:  # the fine rows, kept; the tiles of ``lobe`` their means
        if key not in fine:
            fine[key] = _view_tiles(i, group, hits, patches, F, camera, PREDICT_LOBE, material, lobes, alpha, sources,
                                    tables)
        js, W, tile = _coarse(fine[key], hits.pixel[group], camera, _tile(camera, alpha[i], lobe))
        if interp is not None:
            js, W = _interpolated(interp, i, _tile_means(hits, group, tile, len(W))[0], js, W)
    elif fine is not None and key in fine:
        js, W, tile = fine[key]
    else:
        js, W, tile = _view_tiles(i, group, hits, patches, F, camera, lobe, material, lobes, alpha, sources, tables)
    yield i, group, js, W, tile
    if interp is not None and exact:  # (the interpolation at each pixel's own point: one more block)
        nb, G = interp.gradient(i)
        if len(nb):
            w = (hits.point[group] - interp.center[i]) @ G
            Wx = np.concatenate([-w.sum(axis=1, keepdims=True), w], axis=1)
            yield i, group, np.r_[i, nb], np.repeat(Wx[:, :, None], 3, axis=2), np.arange(len(group))


def _view_tiles(i, group, hits, patches, F, camera, lobe, material, lobes, alpha, sources, tables):
    """(js, W (n_tiles, J, 3), tile (n,)): glossy patch i's view_rows at the mean point and direction
    of its pixels ``group`` in each tile of ``lobe``."""
    n_tiles, tile = _tiles(hits.pixel[group], camera.width, _tile(camera, alpha[i], lobe))
    point, d = _tile_means(hits, group, tile, n_tiles)
    js, W = view_rows(F, patches.reflectance, patches.center, patches.normal, np.full(n_tiles, i), point, d,
                      material, lobes, sources=sources, tables=tables)
    return js, W, tile


def _coarse(fine, pixels, camera, side):
    """(js, W (n_tiles, J, 3), tile (n,)): the rows ``fine`` (_view_tiles' of the same pixels) averaged
    over the pixels in each image tile of ``side`` pixels: each pixel weighs its fine row once."""
    js, Wf, tf = fine
    n_tiles, tile = _tiles(pixels, camera.width, side)
    A = np.bincount(tile * len(Wf) + tf, minlength=n_tiles * len(Wf)).reshape(n_tiles, len(Wf)).astype(np.float64)
    A /= A.sum(axis=1, keepdims=True)
    return js, (A @ Wf.reshape(len(Wf), -1)).reshape(n_tiles, *Wf.shape[1:]), tile


def _block_rows(blocks) -> dict:
    """{block key: its rows (arange)} of _pixel_blocks' blocks in the order a target stacks them (a
    block of W (n_tiles, J, 3) is n_tiles rows)."""
    out, k = {}, 0
    for key, (_, W, _) in blocks.items():
        out[key] = np.arange(k, k + len(W))
        k += len(W)
    return out


def _rows_taken(earlier, made, kept):
    """Target.rows_taken of a target whose blocks ``made`` took the blocks ``kept`` of ``earlier``
    where they were the same (None: none)."""
    mine, theirs = _block_rows(made), _block_rows(kept)
    same = [key for key in made if key in kept and made[key] is kept[key]]
    if not same:
        return None
    return (earlier, np.concatenate([mine[key] for key in same]), np.concatenate([theirs[key] for key in same]))


def _tile_means(hits, group, tile, n_tiles):
    """(point (n_tiles, 3), direction (n_tiles, 3)): the mean point and unit direction of the pixels
    ``group`` of ``hits`` in each tile (their row's, as _pixel_blocks evaluates a glossy patch's)."""
    count = np.bincount(tile, minlength=n_tiles)[:, None]
    point = np.stack([np.bincount(tile, hits.point[group, a], n_tiles) for a in range(3)], 1) / count
    d = np.stack([np.bincount(tile, hits.direction[group, a], n_tiles) for a in range(3)], 1)
    return point, d / np.linalg.norm(d, axis=1, keepdims=True)


def _interpolated(interp, i, point, js, W):
    """view_rows' (js, W) at ``point`` on patch i (js[0] == i, its B_i the diffuse part) with B_i
    interpolated at the points (MatteInterpolation: B_i + g_i . (x - c_i))."""
    nb, G = interp.gradient(i)
    if len(nb) == 0:
        return js, W
    w = (point - interp.center[i]) @ G  # (n, k)
    new = nb[~np.isin(nb, js)]
    js = np.r_[js, new]
    W = np.concatenate([W, np.zeros((len(W), len(new), 3))], axis=1)
    pos = np.searchsorted(js, nb, sorter=np.argsort(js))
    pos = np.argsort(js)[pos]
    W[:, pos, :] += w[:, :, None]
    W[:, 0, :] -= w.sum(axis=1)[:, None]
    return js, W


def matte_interpolation(F, faces, patches) -> MatteInterpolation:
    """The MatteInterpolation of a scene's patches (on F's sampler)."""
    return MatteInterpolation(_sampler(F, patches), patches, _patch_materials(faces, patches)[0])


@TARGET_KINDS.register("view", "Camera View", "Pixels of the camera's image painted with the radiance they should show")
class ViewTarget(Target):
    """The painted pixels of a ViewSpec seen through the patches (module docstring): ``matrix`` (k, P)
    the rows (pixels sharing a row merged), ``values`` (k, 3) W/m^2, ``offset`` (3,) the pixels' squared error no B
    changes, ``hits`` the pixels' first hits, ``pixel_row`` (n,) the row of each, ``channel_spread``
    the largest relative spread of a glossy row between channels. The rows are on TILE_LOBE's tiles,
    what is predicted and reported (``predict``, ``image``, ``pixel_error``) on PREDICT_LOBE's."""

    kind = "view"
    unit = "W/(m^2 sr)"
    kept_by_retarget = True

    def __init__(self, spec, hits, matrix, values, offset, channel_spread, F, patches, faces, pixel_row=None,
                 interp=None, glossy_rows=None, fixed_lamps=()):
        self.spec, self.hits = spec, hits
        #: the rows on glossy patches, where lamps' light is seen through the BSDF (lamp_terms):
        #: (row (g,), patch (g,), point (g, 3), direction (g, 3), weight (g,)), each row at its
        #: tile's mean point and direction, weighted as its row (sqrt of its pixels)
        self.glossy_rows = glossy_rows
        #: the scene's own lamps (engine.lamps.Lamp, fixed light): their highlights are ``fixed_light``
        self.fixed_lamps = list(fixed_lamps)
        self._fixed = None
        self._materials = None  # (material (P,), lobes, {material: BRDFTable}, incidence) for the lamps' highlights
        #: the matte patches' interpolation (MatteInterpolation; None: each reads its own B_i)
        self.interp = interp
        #: (n,) the row each hit pixel shares (its weight: sqrt of how many pixels share it)
        self.pixel_row = pixel_row
        self.matrix = sp.csr_matrix(matrix)
        self.values = np.asarray(values, dtype=np.float64).reshape(-1, 3)
        self.offset = np.asarray(offset, dtype=np.float64)
        self.channel_spread = float(channel_spread)
        self._F, self._patches, self._faces = F, patches, faces
        # (build's key, its _pixel_blocks in row order: a later paint's build takes them again)
        self._blocks = (None, {})
        # (the glossy patches' rows on PREDICT_LOBE's tiles, by _pixel_blocks' key: ``predict``'s, and the
        # rows' means)
        self._fine = {}

    def serves(self, faces, F) -> bool:
        """The same view target (its spec: the camera, the painted pixels and their radiance) on the
        same model (``F``): its rows are the ones ``build`` would make again."""
        spec = getattr(faces, "view_target", None)
        return F is self._F and spec is not None and (spec is self.spec or digest(spec) == digest(self.spec))

    def rows(self, n_patches):
        if self.matrix.shape[1] != n_patches:
            raise ValueError(f"the view target's rows read {self.matrix.shape[1]} patches, not {n_patches}")
        return self.matrix

    def lamp_terms(self, lamps, irradiance=None, samples=None):
        """(k, len(lamps), 3) W/m^2 per unit strength: each lamp's highlight on the rows (engine.view_lamps:
        (pi f(l, v) - rho) E at the glossy rows' points, the matte rows' 0 exactly), None without a
        glossy row. ``irradiance`` (P, len(lamps)): a lamp that lights no glossy patch seen is skipped
        (0); cost one shadow ray per glossy row, lamp and lamp sample (``samples`` for a lamp with an extent)."""
        if self.glossy_rows is None or len(self.glossy_rows[0]) == 0 or not len(lamps):
            return None
        row, patch, point, d, w = self.glossy_rows
        out = np.zeros((self.matrix.shape[0], len(lamps), 3))
        todo = np.arange(len(lamps))
        if irradiance is not None:
            H = sp.csc_matrix(irradiance)[np.unique(patch)]
            todo = np.flatnonzero(np.asarray(abs(H).sum(axis=0)).reshape(-1) > 0)
        if len(todo):
            X = self._lamp_light([lamps[j] for j in todo], patch, point, d, samples or LAMP_VIEW_SAMPLES)
            out[np.ix_(row, todo)] = X * w[:, None, None]
        return out

    def bsdf_rows(self, n_patches):
        """(k, n_patches): each glossy row reads its own patch through the BSDF (view_rows), at its weight."""
        row, patch, _, _, w = self.glossy_rows
        if not len(row):
            return None
        return sp.csr_matrix((np.asarray(w, dtype=np.float64), (row, patch)), shape=(self.matrix.shape[0], n_patches))

    def fixed_light(self):
        """(k, 3) W/m^2: the scene's own lamps' highlights on the rows (lamp_terms at their power), None without."""
        if self._fixed is None and self.fixed_lamps:
            X = self.lamp_terms(self.fixed_lamps)
            self._fixed = None if X is None else X.sum(axis=1)
        return self._fixed

    def _lamp_light(self, lamps, patch, point, d, samples=LAMP_VIEW_SAMPLES):
        P = self._patches
        if self._materials is None:  # (kept: the lamp refinement asks again at every evaluation)
            material, lobes, _ = _patch_materials(self._faces, P)
            self._materials = material, lobes, {}, incidence_of(self._faces, P)
        material, lobes, tables, inc = self._materials
        for m, table in brdf_tables(lobes, [m for m in np.unique(material[patch]) if int(m) not in tables]).items():
            tables[m] = table
        if inc is None:
            excess = None
        else:  # (per patch, then per point: the points of a patch share its excess)
            own, at = np.unique(patch, return_inverse=True)
            excess = lambda lamp: lamp_albedo_excess(lamp, P.center, P.normal, *inc, patches=own)[at.reshape(-1)]
        return lamp_view_light(lamps, point, patch, d, P.normal, P.reflectance, material, lobes,
                               _sampler(self._F, P), samples, tables=tables, excess=excess)

    def shown(self) -> np.ndarray:
        """(k, 3) the rows' values as radiance (merged rows': pixel_error says the pixels')."""
        return self.values / np.pi

    @property
    def pixels(self) -> int:
        """How many pixels were painted."""
        return int(self.spec.painted.sum())

    @classmethod
    def aims(cls, faces, patches, sampler):
        """A TargetAims (None without a view target): per patch its painted pixels see, their mean
        pi x radiance (channels summed: where the candidate lamps aim, target_clusters), and the
        painted highlights' mounts (``highlight_mounts``)."""
        spec = getattr(faces, "view_target", None)
        if spec is None:
            return None
        hits = cast_pixels(spec.camera, sampler, np.flatnonzero(spec.painted.reshape(-1)))
        want = np.pi * spec.radiance.reshape(-1, 3)[hits.pixel].sum(axis=1)
        n = np.bincount(hits.patch, minlength=patches.n_patches)
        radiosity = np.bincount(hits.patch, weights=want, minlength=patches.n_patches) / np.maximum(n, 1)
        points, where = highlight_mounts(spec, hits, want, _patch_materials(faces, patches)[2], sampler)
        return TargetAims(radiosity, points, where)

    @classmethod
    def from_scene(cls, faces, patches, F=None, kept=()):
        """The view target of ``faces.view_target`` (a ViewSpec, or None: no target), on the form
        factors ``F`` (the glossy rows gather through them). ``kept``: targets an earlier paint
        made on the same model (a Live stroke's): a view target's rows of the patches that see the
        same painted pixels are taken again (``build``'s ``earlier``)."""
        spec = getattr(faces, "view_target", None)
        if spec is None:
            return None
        if F is None:
            raise ValueError("a view target needs the form factors")
        return cls.build(spec, faces, patches, F, next((t for t in kept if type(t) is cls), None))

    @classmethod
    def build(cls, spec, faces, patches, F, earlier=None):
        """The target of ``spec``; ``earlier``: a view target whose blocks (_pixel_blocks') are taken
        again where they are the same (its camera, materials and form factors these: the same F,
        the same patches' geometry, whatever their paint; a stroke repainting part of the image
        makes the rows of the patches whose pixels changed: 1.3 s for the whole image on the
        living room)."""
        P = patches.n_patches
        key = digest(spec.camera, getattr(faces, "face_material", None), getattr(faces, "material_lobes", None))
        kept = earlier._blocks[1] if earlier is not None and earlier._F is F and earlier._blocks[0] == key else None
        made = {}
        # (each glossy patch's fine rows, kept for ``predict``: a block taken again keeps its own)
        fine = {} if kept is None else dict(getattr(earlier, "_fine", {}))
        hits = cast_pixels(spec.camera, _sampler(F, patches), np.flatnonzero(spec.painted.reshape(-1)))
        if len(hits.pixel) == 0:
            raise ValueError(f"no painted pixel of the view target {spec.name!r} sees a surface (they see the World "
                             f"or the back of faces)")
        t = np.pi * spec.radiance.reshape(-1, 3)[hits.pixel]  # (n, 3) W/m^2
        rows, cols, data, values, spread = [], [], [], [], 0.0
        pixel_row = np.empty(len(hits.pixel), dtype=np.int64)
        k = 0
        interp = earlier.interp if kept is not None and earlier.interp is not None else \
            matte_interpolation(F, faces, patches)  # (of the same model and materials: 80 ms on the living room)
        alpha = _patch_materials(faces, patches)[2]
        glossy = []  # per glossy block: (its rows, its tiles' mean points and directions, weights)
        for i, group, js, W, tile in _pixel_blocks(hits, patches, F, faces, spec.camera, interp=interp, kept=kept,
                                                   made=made, fine=fine):
            # the pixels sharing a row (a tile's, a matte patch's): one row of weight sqrt(n) asking
            # sqrt(n) x their mean
            w = np.sqrt(np.bincount(tile, minlength=len(W)))[:, None]
            tm = np.stack([np.bincount(tile, t[group, ch], len(W)) for ch in range(3)], 1) / (w * w)
            G = W.mean(axis=2)
            if W.shape[1] > 1:
                spread = max(spread, float(np.max(np.abs(W - G[:, :, None])) / max(np.max(np.abs(G)), TINY)))
            Gc, tc = w * G, w * tm
            r, c = np.nonzero(Gc)
            rows.append(r + k)
            cols.append(js[c])
            data.append(Gc[r, c])
            values.append(tc)
            pixel_row[group] = k + tile
            if np.isfinite(alpha[i]):
                point, d = _tile_means(hits, group, tile, len(W))
                glossy.append((k + np.arange(len(W)), np.full(len(W), i), point, d, w[:, 0]))
            k += len(Gc)
        matrix = sp.csr_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(k, P))
        values = np.concatenate(values)
        offset = np.sum(t * t, axis=0) - np.sum(values * values, axis=0)
        rows = tuple(np.concatenate(x) for x in zip(*glossy)) if glossy else \
            (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
        target = cls(spec, hits, matrix, values, np.maximum(offset, 0.0), spread, F, patches, faces, pixel_row, interp,
                     rows, list(getattr(faces, "lamps", None) or ()))
        target._blocks, target._fine = (key, made), {k: fine[k] for k in made if k in fine}
        if kept is not None:  # (the rows of the blocks taken are the earlier target's, bit for bit)
            target.rows_taken = _rows_taken(earlier, made, kept)
        return target

    def predict(self, B, lamps=(), own=None) -> np.ndarray:
        """(n, 3) the radiance the hit pixels show under radiosity ``B`` (P, 3), W m^-2 sr^-1, with
        the highlights of the scene's own lamps and of ``lamps`` [(engine.lamps.Lamp, strength (3,))]
        (the configuration's lamps: B holds their light Lambertian) at each pixel's point. ``own``
        (P, 3): what B holds of the emitters' first reflection beyond rho (InverseProblem's
        first_reflection), which the glossy pixels see through their BSDF instead (``bsdf_rows``)."""
        L = _radiance(self.hits, np.asarray(B, dtype=np.float64), self._patches, self._F, self._faces,
                      self.spec.camera, self.interp, self._fine)
        return L + self._highlights(self.hits, lamps, own=own)

    def _highlights(self, hits, lamps, samples=PIXEL_LAMP_SAMPLES, own=None) -> np.ndarray:
        """(n, 3) W m^-2 sr^-1: the highlights of the fixed lamps and of ``lamps`` [(Lamp, strength)] at
        ``hits`` (``samples`` lamp samples a pixel for a lamp with an extent), less ``own`` / pi (P, 3)
        on the glossy pixels (``predict``)."""
        out = np.zeros((len(hits.pixel), 3))
        pairs = [(lamp, np.ones(3)) for lamp in self.fixed_lamps] + [(lamp, np.asarray(s, dtype=np.float64))
                                                                      for lamp, s in lamps]
        alpha = _patch_materials(self._faces, self._patches)[2]
        g = np.flatnonzero(np.isfinite(alpha[hits.patch]))
        if len(g) and pairs:
            X = self._lamp_light([lamp for lamp, _ in pairs], hits.patch[g], hits.point[g], hits.direction[g], samples)
            out[g] = np.einsum("nlc,lc->nc", X, np.stack([s for _, s in pairs])) / np.pi
        if own is not None and len(g):
            out[g] -= np.asarray(own, dtype=np.float64)[hits.patch[g]] / np.pi
        return out

    def image(self, B, samples=4, lamps=(), own=None) -> tuple:
        """predicted_image of the whole frame under radiosity ``B`` (``samples`` rays a pixel), with
        the lamps' highlights and less ``own`` on the glossy pixels (``predict``'s)."""
        return predicted_image(self.spec.camera, self._faces, self._patches, self._F, B, samples, interp=self.interp,
                               highlights=lambda hits: self._highlights(hits, lamps, own=own))

    def pixel_error(self, B, lamps=(), own=None) -> dict:
        """The error over the painted pixels under radiosity ``B``: the pixels seen, the free ones,
        the mean of each pixel's relative error (|L - L_t| summed over channels / L_t summed; a pixel
        asking 0 is left out), the RMS error in W m^-2 sr^-1 and relative to the target's RMS."""
        L = self.predict(B, lamps, own)
        Lt = self.spec.radiance.reshape(-1, 3)[self.hits.pixel]
        asked = Lt.sum(axis=1)
        ok = asked > TINY
        rel = np.abs(L - Lt).sum(axis=1)[ok] / asked[ok]
        rms = float(np.sqrt(np.mean((L - Lt) ** 2)))
        rms_t = float(np.sqrt(np.mean(Lt ** 2)))
        return {"painted": self.pixels, "seen": int(len(self.hits.pixel)), "world": self.hits.missed,
                "back": self.hits.back, "mean_relative_error": float(np.mean(rel)) if len(rel) else 0.0,
                "rms_error": rms, "relative_rms_error": rms / rms_t if rms_t > TINY else 0.0,
                "channel_spread": self.channel_spread}


def _radiance(hits, B, patches, F, faces, camera, interp, fine=None) -> np.ndarray:
    out = np.zeros((len(hits.pixel), 3))
    for i, group, js, W, tile in _pixel_blocks(hits, patches, F, faces, camera, PREDICT_LOBE, interp, exact=True,
                                               fine=fine):
        out[group] += np.einsum("njc,jc->nc", W, B[js])[tile] / np.pi
    return out


def predicted_image(camera, faces, patches, F, B, samples=1, seed=0, interp=None, highlights=None) -> tuple:
    """((H, W, 3) the radiance the model predicts the camera sees under radiosity ``B`` (the per
    channel rows: view_rows; ``highlights(hits)``: (n, 3) what lamps add at PixelHits ``hits``), (H, W) the share of each pixel's ``samples`` rays (stratified
    jittered over the pixel) that hit a patch's front; 0 radiance where none does)."""
    H, Wd = camera.height, camera.width
    sampler = _sampler(F, patches)
    interp = matte_interpolation(F, faces, patches) if interp is None else interp
    B = np.asarray(B, dtype=np.float64)
    img = np.zeros((H * Wd, 3))
    cover = np.zeros(H * Wd)
    rng = np.random.default_rng(seed)
    m = max(1, int(round(np.sqrt(samples))))
    pixels = np.arange(H * Wd)
    for a in range(m):
        for b in range(m):
            off = (np.stack([a + rng.random(H * Wd), b + rng.random(H * Wd)], axis=1) / m) if samples > 1 else (0.5, 0.5)
            hits = cast_pixels(camera, sampler, pixels, off)
            img[hits.pixel] += _radiance(hits, B, patches, F, faces, camera, interp)
            if highlights is not None:
                img[hits.pixel] += highlights(hits)
            cover[hits.pixel] += 1.0
    n = m * m
    return (img / n).reshape(H, Wd, 3), (cover / n).reshape(H, Wd)
