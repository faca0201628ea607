"""A lamp kind added from a test, touching no project file (issue 38, item 1's acceptance): a
"downlight", a point of Lambertian intensity I(theta) = P cos(theta) / pi about its -Z axis (none
above its plane; its power P), registered at run time as a LampKind in LIGHT_KINDS, lights a closed
box, and Best k Lights, offered it beside a point lamp and a spot, returns it with the power that
made the targets.

References, independent of the engine: the closed form of its irradiance on a floor parallel to
its plane at height h, E = P h^2 / (pi d^4) (d the distance; cos theta = cos theta' = h / d),
integrated over each floor patch by the midpoint rule; the targets made by A^-1 formed explicitly
(numpy) from a power chosen here.
"""
import math
from dataclasses import dataclass

import numpy as np
import pytest

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.best_lights import best_k_for_problem
from relight_addon.engine.inverse import InverseProblem
from relight_addon.engine.lamps import Lamp, lamp_irradiance
from relight_addon.engine.lights import Capability, LampKind, append_lamps
from relight_addon.engine.lights.point import point_lamp
from relight_addon.engine.lights.spot import spot_lamp
from relight_addon.engine.registry import LIGHT_KINDS
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.pipeline.kept import kept_lamps
from relight_addon.pipeline.report import json_safe, placed_record

SIZE = (2.0, 1.5, 1.2)
#: the downlight: under the ceiling's centre, pointing down
AT = np.array([1.0, 0.75, 1.1])
DOWN, X, Y = np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])


@dataclass(frozen=True)
class DownlightKind(LampKind):
    """I(theta) = P cos(theta) / pi below its plane: the whole of its behaviour the engine asks."""

    blender_type = "POINT"
    flags = Capability.AIMED | Capability.PLACEABLE

    def irradiance_at(self, lamp, y, n, u, far) -> tuple:
        toy = y - lamp.position
        d = np.linalg.norm(toy, axis=1)
        w = -toy / d[:, None]  # towards the lamp
        cos_l = np.maximum(toy @ lamp.direction, 0.0) / d
        e = np.maximum(np.einsum("ij,ij->i", n, w), 0.0) * cos_l / (math.pi * d * d)
        return e, w, d, None

    def report_fields(self, lamp) -> dict:
        return {"lobe": "cosine"}


@pytest.fixture(scope="module")
def downlight():
    kind = DownlightKind("downlight", "Downlight", "A cosine-lobe downlight (a test's own kind)",
                         source="irradiance", strength_unit="W", shape="downlight", writer="placed")
    LIGHT_KINDS.register(kind.name, kind.label, kind.description)(kind)
    yield kind
    del LIGHT_KINDS._methods[kind.name]  # (registered by this test only)
    assert "downlight" not in LIGHT_KINDS


@pytest.fixture(scope="module")
def box():
    return mesh_patches(polygon_faceset(cf.box_polygons(SIZE), reflectance=0.5), max_patch_size=0.25)


def _closed_form_mean(x0, x1, y0, y1, h, m=80):
    """The downlight's mean irradiance per W over the floor rectangle [x0, x1] x [y0, y1] (midpoint rule)."""
    gx, gy = np.meshgrid(x0 + (np.arange(m) + 0.5) / m * (x1 - x0), y0 + (np.arange(m) + 0.5) / m * (y1 - y0))
    d2 = (gx - AT[0]) ** 2 + (gy - AT[1]) ** 2 + h * h
    return float(np.mean(h * h / (math.pi * d2 * d2)))


def test_a_toy_kind_lights_the_floor_as_its_closed_form(box, downlight):
    lamp = Lamp("Downlight", downlight, AT, DOWN, X, Y, np.ones(3))
    H = lamp_irradiance(box, [lamp], seed=0)[:, 0, :]
    np.testing.assert_array_equal(H[:, 0], H[:, 2])  # 1 W in every channel
    floor = np.flatnonzero(box.normal[:, 2] > 0.9)
    assert len(floor) >= 16
    for p in floor:
        v = box.tri_vertices[box.tri_patch == p].reshape(-1, 3)
        (x0, y0, _), (x1, y1, _) = v.min(axis=0), v.max(axis=0)
        assert H[p, 0] == pytest.approx(_closed_form_mean(x0, x1, y0, y1, AT[2]), rel=1e-2)
    above = box.center[:, 2] > AT[2]
    assert np.all(H[above, 0] == 0)  # the ceiling is above its plane: no light
    # what the floor gets: its power on the floor's area, by the closed form of a cosine lobe through
    # the floor's rectangle, within the sampling
    assert float(H[floor, 0] @ box.area[floor]) == pytest.approx(
        _closed_form_mean(0, SIZE[0], 0, SIZE[1], AT[2]) * SIZE[0] * SIZE[1], rel=3e-3)


def test_best_k_lights_returns_the_toy_kind_with_the_power_that_made_the_targets(box, downlight):
    ps = box
    P = ps.n_patches
    rng = np.random.default_rng(3)
    F = rng.uniform(0, 1, (P, P)) * (1 - np.eye(P))
    F *= 0.9 / F.sum(axis=1, keepdims=True)  # any form factors with row sums below 1
    lamps = [point_lamp("p", (0.4, 0.4, 1.0)), spot_lamp("s", (1.6, 1.1, 1.0), (0.2, 0, -1), math.radians(50)),
             Lamp("d", downlight, AT, DOWN, X, Y, np.ones(3))]
    kinds = [lamp.kind.name for lamp in lamps]
    H = lamp_irradiance(ps, lamps, seed=0)[:, :, 0]
    lights = append_lamps(None, np.zeros(0, dtype=np.int64), P, lamps, kinds, H,
                          [lamp.kind.area(lamp) for lamp in lamps])
    assert lights.kind_names == ["point", "spot", "downlight"] and lights.kind_of(2) is downlight
    floor = ps.normal[:, 2] > 0.9
    power = np.array([40.0, 30.0, 20.0])  # W per channel
    B = np.linalg.solve(np.eye(P) - 0.5 * F, 0.5 * H[:, 2:3] * power[None, :])  # what it makes
    prob = InverseProblem(F, ps.area, np.full((P, 3), 0.5), [PaintedRadiance.masked(floor, B)], np.zeros(P, bool),
                          ps.center, ps.normal, lights=lights)
    best = best_k_for_problem(prob, 2)[0]  # one light
    assert best.lights.tolist() == [2]
    strength = np.zeros((3, 3))
    strength[best.lights] = best.exitance  # (the exitance of the lights that are on)
    np.testing.assert_allclose(strength[2], power, rtol=1e-6)
    assert best.relative_error < 1e-6
    np.testing.assert_allclose(lights.power(strength), [0.0, 0.0, 90.0], rtol=1e-6)  # W: its strength's sum
    rec = placed_record(lamps[2], "downlight", strength[2])
    assert rec["kind"] == "downlight" and rec["lobe"] == "cosine" and rec["power"] == pytest.approx(90.0)
    np.testing.assert_allclose(rec["normal"], DOWN)
    assert rec["area"] == 0.0
    # kept (--keep, Keep Lamps): a record of its own kind, written as its Blender type
    kept, notes = kept_lamps({"command": "solve", "final": {"lights": [json_safe(rec)]}})
    assert [(r["kind"], r["type"], r["name"]) for r in kept] == [("downlight", "POINT", "d (kept)")] and not notes
    np.testing.assert_allclose(kept[0]["position"], AT)


def test_a_toy_lamp_kind_answers_a_toy_target_kind(box, downlight, monkeypatch):
    """Both new kinds at once, neither in a project file: the targets are the mean radiosity of each
    quarter of the floor (test_toy_target_kind's MeanRadiosity, registered here), made by 20 W of the
    downlight; offered it, a point lamp in a corner and a spot aimed off-centre, Best k Lights
    returns the downlight alone, at 20 W, with no error, and the forward solve (A^-1 formed by
    numpy) of its answer gives each quarter's mean."""
    from test_toy_target_kind import MeanRadiosity
    from relight_addon.engine.registry import TARGET_KINDS

    monkeypatch.setattr(TARGET_KINDS, "_methods", dict(TARGET_KINDS._methods))
    TARGET_KINDS.register("toy-mean", "Mean Radiosity", "The mean radiosity of a set of patches")(MeanRadiosity)
    ps, P = box, box.n_patches
    rng = np.random.default_rng(5)
    F = rng.uniform(0, 1, (P, P)) * (1 - np.eye(P))
    F *= 0.9 / F.sum(axis=1, keepdims=True)
    lamps = [point_lamp("p", (0.3, 0.3, 1.0)), spot_lamp("s", (1.6, 1.1, 1.0), (0.3, 0.2, -1), math.radians(40)),
             Lamp("d", downlight, AT, DOWN, X, Y, np.ones(3))]
    H = lamp_irradiance(ps, lamps, seed=0)[:, :, 0]
    lights = append_lamps(None, np.zeros(0, dtype=np.int64), P, lamps, [lamp.kind.name for lamp in lamps], H,
                          [lamp.kind.area(lamp) for lamp in lamps])
    A = np.eye(P) - 0.5 * F
    B = np.linalg.solve(A, 0.5 * H[:, 2:3] * np.full((1, 3), 20.0))
    floor = ps.normal[:, 2] > 0.9
    quarters = [np.flatnonzero(floor & ((ps.center[:, 0] < 1.0) == left) & ((ps.center[:, 1] < 0.75) == front))
                for left in (True, False) for front in (True, False)]
    assert all(len(q) >= 4 for q in quarters)
    means = [ps.area[q] @ B[q] / ps.area[q].sum() for q in quarters]
    targets = [TARGET_KINDS["toy-mean"].impl(q, ps.area, m) for q, m in zip(quarters, means)]
    prob = InverseProblem(F, ps.area, np.full((P, 3), 0.5), targets, np.zeros(P, bool), ps.center, ps.normal,
                          lights=lights)
    assert prob.m == 4  # one row a quarter, each averaging its patches
    best = best_k_for_problem(prob, 2)[0]
    assert best.lights.tolist() == [2] and best.relative_error < 1e-6
    np.testing.assert_allclose(best.exitance[0], [20.0] * 3, rtol=1e-6)
    B_answer = np.linalg.solve(A, 0.5 * H[:, 2:3] * best.exitance[0][None, :])
    for q, m in zip(quarters, means):
        np.testing.assert_allclose(ps.area[q] @ B_answer[q] / ps.area[q].sum(), m, rtol=1e-6)
