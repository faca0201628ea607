"""Inverse system: paper SVD formulation, reduced T formulation, NNLS, honest errors.

References: exact 2-D rooms (crossed-strings form factors, tests/flatland.py),
numpy's dense inverse / pseudo-inverse, and the forward solver radiosity.py.
"""
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import flatland
from relight_addon.engine.inverse import (InverseError, InverseProblem, direct_lighting_problem,
                                          solve_inverse)
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.radiosity import solve_radiosity
from relight_addon.engine.scene import SceneError

RHO = np.array([0.5, 0.6, 0.7])


@pytest.fixture(scope="module")
def room():
    return flatland.room(4.0, 3.0, n_per_wall=(12, 9, 12, 9), reflectance=RHO)


def make(r, tmask, b, cmask, F=None):
    return InverseProblem(r["F"] if F is None else F, r["area"], r["reflectance"], [PaintedRadiance.masked(tmask, b)],
                          cmask, r["center"], r["normal"])


def feasible(r, seed=0, n_lights=3):
    """Targets on the floor at the radiosity of a few random positive ceiling/wall lights."""
    rng = np.random.default_rng(seed)
    P = len(r["area"])
    floor = r["wall"] == "floor"
    cand = ~floor
    e = np.zeros((P, 3))
    e[rng.choice(np.flatnonzero(cand), n_lights, replace=False)] = rng.uniform(10, 50, (n_lights, 3))
    B, _ = solve_radiosity(r["F"], r["reflectance"], e, method="direct")
    return make(r, floor, B * floor[:, None], cand), e, B


def test_transfer_is_block_of_inverse(room):
    r = room
    prob, _, _ = feasible(r)
    Ainv = [np.linalg.inv(np.eye(len(r["area"])) - RHO[c] * r["F"]) for c in range(3)]
    for c in range(3):  # m < |C|: solved through A^T
        np.testing.assert_allclose(prob.transfer[c], Ainv[c][np.ix_(prob.targets, prob.candidates)],
                                   rtol=1e-10, atol=1e-13)
    P = len(r["area"])
    few = np.zeros(P, bool)
    few[np.flatnonzero(r["wall"] == "ceiling")[:2]] = True
    big = make(r, ~few, np.zeros((P, 3)), few)  # m > |C|: solved through A
    for c in range(3):
        np.testing.assert_allclose(big.transfer[c], Ainv[c][np.ix_(big.targets, big.candidates)],
                                   rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("solver", ["svd", "reduced", "nnls"])
def test_feasible_targets_reproduced(room, solver):
    prob, _, B = feasible(room)
    res = solve_inverse(prob, solver)
    assert res.relative_error < 1e-9
    # independent check: forward-solve the found configuration
    Bf, _ = solve_radiosity(room["F"], room["reflectance"], res.patch_exitance(prob), method="direct")
    np.testing.assert_allclose(Bf[prob.targets], B[prob.targets], rtol=1e-8, atol=1e-8)
    assert np.isfinite(res.exitance).all() and res.seconds >= 0
    if solver == "nnls":
        assert res.exitance.min() >= 0 and res.n_negative == 0


def test_minimum_norm_solutions_match_pinv(room):
    r = room
    prob, _, _ = feasible(r, seed=3)
    red = solve_inverse(prob, "reduced")
    for c in range(3):
        np.testing.assert_allclose(red.exitance[:, c], np.linalg.pinv(prob.transfer[c]) @ prob.b_target[:, c],
                                   rtol=1e-7, atol=1e-9)
    assert red.rank == min(np.linalg.matrix_rank(t) for t in prob.transfer)
    # paper formulation: [A[:, U] -I[:, C]] x = -A[:, P] b_P, minimum norm
    svd = solve_inverse(prob, "svd")
    P = len(r["area"])
    U = np.flatnonzero(~prob.target_mask)
    for c in range(3):
        A = np.eye(P) - RHO[c] * r["F"]
        M = np.hstack([A[:, U], -np.eye(P)[:, prob.candidates]])
        x = np.linalg.pinv(M) @ (-(A[:, prob.targets] @ prob.b_target[:, c]))
        np.testing.assert_allclose(svd.exitance[:, c], x[len(U):], rtol=1e-7, atol=1e-8)
    explicit = solve_inverse(prob, "svd", svd_driver="svd")
    np.testing.assert_allclose(explicit.exitance, svd.exitance, rtol=1e-8, atol=1e-8)
    assert explicit.rank == svd.rank
    # the two minimum-norm solutions differ (different norms are minimised)
    assert np.abs(svd.exitance - red.exitance).max() > 1e-3


def test_rank_cutoff_is_configurable(room):
    prob, _, _ = feasible(room)
    full = solve_inverse(prob, "reduced")
    cut = solve_inverse(prob, "reduced", rcond=0.05)
    assert cut.rank < full.rank and cut.rcond == 0.05
    with pytest.raises(ValueError, match="rcond"):
        solve_inverse(prob, "reduced", rcond=2.0)


def test_sparse_form_factors_match_dense(room):
    prob, _, _ = feasible(room)
    b = np.zeros((len(room["area"]), 3))
    b[prob.targets] = prob.b_target
    sp_prob = make(room, prob.target_mask, b, prob.candidate_mask, F=sp.csr_matrix(room["F"]))
    for c in range(3):
        np.testing.assert_allclose(sp_prob.transfer[c], prob.transfer[c], rtol=1e-9, atol=1e-12)


def test_nnls_reports_unreachable_brightness(room):
    """A bright floor patch beside a black one cannot be made with positive lights."""
    r = room
    P = len(r["area"])
    fl = np.flatnonzero(r["wall"] == "floor")
    t = np.zeros(P, bool)
    t[fl[5:7]] = True
    b = np.zeros((P, 3))
    b[fl[5]] = 100.0
    prob = make(r, t, b, r["wall"] != "floor")
    res = solve_inverse(prob, "nnls")
    assert res.exitance.min() >= 0 and np.isfinite(res.exitance).all()
    assert any("residual" in w for w in res.warnings)
    resid = np.linalg.norm(np.stack([prob.transfer[c] @ res.exitance[:, c] for c in range(3)], 1) - prob.b_target)
    assert res.error == pytest.approx(resid) and res.relative_error > 0.05
    assert solve_inverse(prob, "reduced").relative_error < 1e-9  # with negatives it is reachable


def test_no_targets_and_no_candidates(room):
    r = room
    P = len(r["area"])
    with pytest.raises(InverseError, match="no target"):
        make(r, np.zeros(P, bool), np.zeros((P, 3)), np.ones(P, bool))
    with pytest.raises(InverseError, match="forbidden"):
        make(r, np.ones(P, bool), np.ones((P, 3)), np.zeros(P, bool))
    assert issubclass(InverseError, SceneError) and issubclass(InverseError, ValueError)


def test_bad_input_messages(room):
    r = room
    P = len(r["area"])
    t = r["wall"] == "floor"
    with pytest.raises(InverseError, match="NaN"):
        F = r["F"].copy()
        F[0, 1] = np.nan
        make(r, t, np.ones((P, 3)), ~t, F=F)
    with pytest.raises(InverseError, match="square"):
        make(r, t, np.ones((P, 3)), ~t, F=r["F"][:, :-1])
    with pytest.raises(InverseError, match="non-negative"):
        make(r, t, -np.ones((P, 3)), ~t)
    prob = make(r, t, np.ones((P, 3)), ~t)
    with pytest.raises(ValueError, match="unknown inverse solver"):
        solve_inverse(prob, "magic")


def test_unreachable_targets_are_named():
    """Two rooms that do not see each other: targets in room 2 with lights only in room 1."""
    r = flatland.room(2.0, 2.0, n_per_wall=(3, 3, 3, 3), reflectance=0.5)
    n = len(r["area"])
    F = np.zeros((2 * n, 2 * n))
    F[:n, :n] = F[n:, n:] = r["F"]
    area = np.tile(r["area"], 2)
    rho = np.tile(r["reflectance"], (2, 1))
    cand = np.zeros(2 * n, bool)
    cand[np.flatnonzero(r["wall"] == "ceiling")] = True  # room 1 only
    t = np.zeros(2 * n, bool)
    t[n + np.flatnonzero(r["wall"] == "floor")] = True  # room 2 floor
    b = np.where(t[:, None], np.full(3, 5.0), 0.0)
    with pytest.raises(InverseError, match=r"no candidate light reaches any target.*" + str(n)):
        solve_inverse(InverseProblem(F, area, rho, [PaintedRadiance.masked(t, b)], cand), "reduced")
    t2 = t.copy()
    t2[np.flatnonzero(r["wall"] == "floor")] = True  # and room 1 floor
    b2 = np.where(t2[:, None], np.full(3, 5.0), 0.0)
    prob2 = InverseProblem(F, area, rho, [PaintedRadiance.masked(t2, b2)], cand)
    res = solve_inverse(prob2, "reduced")
    # the problem records them (the report names their objects: tests/test_engine_artist_geometry.py)
    assert sorted(prob2.unmet.tolist()) == (n + np.flatnonzero(r["wall"] == "floor")).tolist()
    assert np.isfinite(res.exitance).all()


def test_ill_conditioned_closed_room_warns_and_stays_finite():
    r = flatland.room(4.0, 3.0, n_per_wall=(6, 4, 6, 4), reflectance=1.0 - 1e-9)
    P = len(r["area"])
    t = r["wall"] == "floor"
    prob = make(r, t, np.where(t[:, None], np.ones(3), 0.0), r["wall"] == "ceiling")
    res = solve_inverse(prob, "reduced")
    w = [x for x in res.warnings if "ill-conditioned" in x]
    assert w and "condition estimate" in w[0]
    assert prob.condition > 1e8
    assert np.isfinite(res.exitance).all() and np.isfinite(res.error)
    singular = flatland.room(4.0, 3.0, n_per_wall=(6, 4, 6, 4), reflectance=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(InverseError, match="singular"):
            solve_inverse(make(singular, t, np.where(t[:, None], np.ones(3), 0.0), singular["wall"] == "ceiling"),
                          "reduced")
    assert P > 0


def test_direct_lighting_problem(room):
    r = room
    P = len(r["area"])
    e = np.zeros((P, 3))
    lights = np.flatnonzero(r["wall"] == "ceiling")[[2, 7]]
    e[lights] = [[10, 20, 30], [5, 5, 5]]
    prob, e_x = direct_lighting_problem(r["F"], r["area"], r["reflectance"], e, r["center"], r["normal"])
    assert list(prob.candidates) == sorted(lights) and len(prob.targets) == P - 2
    B, _ = solve_radiosity(r["F"], r["reflectance"], e, method="gauss-seidel", tol=1e-12)
    np.testing.assert_allclose(prob.b_target, B[prob.targets], rtol=1e-9)
    assert prob.error(e_x) < 1e-9 * prob.target_norm
    with pytest.raises(InverseError, match="no light"):
        direct_lighting_problem(r["F"], r["area"], r["reflectance"], np.zeros((P, 3)))
    with pytest.raises(InverseError, match="non-negative"):
        direct_lighting_problem(r["F"], r["area"], r["reflectance"], -e)


def test_gram_route_is_the_svd_pseudo_inverse_solution():
    """The default 'auto' driver (Cholesky of M M^T when M has full row rank with margin) gives
    the SVD pseudo-inverse's minimum-norm solution, and falls back to the SVD when M is
    rank-deficient (the cut-off then matters)."""
    import scipy.linalg as sla
    from relight_addon.engine.solvers.common import lstsq_min_norm

    rng = np.random.default_rng(3)
    M = rng.standard_normal((40, 90))
    R = rng.standard_normal((40, 2))
    x_auto, rank_auto = lstsq_min_norm(M, R, 1e-12, "auto")
    x_svd, rank_svd = lstsq_min_norm(M, R, 1e-12, "svd")
    np.testing.assert_allclose(x_auto, x_svd, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(x_auto, np.linalg.pinv(M) @ R, rtol=1e-9, atol=1e-12)
    assert rank_auto == rank_svd == 40
    # rank-deficient: two equal rows; the Gram route refuses, the SVD cut-off gives rank 39
    M2 = M.copy()
    M2[1] = M2[0]
    x2, rank2 = lstsq_min_norm(M2, R, 1e-10, "auto")
    assert rank2 == 39
    np.testing.assert_allclose(x2, sla.pinv(M2, rtol=1e-10) @ R, rtol=1e-8, atol=1e-10)


def test_light_groups_make_a_face_one_light():
    """Patches grouped into one light share one exitance: T's column of a group is the sum of
    its patches' columns, e_x reproduces feasible targets, power = exitance x group area; and
    one patch per group is the ungrouped problem."""
    r = flatland.room(4.0, 3.0, n_per_wall=(8, 6, 8, 6), reflectance=0.5)
    P = len(r["area"])
    floor = (r["wall"] == "floor") & (np.cumsum(r["wall"] == "floor") <= 3)  # 3 targets, 4 lights: feasible
    cand = r["wall"] == "ceiling"
    tgt = np.where(floor[:, None], 1.0, 0.0) * np.array([1.0, 0.9, 0.8])
    groups = np.arange(P) // 2  # pairs of neighbouring patches
    plain = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, tgt)],
                           cand, r["center"], r["normal"])
    grouped = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, tgt)],
                             cand, r["center"], r["normal"],
                             light_groups=groups)
    assert grouped.n_lights == len(np.unique(groups[cand])) < plain.n_lights
    for c in range(3):
        np.testing.assert_allclose(grouped.transfer[c], plain.transfer[c] @ grouped.light_basis.toarray(), atol=1e-14)
    res = solve_inverse(grouped, "reduced")
    e_full = grouped.patch_exitance(res.exitance)
    # every patch of a light has its light's exitance
    for g in np.unique(groups[cand]):
        members = np.flatnonzero(cand & (groups == g))
        np.testing.assert_allclose(e_full[members], e_full[members[:1]].repeat(len(members), axis=0))
    # the forward solve of that configuration meets the targets (floor reachable from the ceiling)
    B, _ = solve_radiosity(r["F"], r["reflectance"], e_full, method="direct")
    np.testing.assert_allclose(B[floor], tgt[floor], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(grouped.light_area, np.bincount(grouped.light_of, weights=r["area"][cand]))
    # the paper's formulation with grouped lights: the structured Gram route ('auto') is the
    # explicit SVD pseudo-inverse's solution
    np.testing.assert_allclose(solve_inverse(grouped, "svd").exitance,
                               solve_inverse(grouped, "svd", svd_driver="svd").exitance, rtol=1e-8, atol=1e-10)
    alone = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, tgt)],
                           cand, r["center"], r["normal"],
                           light_groups=np.arange(P))
    np.testing.assert_allclose(solve_inverse(alone, "reduced").exitance, solve_inverse(plain, "reduced").exitance)


def test_iterative_solves_match_the_factorisation(room, monkeypatch):
    """Large models never factorise A: the iterative sweeps on the sparse F give the same T,
    forward solution and e_x as the LU route (forced here on a small problem)."""
    import scipy.sparse as sp

    from relight_addon.engine import inverse

    r = room
    lu, _, B = feasible(r, seed=2)
    monkeypatch.setattr(inverse, "DIRECT_SOLVE_LIMIT", 10)
    it, _, _ = feasible(r, seed=2)
    sparse = make(r, lu.target_mask, B * lu.target_mask[:, None], lu.candidate_mask, F=sp.csr_matrix(r["F"]))
    for prob in (it, sparse):
        assert isinstance(prob.factors()[0], inverse._Iterative)
        for c in range(3):
            np.testing.assert_allclose(prob.transfer[c], lu.transfer[c], rtol=1e-8, atol=1e-12)
        e = np.zeros((prob.n_patches, 3))
        e[prob.candidates[:5]] = 20.0
        np.testing.assert_allclose(prob.forward_radiosity(e), lu.forward_radiosity(e), rtol=1e-8, atol=1e-10)
        np.testing.assert_allclose(solve_inverse(prob, "reduced").exitance, solve_inverse(lu, "reduced").exitance,
                                   rtol=1e-6, atol=1e-8)
