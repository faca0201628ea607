"""Issue 37's cold solve set-up, shared instead of repeated, the same numbers:

- engine.extent.triangle_measures: one measure of a FaceSet's triangles for the region, the memory
  check before meshing and the adaptive model's mesh; per face by segments when the triangles are in
  face order (an export's are), by ``ufunc.at`` otherwise: the same values as measured directly;
- engine.coincident.covered_share and engine.backs.sides_view given the export's one Embree scene:
  the same answers as with their own, and no scene built when no face has a coincident partner.
"""
import numpy as np
import pytest

from relight_addon.engine import extent
from relight_addon.engine.backs import sides_view
from relight_addon.engine.coincident import covered_share
from relight_addon.engine.cost import estimate_patch_count
from relight_addon.engine.geometry import triangle_areas
from relight_addon.engine.options import JobOptions
from relight_addon.engine.rays import embree_scene
from relight_addon.engine.scene import polygon_faceset
from relight_addon.pipeline import meshing

WALL = np.array([(0, -1.0, 0), (0, -1.0, 1.0), (0, 1.0, 1.0), (0, 1.0, 0)])


def _scene(seed=0, n=40):
    """A room's floor grid, a wall and its flipped copy, scattered small triangles and pentagons."""
    rng = np.random.default_rng(seed)
    polys = [np.array([(x, y, 0), (x + 0.25, y, 0), (x + 0.25, y + 0.25, 0), (x, y + 0.25, 0)])
             for x in np.arange(-1, 1, 0.25) for y in np.arange(-1, 1, 0.25)]
    polys += [WALL + [1.5, 0, 0], (WALL + [1.5, 0, 0])[::-1].copy()]
    for _ in range(n):
        c = rng.uniform(-1, 1, 3) + [0, 0, 1.2]
        k = rng.choice([3, 5])
        a = np.sort(rng.uniform(0, 2 * np.pi, k))
        r = rng.uniform(0.005, 0.3)
        polys.append(c + r * np.stack([np.cos(a), np.sin(a), 0.3 * np.sin(2 * a)], axis=1))
    return polys


def _direct(fs):
    T = fs.vertices[fs.triangles]
    edge = np.linalg.norm(T - np.roll(T, 1, axis=1), axis=2).max(axis=1)
    fe, lo, hi = np.zeros(fs.n_faces), np.full((fs.n_faces, 3), np.inf), np.full((fs.n_faces, 3), -np.inf)
    np.maximum.at(fe, fs.triangle_face, edge)
    np.minimum.at(lo, fs.triangle_face, T.min(axis=1))
    np.maximum.at(hi, fs.triangle_face, T.max(axis=1))
    area = triangle_areas(T)
    return dict(area=area, edge=edge, face_area=np.bincount(fs.triangle_face, weights=area, minlength=fs.n_faces),
                face_edge=fe, face_lo=lo, face_hi=hi)


@pytest.mark.parametrize("shuffle", [False, True])
def test_triangle_measures_are_the_direct_ones_bit_for_bit(shuffle):
    """In face order (segments) or shuffled (ufunc.at), with a face without triangles: each measure
    equal to the one computed directly, and to the other order's."""
    fs = polygon_faceset(_scene(), reflectance=0.5)
    if shuffle:
        order = np.random.default_rng(1).permutation(len(fs.triangles))
        fs.triangles, fs.triangle_face = fs.triangles[order], fs.triangle_face[order]
    keep = fs.triangle_face != 3  # face 3 loses its triangles: 0 edge, an empty box
    fs.triangles, fs.triangle_face = fs.triangles[keep], fs.triangle_face[keep]
    assert np.all(np.diff(fs.triangle_face) >= 0) != shuffle
    m = extent.triangle_measures(fs)
    for name, want in _direct(fs).items():
        got = getattr(m, name)
        if name in ("area", "edge") or not shuffle:
            assert np.array_equal(got, want), name
        else:  # the sum by bincount is order-dependent in its last bit; min and max are exact
            (np.testing.assert_allclose if name == "face_area" else np.testing.assert_array_equal)(got, want)
    assert m.face_edge[3] == 0 and np.all(np.isinf(m.face_lo[3]))


def test_triangle_measures_follow_the_geometry_and_are_dropped_after_meshing():
    """Moved vertices are measured again; mesh_for_job leaves no measure on the FaceSet, and its
    patches and memory estimate are those of a FaceSet measured afresh."""
    fs = polygon_faceset(_scene(2), reflectance=0.5)
    a = extent.triangle_measures(fs)
    assert extent.triangle_measures(fs) is a
    fs.vertices = fs.vertices * 2.0
    b = extent.triangle_measures(fs)
    assert b is not a and np.allclose(b.face_area, 4 * a.face_area)
    opts = JobOptions(patch_model="adaptive").validate()
    est = estimate_patch_count(fs, opts, 0.1, certain=True)
    patches = meshing.mesh_for_job(fs, opts, 0.1)
    assert "_triangle_measures" not in fs.__dict__
    fresh = polygon_faceset(_scene(2), reflectance=0.5)
    fresh.vertices = fresh.vertices * 2.0
    assert estimate_patch_count(fresh, opts, 0.1, certain=True) == est
    again = meshing.mesh_for_job(fresh, opts, 0.1)
    assert np.array_equal(again.tri_vertices, patches.tri_vertices) and np.array_equal(again.area, patches.area)


def test_one_embree_scene_gives_the_same_answers_and_none_is_built_without_twins():
    fs = polygon_faceset(_scene(3), reflectance=0.5)
    geo = (fs.vertices, fs.triangles, fs.triangle_face)
    built = []

    def shared():
        built.append(embree_scene(fs.vertices, fs.triangles))
        return built[-1]

    own = covered_share(*geo, fs.n_faces)
    got = covered_share(*geo, fs.n_faces, scene=shared)
    assert own is not None and np.array_equal(own, got) and own.max() == pytest.approx(1.0)
    obj = np.zeros(fs.n_faces, dtype=np.int64)
    chosen = np.arange(fs.n_faces)
    a = sides_view(*geo, obj, chosen, 0.0, 16, seed=2)
    b = sides_view(*geo, obj, chosen, 0.0, 16, seed=2, scene=embree_scene(fs.vertices, fs.triangles))
    for name in ("front", "back", "back_other"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # the wall's copy moved 1 cm: no pair, and the scene is never asked for
    polys = _scene(3)
    polys[65] = polys[65] + [0.01, 0, 0]
    fs2 = polygon_faceset(polys, reflectance=0.5)
    n = len(built)
    assert covered_share(fs2.vertices, fs2.triangles, fs2.triangle_face, fs2.n_faces, scene=shared) is None
    assert len(built) == n
