"""The lamps a solve places (engine/lights/spot.py, area.py, point.py; issue 17): kinds in the
stored code order, Blender's frame, bad values refused, and each kind as a source.

References, independent of the engine: conservation in a closed box (a point lamp and an area
lamp put all their power on its walls; a spot the share of its cone, 2 pi (1 - cos(size / 2)) x
(1 - blend / 2) of the sphere's 4 pi -- the integral of Cycles' smoothstep over the cone), A^-1
formed explicitly (numpy): a placed lamp's column of T is A^-1 diag(rho) H.
"""
import math

import numpy as np
import pytest

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.inverse import InverseProblem
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.lamps import lamp_irradiance
from relight_addon.engine.lights import append_lamps
from relight_addon.engine.lights.area import area_lamp, blender_shape
from relight_addon.engine.lights.point import point_lamp
from relight_addon.engine.lights.spot import spot_lamp
from relight_addon.engine.registry import LIGHT_KINDS
from relight_addon.engine.scene import mesh_patches, polygon_faceset

SIZE = (2.0, 1.5, 1.2)
INSIDE = (0.7, 0.9, 0.8)


@pytest.fixture(scope="module")
def box():
    return mesh_patches(polygon_faceset(cf.box_polygons(SIZE), reflectance=0.5), max_patch_size=0.25)


def test_placed_kinds_follow_the_scene_lamps_in_stored_code_order():
    assert LIGHT_KINDS.names()[:8] == ("cell", "group", "polygon", "lamp", "sun", "spot", "area", "point")
    for name in ("spot", "area", "point"):
        kind = LIGHT_KINDS[name].impl
        assert kind.source == "irradiance" and kind.strength_unit == "W" and kind.writer == "placed"
        assert kind.shape == name and kind.watts(np.array([3.0]))[0] == 1.0  # the strength is the power


@pytest.mark.parametrize("direction", [(0, 0, -1.0), (0.3, -0.2, -1.0), (1.0, 0, 0), (0, 0, 1.0)])
def test_a_placed_lamp_has_blenders_right_handed_frame(direction):
    lamp = spot_lamp("s", (0, 0, 2), direction, math.radians(40))
    d = np.asarray(direction) / np.linalg.norm(direction)
    np.testing.assert_allclose(lamp.direction, d, atol=1e-12)
    M = np.column_stack([lamp.axis_u, lamp.axis_v, -lamp.direction])  # the object's X, Y, Z
    np.testing.assert_allclose(M.T @ M, np.eye(3), atol=1e-12)
    assert np.linalg.det(M) == pytest.approx(1.0)
    np.testing.assert_array_equal(lamp.power, [1.0, 1.0, 1.0])  # its irradiance is per W


def test_bad_lamp_values_are_refused_with_their_name():
    with pytest.raises(ValueError, match="spot's size"):
        spot_lamp("s", (0, 0, 2), (0, 0, -1), 0.0)
    with pytest.raises(ValueError, match="spot's size"):
        spot_lamp("s", (0, 0, 2), (0, 0, -1), 3.5)
    with pytest.raises(ValueError, match="blend"):
        spot_lamp("s", (0, 0, 2), (0, 0, -1), 1.0, spot_blend=1.5)
    with pytest.raises(ValueError, match="radius"):
        point_lamp("p", (0, 0, 2), radius=-0.1)
    with pytest.raises(ValueError, match="area lamp's size"):
        area_lamp("a", (0, 0, 2), (0, 0, -1), float("nan"))
    with pytest.raises(ValueError, match="direction"):
        area_lamp("a", (0, 0, 2), (0, 0, 0), 0.5)
    for spread in (0.0, -0.2, 3.2, float("nan")):  # Blender's Spread: (0, pi] here (0 is a collimated beam)
        with pytest.raises(ValueError, match="area lamp's spread"):
            area_lamp("a", (0, 0, 2), (0, 0, -1), 0.5, spread=spread)
    assert area_lamp("a", (0, 0, 2), (0, 0, -1), 0.5).spread == math.pi  # Lambertian by default
    assert blender_shape(area_lamp("a", (0, 0, 2), (0, 0, -1), 0.5)) == "SQUARE"
    assert blender_shape(area_lamp("a", (0, 0, 2), (0, 0, -1), 0.5, 0.3)) == "RECTANGLE"
    assert blender_shape(area_lamp("a", (0, 0, 2), (0, 0, -1), 0.5, ellipse=True)) == "DISK"


def _on_walls(box, lamp):
    H = lamp_irradiance(box, [lamp], seed=1)[:, 0, 0]
    return float(H @ box.area)


@pytest.mark.parametrize("size,blend", [(60.0, 0.0), (60.0, 0.5), (120.0, 0.25)])
def test_a_spot_puts_its_cones_share_of_its_power_on_a_closed_box(box, size, blend):
    half = math.radians(size) / 2
    share = (1 - math.cos(half)) * (1 - blend / 2) / 2  # the smoothstep's integral over the cone
    lamp = spot_lamp("s", INSIDE, (0.2, -0.1, -1.0), math.radians(size), blend)
    assert _on_walls(box, lamp) == pytest.approx(share, rel=0.01)


def test_a_point_and_an_area_lamp_put_all_their_power_on_a_closed_box(box):
    assert _on_walls(box, point_lamp("p", INSIDE)) == pytest.approx(1.0, rel=1e-3)
    assert _on_walls(box, area_lamp("a", INSIDE, (0.3, 0.2, -1.0), 0.4, 0.2)) == pytest.approx(1.0, rel=0.01)


@pytest.mark.parametrize("deg", [120.0, 60.0, 20.0, 5.0])
def test_an_area_lamps_power_does_not_depend_on_its_spread(box, deg):
    """Cycles normalises the spread (engine.lamps): a narrower beam is brighter along its axis,
    its power the same; all of it on the closed box's walls."""
    lamp = area_lamp("a", INSIDE, (0.3, 0.2, -1.0), 0.4, 0.2, spread=math.radians(deg))
    assert _on_walls(box, lamp) == pytest.approx(1.0, rel=0.01)


def test_an_area_lamps_report_record_and_stored_record_keep_its_spread():
    from relight_addon.pipeline.report import placed_record

    lamp = area_lamp("a", INSIDE, (0.3, 0.2, -1.0), 0.4, 0.2, ellipse=True, spread=math.radians(45))
    rec = placed_record(lamp, "area", np.array([3.0, 2.0, 1.0]))
    assert rec["shape"] == "ELLIPSE" and rec["size"] == [0.4, 0.2]
    assert rec["spread"] == pytest.approx(math.radians(45)) and rec["spread_deg"] == pytest.approx(45.0)
    assert lamp.kind.record(lamp)["spread"] == pytest.approx(math.radians(45))


def test_a_placed_lamps_column_is_A_inverse_rho_H(box):
    """Cells on the ceiling and one lamp of each placed kind: T's lamp columns against A^-1 formed
    explicitly, and the powers in W of their strengths."""
    ps = box
    P = ps.n_patches
    rng = np.random.default_rng(2)
    F = rng.uniform(0, 1, (P, P)) * (1 - np.eye(P))
    F *= 0.9 / F.sum(axis=1, keepdims=True)  # any form factors with row sums below 1
    lamps = [spot_lamp("s", INSIDE, (0, 0, -1), math.radians(70), 0.2), area_lamp("a", INSIDE, (0.3, 0, -1), 0.3),
             point_lamp("p", INSIDE)]
    H = lamp_irradiance(ps, lamps, seed=0)[:, :, 0]
    floor = ps.normal[:, 2] > 0.9
    ceiling = ps.normal[:, 2] < -0.9
    lights = append_lamps(None, np.flatnonzero(ceiling)[:0], P, lamps, ["spot", "area", "point"], H,
                          [0.0, lamps[1].area, 0.0])
    prob = InverseProblem(F, ps.area, np.full((P, 3), 0.5), [PaintedRadiance.masked(floor, np.ones((P, 3)))],
                          np.zeros(P, bool),
                          ps.center, ps.normal, lights=lights)
    Ainv = np.linalg.inv(np.eye(P) - 0.5 * F)
    for c in range(3):
        np.testing.assert_allclose(prob.transfer[c], (Ainv @ (0.5 * H))[prob.targets], rtol=1e-10)
    assert lights.kind_names == ["spot", "area", "point"] and lights.lamp(1) is lamps[1]
    np.testing.assert_allclose(lights.power(np.array([[1.0, 2.0, 3.0]] * 3)), 6.0)  # W: the channels' sum
    np.testing.assert_allclose(prob.light_center, [lamp.position for lamp in lamps])
