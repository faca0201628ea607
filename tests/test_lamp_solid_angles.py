"""The bare point lamp's patch solid angles (engine/lights/point_source.py, the control variate of a
point's or a spot's patch means): against closed forms, and kept per sampler and position (issue 37)
without changing a bit of what a fresh computation gives."""
import math

import numpy as np
import pytest

from relight_addon.engine.lights import point_source
from relight_addon.engine.lights.point_source import _solid_angles
from relight_addon.engine.lights.spot import SPOT, spot_lamp
from relight_addon.engine.sampling import SceneSampler
from relight_addon.engine.scene import mesh_patches, polygon_faceset


def _box(n=4, side=2.0):
    """A closed box of side ``side`` centred on the origin, each face an n x n grid, faces inward."""
    s, h = side / n, side / 2
    polys = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            for i in range(n):
                for j in range(n):
                    u0, v0 = -h + i * s, -h + j * s
                    quad = [(u0, v0), (u0 + s, v0), (u0 + s, v0 + s), (u0, v0 + s)]
                    pts = []
                    for u, v in quad:
                        p = [0.0, 0.0, 0.0]
                        p[axis], p[(axis + 1) % 3], p[(axis + 2) % 3] = sign * h, u, v
                        pts.append(tuple(p))
                    polys.append(pts if sign < 0 else pts[::-1])  # normals toward the inside
    return mesh_patches(polygon_faceset(polys, reflectance=0.5), 10.0)


def test_a_closed_box_subtends_the_whole_sphere_from_inside_and_its_opening_from_outside():
    ps = _box()
    sm = SceneSampler(ps)
    assert np.all(np.einsum("ij,ij->i", ps.normal, -ps.center) > 0)  # every patch faces the inside
    for x in ([0.0, 0.0, 0.0], [0.3, -0.7, 0.55], [0.9, 0.9, -0.9]):
        om = _solid_angles(sm.tv, np.array(x))
        assert om.sum() == pytest.approx(4 * math.pi, rel=1e-12)
        assert np.all(om >= 0)
    # from outside, 2 m above its top face on its axis: the inner faces that face the point (the
    # bottom and the sides) fill the top face's outline, a square of side 2 at 2 m: 4 asin(1 / 5)
    above = _solid_angles(sm.tv, np.array([0.0, 0.0, 3.0]))
    assert above.sum() == pytest.approx(4 * math.asin(0.2), rel=1e-12)
    assert np.all(above[ps.normal[sm.tri_patch][:, 2] < -0.5] == 0.0)  # the top face turns away


def test_a_squares_solid_angle_on_its_axis_is_the_closed_form():
    # a square of side 2a at distance d on its axis: 4 asin(a^2 / (a^2 + d^2))
    a, d = 0.7, 1.3
    tv = np.array([[[-a, -a, 0], [a, -a, 0], [a, a, 0]], [[-a, -a, 0], [a, a, 0], [-a, a, 0]]])
    om = _solid_angles(tv, np.array([0.0, 0.0, d]))
    assert om.sum() == pytest.approx(4 * math.asin(a * a / (a * a + d * d)), rel=1e-13)
    assert np.all(_solid_angles(tv, np.array([0.0, 0.0, -d])) == 0.0)  # behind it


def _reference_means(sm, position, todo, n_patches):
    """The bare point lamp's patch means as the code before issue 37 computed them (np.cross,
    np.linalg.norm, np.isin over every triangle): a fresh computation, nothing kept."""
    tri = np.flatnonzero(np.isin(sm.tri_patch, todo))
    tv, x = sm.tv[tri].astype(np.float64), position
    a, b, c = tv[:, 0] - x, tv[:, 1] - x, tv[:, 2] - x
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", a, c) * lb + \
        np.einsum("ij,ij->i", b, c) * la
    w = np.where(num < 0, 2.0 * np.arctan2(np.abs(num), den), 0.0)
    om = np.bincount(sm.tri_patch[tri], weights=w, minlength=n_patches)
    return om / (4.0 * math.pi * np.maximum(sm.area, 1e-300))


def test_kept_solid_angles_are_bit_for_bit_a_fresh_computation(monkeypatch):
    monkeypatch.setattr(point_source, "KEPT_POSITIONS", 2)
    ps = _box(n=6)
    sm = SceneSampler(ps)
    P = ps.n_patches
    rng = np.random.default_rng(3)
    positions = [rng.uniform(-0.8, 0.8, 3) for _ in range(3)]
    for rep in range(2):  # the second time: the first positions were dropped (2 kept), then kept again
        for x in positions:
            lamp = spot_lamp("s", x, -x, 1.5, 0.2)
            parts = [np.sort(rng.choice(P, 40, replace=False)) for _ in range(3)]
            for todo in parts + [parts[0][::-1], np.arange(P)]:  # partly kept, in any order, then all
                got = SPOT.point_means(lamp, sm, todo, True, P)
                want = _reference_means(sm, x, todo, P)
                assert np.array_equal(got, want)
                assert np.all(got[np.setdiff1d(np.arange(P), todo)] == 0.0)
            assert np.array_equal(SPOT.point_means(lamp, sm, np.arange(P), False, P),
                                  _reference_means(sm, x, np.arange(P), P))
    assert len(sm.__dict__["_patch_solid_angles"]) == 2
