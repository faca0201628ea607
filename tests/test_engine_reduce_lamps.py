"""The scene's lamps as the lights of the direct-lighting mode (engine/lights/lamp.py, issue 16).

References, independent of the engine: a 2-D room with exact form factors (tests/flatland.py,
Hottel's crossed strings), lamps whose direct irradiance is a closed form (a 2-D point source of
power P sends P dphi / (2 pi) into the angle dphi: a wall segment's mean irradiance is P times
the angle it subtends / (2 pi L)), A^-1 formed explicitly (numpy), and an exhaustive search
over every subset of lamps with scipy's NNLS.
"""
import itertools
import math

import numpy as np
import pytest
import scipy.optimize as sopt

import flatland
from relight_addon.engine.inverse import InverseError, direct_lighting_problem
from relight_addon.engine.lamps import Lamp
from relight_addon.engine.lights.point import POINT
from relight_addon.engine.lights.sun import SUN
from relight_addon.engine.lights import kind_code
from relight_addon.engine.lights.lamp import add_lamps, blender_values
from relight_addon.engine.reduction import StopCriteria, reduce_lights
from relight_addon.engine.registry import DISTRIBUTIONS, LIGHT_KINDS

RHO = np.array([0.5, 0.6, 0.7])
X, Y, DOWN = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, -1.0])
POSITIONS = [(0.8, 2.2), (2.0, 1.0), (3.3, 2.5), (1.5, 0.6)]
POWERS = [(30.0, 30.0, 30.0), (50.0, 40.0, 20.0), (10.0, 12.0, 14.0), (25.0, 25.0, 25.0)]


@pytest.fixture(scope="module")
def room():
    r = flatland.room(4.0, 3.0, n_per_wall=(8, 6, 8, 6), reflectance=RHO)
    segments = []  # the segments' end points, from centres, normals and lengths
    for c, n, L in zip(r["center"][:, :2], r["normal"][:, :2], r["area"]):
        t = np.array([-n[1], n[0]])
        segments.append((c - 0.5 * L * t, c + 0.5 * L * t))
    r["segments"] = np.asarray(segments)
    return r


def closed_form_irradiance(r, position):
    """(P,) mean irradiance (W/m per W) of a 2-D point source at ``position`` on each segment: the
    angle the segment subtends / (2 pi length) (a convex room: nothing occludes)."""
    p = np.asarray(position, dtype=np.float64)
    a, b = r["segments"][:, 0] - p, r["segments"][:, 1] - p
    angle = np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(axis=1)))
    return angle / (2 * math.pi * r["area"])


def lamps_and_lights(r, positions=POSITIONS, powers=POWERS, surface=None):
    lamps = [Lamp(f"lamp{i}", POINT, (x, y, 0.0), DOWN, X, Y, p) for i, ((x, y), p) in
             enumerate(zip(positions, powers))]
    H = np.stack([closed_form_irradiance(r, lamp.position[:2]) for lamp in lamps], axis=1)
    P = len(r["area"])
    return lamps, H, add_lamps(surface, np.zeros(0, dtype=np.int64), P, lamps, H, r["area"])


def lamp_problem(r, **kw):
    """(lamps, H, problem, e_x): the direct problem of the closed-form lamps in room ``r``."""
    lamps, H, lights = lamps_and_lights(r)
    prob, e_x = direct_lighting_problem(r["F"], r["area"], r["reflectance"], np.zeros((len(r["area"]), 3)),
                                        r["center"], r["normal"], lights=lights,
                                        strength=np.array([lamp.power for lamp in lamps]), **kw)
    return lamps, H, prob, e_x


def inverse_of_A(r, c):
    return np.linalg.inv(np.eye(len(r["area"])) - RHO[c] * r["F"])


def test_lamp_kinds_follow_the_surface_kinds_in_stored_code_order():
    assert LIGHT_KINDS.names()[:5] == ("cell", "group", "polygon", "lamp", "sun")
    lamp, sun = LIGHT_KINDS["lamp"].impl, LIGHT_KINDS["sun"].impl
    assert lamp.source == sun.source == "irradiance" and lamp.writer == sun.writer == "lamp"
    assert lamp.strength_unit == "W" and lamp.watts(np.array([0.0]))[0] == 1.0  # a lamp's strength is its power
    assert sun.strength_unit == "W/m^2" and sun.watts(np.array([7.5]))[0] == 7.5  # a sun's: over the area it lights


def test_the_closed_form_lamps_put_all_their_power_on_the_walls(room):
    _, H, _ = lamps_and_lights(room)
    np.testing.assert_allclose((H * room["area"][:, None]).sum(axis=0), 1.0, rtol=1e-12)


def test_direct_problem_of_lamps_against_the_explicit_inverse(room):
    """b_P = sum over the lamps of A^-1 diag(rho) H_l P_l; e_x = the lamps' own power (error 0);
    any configuration's radiosity = the sum of the lamps' columns scaled by their strength."""
    r = room
    P = len(r["area"])
    lamps, H, prob, e_x = lamp_problem(r)
    strength = np.array([lamp.power for lamp in lamps])
    assert prob.n_lights == 4 and len(prob.candidates) == 0 and len(prob.targets) == P
    np.testing.assert_array_equal(e_x, strength)
    columns = [np.stack([inverse_of_A(r, c) @ (RHO[c] * H[:, l]) for c in range(3)], axis=1) for l in range(4)]
    B_ref = sum(columns[l] * strength[l] for l in range(4))
    np.testing.assert_allclose(prob.b_target, B_ref, rtol=1e-10)
    assert prob.error(e_x) < 1e-10 * prob.target_norm
    rng = np.random.default_rng(5)
    s = rng.uniform(0, 60, (4, 3))
    np.testing.assert_allclose(prob.configuration_radiosity(s), sum(columns[l] * s[l] for l in range(4)), rtol=1e-10)
    for c in range(3):  # T's columns are the lamps' columns on the targets
        np.testing.assert_allclose(prob.transfer[c], np.stack([columns[l][:, c] for l in range(4)], axis=1),
                                   rtol=1e-10)
    # the lamps' geometry and their "form-factor rows": the share of their power reaching each patch
    np.testing.assert_allclose(prob.light_center, [lamp.position for lamp in lamps])
    assert [prob.lights.lamp(j) for j in range(4)] == lamps  # each light carries its lamp (its geometry)
    np.testing.assert_allclose(prob.light_rows(), (H * r["area"][:, None]).T, rtol=1e-12)


def test_the_world_is_fixed_background_in_direct_mode(room):
    """A fixed irradiance (the World) is transported into the background radiosity, left out of
    what the lamps must give (b_P) and counted in the norm the relative errors are of."""
    r = room
    world = np.where((r["wall"] == "ceiling")[:, None], np.array([2.0, 3.0, 4.0]), 0.0)
    lamps, H, prob, e_x = lamp_problem(r, background_irradiance=world)
    strength = np.array([lamp.power for lamp in lamps])
    B_world = np.stack([inverse_of_A(r, c) @ (RHO[c] * world[:, c]) for c in range(3)], axis=1)
    B_lamps = np.stack([inverse_of_A(r, c) @ (RHO[c] * (H @ strength[:, c])) for c in range(3)], axis=1)
    np.testing.assert_allclose(prob.background_radiosity, B_world, rtol=1e-10)
    np.testing.assert_allclose(prob.b_target, B_lamps, rtol=1e-10)
    assert prob.target_norm == pytest.approx(np.linalg.norm(B_lamps + B_world), rel=1e-12)
    assert prob.error(e_x) < 1e-10 * prob.target_norm


def exhaustive(T, b, k):
    """min over every subset of k lamps of the per-channel NNLS error (itertools + scipy)."""
    n = T[0].shape[1]
    return min(math.sqrt(sum(sopt.nnls(T[c][:, list(S)], b[:, c])[1] ** 2 for c in range(3)))
               for S in itertools.combinations(range(n), k))


def test_best_k_lamps_curve_against_exhaustive_search(room):
    """Best k Lights on 4 lamps: for every k its error is the exhaustive optimum (every subset,
    NNLS per channel on T formed from the explicit inverse); the 4-lamp point is the scene (0)."""
    r = room
    lamps, H, prob, e_x = lamp_problem(r)
    strength = np.array([lamp.power for lamp in lamps])
    T = [inverse_of_A(r, c) @ (RHO[c] * H) for c in range(3)]
    b = np.stack([T[c] @ strength[:, c] for c in range(3)], axis=1)
    red = reduce_lights(prob, e_x, selection="greedy-swap", stop=StopCriteria(max_lights=4))
    by_k = {p.n_lights: p for p in red.curve}
    assert sorted(by_k) == [1, 2, 3, 4]
    for k in (1, 2, 3):
        assert by_k[k].error == pytest.approx(exhaustive(T, b, k), rel=1e-7, abs=1e-9 * prob.target_norm), k
        assert by_k[k].n_negative == 0
    assert by_k[4].relative_error < 1e-8


@pytest.mark.parametrize("distribution", DISTRIBUTIONS.names())
def test_the_papers_reduction_of_lamps_conserves_their_power(room, distribution):
    """ExitanceElimination over lamps (and an emitter polygon with them): the curve runs from the
    scene (error 0) down to one light, and every step keeps the total power per channel."""
    r = room
    P = len(r["area"])
    e = np.zeros((P, 3))
    ceiling = np.flatnonzero(r["wall"] == "ceiling")[3]
    e[ceiling] = [40.0, 40.0, 40.0]  # an emissive segment, reduced with the lamps
    from relight_addon.engine.lights import lights_from_groups

    class _Patches:  # what lights_from_groups reads
        area, center, normal = r["area"], r["center"], r["normal"]

    surface = lights_from_groups(_Patches, e.max(axis=1) > 0, np.arange(P), kind="polygon")
    lamps, H, _ = lamps_and_lights(r)
    lights = add_lamps(surface, surface.patches, P, lamps, H, r["area"])
    strength = np.array([lamp.power for lamp in lamps])
    prob, e_x = direct_lighting_problem(r["F"], r["area"], r["reflectance"], e, r["center"], r["normal"],
                                        lights=lights, strength=strength)
    assert list(lights.kind) == [kind_code("polygon")] + [kind_code("lamp")] * 4
    red = reduce_lights(prob, e_x, selection="exitance-elimination", distribution=distribution)
    assert [p.n_lights for p in red.curve] == [5, 4, 3, 2, 1]
    assert red.curve[0].error < 1e-10 * prob.target_norm
    total = (e_x * prob.light_watts[:, None]).sum(axis=0)
    for p in red.curve:
        np.testing.assert_allclose((p.exitance * prob.light_watts[p.lights][:, None]).sum(axis=0), total, rtol=1e-10)


def test_a_sun_lights_the_area_its_power_is_counted_over(room):
    r = room
    P = len(r["area"])
    sun = Lamp("sun", SUN, (2.0, 2.0, 0.0), DOWN, X, Y, (3.0, 3.0, 3.0))
    H = np.where(r["wall"] == "floor", 1.0, 0.0)  # 1 W/m^2 per unit strength on the floor
    lights = add_lamps(None, np.zeros(0, dtype=np.int64), P, [sun], H[:, None], r["area"])
    assert lights.kind_names == ["sun"]
    assert lights.area[0] == pytest.approx(4.0)  # the floor's length
    assert lights.power(np.array([[3.0, 3.0, 3.0]]))[0] == pytest.approx(36.0)  # 3 W/m^2 on 4 m, 3 channels


def test_lamps_that_give_no_light_and_bad_strength_are_refused(room):
    r = room
    P = len(r["area"])
    lamps, H, lights = lamps_and_lights(r)
    with pytest.raises(InverseError, match="strength"):
        direct_lighting_problem(r["F"], r["area"], r["reflectance"], np.zeros((P, 3)), lights=lights,
                                strength=-np.ones((4, 3)))
    _, _, dark = lamps_and_lights(r)
    dark.irradiance = dark.irradiance.multiply(0.0).tocsc()
    with pytest.raises(InverseError, match="every light must have a source"):
        direct_lighting_problem(r["F"], r["area"], r["reflectance"], np.zeros((P, 3)), lights=dark,
                                strength=np.ones((4, 3)))
    with pytest.raises(InverseError, match="no lamp"):
        direct_lighting_problem(r["F"], r["area"], r["reflectance"], np.zeros((P, 3)))


def test_blender_values_give_each_channel_its_power():
    """One Power and one colour: the user's colour kept when every channel scales alike, else
    Power = the largest channel's and colour = power / Power (colour x Power = the strength)."""
    energy, color = blender_values([60.0, 48.0, 24.0], 50.0, (1.0, 0.8, 0.4))
    assert energy == pytest.approx(60.0) and color.tolist() == [1.0, 0.8, 0.4]
    energy, color = blender_values([30.0, 30.0, 30.0], 100.0, (0.5, 0.5, 0.5))  # colour kept, Power doubled x 0.6
    assert energy == pytest.approx(60.0) and color.tolist() == [0.5, 0.5, 0.5]
    energy, color = blender_values([80.0, 40.0, 20.0], 50.0, (1.0, 1.0, 1.0))  # the colour changes
    assert energy == pytest.approx(80.0)
    np.testing.assert_allclose(color * energy, [80.0, 40.0, 20.0])
    energy, color = blender_values([0.0, 5.0, 0.0], 10.0, (1.0, 0.0, 0.0))  # a channel the lamp had not
    np.testing.assert_allclose(color * energy, [0.0, 5.0, 0.0])
    assert blender_values([0.0, 0.0, 0.0], 10.0, (1.0, 1.0, 1.0))[0] == 0.0
