"""The kernel estimator's plane test (kernel_transfer._signed_range): each pair's (min, max) over
the second patch's vertices of the signed distance to the first patch's plane, by both of its
ways (a plane paired with most of the scene's triangles: one pass over every triangle reduced per
patch; other pairs: their triangles gathered), against the definition computed vertex by vertex."""
import numpy as np

import relight_addon.engine.kernel_transfer as kt
from relight_addon.engine.scene import mesh_patches, polygon_faceset


def room():
    """Planar quads at random places and orientations (one patch each), and two crumpled
    polygons (non-planar: no plane, NaN)."""
    rng = np.random.default_rng(7)
    polys = []
    for _ in range(40):
        c, u, v = rng.normal(size=3) * 3, rng.normal(size=3), rng.normal(size=3)
        polys.append(np.array([c, c + u, c + u + v, c + v]))
    for _ in range(2):
        polys.append(rng.normal(size=(6, 3)) + rng.normal(size=3) * 3)
    return mesh_patches(polygon_faceset(polys), max_patch_size=1e3)


def reference(g, a, b):
    mn, mx = np.full(len(a), np.nan), np.full(len(a), np.nan)
    for k, (i, j) in enumerate(zip(a, b)):
        if not g.planar[i]:
            continue
        v = g.tv[g.tstart[j]: g.tstart[j] + g.tcount[j]].reshape(-1, 3)
        h = (v - g.center[i]) @ g.normal[i]
        mn[k], mx[k] = h.min(), h.max()
    return mn, mx


def test_both_ways_match_the_definition():
    p = room()
    g = kt.kernel_geometry(p, 16)
    P = p.n_patches
    assert not g.planar.all() and g.planar.sum() >= 40
    # every patch against two planes (the one-pass way: each plane sees all the triangles) ...
    planes = np.flatnonzero(g.planar)[:2]
    a_all = np.repeat(planes, P)
    b_all = np.tile(np.arange(P), len(planes))
    # ... and random pairs, each plane with a few patches (the gathered way), non-planar ones among them
    rng = np.random.default_rng(1)
    a_few, b_few = rng.integers(0, P, 60), rng.integers(0, P, 60)
    per_plane = np.bincount(a_few, weights=g.tcount[b_few], minlength=P)
    assert per_plane.max() <= 0.25 * len(g.tv)  # (these take the gathered way)
    for a, b in ((a_all, b_all), (a_few, b_few), (np.r_[a_all, a_few], np.r_[b_all, b_few])):
        mn, mx, tol = kt._signed_range(g, a, b)
        rmn, rmx = reference(g, a, b)
        np.testing.assert_array_equal(np.isnan(mn), np.isnan(rmn))
        ok = ~np.isnan(rmn)
        assert np.isnan(rmn).any() if a is a_few else True
        np.testing.assert_allclose(mn[ok], rmn[ok], rtol=0, atol=1e-12)
        np.testing.assert_allclose(mx[ok], rmx[ok], rtol=0, atol=1e-12)
        assert np.all(mx[ok] - mn[ok] >= 0) and np.any(np.abs(mx[ok]) > 0.1)
        np.testing.assert_array_equal(tol, 1e-9 * np.maximum(g.diam[a], g.diam[b]))
