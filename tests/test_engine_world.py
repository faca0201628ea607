"""engine/world.py against closed forms: the World as an equirectangular radiance map, its
direct irradiance through the directions that escape the scene, and the suns taken out of it.
Cycles: tests/test_cycles_world.py."""
import math

import numpy as np
import pytest

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from relight_addon.engine.world import EnvironmentMap, world_irradiance


def _floor(n=4, side=2.0, extra=()):
    s = side / n
    polys = [[(x0, y0, 0.0), (x0 + s, y0, 0.0), (x0 + s, y0 + s, 0.0), (x0, y0 + s, 0.0)]
             for y0 in -side / 2 + s * np.arange(n) for x0 in -side / 2 + s * np.arange(n)]
    return mesh_patches(polygon_faceset(polys + list(extra), reflectance=0.5), 10.0)


def _sky(H=64, W=128, fn=None):
    env = EnvironmentMap(np.zeros((H, W, 3)))
    return EnvironmentMap(fn(env.directions()))


def test_texels_directions_and_solid_angles_are_consistent():
    env = EnvironmentMap(np.zeros((32, 64, 3)))
    d = env.directions().reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-12)
    row, col = env.texel(d)
    np.testing.assert_array_equal(row, np.repeat(np.arange(32), 64))
    np.testing.assert_array_equal(col, np.tile(np.arange(64), 32))
    assert env.solid_angles().sum() == pytest.approx(4 * math.pi, rel=1e-12)
    # the convention: the centre column looks along +Y, a quarter to the left along -X, row 0 down
    r, c = env.texel(np.array([[0, 1.0, 0], [-1.0, 0, 0], [1.0, 0, 0], [0, 0, -1.0], [0, 0, 1.0]]))
    assert list(c[:3]) == [32, 16, 48] and r[3] == 0 and r[4] == 31


def test_uniform_map_equals_the_uniform_world():
    ps = _floor()
    L = np.array([0.8, 0.4, 0.2])
    flat = _sky(fn=lambda d: np.broadcast_to(L, d.shape).copy())
    np.testing.assert_allclose(world_irradiance(ps, flat), world_irradiance(ps, L), rtol=1e-12)
    np.testing.assert_allclose(world_irradiance(ps, L), np.pi * L[None, :].repeat(ps.n_patches, 0), rtol=1e-12)


def test_graded_sky_on_an_open_floor():
    # L(w) = a + b cos(theta) above the horizon, c below: E_up = pi a + 2 pi b / 3 (the ground
    # is not seen by an upward-facing floor)
    a, b, c = 0.5, 2.0, 7.0
    sky = _sky(H=128, W=256, fn=lambda d: np.where(d[..., 2:] > 0, a + b * np.maximum(d[..., 2:], 0), c)
               * np.ones(3))
    ref = math.pi * a + 2 * math.pi * b / 3
    assert sky.irradiance_up()[0] == pytest.approx(ref, rel=2e-3)  # the map's own quadrature
    E = world_irradiance(_floor(), sky, rays_per_patch=4096)
    assert E[:, 0].mean() == pytest.approx(ref, rel=5e-3)
    assert np.all(np.abs(E[:, 0] / ref - 1) < 0.03)


def test_sun_in_the_map_is_lit_as_a_sun_with_its_shadow():
    # one texel 2e5 times the sky: taken out as a sun of its radiance x solid angle; an opaque
    # plate above x < 0 shadows it exactly, the sky stays seen around the plate's edge
    env = EnvironmentMap(np.full((64, 128, 3), 0.1))
    row, col = env.texel(np.array([[0.3, -0.2, 0.93]]) / np.linalg.norm([0.3, -0.2, 0.93]))
    rad = env.radiance.copy()
    rad[row[0], col[0]] = 2e4
    env = EnvironmentMap(rad)
    suns, rest = env.split_suns()
    assert len(suns) == 1 and rest.radiance.max() == pytest.approx(0.1)
    strength = 2e4 * env.solid_angles()[row[0], col[0]]
    np.testing.assert_allclose(suns[0].power, strength, rtol=1e-12)
    d_sun = env.directions()[row[0], col[0]]
    np.testing.assert_allclose(-suns[0].direction, d_sun, atol=1e-12)
    ps = _floor(n=6, side=3.0)
    E = world_irradiance(ps, env, rays_per_patch=1024)[:, 0]
    expect = strength * d_sun[2] + math.pi * 0.1  # sun at its elevation + the uniform sky
    np.testing.assert_allclose(E, expect, rtol=2e-3)
    plate = [[(-2.0, -2.0, 0.3), (0.0, -2.0, 0.3), (0.0, 2.0, 0.3), (-2.0, 2.0, 0.3)]]
    shaded = _floor(n=6, side=3.0, extra=plate)
    E = world_irradiance(shaded, env, rays_per_patch=1024)[:, 0]
    # floor patches whose ray to the sun passes under the plate (x + 0.3 dx/dz < 0) get no sun
    dark = (shaded.center[:, 2] < 0.1) & (shaded.center[:, 0] + 0.3 * d_sun[0] / d_sun[2] < -0.6)
    lit = (shaded.center[:, 2] < 0.1) & (shaded.center[:, 0] > 0.6)
    assert dark.any() and lit.any()
    assert np.all(E[dark] < math.pi * 0.1 * 1.01)  # only (part of) the sky
    assert np.all(E[lit] > strength * d_sun[2])


def test_window_lets_in_only_its_share_of_the_sky():
    # the box without its top: the floor sees the sky through a unit square 1 m up; a sky of
    # radiance 1 above the horizon (0 below): the floor gets pi F, F its form factor to the square
    box = cf.box_polygons()
    open_box = mesh_patches(polygon_faceset([p for i, p in enumerate(box) if i != 1]), 10.0)
    sky = _sky(fn=lambda d: np.where(d[..., 2:] > 0, 1.0, 0.0) * np.ones(3))
    E = world_irradiance(open_box, sky, rays_per_patch=4096)
    floor = np.flatnonzero(open_box.center[:, 2] < 1e-9)
    assert E[floor, 0].mean() == pytest.approx(math.pi * cf.parallel_rectangles(1.0, 1.0, 1.0), rel=0.03)


def test_bad_maps_are_refused():
    with pytest.raises(ValueError, match="NaN or infinite"):
        EnvironmentMap(np.full((4, 8, 3), np.nan))
    with pytest.raises(ValueError, match="shape"):
        EnvironmentMap(np.zeros((4, 8)))


def test_sees_sky_finds_small_openings_and_nothing_in_a_closed_box():
    from relight_addon.engine.world import sees_sky

    box = cf.box_polygons((4.0, 3.0, 2.5))
    assert not sees_sky(polygon_faceset(box))
    # the same box with a 10 x 10 cm hole in its top (the top split around the hole): 0.03 % of its area
    polys = [p for i, p in enumerate(box) if i != 1]
    z = max(v[2] for p in box for v in p)
    xs, ys = (0.0, 2.0, 2.1, 4.0), (0.0, 1.5, 1.6, 3.0)
    top = [[(xs[i], ys[j], z), (xs[i], ys[j + 1], z), (xs[i + 1], ys[j + 1], z), (xs[i + 1], ys[j], z)]
           for i in range(3) for j in range(3) if (i, j) != (1, 1)]
    closed_top = top + [[(2.0, 1.5, z), (2.0, 1.6, z), (2.1, 1.6, z), (2.1, 1.5, z)]]
    assert not sees_sky(polygon_faceset(polys + closed_top))  # the split top, closed: still no sky
    assert sees_sky(polygon_faceset(polys + top))


def test_sees_sky_ignores_a_face_lying_on_the_floor_unless_it_is_a_target():
    from relight_addon.engine.world import sees_sky

    box = cf.box_polygons((4.0, 3.0, 2.5))
    rug = [(1.0, 1.0, 0.0), (1.0, 2.0, 0.0), (2.0, 2.0, 0.0), (2.0, 1.0, 0.0)]  # facing down, on the floor
    faces = polygon_faceset(box + [rug])
    assert not sees_sky(faces)  # its rays leave below the floor, but its light reaches nothing
    faces.target = np.zeros(faces.n_faces, dtype=bool)
    faces.target[-1] = True
    assert sees_sky(faces)  # painted: the World's light on it is what the artist sees
