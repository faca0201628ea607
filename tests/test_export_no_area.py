"""The export's 'no area in world space' check (blender.meshes.no_area, which skips measuring every
triangle when the object's matrix cannot shrink a triangle's area below the threshold), against
the triangles' areas measured before and after the matrix."""
import numpy as np
import pytest

from relight_addon.blender.meshes import no_area


def geometry(rng, n=50):
    V = rng.normal(size=(3 * n, 3))
    return {"V": V, "lt": np.arange(3 * n).reshape(n, 3)}


def flat_geometry(rng, axis, n=50):
    g = geometry(rng, n)
    g["V"][:, axis] = 0.0  # the mesh lies in a coordinate plane
    return g


def measured(geo, M):
    T = geo["V"][geo["lt"]]
    local = np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1).sum()
    W = T @ np.asarray(M)[:3, :3].T
    world = np.linalg.norm(np.cross(W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]), axis=1).sum()
    return bool(local > 0 and not world > 1e-12 * local)


def matrix(diag, rng=None):
    M = np.eye(4)
    M[:3, :3] = np.diag(diag)
    if rng is not None:  # turned and sheared
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        M[:3, :3] = Q @ M[:3, :3] @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    M[:3, 3] = [1.0, -2.0, 3.0]
    return M


@pytest.mark.parametrize("diag, flat_axis, expected", [
    ((1, 1, 1), None, False),
    ((2, 0.5, 3), None, False),
    ((1, 1, 0), None, False),      # a solid squashed flat: its triangles keep some area
    ((1, 1, 0), 0, True),          # a mesh in the y-z plane squashed along z: a line along y
    ((1, 1, 0), 2, False),         # a mesh in the x-y plane squashed along z: unchanged
    ((0, 1, 0), 0, True),          # a mesh in the y-z plane, x and z scaled to 0: a line
    ((1e-7, 1e-7, 1e-7), None, True),  # scaled to almost nothing: area ratio 1e-14
    ((1e-3, 1e-3, 1e-3), None, False),  # small but measurable: 1e-6
    ((0, 0, 0), None, True),
])
def test_no_area_as_measured(diag, flat_axis, expected):
    rng = np.random.default_rng(3)
    geo = geometry(rng) if flat_axis is None else flat_geometry(rng, flat_axis)
    for turn in (None, np.random.default_rng(5)):
        M = matrix(diag, turn)
        assert no_area(geo, M) == measured(geo, M)
    assert no_area(geo, matrix(diag)) == expected
