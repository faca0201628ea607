"""The best k-light configurations (engine.best_lights), checked against independent references.

- Exhaustive search written here from scratch (itertools over every subset, scipy's NNLS on T per
  channel): the optimum for k = 1, 2, 3 on small random and structured problems.
- Designed instances with a known optimum: greedy alone is suboptimal and one swap fixes it;
  duplicate lights of different areas (the least-power tie-break); feasible targets (error 0).
- The tolerance LP: its constraints re-checked with numpy; its power against other feasible
  configurations (the generating lights, and feasible points of LPs with random objectives).
- The staircase (sample_blends/staircase_targets.blend, built as `relight solve` builds it):
  relative error at 3 lights <= 0.125 (issue 8), certificate <= achieved.
"""
import itertools
import os
import sys

import numpy as np
import pytest
import scipy.optimize as sopt

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
from relight_addon.engine import best_lights as bl  # noqa: E402

# ---------------------------------------------------------------------------------------------
# problems and the independent reference
# ---------------------------------------------------------------------------------------------


def geo_problem(seed, m=14, n=22, noise=0.3, k_true=3):
    """Lights and targets on a unit square, T ~ falloff with distance, coloured channels; the
    targets are what 3 positive lights give, perturbed by +-noise (so usually not reachable)."""
    rng = np.random.default_rng(seed)
    L, P = rng.uniform(0, 1, (n, 2)), rng.uniform(0, 1, (m, 2))
    base = 0.05 / (((P[:, None] - L[None]) ** 2).sum(-1) + 0.05)
    T = [base * (1 + 0.2 * rng.uniform(-1, 1, (1, n))) for _ in range(3)]
    e = np.zeros((n, 3))
    e[rng.choice(n, k_true, replace=False)] = rng.uniform(1, 5, (k_true, 3))
    b = np.stack([T[c] @ e[:, c] for c in range(3)], axis=1) * (1 + noise * rng.uniform(-1, 1, (m, 3)))
    return T, b, rng.uniform(0.5, 2.0, n)


def rand_problem(seed, m=10, n=20):
    """Sparse-ish positive T shared by the channels, random targets."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 1, (m, n)) ** 3
    return [t, t, t], rng.uniform(0, 1, (m, 3)), np.ones(n)


PROBLEMS = [("geo", s) for s in range(8)] + [("rand", s) for s in range(8)]


def make(kind, seed):
    return geo_problem(seed) if kind == "geo" else rand_problem(seed)


def eq1(T, b, lights, e):
    """Eq. 1 of a configuration, straight from T (numpy)."""
    r = np.stack([T[c][:, lights] @ e[:, c] for c in range(3)], axis=1) - b
    return float(np.linalg.norm(r))


def brute_force(T, b, k):
    """min over every subset of exactly k lights of the per-channel NNLS error (itertools + scipy)."""
    n = T[0].shape[1]
    best = (np.inf, None)
    for S in itertools.combinations(range(n), k):
        S = list(S)
        err2 = sum(sopt.nnls(T[c][:, S], b[:, c])[1] ** 2 for c in range(3))
        if err2 < best[0]:
            best = (err2, S)
    return np.sqrt(best[0]), best[1]


_BRUTE = {}


def brute(kind, seed, k):
    key = (kind, seed, k)
    if key not in _BRUTE:
        T, b, _ = make(kind, seed)
        _BRUTE[key] = brute_force(T, b, k)
    return _BRUTE[key]


def check_curve(curve, T, b, area, k_max):
    """Shape, non-negativity, Eq. 1, power and monotonicity of a curve."""
    assert [p.k for p in curve] == list(range(1, k_max + 1))
    norm = np.linalg.norm(b)
    prev = np.inf
    for p in curve:
        assert p.n_lights == len(p.lights) <= p.k
        assert p.exitance.shape == (p.n_lights, 3)
        assert np.all(np.isfinite(p.exitance)) and np.all(p.exitance >= 0)
        assert len(set(p.lights.tolist())) == p.n_lights
        if p.n_lights:
            assert np.all(p.exitance.max(axis=1) > 0)  # every listed light is on
        assert p.error == pytest.approx(eq1(T, b, p.lights, p.exitance), rel=1e-9, abs=1e-12)
        assert p.relative_error == pytest.approx(p.error / norm if norm > 0 else p.error, rel=1e-12)
        assert p.power == pytest.approx(float((area[p.lights] * p.exitance.sum(1)).sum()), rel=1e-12, abs=1e-300)
        assert p.error <= prev + 1e-12 * max(norm, 1.0)
        prev = p.error


# ---------------------------------------------------------------------------------------------
# exhaustive search and the certificate
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind,seed", PROBLEMS)
def test_lower_bounds_exact_matches_brute_force(kind, seed):
    T, b, _ = make(kind, seed)
    lb = bl.lower_bounds(T, b, 3)
    assert lb.exact.all()
    for k in (1, 2, 3):
        opt, _ = brute(kind, seed, k)
        # the bound is the optimum minus the rounding margin, and that optimum is reached by its set
        assert lb.bound[k - 1] <= opt
        assert lb.bound[k - 1] == pytest.approx(opt, rel=1e-7, abs=1.01 * bl.BOUND_ROUNDING * np.linalg.norm(b))
        S = lb.optimum_lights[k - 1]
        assert len(S) <= k
        e = np.stack([sopt.nnls(T[c][:, S], b[:, c])[0] for c in range(3)], axis=1)
        assert eq1(T, b, S, e) == pytest.approx(opt, rel=1e-7, abs=1e-12)
    # all-lights NNLS: below every k's optimum
    assert lb.nnls <= lb.bound.min() * (1 + 1e-12)


@pytest.mark.parametrize("kind,seed", PROBLEMS)
def test_default_curve_is_optimal_on_small_problems(kind, seed):
    """Small enough to enumerate: the default search includes the exhaustive optimum."""
    T, b, area = make(kind, seed)
    curve = bl.best_k_curve(T, b, 5, area)
    check_curve(curve, T, b, area, 5)
    lb = bl.lower_bounds(T, b, 5)
    for k in (1, 2, 3):
        opt, _ = brute(kind, seed, k)
        assert curve[k - 1].error == pytest.approx(opt, rel=1e-7, abs=1e-12)
    for p in curve:  # the certificate never exceeds what was achieved
        assert lb.at(p.k) <= p.error


@pytest.mark.parametrize("score", bl.SCORES)
def test_heuristic_alone_against_exhaustive_search(score):
    """Greedy and greedy + swap without the exhaustive start, on the 16 problems (k = 1, 2, 3).

    Measured on these problems: k = 1 is always optimal (a closed form). Greedy alone is optimal
    in 31 % (k = 2) and 38 % / 13 % (k = 3, error- / correlation-scored) of the cases, up to
    48 % (k = 2) and 82 % / 112 % (k = 3) above the optimum. With the swap search: 69-75 %
    optimal, at most 9 % (k = 2) and 22 % (k = 3) above, 0.7-2.7 % above on average. Asserted
    with some room: >= 60 % optimal, <= 25 % above, <= 4 % on average, and never worse than greedy.
    """
    excess = {(s, k): [] for s in (False, True) for k in (1, 2, 3)}
    for kind, seed in PROBLEMS:
        T, b, area = make(kind, seed)
        for swap in (False, True):
            curve = bl.best_k_curve(T, b, 3, area, swap=swap, score=score, exhaustive_limit=0)
            check_curve(curve, T, b, area, 3)
            for k in (1, 2, 3):
                opt, _ = brute(kind, seed, k)
                assert curve[k - 1].error >= opt * (1 - 1e-9)  # never below the optimum
                excess[(swap, k)].append(curve[k - 1].error / opt - 1)
    ex = {key: np.array(v) for key, v in excess.items()}
    for swap in (False, True):
        assert ex[(swap, 1)].max() < 1e-9
    for k in (2, 3):
        opt_swap = np.mean(ex[(True, k)] < 1e-7)
        opt_greedy = np.mean(ex[(False, k)] < 1e-7)
        assert opt_swap >= 0.6, (k, opt_swap)
        assert ex[(True, k)].max() <= 0.25, (k, ex[(True, k)].max())
        assert ex[(True, k)].mean() <= 0.04, (k, ex[(True, k)].mean())
        assert np.all(ex[(True, k)] <= ex[(False, k)] + 1e-9)  # the swap starts from the greedy result
        assert opt_swap > opt_greedy  # and does improve on it here
        assert ex[(False, k)].max() > 0.4  # greedy alone is far off somewhere: the swap matters


@pytest.mark.parametrize("seed", range(6))
def test_screening_bounds_bracket_the_exact_fits(seed):
    """The search's screening (engine-internal): for every candidate addition and every swap, the
    lower bound is <= the exact NNLS error (scipy, per subset) <= the upper bound, and where the
    two bounds coincide (certified exact) they are that error. Channels differ or not, some target
    channels are 0 (lights switched off in one channel: the KKT branch)."""
    rng = np.random.default_rng(seed)
    m, n = 10, 18
    t = rng.uniform(0, 1, (m, n)) ** 3
    T = [t, t, t] if seed % 2 else [rng.uniform(0, 1, (m, n)) ** 3 for _ in range(3)]
    b = rng.uniform(0, 1, (m, 3))
    b[:, seed % 3] *= rng.uniform(0, 1, m) > 0.5
    model = bl._Model(T, b, None)
    tol = 1e-9 * model.bb.sum()

    def exact(S):
        return sum(sopt.nnls(T[c][:, list(S)], b[:, c])[1] ** 2 for c in range(3))

    n_cert = 0
    for k in (0, 2, 4, 6):
        lights, e, err2, _ = model.fit(rng.choice(n, k, replace=False))
        LB, UB, _ = model.add_bounds(lights, e, err2)
        for j in set(range(n)) - set(lights.tolist()):
            v = exact(list(lights) + [j])
            assert LB[j] <= v + tol and v <= UB[j] + tol, (k, j)
            n_cert += UB[j] == LB[j]
        if len(lights):
            I, J, LBs, UBs = model.swap_bounds(lights, e, err2)
            assert len(I) == len(lights) * (n - len(lights))
            for i, j, lo, hi in zip(I, J, LBs, UBs):
                v = exact(list(np.delete(lights, i)) + [j])
                assert lo <= v + tol and v <= hi + tol, (k, i, j)
                n_cert += hi == lo
    assert n_cert > 0  # the certificate is used


def adversarial(n_extra=12, seed=0):
    """b = t1 + t2 (error 0 with 2 lights), but a third light t3 ~ b is the best single light:
    greedy takes it first and then cannot reach 0; swapping t3 for the missing one does."""
    rng = np.random.default_rng(seed)
    t1 = np.array([1.0, 0.0, 0.0, 0.0])
    t2 = np.array([0.0, 1.0, 0.0, 0.0])
    t3 = np.array([1.0, 1.0, 0.8, 0.0])
    extra = rng.uniform(0, 0.05, (4, n_extra)) * np.array([0.2, 0.2, 1.0, 1.0])[:, None]  # distractors
    t = np.column_stack([t3, extra, t1, t2])  # indices: t3 = 0, t1 = n_extra + 1, t2 = n_extra + 2
    b = np.repeat((t1 + t2)[:, None], 3, axis=1) * np.array([1.0, 2.0, 3.0])
    return [t, t, t], b, np.ones(t.shape[1]), (n_extra + 1, n_extra + 2)


@pytest.mark.parametrize("score", bl.SCORES)
def test_swap_fixes_the_greedy_trap(score):
    T, b, area, pair = adversarial()
    greedy = bl.best_k_curve(T, b, 2, area, swap=False, score=score, exhaustive_limit=0)
    assert greedy[0].lights.tolist() == [0]  # the trap: t3 is the best single light
    assert greedy[1].relative_error > 0.1  # and greedy cannot recover
    swapped = bl.best_k_curve(T, b, 2, area, swap=True, score=score, exhaustive_limit=0)
    assert swapped[1].lights.tolist() == list(pair)
    assert swapped[1].error < 1e-9 * np.linalg.norm(b)
    # the exact exitances: b = (1, 2, 3) t1 + (1, 2, 3) t2 per channel
    assert np.allclose(swapped[1].exitance, [[1, 2, 3], [1, 2, 3]], rtol=1e-9)
    check_curve(swapped, T, b, area, 2)


def test_feasible_targets_are_met_exactly():
    """Targets made by 3 positive lights: 3 lights reach error 0 and the curve stays there."""
    T, _, area = geo_problem(3, noise=0.0)
    rng = np.random.default_rng(5)
    e = np.zeros((T[0].shape[1], 3))
    e[[2, 9, 17]] = rng.uniform(1, 4, (3, 3))
    b = np.stack([T[c] @ e[:, c] for c in range(3)], axis=1)
    curve = bl.best_k_curve(T, b, 6, area)
    check_curve(curve, T, b, area, 6)
    assert curve[2].relative_error < 1e-8
    assert sorted(curve[2].lights.tolist()) == [2, 9, 17]
    assert np.allclose(curve[2].exitance, e[[2, 9, 17]], rtol=1e-6)
    for p in curve[3:]:
        assert p.relative_error < 1e-8 and p.n_lights == 3  # no light added for nothing
    lb = bl.lower_bounds(T, b, 6)
    assert lb.relative[2] < 1e-8 and lb.exact[2]
    assert lb.relative[0] > 0.01  # one light is not enough, certified


def test_least_power_among_equal_errors():
    """Two lights with the same transfer column (the same effect per unit exitance) but areas 2 and
    1 m^2: the same error, half the power with the small one. It has the higher index, so the
    tie-break is what picks it (not the order)."""
    rng = np.random.default_rng(1)
    m, n = 6, 10
    t = rng.uniform(0, 0.1, (m, n))
    t[:, 7] = t[:, 2] = rng.uniform(0.5, 1.0, m)
    area = np.ones(n)
    area[2], area[7] = 2.0, 1.0
    e_true = np.array([3.0, 2.0, 1.0])
    b = np.outer(t[:, 2], e_true)
    for score in bl.SCORES:
        for swap in (False, True):
            for limit in (0, 20_000):
                curve = bl.best_k_curve([t, t, t], b, 2, area, swap=swap, score=score, exhaustive_limit=limit)
                p = curve[0]
                assert p.lights.tolist() == [7], (score, swap, limit)
                assert p.error < 1e-9 * np.linalg.norm(b)
                assert p.power == pytest.approx(1.0 * e_true.sum(), rel=1e-9)
                assert curve[1].n_lights == 1  # a second light adds nothing
    assert bl.total_power(np.array([e_true]), area, [2]) == pytest.approx(2 * e_true.sum())


def test_curve_properties_and_bounds_on_random_problems():
    for seed in range(6):
        T, b, area = geo_problem(100 + seed, m=20, n=60, noise=0.5)
        lb = bl.lower_bounds(T, b, 12, exhaustive_limit=1000)  # k = 1 exact only (60 + C(60, 2) > 1000)
        assert lb.exact[0] and not lb.exact[1]
        for score in bl.SCORES + ("both",):
            curve = bl.best_k_curve(T, b, 12, area, score=score)
            check_curve(curve, T, b, area, 12)
            for p in curve:
                assert lb.at(p.k) <= p.error
            assert curve[0].error == pytest.approx((lb.bound[0] + bl.BOUND_ROUNDING * np.linalg.norm(b)) / (1 - bl.BOUND_MARGIN), rel=1e-9)
        greedy = bl.best_k_curve(T, b, 12, area, swap=False)
        check_curve(greedy, T, b, area, 12)
        swapped = bl.best_k_curve(T, b, 12, area)
        for g, s in zip(greedy, swapped):
            assert s.error <= g.error * (1 + 1e-12)


def test_determinism_and_seed():
    T, b, area = geo_problem(7, m=12, n=40)
    kw = dict(restarts=2, exhaustive_limit=0)
    a = bl.best_k_curve(T, b, 5, area, seed=3, **kw)
    c = bl.best_k_curve(T, b, 5, area, seed=3, **kw)
    for p, q in zip(a, c):
        assert p.lights.tolist() == q.lights.tolist() and np.array_equal(p.exitance, q.exitance)
    # without restarts the seed is not used
    d0 = bl.best_k_curve(T, b, 5, area, seed=0)
    d1 = bl.best_k_curve(T, b, 5, area, seed=12345)
    assert [p.lights.tolist() for p in d0] == [p.lights.tolist() for p in d1]


def test_cancel_progress_and_arguments():
    T, b, area = geo_problem(2)
    seen = []
    curve = bl.best_k_curve(T, b, 6, area, progress=lambda d, t: seen.append((d, t)), cancel=lambda: len(seen) >= 3)
    assert len(curve) == 3 and seen == [(1, 6), (2, 6), (3, 6)]
    assert len(bl.best_k_curve(T, b, 100, area, exhaustive_limit=0)) == T[0].shape[1]  # k_max capped at n
    with pytest.raises(ValueError, match="score"):
        bl.best_k_curve(T, b, 3, area, score="magic")
    with pytest.raises(ValueError, match="k_max"):
        bl.best_k_curve(T, b, 0, area)
    with pytest.raises(ValueError, match="light areas"):
        bl.best_k_curve(T, b, 3, -area)
    with pytest.raises(ValueError, match="shape"):
        bl.best_k_curve(T, b[:-1], 3, area)


def test_zero_targets_need_no_light():
    T, b, area = geo_problem(4)
    curve = bl.best_k_curve(T, np.zeros_like(b), 3, area)
    assert all(p.n_lights == 0 and p.error == 0 and p.source == "none" for p in curve)
    lb = bl.lower_bounds(T, np.zeros_like(b), 3)
    assert np.all(lb.bound == 0)


def test_curve_notes():
    T, b, area, _ = adversarial()
    curve = bl.best_k_curve(T, b, 2, area)
    lb = bl.lower_bounds(T, b, 2)
    notes = bl.curve_notes(curve, lb, np.linalg.norm(b))
    assert notes == ["2 light(s) meet the targets (relative error 0)"] or "meet the targets" in notes[-1]
    T, b, area = rand_problem(3)
    curve = bl.best_k_curve(T, b, 2, area)
    notes = bl.curve_notes(curve, bl.lower_bounds(T, b, 2), np.linalg.norm(b))
    assert notes[-1].startswith("2 light(s): optimal (exhaustive search), relative error")
    # targets no positive lights can give: a bright target and a dark one seen the same way
    t = np.array([[1.0, 0.9], [0.9, 1.0]])
    bb = np.array([[10.0] * 3, [0.0] * 3])
    curve = bl.best_k_curve([t, t, t], bb, 2)
    notes = bl.curve_notes(curve, bl.lower_bounds([t, t, t], bb, 2), np.linalg.norm(bb))
    assert any("no non-negative lights meet these targets" in n for n in notes)


# ---------------------------------------------------------------------------------------------
# tolerance mode (LP)
# ---------------------------------------------------------------------------------------------
def band_ok(T, b, e, tol, zero_band, slack=1e-6):
    s = np.where(b > 0, b, zero_band)
    dev = np.abs(np.stack([T[c] @ e[:, c] for c in range(3)], axis=1) - b)
    return bool(np.all(dev <= tol * s * (1 + slack) + 1e-9))


def feasible_points(T, b, tol, zero_band, n_points, seed):
    """Feasible configurations from LPs with random positive objectives (independent of the
    least-power objective)."""
    rng = np.random.default_rng(seed)
    s = np.where(b > 0, b, zero_band)
    n = T[0].shape[1]
    pts = []
    for _ in range(n_points):
        e = np.zeros((n, 3))
        for c in range(3):
            A = np.vstack([T[c], -T[c]])
            ub = np.concatenate([b[:, c] + tol * s[:, c], -(b[:, c] - tol * s[:, c])])
            res = sopt.linprog(rng.uniform(0.1, 10, n), A_ub=A, b_ub=ub, bounds=(0, None), method="highs-ds")
            assert res.status == 0
            e[:, c] = np.maximum(res.x, 0)
        pts.append(e)
    return pts


@pytest.mark.parametrize("seed", range(4))
def test_tolerance_mode_least_power(seed):
    T, _, area = geo_problem(seed, m=12, n=30)
    rng = np.random.default_rng(seed)
    e_true = np.zeros((30, 3))
    e_true[rng.choice(30, 4, replace=False)] = rng.uniform(1, 5, (4, 3))
    b = np.stack([T[c] @ e_true[:, c] for c in range(3)], axis=1)  # feasible for every tolerance
    for tol in (0.0, 0.05, 0.2):
        r = bl.least_power_within_tolerance(T, b, area, tol)
        assert r.status == "ok", r.message
        assert np.all(r.exitance >= 0) and np.all(np.isfinite(r.exitance))
        assert band_ok(T, b, r.exitance, tol, r.zero_band)
        assert r.max_deviation <= tol * (1 + 1e-6) + 1e-9
        assert r.power == pytest.approx(float((area * r.exitance.sum(1)).sum()), rel=1e-12)
        assert r.n_lights == len(r.lights) == int((r.exitance.max(1) > 0).sum())
        assert r.error == pytest.approx(eq1(T, b, np.arange(30), r.exitance), rel=1e-9, abs=1e-12)
        # no feasible configuration we can construct has less power
        others = [e_true] + feasible_points(T, b, tol, r.zero_band, 5, seed)
        for e in others:
            assert band_ok(T, b, e, tol, r.zero_band)
            assert r.power <= bl.total_power(e, area) * (1 + 1e-7)
        # the NNLS solution, when it happens to be inside the band
        e_n = np.stack([sopt.nnls(T[c], b[:, c])[0] for c in range(3)], axis=1)
        if band_ok(T, b, e_n, tol, r.zero_band):
            assert r.power <= bl.total_power(e_n, area) * (1 + 1e-7)
        assert "every target within" in r.message
    # a wider band never costs more
    p = [bl.least_power_within_tolerance(T, b, area, x).power for x in (0.0, 0.1, 0.3)]
    assert p[0] >= p[1] * (1 - 1e-9) >= p[2] * (1 - 1e-9)


def test_tolerance_mode_infeasible_says_what_is_reachable():
    """A bright target beside a dark one that the lights see the same way: no band below the
    min-max deviation is feasible; the result names it and returns the closest configuration."""
    t = np.array([[1.0, 0.8, 0.2], [0.95, 0.85, 0.25], [0.3, 0.4, 1.0]])
    b = np.array([[10.0] * 3, [1.0] * 3, [5.0] * 3])
    area = np.array([1.0, 2.0, 0.5])
    T = [t, t, t]
    r = bl.least_power_within_tolerance(T, b, area, 0.05)
    assert r.status == "infeasible"
    x = r.reachable_tolerance
    assert x > 0.05
    assert r.message.startswith("no non-negative lights keep every target within \u00b15 %; the closest is \u00b1")
    assert f"{100 * x:.3g} %" in r.message
    assert np.all(r.exitance >= 0) and r.max_deviation <= x * (1 + 1e-5) + 1e-9
    # x is the frontier: feasible just above, infeasible below
    assert bl.least_power_within_tolerance(T, b, area, x * (1 + 1e-5)).status == "ok"
    assert bl.least_power_within_tolerance(T, b, area, x * 0.99).status == "infeasible"
    # independent check of x on one channel: the LP's min-max deviation vs a fine scan of e >= 0
    g = np.linspace(0, 12, 121)
    E = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    best = (np.abs(E @ t.T - b[:, 0]) / b[:, 0]).max(axis=1).min()
    assert x <= best + 1e-9 and best - x < 0.02


def test_tolerance_mode_black_targets_use_the_absolute_band():
    """b = 0 on a target channel: |T e| <= tolerance * zero_band there (documented default: the
    mean of the positive targets); a light that reaches it is allowed that much."""
    t = np.array([[1.0, 0.0], [0.2, 0.0], [0.0, 1.0]])
    b = np.array([[10.0, 10.0, 10.0], [0.0, 0.0, 0.0], [4.0, 4.0, 4.0]])
    T = [t, t, t]
    r = bl.least_power_within_tolerance(T, b, np.ones(2), 0.1)
    assert r.zero_band == pytest.approx(7.0)  # mean of 10 and 4
    # light 0 must give target 0 at least 9, i.e. target 1 at least 1.8 > 0.1 * 7: infeasible
    assert r.status == "infeasible"
    r2 = bl.least_power_within_tolerance(T, b, np.ones(2), 0.1, zero_band=20.0)  # band 2 W/m^2
    assert r2.status == "ok" and band_ok(T, b, r2.exitance, 0.1, 20.0)
    assert r2.exitance[0, 0] == pytest.approx(9.0, rel=1e-6)  # least power: the band's lower edge
    z = bl.least_power_within_tolerance(T, np.zeros_like(b), np.ones(2), 0.1)
    assert z.status == "ok" and z.power == 0 and z.n_lights == 0


# ---------------------------------------------------------------------------------------------
# the staircase (issue 8's numbers)
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def staircase():
    """(T, b, light areas) of the shipped staircase, built as `relight solve` builds it."""
    pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
    sys.path.insert(0, os.path.join(ROOT, "benchmarks"))
    from bench_best_lights import staircase_problem

    prob = staircase_problem()
    return prob.transfer, prob.b_target, prob.light_area


def test_staircase_quality(staircase):
    T, b, area = staircase
    assert T[0].shape == (44, 693)
    curve, lb = bl.best_k_with_certificate(T, b, 32, area)  # as the greedy-swap selection runs it
    check_curve(curve, T, b, area, 32)
    assert curve[2].relative_error <= 0.125  # issue 8: <= 0.125 at 3 lights (paper default 0.581)
    assert curve[0].n_lights == 1 and curve[2].n_lights == 3
    assert lb.exact[0] and lb.exact[1] and not lb.exact[2]  # C(693, 2) subsets: exact up to 2 lights
    for p in curve:
        assert lb.at(p.k) <= p.error
    assert curve[0].error == pytest.approx((lb.bound[0] + bl.BOUND_ROUNDING * np.linalg.norm(b)) / (1 - bl.BOUND_MARGIN), rel=1e-9)  # k = 1 optimal
    # optimal at 2 lights (seeded with the certificate's optimum), near the NNLS floor at 32
    assert curve[1].error == pytest.approx((lb.bound[1] + bl.BOUND_ROUNDING * np.linalg.norm(b)) / (1 - bl.BOUND_MARGIN), rel=1e-9)
    assert curve[31].error <= 1.05 * lb.nnls
    # the plain greedy path (error-scored) comes close at 3 lights (0.126 with the reciprocity-weighted
    # form factors, 0.12 before), the swaps bring it under the target; correlation-scored is worse
    g = bl.best_k_curve(T, b, 3, area, swap=False)
    assert curve[2].relative_error <= g[2].relative_error <= 0.13
    gc = bl.best_k_curve(T, b, 3, area, swap=False, score="correlation")
    assert gc[2].relative_error >= g[2].relative_error


def test_the_gram_matrix_is_shared_by_content_and_follows_changes_in_place():
    """best_lights.gram / column_subset: one Gram matrix per transfer array's content (the
    certificate, the curve and the surface lights' curve share it); an array changed in place, as
    InverseProblem.correct_direct changes T, gets its own."""
    from relight_addon.engine import best_lights

    rng = np.random.default_rng(5)
    t = rng.random((30, 12))
    G = best_lights.gram(t)
    assert best_lights.gram(t) is G and np.allclose(G, t.T @ t)
    cols = np.array([0, 3, 4, 9])
    sub = best_lights.column_subset([t, t, t], cols)
    assert sub[0] is sub[1] is sub[2] and np.allclose(best_lights.gram(sub[0]), t[:, cols].T @ t[:, cols])
    t[:, 2] += 1.0  # in place
    assert np.allclose(best_lights.gram(t), t.T @ t)


@pytest.mark.parametrize("kind,seed", PROBLEMS[::3])
def test_the_certificate_started_from_another_nnls_reaches_the_same_optimum(kind, seed):
    """A Live stroke's certificate starts its all-lights NNLS from an earlier problem's active
    lights (the last solve's or stroke's): the bound is the cold NNLS's (scipy on every column),
    whatever the start: none, the optimum itself, another problem's, or every light."""
    T, b, _ = make(kind, seed)
    n = T[0].shape[1]
    cold = np.sqrt(sum(sopt.nnls(T[c], b[:, c])[1] ** 2 for c in range(3)))
    other = bl.lower_bounds(T, b * np.random.default_rng(seed).uniform(0.2, 2.0, b.shape), 2).nnls_exitance
    optimum = bl.lower_bounds(T, b, 2).nnls_exitance
    for start in (None, np.zeros((n, 3)), optimum, other, np.ones((n, 3))):
        got = bl.lower_bounds(T, b, 2, nnls_start=start)
        assert got.nnls == pytest.approx(cold * (1 - bl.BOUND_MARGIN), rel=1e-9, abs=1e-12)
        r = np.stack([T[c] @ got.nnls_exitance[:, c] for c in range(3)], axis=1) - b
        assert np.all(got.nnls_exitance >= 0) and np.linalg.norm(r) == pytest.approx(cold, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_a_tall_fit_on_the_gram_factor_is_scipys_nnls(seed):
    """_Model.fit takes a fit of k lights on m rows, m >= GRAM_FIT_ROWS k and m k >= GRAM_FIT_SIZE (a
    camera-view target's 941 rows), on the Cholesky factor of the lights' Gram matrix: the same
    optimum as scipy's NNLS on the columns themselves (checked on sets where some lights go to 0),
    and the fit's error the same to 1e-10 (from the Gram matrix: ||b||^2 - 2 h.x + x.G x; from T
    when that would cancel: targets met to 1e-8 get their error from the rows, not rounding's
    1e-14 ||b||^2); smaller fits are scipy's on T. Nearly dependent columns (a light twice, up to
    1e-9) fall back to scipy on T."""
    rng = np.random.default_rng(seed)
    m, n = 1024, 24
    t = rng.uniform(0, 1, (m, n)) ** 2
    b = rng.uniform(0, 1, (m, 3)) - 0.3
    model = bl._Model([t, t, t], b, np.ones(n))
    routed = []
    real_normal = bl._nnls_normal
    bl._nnls_normal = lambda *a: routed.append(len(a[1])) or real_normal(*a)
    zeros = 0
    try:
        sets = [tuple(sorted(rng.choice(n, size, replace=False))) for size in (3, 5, 8, 12, 16, 20) for _ in range(4)]
        for S in sets:
            lights, e, err2, _ = model.fit(S)
            for c in range(3):
                x, res = sopt.nnls(t[:, list(S)], b[:, c])
                got = np.zeros(len(S))
                got[np.searchsorted(S, lights)] = e[:, c]
                np.testing.assert_allclose(got, x, rtol=1e-9, atol=1e-12)
                assert err2[c] == pytest.approx(res ** 2, rel=1e-10)
                zeros += int(np.sum(x == 0))
    finally:
        bl._nnls_normal = real_normal
    assert zeros > 0  # (the bounds were active somewhere)
    # targets that 12 of the lights meet exactly: the error is the rows' (~1e-30 ||b||^2), not the
    # Gram sum's cancellation (~1e-14 ||b||^2)
    S = tuple(range(12))
    met = np.stack([t[:, list(S)] @ rng.uniform(0.5, 1.5, 12) for _ in range(3)], axis=1)
    _, _, err2, _ = bl._Model([t, t, t], met, np.ones(n)).fit(S)
    assert np.all(err2 <= 1e-20 * (met * met).sum(axis=0))
    assert sorted(set(routed)) == [8, 12, 16, 20]  # (m k >= 8192: 8 lights and more on 1,024 rows)
    assert len(routed) == 3 * len({S for S in sets if len(S) * m >= bl.GRAM_FIT_SIZE})
    # a light twice (to 1e-9): the Gram factor's pivot is ~1e-18 of the diagonal, scipy on T instead
    A = np.column_stack([t[:, :3], t[:, 0] * (1 + 1e-9)])
    y = b[:, 0] + 0.5
    calls = []
    real = bl._nnls
    try:
        bl._nnls = lambda M, v: calls.append(M.shape) or real(M, v)
        x = bl._nnls_normal(A.T @ A, A.T @ y, lambda: A, y)
    finally:
        bl._nnls = real
    assert calls == [A.shape]
    np.testing.assert_allclose(A @ x, A @ sopt.nnls(A, y)[0], rtol=1e-8, atol=1e-10)


def test_the_all_lights_nnls_is_computed_once_per_problem():
    """The light colour's choice, the certificate and the report each ask lower_bounds for the
    all-lights NNLS of one problem (a view target's: 0.28 s each): computed once per content; the
    same targets changed, computed anew."""
    T, b, _ = geo_problem(11, m=40, n=30)
    calls = []
    real = bl._nnls
    try:
        bl._nnls = lambda M, v: calls.append(M.shape) or real(M, v)
        first = bl.lower_bounds(T, b, 1, exhaustive_limit=0)
        n_first = len(calls)
        again = bl.lower_bounds([t.copy() for t in T], b.copy(), 1, exhaustive_limit=0)
        assert len(calls) == n_first == 3  # one per channel, the first time only
        assert again.nnls == first.nnls and np.array_equal(again.nnls_exitance, first.nnls_exitance)
        again.nnls_exitance[:] = -1.0  # (a copy: the kept answer is not changed by its user)
        b2 = b.copy()
        b2[0, 0] += 0.5
        other = bl.lower_bounds(T, b2, 1, exhaustive_limit=0)
        assert len(calls) == n_first + 3
        cold = np.sqrt(sum(sopt.nnls(T[c], b2[:, c])[1] ** 2 for c in range(3)))
        assert other.nnls == pytest.approx(cold * (1 - bl.BOUND_MARGIN), rel=1e-9)
        assert np.all(bl.lower_bounds(T, b, 1, exhaustive_limit=0).nnls_exitance >= 0)
    finally:
        bl._nnls = real


def test_a_strokes_warm_all_lights_nnls_serves_the_later_cold_ask():
    """A Live stroke's quick answer takes the all-lights NNLS from the earlier answer's lights
    (``nnls_start``), its later answer's full search asks it cold of the same problem: computed
    once, the optimum of a cold NNLS (scipy's on every light)."""
    T, b, _ = geo_problem(23, m=40, n=30)
    start = bl.lower_bounds(T, b * 1.3, 1, exhaustive_limit=0).nnls_exitance  # (an earlier paint's optimum)
    warm_calls, cold_calls = [], []
    real_from, real = bl._nnls_from, bl._nnls
    try:
        bl._nnls_from = lambda *a: warm_calls.append(1) or real_from(*a)
        bl._nnls = lambda M, v: cold_calls.append(1) or real(M, v)
        warm = bl.lower_bounds(T, b, 1, exhaustive_limit=0, nnls_start=start)
        assert len(warm_calls) == 3
        del cold_calls[:]  # (the working sets' fits)
        cold = bl.lower_bounds(T, b, 1, exhaustive_limit=0)
    finally:
        bl._nnls_from, bl._nnls = real_from, real
    assert len(warm_calls) == 3 and not cold_calls  # (the cold ask took the warm answer)
    assert cold.nnls == warm.nnls and np.array_equal(cold.nnls_exitance, warm.nnls_exitance)
    scipy_cold = np.sqrt(sum(sopt.nnls(T[c], b[:, c])[1] ** 2 for c in range(3)))
    assert cold.nnls == pytest.approx(scipy_cold * (1 - bl.BOUND_MARGIN), rel=1e-9)


def test_a_large_cold_all_lights_nnls_is_the_working_sets_with_scipys_optimum():
    """A problem with WORKING_SET_SIZE entries per channel or more (a view target's 941 rows) and no
    earlier answer: the every-light NNLS grown from no light (_nnls_from), its error and lights
    those of scipy's NNLS over every light; below the size, scipy's over every light."""
    rng = np.random.default_rng(5)
    m, n = 700, 400  # (280,000 entries: above 2^18)
    assert m * n >= bl.WORKING_SET_SIZE
    t = rng.uniform(0, 1, (m, n)) ** 3
    b = t[:, :3] @ rng.uniform(0.5, 1.5, (3, 3)) + 0.3 * rng.uniform(-1, 1, (m, 3))
    calls = []
    real_from = bl._nnls_from
    try:
        bl._nnls_from = lambda *a: calls.append(1) or real_from(*a)
        got = bl.lower_bounds([t, t, t], b, 1, exhaustive_limit=0)
        assert len(calls) == 3
        small = bl.lower_bounds([t[:300, :200]] * 3, b[:300], 1, exhaustive_limit=0)
        assert len(calls) == 3  # (60,000 entries: scipy's)
    finally:
        bl._nnls_from = real_from
    for c in range(3):
        x, res = sopt.nnls(t, b[:, c])
        assert np.linalg.norm(t @ got.nnls_exitance[:, c] - b[:, c]) == pytest.approx(res, rel=1e-10)
        assert np.array_equal(got.nnls_exitance[:, c] > 0, x > 0)
        assert 0 < np.count_nonzero(x) < n  # (some lights on, some off)
    scipy_cold = np.sqrt(sum(sopt.nnls(t, b[:, c])[1] ** 2 for c in range(3)))
    assert got.nnls == pytest.approx(scipy_cold * (1 - bl.BOUND_MARGIN), rel=1e-10)
    assert small.nnls > 0


def test_a_halt_stops_the_all_lights_nnls_between_channels():
    """A newer stroke's halt heard before each channel's all-lights NNLS (30-90 ms each on the
    living room, holding the interpreter): Cancelled, nothing kept, the next ask computes it whole."""
    from relight_addon.engine.sampling import Cancelled

    T, b, _ = geo_problem(29, m=40, n=30)
    calls = []
    real = bl._nnls
    try:
        bl._nnls = lambda M, v: calls.append(1) or real(M, v)
        with pytest.raises(Cancelled):
            bl.lower_bounds(T, b, 1, exhaustive_limit=0, halt=lambda: len(calls) >= 1)
        assert len(calls) == 1  # (the first channel's, then the halt)
        whole = bl.lower_bounds(T, b, 1, exhaustive_limit=0, halt=lambda: False)
        assert len(calls) == 4
    finally:
        bl._nnls = real
    scipy_cold = np.sqrt(sum(sopt.nnls(T[c], b[:, c])[1] ** 2 for c in range(3)))
    assert whole.nnls == pytest.approx(scipy_cold * (1 - bl.BOUND_MARGIN), rel=1e-9)


def test_a_halt_stops_the_curve_within_a_swap_search():
    """A newer stroke's halt heard before each greedy addition and each swap round of the curve
    (not only after a whole k: 55 ms of a later answer's search on the living room): Cancelled at
    the first round after it says so; never saying so, the curve is the one found without it."""
    from relight_addon.engine.sampling import Cancelled

    T, b, w = geo_problem(31, m=40, n=30)
    rounds = []
    real = bl._swap_search
    try:
        bl._swap_search = lambda *a, **k: rounds.append(1) or real(*a, **k)
        heard = []
        free = bl.best_k_curve(T, b, 4, w, halt=lambda: heard.append(1) and False)
        n_rounds = len(rounds)
        assert len(heard) > 4 + n_rounds  # (the additions' and the rounds': more often than once a k)
        with pytest.raises(Cancelled):
            bl.best_k_curve(T, b, 4, w, halt=lambda: len(rounds) > n_rounds + 1)
        assert len(rounds) == n_rounds + 2  # (stopped in the second swap search it started)
    finally:
        bl._swap_search = real
    plain = bl.best_k_curve(T, b, 4, w)
    assert [tuple(p.lights) for p in free] == [tuple(p.lights) for p in plain]
    np.testing.assert_array_equal(np.array([p.error for p in free]), np.array([p.error for p in plain]))


@pytest.mark.parametrize("kind,seed", [("geo", 3), ("geo", 5), ("rand", 2)])
def test_gram_rows_are_the_gram_matrix_computed_as_read(kind, seed):
    """A stroke's quick search reads its Gram matrices' rows as it needs them (GramRows): each
    index form gives T^T T's entries, only the rows read are computed, and the curve and the
    certificate are those of the whole products (the same lights; errors to rounding)."""
    T, b, w = (geo_problem(seed, m=12, n=40) if kind == "geo" else rand_problem(seed, m=12, n=40))
    t = np.ascontiguousarray(T[0])
    full = np.dot(t.T, t)
    G = bl.GramRows(t)
    np.testing.assert_allclose(G[np.array([3, 7, 3])], full[[3, 7, 3]], rtol=1e-13, atol=0)
    assert np.flatnonzero(G._have).tolist() == [3, 7]
    A = np.array([1, 4, 7])
    np.testing.assert_allclose(G[np.ix_(A, A)], full[np.ix_(A, A)], rtol=1e-13, atol=0)
    C = np.array([[0, 9], [2, 5]])
    np.testing.assert_allclose(G[C[:, 0], C[:, 1]], full[C[:, 0], C[:, 1]], rtol=1e-13, atol=0)
    np.testing.assert_allclose(G[C[:, :, None], C[:, None, :]], full[C[:, :, None], C[:, None, :]], rtol=1e-13)
    assert np.flatnonzero(G._have).tolist() == [0, 1, 2, 3, 4, 5, 7, 9]
    np.testing.assert_allclose(G.diagonal(), np.diag(full), rtol=1e-13)
    bl._GRAMS.clear()
    bl._ALL_LIGHTS.clear()
    lazy, lb_lazy = bl.best_k_with_certificate(T, b, 5, w, lazy_gram=True, swap_all=False, max_swap_rounds=2)
    assert not bl._GRAMS  # (no whole product was made)
    whole, lb_whole = bl.best_k_with_certificate(T, b, 5, w, swap_all=False, max_swap_rounds=2)
    assert [tuple(p.lights) for p in lazy] == [tuple(p.lights) for p in whole]
    np.testing.assert_allclose([p.error for p in lazy], [p.error for p in whole], rtol=1e-12)
    np.testing.assert_allclose(lb_lazy.bound, lb_whole.bound, rtol=1e-12)
