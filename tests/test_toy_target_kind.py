"""A target kind added from a test, at run time (issue 38: a new kind touches no project file).

The toy kind asks for the area-weighted mean radiosity of a set of patches: one row that averages
several patches, a linear map on B unlike a painted mask. It is registered in TARGET_KINDS here,
stacked with a painted target, solved on a small room and checked by a forward radiosity solve."""
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

import flatland
from relight_addon.engine.inverse import InverseProblem, solve_inverse, target_rows
from relight_addon.engine.radiosity import solve_radiosity
from relight_addon.engine.reduction import StopCriteria, reduce_lights
from relight_addon.engine.registry import TARGET_KINDS
from relight_addon.engine.scene import SceneError
from relight_addon.engine.targets import PaintedRadiance, Target, scene_targets

RHO = np.array([0.5, 0.6, 0.7])


class MeanRadiosity(Target):
    """The area-weighted mean radiosity of ``patches`` equals ``value`` (3,) W/m^2: one row."""

    kind = "toy-mean"

    def __init__(self, patches, area, value):
        self.patches = np.asarray(patches)
        self.weights = np.asarray(area, dtype=np.float64)[self.patches] / np.sum(np.asarray(area)[self.patches])
        self.values = np.asarray(value, dtype=np.float64).reshape(1, 3)

    def rows(self, n_patches):
        return sp.csr_matrix((self.weights, self.patches, [0, len(self.patches)]), shape=(1, n_patches))


@pytest.fixture
def toy_kind(monkeypatch):
    """The toy kind registered for this test only (the registry's methods restored after)."""
    monkeypatch.setattr(TARGET_KINDS, "_methods", dict(TARGET_KINDS._methods))
    TARGET_KINDS.register("toy-mean", "Mean Radiosity", "The mean radiosity of a set of patches")(MeanRadiosity)
    return TARGET_KINDS["toy-mean"].impl


@pytest.fixture(scope="module")
def room():
    return flatland.room(4.0, 3.0, n_per_wall=(8, 6, 8, 6), reflectance=RHO)


def _problem(r, kind):
    """The floor's mean and two wall patches asked for what two positive ceiling lights give them
    (feasible with non-negative lights); the candidates are the ceiling's patches."""
    floor, left, cand = r["wall"] == "floor", r["wall"] == "left", r["wall"] == "ceiling"
    e = np.zeros((len(r["area"]), 3))
    e[np.flatnonzero(cand)[[1, 4]]] = [[30.0, 25.0, 20.0], [10.0, 12.0, 15.0]]
    B, _ = solve_radiosity(r["F"], r["reflectance"], e, method="direct")
    a = r["area"][floor]
    mean = a @ B[floor] / a.sum()
    painted = np.flatnonzero(left)[:2]  # two wall patches painted besides the floor's mean
    targets = [kind(np.flatnonzero(floor), r["area"], mean), PaintedRadiance(painted, B[painted])]
    prob = InverseProblem(r["F"], r["area"], r["reflectance"], targets, cand, r["center"], r["normal"])
    return prob, floor, painted, mean, B[painted]


def _forward(r, prob, strength):
    B, _ = solve_radiosity(r["F"], r["reflectance"], prob.patch_exitance(strength), method="direct")
    return B


def test_toy_kind_is_registered_and_asked_by_scenes(toy_kind):
    assert "toy-mean" in TARGET_KINDS.names()
    assert toy_kind.from_scene(None, None) is None  # (a kind without scene targets adds none)


@pytest.mark.parametrize("solver", ["reduced", "nnls"])
def test_solved_lights_give_the_mean(room, toy_kind, solver):
    r = room
    prob, floor, painted, mean, wall = _problem(r, toy_kind)
    rows = prob.target_rows
    assert prob.m == 3 and not rows.selects  # the mean's row first (its first patch is the floor's lowest)
    assert rows.kind_of(0) == "toy-mean" and rows.kind_of(1) == rows.kind_of(2) == "radiance"
    assert prob.target_mask.sum() == floor.sum() + 2
    res = solve_inverse(prob, solver)
    assert res.relative_error < 1e-8
    B = _forward(r, prob, res.exitance)
    a = r["area"][floor]
    np.testing.assert_allclose(a @ B[floor] / a.sum(), mean, rtol=1e-8)
    np.testing.assert_allclose(B[painted], wall, rtol=1e-8)
    if solver == "nnls":
        assert np.all(res.exitance >= 0)


def test_reduction_keeps_the_rows(room, toy_kind):
    """The reduction's forward route (Gauss-Seidel) reads the same rows as the transfer."""
    r = room
    prob = _problem(r, toy_kind)[0]
    e_x = solve_inverse(prob, "nnls").exitance
    red = reduce_lights(prob, e_x, "exitance-elimination", "distance",
                        StopCriteria(max_lights=4, require_positive=False), error_route="gauss-seidel")
    final = red.final
    strength = np.zeros((prob.n_lights, 3))
    strength[final.lights] = final.exitance
    B = _forward(r, prob, strength)
    got = prob.target_rows.of(B)
    assert final.n_lights <= 4
    # (Gauss-Seidel's error is within its tolerance of the direct solve's)
    assert abs(np.linalg.norm(got - prob.b_target) - final.error) <= 1e-5 * prob.target_norm


def test_paper_formulation_refuses_a_mixing_row(room, toy_kind):
    prob = _problem(room, toy_kind)[0]
    with pytest.raises(SceneError, match="reduced or nnls"):
        solve_inverse(prob, "svd")


def test_scene_targets_keep_the_patch_order():
    """A scene's painted and illuminance targets are stacked in the patches' order (today's rows)."""
    P = 6
    patches = SimpleNamespace(target=np.array([1, 1, 0, 1, 1, 0], bool), target_radiosity=np.arange(18.0).reshape(P, 3),
                              face=np.arange(P), object=np.array([0, 0, 1, 1, 2, 2]))
    faces = SimpleNamespace(target_lux=np.array([0, 50.0, 0, 0, 20.0, 0]))
    rows = target_rows(scene_targets(faces, patches), P)
    assert rows.selects and rows.patch.tolist() == [0, 1, 3, 4]
    np.testing.assert_array_equal(rows.values, patches.target_radiosity[[0, 1, 3, 4]])
    assert rows.region.tolist() == [-1, 0, -1, 2]
    painted, lux = rows.targets  # (each kind says its values in its own unit: lx for illuminance)
    assert (painted.unit, lux.unit) == ("W/m^2", "lx")
    np.testing.assert_array_equal(painted.shown(), patches.target_radiosity[[0, 3]])
    np.testing.assert_array_equal(lux.shown(), [[50.0] * 3, [20.0] * 3])
