"""Light colour modes (issue 21; engine.light_colour, engine/colours/), checked against independent
references:

- Blender's own blackbody colour (a Light's ``temperature_color``, bpy) for the conversion;
- exhaustive search written here (every subset, scipy's NNLS on the channels stacked by hand) for
  white lights, and every (light, temperature of the grid) for one blackbody light;
- the certificate of the constrained problem: below every configuration the searches find, and
  below blackbody lights at temperatures off the grid (the relaxation's cone holds the range);
- the other selections (the paper's exitance elimination, least power) keep the colour too.
"""
import itertools

import numpy as np
import pytest
import scipy.optimize as sopt

import flatland
from relight_addon.engine import light_colour as lc
from relight_addon.engine.colours.blackbody import Blackbody
from relight_addon.engine.colours.white import White
from relight_addon.engine.inverse import InverseProblem, solve_inverse
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.options import JobOptions
from relight_addon.engine.reduction import StopCriteria, reduce_lights
from relight_addon.engine.registry import SELECTIONS

WARM = np.array([0.7, 0.55, 0.4])  # a warm floor and walls


def room(target=(0.3, 0.28, 0.25), colour=None):
    """A 2-D room (exact form factors), its floor painted ``target`` (radiosity, W/m^2 per channel),
    every other segment a candidate light; the problem with light colour ``colour``."""
    r = flatland.room(4.0, 3.0, n_per_wall=(6, 5, 6, 5), reflectance=WARM)
    floor = r["wall"] == "floor"
    B = np.where(floor[:, None], np.asarray(target, dtype=np.float64)[None, :], 0.0)
    prob = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, B)],
                          ~floor, r["center"], r["normal"])
    prob.colour = colour
    return prob


def stacked_error(prob, S, colours):
    """The best error of lights ``S`` of fixed colours (k, 3): NNLS on the channels stacked, built here."""
    T, b = prob.transfer, prob.b_target
    A = np.vstack([T[c][:, list(S)] * colours[:, c][None, :] for c in range(3)])
    y = np.concatenate([b[:, c] for c in range(3)])
    x, r = sopt.nnls(A, y)
    return r


def solve(prob, selection="greedy-swap", max_lights=None, **params):
    """The reduction of the svd solution by ``selection`` with its parameters ``params``."""
    e_x = solve_inverse(prob, "svd").exitance
    return reduce_lights(prob, e_x, SELECTIONS[selection].bind(**params), stop=StopCriteria(max_lights=max_lights))


def test_blackbody_is_blenders():
    """blackbody_rec709 is the colour Blender gives a Light's Temperature (its temperature_color,
    the Blackbody node's conversion), 1,000-12,000 K."""
    bpy = pytest.importorskip("bpy")
    light = bpy.data.lights.new("bb", "POINT")
    if not hasattr(light, "temperature_color"):
        pytest.skip(f"Blender {bpy.app.version_string} has no Light Temperature (4.5 on)")
    light.use_temperature = True
    temps = np.geomspace(1000.0, 12000.0, 41)
    ours = lc.blackbody_rec709(temps)
    for t, c in zip(temps, ours):
        light.temperature = float(t)
        bpy.context.view_layer.update()
        np.testing.assert_allclose(np.array(light.temperature_color)[:3], c, rtol=2e-5, atol=2e-6, err_msg=f"{t} K")
    bpy.data.lights.remove(light)


def test_white_is_the_exhaustive_optimum_and_bounded():
    """White lights: every light's channels equal; at k = 1, 2 the curve's error is the optimum of
    every subset (stacked NNLS here); the certificate is below it (exact there) and below the
    white curve everywhere; free colours are never worse at any k (white is a constraint)."""
    prob = room(colour=White())
    red = solve(prob, max_lights=3)
    ones = lambda k: np.ones((k, 3))  # noqa: E731
    for pt in red.curve:
        np.testing.assert_allclose(pt.exitance, pt.exitance[:, :1].repeat(3, axis=1), rtol=0, atol=0)
        assert np.all(pt.exitance >= 0)
    bounds = red.certificate
    n = prob.n_lights
    for k in (1, 2):
        best = min(stacked_error(prob, S, ones(k)) for S in itertools.combinations(range(n), k))
        pt = red.curve[k - 1]
        assert pt.error == pytest.approx(best, rel=1e-9, abs=1e-12)
        assert bounds.at(k) <= best * (1 + 1e-9)
        assert bounds.exact[k - 1]
    for pt in red.curve:
        assert bounds.at(pt.n_lights) <= pt.error * (1 + 1e-9) + 1e-12
    # white costs error against free colours on warm walls with grey-ish targets, never less
    free = solve(room(colour=None), max_lights=3)
    assert all(f.error <= w.error * (1 + 1e-9) + 1e-12 for f, w in zip(free.curve, red.curve))


def test_blackbody_lights_are_blackbody_and_k1_is_exhaustive():
    """Blackbody lights: each light's exitance is a power times the blackbody colour of its
    reported temperature, in the range; with one light the curve's error is the best of every light
    at every temperature of the grid (stacked NNLS here); the certificate (the cone relaxation) is
    below every configuration found and below blackbody lights at temperatures off the grid."""
    mode = Blackbody(temperature_min=3000.0, temperature_max=6000.0)
    prob = room(colour=mode)
    red = solve(prob, max_lights=3)
    for pt in red.curve:
        temps = [d["temperature_K"] for d in mode.describe(pt.exitance)]
        for e, t in zip(pt.exitance, temps):
            assert 3000.0 - 1e-6 <= t <= 6000.0 + 1e-6
            chi = lc.blackbody_rec709(t)
            np.testing.assert_allclose(e / e.sum(), chi / chi.sum(), rtol=1e-9, atol=1e-12)
    grid = lc.temperature_grid(3000.0, 6000.0)
    chis = lc.blackbody_rec709(grid)
    best1 = min(stacked_error(prob, [j], chi[None, :]) for j in range(prob.n_lights) for chi in chis)
    assert red.curve[0].error == pytest.approx(best1, rel=1e-9, abs=1e-12)
    bounds = red.certificate
    assert not bounds.exact.any()
    for pt in red.curve:
        assert bounds.at(pt.n_lights) <= pt.error * (1 + 1e-9)
    rng = np.random.default_rng(3)
    for _ in range(40):  # blackbody lights at random (continuous) temperatures of the range
        k = int(rng.integers(1, 4))
        S = rng.choice(prob.n_lights, k, replace=False)
        temps = 1e6 / rng.uniform(1e6 / 6000.0, 1e6 / 3000.0, k)
        assert bounds.nnls <= stacked_error(prob, S, lc.blackbody_rec709(temps)) * (1 + 1e-9)


def test_cone_holds_the_range():
    """Every blackbody colour of a range, on the grid or not, is a non-negative combination of the
    relaxation's edges (scipy's NNLS residual ~ 0), for the default range and a wide one."""
    rng = np.random.default_rng(0)
    for lo, hi in ((2700.0, 6500.0), (1200.0, 11000.0), (4000.0, 4100.0)):
        E = lc.cone_edges(lo, hi)
        for t in 1e6 / rng.uniform(1e6 / hi, 1e6 / lo, 300):
            c = lc.blackbody_rec709(t)
            assert sopt.nnls(E.T, c)[1] <= 1e-8 * np.linalg.norm(c), t


@pytest.mark.parametrize("selection", ["exitance-elimination", "least-power", "nnls-greedy"])
def test_other_selections_keep_white(selection):
    """The paper's exitance elimination, least power and NNLS greedy, on white lights: every
    configuration's channels equal, its error recomputed on T exactly; least power keeps its band
    on every target channel."""
    prob = room(colour=White())
    kw = {"tolerance": 0.5} if selection == "least-power" else {"max_lights": 3}
    red = solve(prob, selection=selection, **kw)
    T, b = prob.transfer, prob.b_target
    for pt in red.curve:
        np.testing.assert_allclose(pt.exitance, pt.exitance[:, :1].repeat(3, axis=1), rtol=0, atol=0)
        r = np.stack([T[c][:, pt.lights] @ pt.exitance[:, c] for c in range(3)], axis=1) - b
        assert pt.error == pytest.approx(float(np.linalg.norm(r)), rel=1e-9, abs=1e-12)
    if selection == "least-power":  # (white lights can keep these targets within +-50 %, not +-30 %)
        pt = red.final
        dev = np.abs(np.stack([T[c][:, pt.lights] @ pt.exitance[:, c] for c in range(3)], axis=1) - b)
        assert np.all(dev <= 0.5 * b * (1 + 1e-7) + 1e-9)


def test_bad_range_refused():
    """A reversed range is refused by the options' check (before any work), naming it."""
    with pytest.raises(ValueError, match="blackbody range .* 7000-3000 K"):
        JobOptions(light_colour="blackbody", temperature_min=7000.0, temperature_max=3000.0).validate()


def test_one_colour_per_light():
    """One colour per light: the selection keeps each light's channels together (its colour the one
    it alone fits best), then each configuration's colours are refitted per channel; every
    configuration is non-negative and no worse than its lights at their solo colours (stacked NNLS
    here), and the certificate is the free problem's, below every configuration."""
    from relight_addon.engine.best_lights import lower_bounds
    from relight_addon.engine.colours.one_colour import OneColour

    prob = room(colour=OneColour())
    red = solve(prob, max_lights=3)
    solo = lc.solo_colours(prob)
    free_bound = lower_bounds(prob.transfer, prob.b_target, len(red.certificate.bound))
    np.testing.assert_allclose(red.certificate.bound, free_bound.bound, rtol=1e-12)
    for pt in red.curve:
        assert np.all(pt.exitance >= 0)
        assert pt.error <= stacked_error(prob, pt.lights, solo[pt.lights]) * (1 + 1e-9) + 1e-12
        assert red.certificate.at(pt.n_lights) <= pt.error * (1 + 1e-9) + 1e-12
