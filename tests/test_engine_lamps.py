"""engine/lamps.py against closed forms: the lamps' direct irradiance on patches, and the
inverse problem's fixed lamp light (A^-1 rho H). Cycles: tests/test_cycles_lamps.py."""
import math

import numpy as np
import pytest

import flatland
from relight_addon.engine.inverse import InverseProblem
from relight_addon.engine.lamps import Lamp, lamp_irradiance
from relight_addon.engine.scene import mesh_patches, polygon_faceset

DOWN, X, Y = np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])


def _grid(n=6, side=3.0, z=0.0, extra=()):
    s = side / n
    polys = [[(x0, y0, z), (x0 + s, y0, z), (x0 + s, y0 + s, z), (x0, y0 + s, z)]
             for y0 in -side / 2 + s * np.arange(n) for x0 in -side / 2 + s * np.arange(n)]
    return mesh_patches(polygon_faceset(polys + list(extra), reflectance=0.5), 10.0), s


def _face_mean(f, x0, y0, s, m=60):
    g = (np.arange(m) + 0.5) / m
    Xg, Yg = np.meshgrid(x0 + g * s, y0 + g * s)
    return f(Xg, Yg).mean()


def test_point_lamp_is_intensity_times_solid_angle():
    ps, s = _grid()
    lamp = Lamp("p", "POINT", (0.3, -0.2, 1.0), DOWN, X, Y, (100.0, 50.0, 0.0))
    H = lamp_irradiance(ps, [lamp])[:, 0]
    I = 100.0 / (4 * math.pi)
    for p in range(ps.n_patches):
        x0, y0 = ps.tri_vertices[ps.tri_patch == p].reshape(-1, 3)[:, :2].min(axis=0)
        ref = _face_mean(lambda Xg, Yg: I * 1.0 / ((Xg - 0.3) ** 2 + (Yg + 0.2) ** 2 + 1.0) ** 1.5, x0, y0, s)
        assert H[p, 0] == pytest.approx(ref, rel=2e-4)
        assert H[p, 1] == pytest.approx(ref / 2, rel=2e-4) and H[p, 2] == 0.0  # colour x power per channel


def test_sun_and_its_shadow():
    # a sun straight down; an opaque plate 0.5 m up covering x < 0 exactly: the left half is dark
    plate = [[(-1.5, -1.5, 0.5), (0.0, -1.5, 0.5), (0.0, 1.5, 0.5), (-1.5, 1.5, 0.5)]]
    ps, _ = _grid(extra=plate)
    lamp = Lamp("sun", "SUN", (0, 0, 5.0), DOWN, X, Y, (3.0, 3.0, 3.0))
    H = lamp_irradiance(ps, [lamp])[:, 0, 0]
    floor = ps.center[:, 2] < 0.25
    left, right = floor & (ps.center[:, 0] < 0), floor & (ps.center[:, 0] > 0)
    np.testing.assert_allclose(H[right], 3.0, rtol=1e-12)  # E = S cos 0, unshadowed
    np.testing.assert_array_equal(H[left], 0.0)
    tilted = Lamp("sun", "SUN", (0, 0, 5.0), np.array([math.sin(0.4), 0, -math.cos(0.4)]), X, Y, (3.0,) * 3,
                  cast_shadow=False)
    np.testing.assert_allclose(lamp_irradiance(ps, [tilted])[floor, 0, 0], 3.0 * math.cos(0.4), rtol=1e-12)


def test_spot_cone_without_blend_cuts_at_its_angle():
    ps, s = _grid(n=12)
    spot = Lamp("s", "SPOT", (0, 0, 1.0), DOWN, X, Y, (100.0,) * 3, spot_size=math.radians(90))
    point = Lamp("p", "POINT", (0, 0, 1.0), DOWN, X, Y, (100.0,) * 3)
    H = lamp_irradiance(ps, [spot, point])[:, :, 0]
    # the cone's edge on the floor: radius tan(45 deg) x 1 m = 1 m; patches wholly inside / outside
    corner = np.linalg.norm(ps.center[:, :2], axis=1)
    inside, outside = corner + s * 0.75 < 1.0, corner - s * 0.75 > 1.0
    np.testing.assert_allclose(H[inside, 0], H[inside, 1], rtol=1e-12)
    assert np.all(H[outside, 0] == 0.0) and np.all(H[outside, 1] > 0)


def test_area_lamp_power_on_a_large_floor():
    # a small area lamp 1 m above a 40 x 40 m floor of 1 m patches: the power P lands in the
    # proportion of the floor's form factor seen from the lamp, (4 / pi) x/sqrt(1+x^2) atan(...)
    ps, s = _grid(n=40, side=40.0)
    lamp = Lamp("a", "AREA", (0.1, 0.2, 1.0), DOWN, X, Y, (10.0,) * 3, size_u=0.5, size_v=0.25)
    H = lamp_irradiance(ps, [lamp])[:, 0, 0]
    x = 20.0 / 1.0
    q = x / math.sqrt(1 + x * x)
    share = 4 / math.pi * q * math.atan(q)
    assert float(np.sum(H * ps.area)) == pytest.approx(10.0 * share, rel=0.01)


def test_inverse_problem_subtracts_the_lamps_radiosity():
    r = flatland.room(4.0, 3.0, n_per_wall=(8, 6, 8, 6), reflectance=np.array([0.5, 0.6, 0.7]))
    P = len(r["area"])
    floor = r["wall"] == "floor"
    rng = np.random.default_rng(1)
    H = np.where(floor[:, None], rng.uniform(1, 4, (P, 3)), 0.0)  # a lamp lighting the floor
    painted = np.where(floor[:, None], 5.0, np.zeros((P, 3)))
    prob = InverseProblem(r["F"], r["area"], r["reflectance"], floor, painted, ~floor, r["center"], r["normal"],
                          background_irradiance=H)
    for c in range(3):
        B_lamp = np.linalg.solve(np.eye(P) - r["reflectance"][:, c:c + 1] * r["F"], r["reflectance"][:, c] * H[:, c])
        np.testing.assert_allclose(prob.background_radiosity[:, c], B_lamp, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(prob.b_target[:, c], 5.0 - B_lamp[floor], rtol=1e-10)
    assert prob.target_norm == pytest.approx(np.linalg.norm(painted[floor]))  # relative errors: of what was painted


def test_uniform_world_lights_what_sees_the_sky():
    from relight_addon.engine.world import world_irradiance

    L = np.array([1.0, 0.5, 0.25])
    ps, _ = _grid()  # a floor alone: its whole hemisphere is sky
    np.testing.assert_allclose(world_irradiance(ps, L), np.pi * np.broadcast_to(L, (ps.n_patches, 3)), rtol=1e-12)
    # a closed box (faces inward): no ray escapes
    from relight_addon.engine import closed_forms as cf

    box = cf.box_polygons()
    closed = mesh_patches(polygon_faceset(box), 10.0)
    np.testing.assert_array_equal(world_irradiance(closed, L), 0.0)
    # the box without its top: the floor sees the sky through a unit square 1 m up; the share of
    # its cosine-weighted hemisphere is the form factor to that square (Howell C-11), mean over the floor
    open_box = mesh_patches(polygon_faceset([p for i, p in enumerate(box) if i != 1]), 10.0)
    E = world_irradiance(open_box, L, rays_per_patch=4096)
    floor = np.flatnonzero(open_box.center[:, 2] < 1e-9)
    F = cf.parallel_rectangles(1.0, 1.0, 1.0)
    assert E[floor, 0].mean() == pytest.approx(np.pi * L[0] * F, rel=0.03)
