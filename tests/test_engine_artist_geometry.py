"""Form factors on artists' geometry: tiles laid on a wall (coincident, overlapping, a hair in front
of it), a box sunk into the floor. References: the law every row of F obeys (the share of a
patch's light that reaches the scene: at most 1), and the spectral radius of diag(rho) F computed
by numpy's eigenvalues."""
import numpy as np
import pytest

from relight_addon.engine.formfactors import compute_form_factors
from relight_addon.engine.kernel_transfer import ROW_SLACK
from relight_addon.engine.inverse import DivergentTransport, _Iterative, growth_bound
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from test_engine_extent import _quad  # (a quad of 4 corners)

X, Y, Z = 5.0, 4.0, 3.0
TILE = 0.2


def tiled_room(kind):
    """A closed room (faces in), 10 x 10 tiles on its y = 0 wall (``kind``: "coincident" with
    it, 1 mm "front" of it, or "overlap": each tile 1.5 x wider, overlapping its neighbours), and a
    box sunk 0.2 m into the floor; the floor painted."""
    polys = [_quad((0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)), _quad((0, 0, 0), (0, 0, Z), (X, 0, Z), (X, 0, 0)),
             _quad((0, Y, 0), (X, Y, 0), (X, Y, Z), (0, Y, Z)), _quad((0, 0, 0), (0, Y, 0), (0, Y, Z), (0, 0, Z)),
             _quad((X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)), _quad((0, 0, Z), (0, Y, Z), (X, Y, Z), (X, 0, Z))]
    off = 0.001 if kind == "front" else 0.0
    w = TILE * (1.5 if kind == "overlap" else 1.0)
    for i in range(10):
        for j in range(10):
            x0, z0 = 1 + i * TILE, 0.5 + j * TILE
            polys.append(_quad((x0, off, z0), (x0, off, z0 + w), (x0 + w, off, z0 + w), (x0 + w, off, z0)))
    lo, hi, h = 2.0, 2.5, 0.6
    polys += [_quad((lo, lo, h), (hi, lo, h), (hi, hi, h), (lo, hi, h)),
              _quad((lo, lo, -0.2), (lo, lo, h), (hi, lo, h), (hi, lo, -0.2)),
              _quad((lo, hi, -0.2), (hi, hi, -0.2), (hi, hi, h), (lo, hi, h)),
              _quad((lo, lo, -0.2), (lo, hi, -0.2), (lo, hi, h), (lo, lo, h)),
              _quad((hi, lo, -0.2), (hi, lo, h), (hi, hi, h), (hi, hi, -0.2))]
    faces = polygon_faceset(polys, reflectance=0.8)
    faces.target[0] = True
    faces.target_radiosity[0] = 1.0
    return faces


@pytest.mark.parametrize("kind", ["coincident", "front", "overlap"])
def test_rows_of_f_never_exceed_one_on_tiles_with_the_kernel_pairs(kind):
    """The kernel's pairs (the floor x every patch, as a solve asks) on tiles: the
    point-to-polygon kernel sees both of two coincident faces whole; its rows (and, by
    reciprocity, the tiles' rows) summed to 1.18 (coincident) and 1.40 (overlap) before. Every
    row now sums to at most 1 + ROW_SLACK (the sending scale of half-buried patches taken out)."""
    patches = mesh_patches(tiled_room(kind), 0.5)
    floor = np.flatnonzero(patches.target)
    for pairs in ((floor, np.arange(patches.n_patches)),):
        F = compute_form_factors(patches, rays_per_patch=64, kernel_pairs=pairs)
        send = np.ones(patches.n_patches) if F.send is None else np.asarray(F.send)
        rows = np.asarray((np.asarray(F.matrix, dtype=np.float64) / send[None, :]).sum(axis=1)).ravel()
        assert rows.max() <= 1.0 + ROW_SLACK, (kind, rows.max())
        assert np.median(rows[floor]) > 0.99  # (the floor of a closed room sees the room; under the box, less)


def test_growth_bound_is_the_spectral_radius_not_the_largest_row():
    """A matrix whose rows sum above 1 where the whole still loses light (patches seeing
    half-buried ones: their columns carry 1 / their visible share): the iteration converges, and
    the bound found lies between the spectral radius and 1; a matrix that does create light is
    refused with the rows where it grows."""
    rng = np.random.default_rng(1)
    P = 60
    F = rng.random((P, P))
    F[:, :10] *= 0.01  # ten half-buried patches, seen little ...
    F[10:15, :10] *= 1000.0  # ... but by five patches next to them, mostly
    F /= F.sum(axis=1, keepdims=True)
    send = np.where(np.arange(P) < 10, 2.0, 1.0)
    rho = np.full(P, 0.8)
    M = F * send[None, :]
    assert (rho * M.sum(axis=1)).max() > 1.0  # the old row-sum test refused it
    radius = float(np.abs(np.linalg.eigvals(rho[:, None] * M)).max())
    bound, rows = growth_bound(M, rho)
    assert radius <= bound < 1.0
    it = _Iterative(M, rho)
    b = it.solve(np.ones(P))
    np.testing.assert_allclose(b, np.linalg.solve(np.eye(P) - rho[:, None] * M, np.ones(P)), rtol=1e-8)
    M2 = M.copy()
    M2[:5, :5] += 1.0  # five patches that send each other more than they receive
    with pytest.raises(DivergentTransport) as exc:
        _Iterative(M2, rho)
    assert exc.value.rows[:5].all()
    named = exc.value.named(["Tiles", "Wall"], np.where(np.arange(P) < 5, 0, 1))
    assert "'Tiles'" in str(named) and "overlap, coincide" in str(named)


def test_a_reduce_whose_lights_are_all_lamps_solves_without_surface_columns():
    """The iterative solver of a large model given no right-hand side (a reduce whose only lights
    are lamps has no surface column): numpy's 'zero-size array to reduction operation maximum'
    reached the user on an artist's temple lit by a Sun."""
    rng = np.random.default_rng(2)
    F = rng.random((8, 8))
    F /= 2 * F.sum(axis=1, keepdims=True)
    out = _Iterative(F, np.full(8, 0.5)).solve(np.zeros((8, 0)))
    assert out.shape == (8, 0)


def test_targets_no_light_reaches_are_named_by_object():
    """Two rooms: the first's ceiling may hold lights, the second (closed, every face forbidden)
    has its floor painted too: its targets are named by the object, not by patch numbers."""
    from relight_addon.engine.options import JobOptions
    from relight_addon.pipeline.jobs import run_solve

    def box(x0):
        return [_quad((x0, 0, 0), (x0 + 2, 0, 0), (x0 + 2, 2, 0), (x0, 2, 0)),
                _quad((x0, 0, 0), (x0, 0, 2), (x0 + 2, 0, 2), (x0 + 2, 0, 0)),
                _quad((x0, 2, 0), (x0 + 2, 2, 0), (x0 + 2, 2, 2), (x0, 2, 2)),
                _quad((x0, 0, 0), (x0, 2, 0), (x0, 2, 2), (x0, 0, 2)),
                _quad((x0 + 2, 0, 0), (x0 + 2, 0, 2), (x0 + 2, 2, 2), (x0 + 2, 2, 0)),
                _quad((x0, 0, 2), (x0, 2, 2), (x0 + 2, 2, 2), (x0 + 2, 0, 2))]
    faces = polygon_faceset(box(0.0) + box(5.0), reflectance=0.5, object_names=["Lit", "Closed"],
                            face_object=np.repeat([0, 1], 6))
    faces.target[[0, 6]] = True
    faces.target_radiosity[[0, 6]] = 1.0
    faces.forbidden[:5] = True
    faces.forbidden[6:] = True
    out = run_solve(faces, JobOptions(spot_lamps=False, max_lights=1, max_patch_size=1.0, seed=1))
    notes = [w for w in out.report["warnings"] if "cannot be met" in w]
    assert len(notes) == 1 and "4 of 'Closed'" in notes[0] and "patches [" not in notes[0], notes


def test_a_kernel_value_that_is_not_finite_is_left_to_the_rays():
    """A kernel pair that comes out NaN (a receiver point on a source's edge: collision helpers laid
    over a door made "form factors contain NaN" refuse the solve) takes the rays' estimate, and
    the objects are recorded for the report."""
    from relight_addon.engine.formfactors import _finite_kernel

    patches = mesh_patches(tiled_room("coincident"), 1.0)
    M = np.full((patches.n_patches, patches.n_patches), 0.01, dtype=np.float32)
    rec, src = np.array([0, 1]), np.array([2, 3, 110])
    K = np.full((2, 3), 0.02)
    K[1, 2] = np.nan
    out, (n, objs) = _finite_kernel(K, M, patches, rec, src)
    assert np.isfinite(out).all() and out[1, 2] == pytest.approx(0.01) and out[0, 0] == 0.02 and n == 1
    assert set(objs.tolist()) == {int(patches.object[1]), int(patches.object[110])}
    assert _finite_kernel(out, M, patches, rec, src)[1] is None
