"""The viewport's views of a stored result (relight_addon/pipeline/false_colour.py, no bpy).

References: hand computations with the photometric constants written out here (683 lm/W, the
Rec.709 weights 0.2126, 0.7152, 0.0722, radiance = exitance / pi), on a small stored result built
by hand (three polygons over four patches, one of them a light cell); the legend's pixels read
back at its ticks; random and extreme inputs for finiteness.
"""
import math
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from relight_addon.pipeline import false_colour as fc

K, WR, WG, WB = 683.0, 0.2126, 0.7152, 0.0722


def _lux_by_hand(E):
    return K * (WR * E[0] + WG * E[1] + WB * E[2])


def _result():
    """Patches 0..3; polygon 0 = patches 0 (1/4 of its area) and 1 (3/4), polygon 1 = patch 2 (a
    light cell of exitance (0.9, 0.6, 0.3) W/m^2, one light), polygon 2 = patch 3 (a channel
    reflecting 0.005: too dark to read). Painted: patches 0 and 1 (polygon 0) and patch 3."""
    rho = np.array([[0.5, 0.4, 0.3], [0.5, 0.4, 0.3], [0.8, 0.8, 0.8], [0.6, 0.005, 0.6]])
    E = np.array([[1.0, 1.0, 1.0], [2.0, 1.5, 1.0], [0.5, 0.25, 0.125], [1.0, 1.0, 1.0]])  # arriving, W/m^2
    e = np.zeros((4, 3))
    e[2] = [0.9, 0.6, 0.3]
    B = e + rho * E
    W = sp.csr_matrix(np.array([[0.25, 0.75, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]))
    basis = sp.csr_matrix(np.array([[1.0]]))  # one cell (patch 2), one light
    return SimpleNamespace(
        radiosity=B[None], exitance=np.array([[[0.9, 0.6, 0.3]]]), cell_patch=np.array([2]),
        light_basis=lambda: basis, polygon_weight_matrix=lambda: W, patch_reflectance=rho,
        target_patch=np.array([0, 1, 3]), target_value=np.array([[0.5, 0.4, 0.3], [1.0, 0.6, 0.3],
                                                                  [0.6, 0.005, 0.6]])), E, B


def test_illuminance_of_a_face_of_known_radiosity_exitance_and_reflectance():
    data, E, B = _result()
    v = fc.view(data, 0, "ILLUMINANCE")
    # polygon 0: the area-weighted mean of its patches' lux, each E = B / reflectance (no emission)
    lux0 = 0.25 * _lux_by_hand(E[0]) + 0.75 * _lux_by_hand(E[1])
    assert lux0 == pytest.approx(0.25 * 683.0 + 0.75 * 683.0 * (0.4252 + 1.0728 + 0.0722))
    # polygon 1, a light: E = (B - e) / reflectance = (0.5, 0.25, 0.125) W/m^2
    lux1 = 683.0 * (0.2126 * 0.5 + 0.7152 * 0.25 + 0.0722 * 0.125)
    np.testing.assert_allclose(v.values[:2], [lux0, lux1], rtol=1e-12)
    assert v.shown.tolist() == [True, True, False]  # polygon 2 reflects 0.005 in green: unread
    assert v.values[2] == 0.0 and tuple(v.colours[2]) == fc.NOT_SHOWN
    assert v.unit == "lx" and v.display and not v.smooth


def test_luminance_is_683_times_the_weighted_radiance():
    data, E, B = _result()
    v = fc.view(data, 0, "LUMINANCE")
    L1 = B[2] / math.pi  # the light's face: its emission counts
    assert v.values[1] == pytest.approx(683.0 * (0.2126 * L1[0] + 0.7152 * L1[1] + 0.0722 * L1[2]), rel=1e-12)
    # a uniform radiance of 1 W/(m^2 sr) in every channel is 683 cd/m^2
    data.radiosity = np.full((1, 4, 3), math.pi)
    assert fc.view(data, 0, "LUMINANCE").values == pytest.approx([683.0] * 3, rel=1e-12)
    assert fc.view(data, 0, "LUMINANCE").shown.all()


def test_difference_reads_plus_ten_percent_for_predicted_1_1_against_painted_1_0():
    data, E, B = _result()
    data.radiosity = np.full((1, 4, 3), 1.1)
    data.target_value = np.full((3, 3), 1.0)
    v = fc.view(data, 0, "DIFFERENCE")
    assert v.values[0] == pytest.approx(10.0, rel=1e-12) and v.values[2] == pytest.approx(10.0, rel=1e-12)
    assert v.shown.tolist() == [True, False, True]  # polygon 1 is not painted: no difference shown
    assert tuple(v.colours[1]) == fc.NOT_SHOWN and v.unit == "%"
    data.radiosity = np.full((1, 4, 3), 0.9)
    assert fc.view(data, 0, "DIFFERENCE").values[0] == pytest.approx(-10.0, rel=1e-12)
    # luminance-weighted: predicted (1.2, 1, 1) against painted (1, 1, 1) is +0.2 x 0.2126
    assert fc.relative_difference([1.2, 1.0, 1.0], [1.0, 1.0, 1.0]) == pytest.approx(100 * 0.2 * 0.2126)
    # painted black: finite, beyond any scale
    d = fc.relative_difference([[0.5, 0.5, 0.5], [1, 1, 1]], [[0.0, 0.0, 0.0], [1, 1, 1]])
    assert np.all(np.isfinite(d)) and d[0] > 1e4 and d[1] == 0.0


def test_predicted_view_is_the_radiance_times_two_to_the_exposure():
    data, E, B = _result()
    for ev in (0.0, 2.0, -1.5):
        v = fc.view(data, 0, "PREDICTED", exposure=ev)
        expected = np.array([(0.25 * B[0] + 0.75 * B[1]), B[2], B[3]]) / math.pi * 2.0 ** ev
        np.testing.assert_allclose(v.colours, expected, rtol=1e-12)
        assert v.smooth and not v.display


def test_painted_view_shows_the_painted_radiance_and_grey_elsewhere():
    data, E, B = _result()
    v = fc.view(data, 0, "PAINTED", exposure=1.0)
    np.testing.assert_allclose(v.colours[0], (0.25 * np.array([0.5, 0.4, 0.3]) + 0.75 * np.array([1.0, 0.6, 0.3]))
                               / math.pi * 2.0, rtol=1e-12)
    assert tuple(v.colours[1]) == fc.UNPAINTED and v.shown.tolist() == [True, False, True]


def test_a_polygon_counts_where_half_its_area_is_painted_or_readable():
    W = sp.csr_matrix(np.array([[0.4, 0.6], [0.6, 0.4]]))
    vals, counted = fc.to_polygons(W, np.array([10.0, 20.0]), np.array([False, True]))
    assert counted.tolist() == [True, False]
    assert vals.tolist() == [20.0, 0.0]  # the mean over its counted part only


def test_the_colour_at_each_tick_is_the_legends_colour_there():
    for vmax, log, div in ((800.0, False, False), (1500.0, False, False), (800.0, True, False), (20.0, False, True)):
        img, g = fc.legend(vmax, log, div, size=160, scale=1)
        top = img[::-1]
        x0, y0, x1, y1 = g["bar"]
        bar = top[y0:y1 + 1, (x0 + x1) // 2, :3]
        step = np.abs(np.diff(bar, axis=0)).max(axis=0)  # the colour change from one row to the next
        assert [t for t, _ in g["ticks"]] == fc.ticks(vmax, log, div)
        for value, y in g["ticks"]:
            got = top[y, (x0 + x1) // 2, :3]
            want = fc.colours(value, vmax, log, div)
            assert np.all(np.abs(got - want) <= step + 1e-6), (vmax, log, div, value)
        # the scale's ends: its bottom colour and its top colour
        anchors = fc.DIVERGING if div else fc.SEQUENTIAL
        np.testing.assert_allclose(top[y1, x0, :3], anchors[0][1], atol=1e-6)
        np.testing.assert_allclose(top[y0, x0, :3], anchors[-1][1], atol=1e-6)
        assert g["ticks"][0][1] == y1 and g["ticks"][-1][1] == y0


def test_scales_ends_beyond_them_and_the_log_scale():
    red, violet = fc.SEQUENTIAL[-1][1], fc.SEQUENTIAL[0][1]
    np.testing.assert_allclose(fc.colours([0.0, 500.0, 5000.0, -3.0], 500.0),
                               [violet, red, red, violet], atol=1e-12)
    # log over 3 decades: 0.5, 5, 50, 500 evenly spaced
    assert fc.position([0.5, 5, 50, 500, 0.0], 500.0, log=True).tolist() == pytest.approx([0, 1 / 3, 2 / 3, 1, 0])
    # diverging: 0 is white
    np.testing.assert_allclose(fc.colours(0.0, 20.0, diverging=True), fc.DIVERGING[2][1], atol=1e-12)


def test_ticks_are_round_evenly_spaced_and_end_at_the_max():
    assert fc.ticks(800) == [0, 200, 400, 600, 800]
    assert fc.ticks(500) == [0, 100, 200, 300, 400, 500]
    assert fc.ticks(1200) == [0, 200, 400, 600, 800, 1000, 1200]
    assert fc.ticks(0.3) == [0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3]
    assert fc.ticks(730) == pytest.approx([0, 146, 292, 438, 584, 730])  # the user's max: 5 even steps
    assert fc.ticks(800, log=True) == pytest.approx([0.8, 8, 80, 800])
    assert fc.ticks(20, diverging=True) == [-20, -10, 0, 10, 20]
    assert [fc.label(v) for v in (0.8, 1500, 12000, 0)] == ["0.8", "1500", "12k", "0"]
    assert fc.label(10, signed=True) == "+10"


def test_automatic_max_is_a_round_number_above_the_targets_and_the_95th_percentile():
    values = np.arange(1, 101, dtype=float) * 5  # 5 .. 500: 95th percentile 475.25
    assert fc.auto_max(values) == 500
    assert fc.auto_max(values, targets=[510.0]) == 600  # the targets' max above it
    assert fc.auto_max(values * 1.3) == 800  # 617.8 -> the next round number
    assert fc.auto_max([]) == 1.0 and fc.auto_max([np.nan, np.inf]) == 1.0
    assert fc.auto_max([-30.0, 5.0, 12.0], diverging=True) == 30  # magnitudes
    data, E, B = _result()
    v = fc.view(data, 0, "ILLUMINANCE")
    # per readable patch: 683, 683 x 1.5702 = 1072.4 (both painted, at that) and the light's 200.9 lx:
    # 95th percentile 1033.4, painted max 1072.4 -> 1200
    assert v.auto and v.vmax == 1200 and v.ticks == [0, 200, 400, 600, 800, 1000, 1200]
    v = fc.view(data, 0, "ILLUMINANCE", vmax=300.0, log=True)
    assert not v.auto and v.vmax == 300.0 and v.log and v.ticks == pytest.approx([0.3, 3, 30, 300])


def test_never_nan_or_inf():
    rng = np.random.default_rng(3)
    data, E, B = _result()
    for trial in range(20):
        data.radiosity = rng.choice([0.0, 1e-30, 1.0, 1e12], size=(1, 4, 3)) * rng.random((1, 4, 3))
        data.patch_reflectance = rng.choice([0.0, 0.005, 0.5, 0.99], size=(4, 3))
        data.target_value = rng.choice([0.0, 1e-20, 2.0], size=(3, 3))
        for mode in fc.MODES:
            for vmax, log in ((0.0, False), (1e-9, True), (float("inf"), False), (float("nan"), True)):
                v = fc.view(data, 0, mode, exposure=rng.uniform(-20, 20), vmax=vmax, log=log)
                assert np.all(np.isfinite(v.colours)), mode
                assert v.values is None or np.all(np.isfinite(v.values))
                assert math.isfinite(v.vmax) and all(math.isfinite(t) for t in v.ticks)


def test_a_result_without_reflectance_says_so():
    data, E, B = _result()
    data.patch_reflectance = None
    with pytest.raises(ValueError, match="solve again"):
        fc.view(data, 0, "ILLUMINANCE")
    assert fc.view(data, 0, "LUMINANCE").values is not None  # the others do not need it
