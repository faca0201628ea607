"""Small geometric and grouping helpers shared by the engine (no bpy).

``group_sum`` / ``group_mean`` are the one implementation of "per group, the (weighted)
sum / mean of per-item values" (per face over its triangles, per light over its patches,
per polygon over its faces, per vertex over its corners ...).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["triangle_areas", "triangle_cross", "group_sum", "group_mean", "group_mean_basis", "unit"]


def triangle_cross(tv) -> np.ndarray:
    """(T, 3) cross products (b - a) x (c - a) of triangles tv (T, 3, 3): twice the area along the normal."""
    tv = np.asarray(tv, dtype=np.float64)
    return np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])


def triangle_areas(tv) -> np.ndarray:
    """(T,) areas (m^2) of triangles tv (T, 3, 3)."""
    return 0.5 * np.linalg.norm(triangle_cross(tv), axis=1)


def unit(v, axis=-1) -> np.ndarray:
    """Vectors scaled to unit length (zero vectors stay zero)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v, axis=axis, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


#: group_sum sums values of at most this many columns with a bincount each
BINCOUNT_COLUMNS = 8


def group_sum(index, values, n, weights=None) -> np.ndarray:
    """Per group g in 0..n-1, the sum over items i with index[i] == g of weights[i] * values[i].

    ``values`` (N,) or (N, k); items with a negative index are left out. Returns (n,) or (n, k).
    """
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    values = np.asarray(values, dtype=np.float64)
    w = np.ones(len(index)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    keep = index >= 0
    if not keep.all():
        index, values, w = index[keep], values[keep], w[keep]
    if values.ndim == 1:
        return np.bincount(index, weights=w * values, minlength=n)[:n]
    flat = values.reshape(len(index), -1)
    if flat.shape[1] <= BINCOUNT_COLUMNS:  # (a few columns: one bincount each, no sparse matrix built)
        return np.stack([np.bincount(index, weights=w * flat[:, j], minlength=n)[:n] for j in range(flat.shape[1])],
                        axis=1)
    S = sp.csr_matrix((w, (index, np.arange(len(index)))), shape=(n, len(index)))
    return np.asarray(S @ flat)


def group_mean(index, values, n, weights=None, empty=0.0) -> np.ndarray:
    """Per group, the ``weights``-weighted mean of ``values`` (plain mean when the group's weights
    sum to 0; ``empty`` for groups without items)."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    values = np.asarray(values, dtype=np.float64)
    w = np.ones(len(index)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    num = group_sum(index, values, n, w)
    den = group_sum(index, w, n)
    den_b = den.reshape((-1,) + (1,) * (values.ndim - 1))
    out = num / np.where(den_b > 0, den_b, 1.0)
    if np.all(den > 0):
        return out
    cnt = group_sum(index, np.ones(len(index)), n)
    plain = group_sum(index, values, n) / np.maximum(cnt, 1).reshape((-1,) + (1,) * (values.ndim - 1))
    out = np.where(den_b > 0, out, plain)
    if empty != 0.0:
        out[cnt == 0] = empty
    return out


def group_mean_basis(basis, values, weights) -> np.ndarray:
    """Per column l of a 0/1 membership matrix ``basis`` (items x groups, scipy.sparse), the
    ``weights``-weighted mean of the member items' ``values`` (items, k)."""
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    values = np.asarray(values, dtype=np.float64)
    k = int(np.prod(values.shape[1:])) if values.ndim > 1 else 1  # (no items: still k columns)
    num = np.asarray(basis.T @ (w[:, None] * values.reshape(len(w), k)))
    den = np.asarray(basis.T @ w).reshape(-1)
    return num / np.where(den > 0, den, 1.0)[:, None]
