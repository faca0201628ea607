"""Catalogue fixtures dimmed between 0 and 100 % of their rated flux (issue 39, open point 1): a light's
``LightKind.strength_upper`` bounds its strength in every selection, fit and programme
(engine.best_lights: bounded least squares, BVLS; engine.light_colour: the colour views' power bound).

The references are independent of the selection: every subset of a small problem fitted by scipy's
``lsq_linear`` within the bounds (exhaustive search), the programme's bounds read from its answer, and the
fixture's rated lumens at its bound (683 lm/W, Rec.709 luminance).
"""
import itertools
import math

import numpy as np
import pytest
import scipy.optimize as sopt

from relight_addon.engine.best_lights import (best_k_curve, best_k_with_certificate, least_power_within_tolerance,
                                              lower_bounds)
from relight_addon.engine.light_colour import blackbody_rec709, fit_colours, fit_per_channel, power_upper
from relight_addon.engine.lights.fixture import FIXTURE, dimming, fixture_lamp
from relight_addon.engine.photometry import library as lib
from relight_addon.engine.units import LUMENS_PER_WATT, luminance_weighted


def _problem(seed, m=10, n=7):
    """A small transfer T (m, n) >= 0 (three channels alike but scaled), targets b that need a few
    lights at strengths above 1, and bounds of 1 on those and on about a third of the others (a fixture at 100 %)."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 1.0, (m, n)) * (rng.uniform(size=(m, n)) < 0.6)
    T = [t, 0.9 * t, 0.8 * t]
    x = np.zeros(n)
    lit = rng.choice(n, 3, replace=False)
    x[lit] = rng.uniform(1.5, 3.0, 3)
    b = np.stack([T[c] @ x for c in range(3)], axis=1) + rng.uniform(0.0, 0.05, (m, 3))
    upper = np.where(rng.uniform(size=n) < 0.3, 1.0, np.inf)
    upper[lit] = 1.0
    return T, b, upper


def _exhaustive(T, b, upper, k_max):
    """[k = 1 .. k_max] the best squared error with at most k lights within [0, upper], every subset fitted
    by scipy's lsq_linear (its own trust-region method, not the selection's BVLS)."""
    n = T[0].shape[1]
    best = [float((b * b).sum())]
    for s in range(1, k_max + 1):
        errs = []
        for S in itertools.combinations(range(n), s):
            S = list(S)
            errs.append(sum(2.0 * sopt.lsq_linear(T[c][:, S], b[:, c], bounds=(np.zeros(s), upper[S]), method="trf",
                                                  tol=1e-13, max_iter=5000).cost for c in range(3)))
        best.append(min(best[-1], min(errs)))
    return best[1:]


@pytest.mark.parametrize("seed", range(4))
def test_the_bounded_curve_is_the_exhaustive_optimum_and_the_certificate_bounds_it(seed):
    T, b, upper = _problem(seed)
    k_max = 4
    curve, bounds = best_k_with_certificate(T, b, k_max, upper=upper)
    free = best_k_curve(T, b, k_max)
    over = False
    opts = _exhaustive(T, b, upper, k_max)
    for pt in curve:
        opt = math.sqrt(opts[pt.k - 1])
        # the selection finds the optimum within the bounds, and no light exceeds its bound
        assert pt.error == pytest.approx(opt, rel=1e-6, abs=1e-9), (pt.k, pt.error, opt)
        assert np.all(pt.exitance <= upper[pt.lights][:, None] * (1 + 1e-12))
        assert np.all(pt.exitance >= 0)
        # the certificate is a lower bound on it (the unbounded relaxation's, or the all-lights bounded fit)
        assert bounds.at(pt.k) <= opt * (1 + 1e-9) + 1e-12
        over |= bool(np.any(free[pt.k - 1].exitance > upper[free[pt.k - 1].lights][:, None] * 1.01))
    # the bounds matter: without them some configuration puts a bounded light above its bound (measured:
    # every seed here)
    assert over


def test_the_certificate_with_bounds_is_the_bounded_all_lights_fit_where_it_is_larger():
    """All lights within their bounds bound every k (each k-configuration is one of them): a larger
    bound than the unbounded NNLS of every light, and never above any k's exhaustive optimum."""
    T, b, upper = _problem(3)
    loose = lower_bounds(T, b, 3)
    tight = lower_bounds(T, b, 3, upper=upper)
    assert tight.nnls >= loose.nnls * (1 - 1e-9)
    assert not any(tight.exact[:3]) or T[0].shape[1] <= 3  # the enumeration's optima are a relaxation now
    for k, opt in enumerate(_exhaustive(T, b, upper, 3), start=1):
        assert tight.at(k) <= math.sqrt(opt) * (1 + 1e-9)


def test_without_bounds_nothing_changes():
    """Bounds of inf (no light bounded) give the very curve of no bounds (the existing scenes' results)."""
    T, b, _ = _problem(4)
    a = best_k_curve(T, b, 4)
    c = best_k_curve(T, b, 4, upper=np.full(T[0].shape[1], np.inf))
    for p, q in zip(a, c):
        assert p.error == q.error and np.array_equal(p.lights, q.lights) and np.array_equal(p.exitance, q.exitance)


def test_least_power_keeps_the_bounds_and_says_what_is_reachable():
    T, b, upper = _problem(5)
    res = least_power_within_tolerance(T, b, np.ones(T[0].shape[1]), 0.1, upper=upper)
    assert np.all(res.exitance <= upper[:, None] * (1 + 1e-9) + 1e-12)
    free = least_power_within_tolerance(T, b, np.ones(T[0].shape[1]), 0.1)
    if res.status == "ok":
        assert res.max_deviation <= 0.1 + 1e-6
    else:  # the band is out of reach within the bounds: the reachable tolerance is at least the free one's
        assert res.reachable_tolerance >= (free.reachable_tolerance or 0.0) - 1e-9


def test_the_colour_fits_bound_the_luminance():
    """A blackbody light's power p (strength p chi) is bounded by upper / luminance(chi): its luminance
    at most the bound; free colours are bounded per channel."""
    rng = np.random.default_rng(7)
    cols = [rng.uniform(0, 1, (9, 3)) for _ in range(3)]
    b = np.full((9, 3), 40.0)
    chi = blackbody_rec709(np.array([2700.0, 4000.0, 6500.0]))
    upper = np.array([1.0, 2.0, np.inf])
    e, _, _ = fit_colours(cols, b, chi, upper=upper)
    assert np.all(luminance_weighted(e)[:2] <= upper[:2] * (1 + 1e-9))
    assert luminance_weighted(e)[0] == pytest.approx(1.0)  # (40 W/m^2 asks far more: at its bound)
    np.testing.assert_allclose(power_upper(upper, chi)[:2], upper[:2] / luminance_weighted(chi[:2]))
    x, _ = fit_per_channel(cols, b, upper)
    assert np.all(x[:2] <= upper[:2, None] * (1 + 1e-12)) and x[2].max() > 2.0


def test_a_fixtures_bound_is_its_rated_lumens():
    """FixtureKind.strength_upper: white at the bound gives exactly the rated lumens (dimming 100 %)."""
    for f in lib.load_library(lib.BUILTIN):
        lamp = fixture_lamp("f", f, np.zeros(3), np.array([0.0, 0.0, -1.0]))
        u = FIXTURE.strength_upper(lamp)
        assert LUMENS_PER_WATT * u == pytest.approx(f.lumens)
        assert dimming(np.full(3, u), f.lumens) == pytest.approx(1.0)
