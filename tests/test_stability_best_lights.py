"""Stability of the best k-light search (engine.best_lights) where methods fail.

The cases of benchmarks/stability_table.py (a small closed room, ray-cast form factors) plus
degenerate transfer matrices built here: duplicate and zero light columns, zero target rows
(occluded), no reachable target, a bright target beside a dark one, all-zero targets. On each:
best_k_curve (both scores, with the swap search), lower_bounds and the tolerance LP never raise
on valid input, never return NaN/inf or a negative exitance, keep the curve monotone and the
bound below it, and say when the targets cannot be met. Independent references:
- Eq. 1 of the chosen configurations recomputed with a plain dense solve of (I - diag(rho) F) B = e;
- the lights that painted the reference room's targets (3 random candidates, known);
- which targets are unreachable, from the geometry (the inner floor of a closed box);
- scipy's NNLS on all candidates: the floor of every positive configuration.
The set-up failures (reflectance exactly 1, every target occluded, no target, every face
forbidden) raise InverseError before any selection runs; tests/test_stability.py covers them.
"""
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.optimize as sopt

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import stability_table as st  # noqa: E402
from relight_addon.engine import best_lights as bl  # noqa: E402
from relight_addon.engine.inverse import InverseError, solve_inverse  # noqa: E402
from relight_addon.engine.radiosity import solve_radiosity  # noqa: E402

CASES = st.case_builders()
K = 6


@pytest.fixture(scope="module")
def problems():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = CASES[name][1]()
        return cache[name]

    return get


def forward_targets(prob, e_full):
    """Radiosity (targets, all patches) from a plain dense solve of (I - diag(rho) F) B = e."""
    F = np.asarray(prob.F, dtype=np.float64)
    B = np.stack([np.linalg.solve(np.eye(len(F)) - prob.reflectance[:, c, None] * F, e_full[:, c])
                  for c in range(3)], axis=1)
    return B[prob.targets], B


def full(prob, p):
    e = np.zeros((prob.n_lights, 3))
    e[p.lights] = p.exitance
    return prob.patch_exitance(e)


def check(T, b, area, k_max=K, norm=None):
    """Every method on (T, b): returns (curves by score, bounds); checks the common properties."""
    norm = float(np.linalg.norm(b)) if norm is None else norm
    lb = bl.lower_bounds(T, b, k_max)
    assert np.all(np.isfinite(lb.bound)) and np.all(lb.bound >= 0)
    curves = {}
    for score in bl.SCORES:
        curve = bl.best_k_curve(T, b, k_max, area, score=score)
        assert len(curve) == min(k_max, T[0].shape[1])
        prev = np.inf
        for p in curve:
            assert np.isfinite(p.error) and np.isfinite(p.power)
            assert np.all(np.isfinite(p.exitance)) and np.all(p.exitance >= 0)
            assert p.n_lights <= p.k and p.n_negative == 0
            assert p.error <= prev * (1 + 1e-12) + 1e-300
            prev = p.error
            assert lb.at(p.k) <= p.error
            r = np.stack([T[c][:, p.lights] @ p.exitance[:, c] for c in range(3)], axis=1) - b
            assert p.error == pytest.approx(np.linalg.norm(r), rel=1e-9, abs=1e-12 * max(norm, 1e-300))
        curves[score] = curve
    return curves, lb


def test_reference_room_finds_the_painting_lights(problems):
    """Targets painted by 3 known positive lights: 3 lights meet them, and they are those lights."""
    prob = problems("room")
    curves, lb = check(prob.transfer, prob.b_target, prob.light_area)
    p, F, cube = st.room()
    t, c = st.room_masks(p, cube)
    # as stability_table.painted draws them (``e[rng.choice(...)] = rng.uniform(...)``: Python
    # evaluates the right-hand side first)
    rng = np.random.default_rng(0)
    values = rng.uniform(20, 60, (3, 3))
    idx = rng.choice(np.flatnonzero(c), 3, replace=False)
    order = np.argsort(idx)
    for curve in curves.values():
        p3 = curve[2]
        assert p3.relative_error < 1e-9
        assert np.array_equal(prob.candidates[p3.lights], idx[order])
        assert np.allclose(p3.exitance, values[order], rtol=1e-7)
        bt, _ = forward_targets(prob, full(prob, p3))
        assert np.linalg.norm(bt - prob.b_target) < 1e-8 * prob.target_norm
        assert "meet the targets" in bl.curve_notes(curve, lb, prob.target_norm, k=3)[0]
    assert lb.relative[0] > 0.1 and lb.exact[0]  # one light cannot, certified
    r = bl.least_power_within_tolerance(prob.transfer, prob.b_target, prob.light_area, 0.05)
    assert r.status == "ok" and r.max_deviation <= 0.05 * (1 + 1e-6)


def test_ill_conditioned_room(problems):
    """Reflectance 1 - 1e-9 in a closed room (condition ~1e9): finite, positive, and the reported
    error agrees with a dense forward solve (to the conditioning)."""
    prob = problems("reflectance 1-1e-9")
    T = prob.transfer
    assert prob.condition > 1e6 and any("ill-conditioned" in w for w in prob.warnings)
    curves, lb = check(T, prob.b_target, prob.light_area)
    for curve in curves.values():
        for p in curve[:3]:
            bt, _ = forward_targets(prob, full(prob, p))
            err = np.linalg.norm(bt - prob.b_target)
            assert abs(err - p.error) <= 1e-4 * prob.target_norm
            assert p.relative_error < 1e-3  # in a nearly closed white room one light evens everything out
    r = bl.least_power_within_tolerance(T, prob.b_target, prob.light_area, 0.05)
    assert r.status == "ok" and np.all(np.isfinite(r.exitance)) and np.all(r.exitance >= 0)


def test_duplicate_and_zero_columns(problems):
    """Singular T: every light duplicated (a half-area twin with the same transfer column) and
    dark lights (zero columns). The curve's errors are those of the original problem (the same
    configurations exist), the twins win the power tie-break, the dark lights are never used."""
    prob = problems("infeasible contrast")  # an unreachable pattern: errors stay well above 0
    T0, b, A0 = prob.transfer, prob.b_target, prob.light_area
    n = T0[0].shape[1]
    zeros = np.zeros((T0[0].shape[0], 5))
    T = [np.hstack([t, t, zeros]) for t in T0]
    A = np.concatenate([A0, A0 / 2, np.ones(5)])
    base = bl.best_k_curve(T0, b, K, A0)
    curves, lb = check(T, b, A)
    for curve in curves.values():
        for p in curve:
            assert np.all(p.lights < 2 * n)  # no dark light
        for p, q in zip(curves["error"], base):
            assert p.error == pytest.approx(q.error, rel=1e-9)
            assert np.all(p.lights >= n)  # the half-area twins: the same error at half the power
            assert p.power == pytest.approx(q.power / 2, rel=1e-6)
    r = bl.least_power_within_tolerance(T, b, A, 0.5)
    assert np.all(r.lights < 2 * n) and np.all(np.isfinite(r.exitance))


def test_occluded_targets(problems):
    prob = problems("occluded (some)")
    p, F, cube = st.room(cube=True)
    hidden = np.flatnonzero(cube & (p.normal[:, 2] > 0.5))  # from the geometry, not from T
    rows = np.flatnonzero(np.isin(prob.targets, hidden))
    assert len(rows) == len(hidden) > 0
    T, b = prob.transfer, prob.b_target
    assert all(np.all(t[rows] == 0) for t in T)
    curves, lb = check(T, b, prob.light_area)
    floor = np.linalg.norm(b[rows]) / prob.target_norm  # what the hidden targets alone cost
    for curve in curves.values():
        _, B = forward_targets(prob, full(prob, curve[-1]))
        assert np.abs(B[hidden]).max() <= 1e-12 * np.abs(B).max()  # they stay dark
        assert curve[-1].relative_error >= floor * (1 - 1e-9)
        notes = bl.curve_notes(curve, lb, prob.target_norm)
        assert notes[0].startswith("no non-negative lights meet these targets")
    assert lb.nnls_relative >= floor * (1 - 1e-9)
    r = bl.least_power_within_tolerance(T, b, prob.light_area, 0.1)
    assert r.status == "partial" and np.array_equal(r.unreachable, rows)
    assert f"{len(rows)} target(s) no candidate light reaches are left out" in r.message
    assert r.max_deviation <= 0.1 * (1 + 1e-6)  # on the targets a light reaches


def test_no_reachable_target():
    """Every target occluded: the problem refuses at set-up; the engine functions given such a T
    (all rows zero) keep every light off and say so."""
    prob = CASES["occluded (all)"][1]()
    with pytest.raises(InverseError, match="no candidate light reaches any target"):
        prob.transfer  # noqa: B018
    m, n = 4, 9
    T = [np.zeros((m, n))] * 3
    b = np.full((m, 3), 10.0)
    curves, lb = check(T, b, np.ones(n), k_max=3)
    for curve in curves.values():
        assert all(p.n_lights == 0 and p.source == "none" for p in curve)
        assert curve[-1].relative_error == pytest.approx(1.0)
    assert lb.relative == pytest.approx(np.ones(3)) and lb.exact.all()
    r = bl.least_power_within_tolerance(T, b, np.ones(n), 0.2)
    assert r.status == "infeasible" and r.power == 0 and r.n_lights == 0
    assert r.message.startswith("no candidate light reaches any painted target")


def test_infeasible_contrast(problems):
    """One bright target beside black ones: no positive configuration meets it. The curve ends at the
    NNLS floor, the notes say so, the LP names the smallest tolerance it can keep."""
    prob = problems("infeasible contrast")
    T, b = prob.transfer, prob.b_target
    curves, lb = check(T, b, prob.light_area)
    nn = solve_inverse(prob, "nnls")  # scipy NNLS on every candidate
    assert lb.nnls == pytest.approx(nn.error, rel=1e-6)
    for curve in curves.values():
        assert curve[-1].error >= nn.error * (1 - 1e-6)
        assert curve[-1].error <= 1.05 * nn.error  # 6 lights get within 5 % of the floor
        notes = bl.curve_notes(curve, lb, prob.target_norm)
        assert notes[0].startswith("no non-negative lights meet these targets")
        assert f"{lb.nnls_relative:.3g}" in notes[0]
    r = bl.least_power_within_tolerance(T, b, prob.light_area, 0.05)
    assert r.status == "infeasible"
    assert r.message.startswith("no non-negative lights keep every target within \u00b15 %; the closest is")
    assert r.reachable_tolerance > 0.05 and r.max_deviation <= r.reachable_tolerance * (1 + 1e-5) + 1e-9
    assert np.all(np.isfinite(r.exitance)) and np.all(r.exitance >= 0)


def test_all_zero_targets(problems):
    prob = problems("room")
    T = prob.transfer
    b = np.zeros_like(prob.b_target)
    curves, lb = check(T, b, prob.light_area, norm=0.0)
    for curve in curves.values():
        assert all(p.n_lights == 0 and p.error == 0 and p.relative_error == 0 for p in curve)
    assert np.all(lb.bound == 0)
    r = bl.least_power_within_tolerance(T, b, prob.light_area, 0.05)
    assert r.status == "ok" and r.power == 0 and r.n_lights == 0


def test_noisy_form_factors(problems):
    """Solved on 8-ray form factors: finite and positive; the same lights under the accurate ones too."""
    prob = problems("8 rays/patch")
    base = problems("room")
    curves, lb = check(prob.transfer, prob.b_target, prob.light_area)
    for curve in curves.values():
        B, _ = solve_radiosity(base.F, base.reflectance, full(prob, curve[2]), method="direct")
        assert np.all(np.isfinite(B))


def test_nnls_bound_is_scipys():
    """The certificate's all-lights floor is scipy's NNLS on every candidate (lowered by the margin)."""
    rng = np.random.default_rng(4)
    T = [rng.uniform(0, 1, (12, 40)) ** 4 for _ in range(3)]
    b = rng.uniform(0, 1, (12, 3))
    floor = np.sqrt(sum(sopt.nnls(T[c], b[:, c])[1] ** 2 for c in range(3)))
    lb = bl.lower_bounds(T, b, 3)
    assert lb.nnls <= floor and lb.nnls == pytest.approx(floor, rel=1e-8)
