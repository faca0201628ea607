"""Light-source reduction: invariants (energy conservation), error routes, vectorised trials vs brute force."""
import numpy as np
import pytest

import flatland
from relight_addon.engine.inverse import InverseProblem, solve_inverse
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.radiosity import solve_radiosity
from relight_addon.engine.reduction import Distributor, StopCriteria, reduce_lights
from relight_addon.engine.registry import DISTRIBUTIONS, SELECTIONS

RHO = np.array([0.5, 0.6, 0.7])


def feasible(seed, n=(10, 8, 10, 8), n_lights=3):
    r = flatland.room(4.0, 3.0, n_per_wall=n, reflectance=RHO)
    rng = np.random.default_rng(seed)
    P = len(r["area"])
    floor = r["wall"] == "floor"
    e = np.zeros((P, 3))
    e[rng.choice(np.flatnonzero(~floor), n_lights, replace=False)] = rng.uniform(10, 50, (n_lights, 3))
    B, _ = solve_radiosity(r["F"], r["reflectance"], e, method="direct")
    prob = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, B * floor[:, None])],
                          ~floor, r["center"], r["normal"])
    return prob, solve_inverse(prob, "svd").exitance


@pytest.fixture(scope="module")
def case():
    return feasible(0)


@pytest.mark.parametrize("selection", [s.name for s in SELECTIONS if s.traits.distributes])
@pytest.mark.parametrize("distribution", DISTRIBUTIONS.names())
def test_power_conserved_and_errors_exact(case, selection, distribution):
    prob, e_x = case
    A = prob.area[prob.candidates]
    total = (e_x * A[:, None]).sum(0)
    res = reduce_lights(prob, e_x, selection, distribution, max_steps=12)
    assert len(res.curve) >= 12
    for pt in res.curve:
        np.testing.assert_allclose((pt.exitance * A[pt.lights, None]).sum(0), total, rtol=1e-10, atol=1e-9)
        full = np.zeros_like(e_x)
        full[pt.lights] = pt.exitance
        assert pt.error == pytest.approx(prob.error(full), rel=1e-9, abs=1e-12)
        assert pt.n_negative == int((pt.exitance < 0).any(1).sum()) and pt.n_lights == len(pt.lights)
    if "elimination" in selection:
        assert [p.n_lights for p in res.curve] == list(range(len(e_x), 0, -1))


def test_gauss_seidel_route_agrees_and_warm_start_saves(case):
    prob, e_x = case
    t = reduce_lights(prob, e_x, "exitance-elimination", "distance")
    g = reduce_lights(prob, e_x, "exitance-elimination", "distance", error_route="gauss-seidel",
                      gs_compare_cold=True)
    scale = prob.target_norm
    for a, b in zip(t.curve, g.curve):
        assert abs(a.error - b.error) < 1e-6 * scale
    assert sum(g.gs_iterations) < sum(g.gs_cold_iterations)
    with pytest.raises(ValueError, match="Gauss-Seidel"):
        reduce_lights(prob, e_x, "error-elimination", error_route="gauss-seidel")


def test_error_elimination_matches_brute_force(case):
    """The vectorised trial evaluation picks what a loop of distribute + error picks."""
    prob, e_x = case
    res = reduce_lights(prob, e_x, "error-elimination", "distance")
    dist = Distributor(prob, "distance")
    A = prob.area[prob.candidates]
    S, e = np.arange(len(e_x)), e_x.copy()
    for pt in res.curve[1:8]:
        best = None
        for i in range(len(S)):
            keep = np.arange(len(S)) != i
            e2 = dist.distribute(e[keep], S[keep], [S[i]], e[i:i + 1] * A[S[i]])
            full = np.zeros_like(e_x)
            full[S[keep]] = e2
            err = prob.error(full)
            if best is None or err < best[0] - 1e-12:
                best = (err, i, e2)
        err, i, e2 = best
        S, e = S[np.arange(len(S)) != i], e2
        assert list(pt.lights) == list(S) and pt.error == pytest.approx(err, rel=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_exitance_elimination_ends_positive(seed):
    prob, e_x = feasible(seed, n_lights=1 + seed % 3)
    res = reduce_lights(prob, e_x, "exitance-elimination", "distance", StopCriteria(relative_error_threshold=0.2))
    A = prob.area[prob.candidates]
    assert ((e_x * A[:, None]).sum(0) > 0).all()  # total power positive: the premise of the guarantee
    assert res.final.n_negative == 0 and res.curve[-1].n_negative == 0
    # negatives go first: while a negative light remains, the removed light had a negative channel
    for prev, pt in zip(res.curve, res.curve[1:]):
        if prev.n_negative:
            j = list(prev.lights).index(pt.changed)
            assert (prev.exitance[j] < 0).any()


def test_nnls_greedy_non_negative_and_monotone(case):
    prob, e_x = case
    res = reduce_lights(prob, e_x, "nnls-greedy")
    errs = [p.error for p in res.curve]
    assert all(p.exitance.min() >= 0 for p in res.curve)
    assert all(b <= a * (1 + 1e-9) + 1e-12 for a, b in zip(errs, errs[1:]))
    assert res.curve[-1].relative_error < 1e-6  # a feasible positive configuration exists


def test_stop_criteria(case):
    prob, e_x = case
    res = reduce_lights(prob, e_x, stop=StopCriteria(max_lights=4))
    assert res.final.n_lights <= 4 and res.final.n_negative == 0
    thr = 0.05 * prob.target_norm
    res = reduce_lights(prob, e_x, stop=StopCriteria(error_threshold=thr))
    ok = [p for p in res.curve if p.error <= thr and p.n_negative == 0]
    assert res.final.error <= thr and res.final.n_lights == min(p.n_lights for p in ok)
    res = reduce_lights(prob, e_x, stop=StopCriteria(error_threshold=0.0, max_lights=1))
    assert res.warnings and res.final.n_lights == 1
    np.testing.assert_allclose(res.patch_exitance(prob)[prob.candidates[res.final.lights]], res.final.exitance)


def test_distance_and_local_weights():
    r = flatland.room(4.0, 3.0, n_per_wall=(4, 3, 4, 3), reflectance=0.5)
    P = len(r["area"])
    floor = r["wall"] == "floor"
    prob = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, np.ones((P, 3)))],
                          ~floor, r["center"], r["normal"])
    d = Distributor(prob, "distance")
    np.testing.assert_allclose(d.weights([0], [3]), [[1.0]])  # one light left takes everything
    w = d.weights([0], [1, 2, 3, 4])
    assert w.sum() == pytest.approx(1.0) and (w >= 0).all()
    D = d.pair[0, [1, 2, 3, 4]]
    below = D < D.mean()
    np.testing.assert_allclose(w[0, below], (1 / D[below]) / (1 / D[below]).sum())
    assert (w[0, ~below] == 0).all()
    co = Distributor(prob, "coplanar")
    ceiling = np.flatnonzero(r["wall"][prob.candidates] == "ceiling")
    wl = co.weights([ceiling[0]], ceiling[1:])
    np.testing.assert_allclose(wl, np.full((1, len(ceiling) - 1), 1 / (len(ceiling) - 1)))
    right = np.flatnonzero(r["wall"][prob.candidates] == "right")
    np.testing.assert_allclose(co.weights([ceiling[0]], right), np.full((1, len(right)), 1 / len(right)))
    assert P > 0


def test_bad_input_and_cancel(case):
    prob, e_x = case
    with pytest.raises(ValueError, match="unknown selection"):
        reduce_lights(prob, e_x, "random")
    with pytest.raises(ValueError, match="unknown distribution"):
        reduce_lights(prob, e_x, distribution="magic")
    with pytest.raises(ValueError, match="shape"):
        reduce_lights(prob, e_x[:-1])
    with pytest.raises(ValueError, match="NaN"):
        reduce_lights(prob, np.full_like(e_x, np.nan))
    calls = []
    res = reduce_lights(prob, e_x, progress=lambda d, t: calls.append(d), cancel=lambda: len(calls) >= 3)
    assert res.cancelled and len(res.curve) == 3 and calls == [0, 1, 2]
    a, b = reduce_lights(prob, e_x), reduce_lights(prob, e_x)
    assert [p.error for p in a.curve] == [p.error for p in b.curve]
