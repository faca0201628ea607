"""engine/geometry.py's grouped sums and means against plain loops over the items (no bpy)."""
import numpy as np
import pytest

from relight_addon.engine.geometry import BINCOUNT_COLUMNS, group_mean, group_sum


def _loop_sum(index, values, n, w):
    out = np.zeros((n,) + values.shape[1:])
    for i, g in enumerate(index):
        if g >= 0:
            out[g] += w[i] * values[i]
    return out


@pytest.mark.parametrize("cols", [None, 3, BINCOUNT_COLUMNS + 2])  # 1-D, a bincount a column, the sparse product
def test_group_sum_and_mean_are_the_loops(cols):
    rng = np.random.default_rng(4)
    N, n = 300, 40  # (groups 35..39 get no item; some items have index -1: left out)
    index = rng.integers(-1, 35, N)
    values = rng.normal(size=N if cols is None else (N, cols))
    w = rng.random(N)
    w[index == 7] = 0.0  # a group whose weights sum to 0: its plain mean
    want = _loop_sum(index, values, n, w)
    np.testing.assert_allclose(group_sum(index, values, n, w), want, rtol=1e-12, atol=1e-12)
    mean = group_mean(index, values, n, w, empty=-5.0)
    for g in range(n):
        items = index == g
        if not items.any():
            expect = np.full(np.shape(mean[g]), -5.0)
        elif w[items].sum() > 0:
            expect = (w[items][:, None] * values[items].reshape(items.sum(), -1)).sum(axis=0) / w[items].sum()
        else:
            expect = values[items].reshape(items.sum(), -1).mean(axis=0)
        np.testing.assert_allclose(np.ravel(mean[g]), np.ravel(expect), rtol=1e-12, atol=1e-12)
    # every group weighted (no plain-mean fallback needed): the same means
    full = group_mean(np.arange(N) % n, values, n, w + 0.1)
    np.testing.assert_allclose(full, _loop_sum(np.arange(N) % n, values, n, w + 0.1)
                               / (_loop_sum(np.arange(N) % n, np.ones(N), n, w + 0.1).reshape((n,) + (1,) * (values.ndim - 1))),
                               rtol=1e-12)
