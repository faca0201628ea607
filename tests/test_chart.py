"""The Results panel's error chart (relight_addon/chart.py, pure numpy): what an artist must be
able to read in it. References: the pixel geometry the chart reports, checked against the
image itself (colours at the reported places), and the axis rules the module documents."""
import math

import numpy as np
import pytest

from relight_addon.pipeline import chart

C = {k: np.array(v[:3], dtype=np.float32) for k, v in chart.COLORS.items()}


def _staircase_like(n=693):
    """A reduction curve like the staircase's: e_x exact (1e-14) with negatives at n lights,
    then errors rising to ~0.6 at 1 light; configurations above 40 lights have negatives."""
    lights = np.arange(n, 0, -1)
    err = 0.02 + 0.6 * np.exp(-lights / 15.0)
    err[0] = 1e-14
    return lights, err, (lights > 40).astype(int)


def _topdown(img):
    return img[::-1]


def _has(img, x, y, color, r=2):
    h, w = img.shape[:2]
    sub = img[max(0, int(y) - r):min(h, int(y) + r + 1), max(0, int(x) - r):min(w, int(x) + r + 1), :3]
    return bool(np.any(np.all(np.abs(sub - color) < 1e-6, axis=-1)))


def test_linear_y_axis_is_not_squashed_by_the_exact_point():
    lights, err, neg = _staircase_like()
    img, g = chart.render(lights, err, neg, current=len(lights) - 3, size=(228, 182))
    x0, y0, x1, y1 = g["plot"]
    assert g["y_max"] == pytest.approx(0.6)  # the round number just above the curve's 0.58 max
    # every configuration from 1 to 40 lights (errors 0.04..0.6) spreads over most of the height
    top = _topdown(img)
    ys = [y for y in range(y0, y1 + 1) if np.any(np.all(np.abs(top[y, x0:x1, :3] - C["curve"]) < 1e-6, axis=-1))]
    assert (max(ys) - min(ys)) > 0.75 * (y1 - y0)
    # the e_x point (1e-14) is on the x axis, at the right end
    assert _has(top, x1 - 2, y1, C["negative"], r=3)


def test_marker_is_at_the_current_configuration():
    lights, err, neg = _staircase_like()
    for k in (len(lights) - 1, len(lights) - 3, len(lights) - 10, 100):
        img, g = chart.render(lights, err, neg, current=k, size=(228, 182))
        top = _topdown(img)
        mx, my = g["marker"]
        x0, y0, x1, y1 = g["plot"]
        # log x from 1 light to the most (693)
        assert g["x_log"] and g["x_range"] == [1.0, 693.0]
        t = math.log10(lights[k]) / math.log10(693)
        assert mx == pytest.approx(x0 + 2 + t * (x1 - x0 - 4), abs=0.5)
        assert my == pytest.approx(y1 - err[k] / g["y_max"] * (y1 - y0), abs=0.5)
        assert _has(top, mx, my, C["marker"]) and _has(top, mx, y0 + 1, C["marker"], r=1)
        # no marker colour far from the marker's column
        cols = np.flatnonzero(np.any(np.all(np.abs(top[:, :, :3] - C["marker"]) < 1e-6, axis=-1), axis=0))
        assert cols.min() >= mx - 4 and cols.max() <= mx + 4


def test_bound_is_a_line_at_its_value_and_absent_when_unknown():
    lights, err, neg = _staircase_like()
    img, g = chart.render(lights, err, neg, current=len(lights) - 3, bound=0.187, size=(228, 182))
    x0, y0, x1, y1 = g["plot"]
    assert g["bound_y"] == pytest.approx(y1 - 0.187 / g["y_max"] * (y1 - y0))
    row = _topdown(img)[int(round(g["bound_y"])), x0:x1, :3]
    assert np.mean(np.all(np.abs(row - C["bound"]) < 1e-6, axis=-1)) > 0.3  # dashed
    img2, g2 = chart.render(lights, err, neg, current=len(lights) - 3, size=(228, 182))
    assert g2["bound_y"] is None
    assert not np.any(np.all(np.abs(img2[..., :3] - C["bound"]) < 1e-6, axis=-1))


def test_axes_have_labels():
    lights, err, neg = _staircase_like()
    img, g = chart.render(lights, err, neg, current=0, size=(228, 182))
    top = _topdown(img)
    x0, y0, x1, y1 = g["plot"]
    text = np.all(np.abs(top[..., :3] - C["text"]) < 1e-6, axis=-1)
    assert text[:, :x0].sum() > 50      # y tick labels left of the plot
    assert text[y1 + 2:, :].sum() > 50  # x tick labels and title below it
    assert text[:y0, :].sum() > 40      # y title above it
    assert chart.y_ticks(0.6) == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    assert chart.x_ticks(1, 693, True)[0] == [1.0, 10.0, 100.0]


def test_clipped_range_when_some_configurations_are_far_off():
    """A curve with a few wild configurations (relative error 40) keeps a readable axis."""
    lights = np.arange(20, 0, -1)
    err = np.linspace(0.05, 0.5, 20)
    err[-1] = 40.0
    img, g = chart.render(lights, err, current=10, size=(228, 182))
    assert g["y_max"] <= chart.CLIP
    # the shown configuration's error sets the top when it is above the clip
    img, g = chart.render(lights, err, current=19, size=(228, 182))
    assert g["y_max"] >= 40.0


def test_a_clipped_range_with_a_bound_per_configuration():
    """Some configurations far off (above the clip) and a bound per configuration (the stored
    certificate): the axis is clipped, and kept up to the shown configuration's bound when that is
    above the clip (it raised in the Results panel's draw: a per-point bound read as one number)."""
    lights = np.arange(20, 0, -1)
    err = np.linspace(0.05, 0.5, 20)
    err[-1] = 40.0
    bound = 0.8 * err
    bound[0] = np.nan
    img, g = chart.render(lights, err, current=10, bound=bound, size=(228, 182))
    assert g["y_max"] <= chart.CLIP and g["bound_y"] is not None
    img, g = chart.render(lights, err, current=19, bound=bound, size=(228, 182))
    assert g["y_max"] >= 40.0
    img, g = chart.render(lights, 0.8 * err, current=10, bound=np.where(lights == 10, 30.0, np.nan),
                          size=(228, 182))
    assert g["y_max"] >= 30.0  # (the shown configuration's bound, above the clip: in view)


def test_degenerate_inputs():
    img, g = chart.render([], [], size=(100, 80))
    assert img.shape == (80, 100, 4) and g["marker"] is None
    img, g = chart.render([3], [0.2], current=0, size=(100, 80))
    assert g["marker"] is not None
    img, g = chart.render([3, 2], [float("nan"), 0.3], current=0, size=(100, 80))
    assert g["marker"] is None and g["points"] == 1
    assert chart.nice_ceil(0.581) == pytest.approx(0.6) and chart.nice_ceil(1.3) == pytest.approx(1.5)


def test_per_point_bound_is_a_line_through_each_configurations_bound():
    """The stored certificate: per configuration, a lower bound for its number of lights (NaN
    where there is none); drawn as a green line, at the current point's bound."""
    lights, err, neg = _staircase_like()
    bound = 0.5 * err
    bound[lights > 32] = 0.05   # above 32 lights: the all-lights NNLS bound
    bound[0] = np.nan           # e_x: no certificate
    k = len(lights) - 3
    img, g = chart.render(lights, err, neg, current=k, bound=bound, size=(228, 182))
    x0, y0, x1, y1 = g["plot"]
    assert g["bound_points"] == len(lights) - 1
    assert g["bound_y"] == pytest.approx(y1 - bound[k] / g["y_max"] * (y1 - y0))
    # green at the bound of the shown configuration, at its x
    assert _has(_topdown(img), g["marker"][0], g["bound_y"], C["bound"], r=2)
    # an all-NaN bound draws nothing
    img2, g2 = chart.render(lights, err, neg, current=k, bound=np.full(len(lights), np.nan), size=(228, 182))
    assert g2["bound_y"] is None and not np.any(np.all(np.abs(img2[..., :3] - C["bound"]) < 1e-6, axis=-1))
