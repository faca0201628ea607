"""Forward radiosity solvers against analytic results and physical laws (pure engine)."""
import numpy as np
import pytest
import scipy.sparse as sp

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.formfactors import compute_form_factors
from relight_addon.engine.radiosity import RadiosityError, lossless_patches, radiosity_matrix, solve_radiosity
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from relight_addon.engine.units import MAX_REFLECTANCE


@pytest.fixture(scope="module")
def closed_box():
    ps = mesh_patches(polygon_faceset(cf.box_polygons((1.0, 0.8, 0.6))), max_patch_size=0.15)
    ff = compute_form_factors(ps, 2048, seed=0)
    return ps, ff


def test_closed_box_uniform_gives_e_over_one_minus_rho(closed_box):
    # Closed scene, uniform rho and e: B = e + rho B (row sums 1) -> B = e / (1 - rho). The
    # reciprocity-weighted rows are 1 to float32 rounding (never above, within 1.2e-7 below),
    # which 1 / (1 - rho) = 10 amplifies to about 1e-6: rtol 1e-5
    ps, ff = closed_box
    assert np.all(ff.row_sums() <= 1) and np.all(ff.row_sums() > 1 - 2e-7)
    P = ps.n_patches
    rho = np.tile([0.2, 0.5, 0.9], (P, 1))
    e = np.tile([1.0, 2.0, 3.0], (P, 1))
    expected = e[0] / (1 - rho[0])
    for method in ("direct", "gauss-seidel"):
        B, info = solve_radiosity(ff, rho, e, method=method, tol=1e-9)
        assert info["converged"] and info["method"] == method
        assert np.allclose(B, expected, rtol=1e-5), (method, B.min(0), B.max(0), expected)


def test_energy_balance_in_closed_box(closed_box):
    # Emitted power = absorbed power: sum A e = sum A (1 - rho) H, H = F B the
    # irradiance gathered by each patch (W/m^2). Holds exactly for exact form
    # factors (reciprocity + closure); ray-cast F is within its noise.
    ps, ff = closed_box
    P = ps.n_patches
    rng = np.random.default_rng(0)
    rho = rng.uniform(0.1, 0.9, (P, 3))
    e = np.zeros((P, 3))
    e[ps.face == 1] = [10.0, 5.0, 1.0]  # ceiling lights
    B, info = solve_radiosity(ff, rho, e, method="direct")
    H = ff.matvec(B)
    assert np.allclose(B, e + rho * H, rtol=1e-9)  # the solved equation
    emitted = ps.area @ e
    absorbed = ps.area @ ((1 - rho) * H)
    assert np.allclose(absorbed, emitted, rtol=0.01), (absorbed, emitted)


def test_gauss_seidel_agrees_with_direct_dense_and_sparse(closed_box):
    ps, ff = closed_box
    P = ps.n_patches
    rng = np.random.default_rng(1)
    rho = rng.uniform(0.0, 0.95, (P, 3))
    e = rng.uniform(0.0, 1.0, (P, 3)) * (rng.random((P, 1)) < 0.1)
    Bd, _ = solve_radiosity(ff, rho, e, method="direct")
    Bg, info = solve_radiosity(ff, rho, e, method="gauss-seidel", tol=1e-10)
    assert info["converged"] and info["residual"] <= 1e-10
    assert np.allclose(Bg, Bd, rtol=1e-7, atol=1e-9 * Bd.max())
    S = sp.csr_matrix(ff.matrix)
    Bs, info_s = solve_radiosity(S, rho, e, method="gauss-seidel", tol=1e-10)
    assert np.allclose(Bs, Bd, rtol=1e-7, atol=1e-9 * Bd.max())
    Bsd, _ = solve_radiosity(S, rho, e, method="direct")
    assert np.allclose(Bsd, Bd, rtol=1e-8)
    # residual reported = ||e - A B|| / ||e|| computed independently
    A = radiosity_matrix(ff, rho[:, 0])
    assert np.linalg.norm(e[:, 0] - A @ Bg[:, 0]) / np.linalg.norm(e[:, 0]) <= 1e-10


def test_warm_start_reduces_iterations(closed_box):
    ps, ff = closed_box
    P = ps.n_patches
    rho = np.full((P, 3), 0.8)
    e = np.zeros((P, 3))
    e[ps.face == 1] = 1.0
    B, cold = solve_radiosity(ff, rho, e, method="gauss-seidel")
    e2 = e.copy()
    e2[ps.face == 1] *= 1.05
    e2[ps.face == 0] = 0.05  # a small change of the lights
    B2c, cold2 = solve_radiosity(ff, rho, e2, method="gauss-seidel")
    B2w, warm = solve_radiosity(ff, rho, e2, method="gauss-seidel", x0=B)
    assert sum(warm["iterations"]) < sum(cold2["iterations"]), (warm, cold2)
    assert np.allclose(B2w, B2c, rtol=1e-4)


def test_radiosity_matrix_dense_and_sparse(closed_box):
    ps, ff = closed_box
    rho = np.linspace(0, 0.9, ps.n_patches)
    ref = np.eye(ps.n_patches) - rho[:, None] * ff.to_dense().astype(np.float64)
    assert np.allclose(radiosity_matrix(ff, rho), ref)
    As = radiosity_matrix(sp.csr_matrix(ff.matrix), rho)
    assert sp.issparse(As) and np.allclose(As.toarray(), ref)


def test_reflectance_one_is_clamped_with_warning(closed_box):
    ps, ff = closed_box
    P = ps.n_patches
    rho = np.ones((P, 3))
    e = np.ones((P, 3))
    B, info = solve_radiosity(ff, rho, e, method="direct")
    assert info["warnings"] and "clamped" in info["warnings"][0]
    assert np.all(np.isfinite(B))
    assert np.allclose(B, 1 / (1 - MAX_REFLECTANCE), rtol=1e-3)
    # Gauss-Seidel converges slowly at the clamped reflectance; it stays finite and says so
    B, info = solve_radiosity(ff, rho, e, method="gauss-seidel", max_iter=30)
    assert info["warnings"] and np.all(np.isfinite(B)) and not info["converged"]


def test_iteration_cap_returns_not_converged(closed_box):
    ps, ff = closed_box
    P = ps.n_patches
    B, info = solve_radiosity(ff, np.full((P, 3), 0.95), np.ones((P, 3)), method="gauss-seidel", max_iter=2)
    assert not info["converged"] and "max_iter" in info["message"]
    assert info["iterations"] == [2, 2, 2] and info["residual"] > 1e-6


def test_divergence_raises_clear_error():
    # row sums 2 (not a physical form-factor matrix): rho F has spectral radius 1.8
    F = np.full((4, 4), 2 / 3, dtype=np.float32)
    np.fill_diagonal(F, 0)
    with pytest.raises(RadiosityError, match="diverged"):
        solve_radiosity(F, np.full((4, 3), 0.9), np.ones((4, 3)), method="gauss-seidel")


def test_bad_inputs(closed_box):
    ps, ff = closed_box
    P = ps.n_patches
    with pytest.raises(RadiosityError, match="NaN"):
        solve_radiosity(ff, np.full((P, 3), 0.5), np.full((P, 3), np.nan))
    with pytest.raises(RadiosityError, match=">= 0"):
        solve_radiosity(ff, np.full((P, 3), -0.1), np.ones((P, 3)))
    with pytest.raises(ValueError, match="method"):
        solve_radiosity(ff, np.full((P, 3), 0.5), np.ones((P, 3)), method="jacobi")
    with pytest.raises(ValueError, match=r"\(P, 3\)"):
        solve_radiosity(ff, np.full((P + 1, 3), 0.5), np.ones((P, 3)))
    B, info = solve_radiosity(ff, np.full((P, 3), 0.5), np.zeros((P, 3)), method="gauss-seidel")
    assert np.all(B == 0) and info["converged"]


def test_lossless_patches_find_the_closed_white_class():
    # I - rho F is singular exactly when some patches keep all their light: reflectance 1, every
    # ray caught, and light sent only among themselves. The weighted form factors' rows are 1 only
    # to float32 rounding, so this is decided from the structure, and checked against the
    # smallest singular value of A.
    a = cf.box_polygons((1.0, 1.0, 1.0))
    b = [p + np.array([3.0, 0.0, 0.0]) for p in a]  # a second closed box, apart
    ps = mesh_patches(polygon_faceset(a + b), max_patch_size=0.5)
    F = compute_form_factors(ps, 512, seed=1)
    first = ps.face < 6
    for rho, want in [(np.ones(ps.n_patches), np.ones(ps.n_patches, bool)),  # both boxes white
                      (np.where(first, 1.0, 0.8), first),  # only the first
                      (np.where(ps.face == 0, 0.5, 1.0), ~first),  # one grey face drains its box
                      (np.full(ps.n_patches, 1 - 1e-3), np.zeros(ps.n_patches, bool))]:
        got = lossless_patches(F, rho)
        assert np.array_equal(got, want)
        smin = np.linalg.svd(radiosity_matrix(F, rho), compute_uv=False).min()
        assert (smin < 1e-5) == bool(want.any()), smin
    # an open scene (two squares facing each other) loses rays: never lossless, even white
    ps2 = mesh_patches(polygon_faceset(cf.parallel_rectangles_polygons(1, 1, 1)), max_patch_size=1e3)
    assert not lossless_patches(compute_form_factors(ps2, 512), np.ones(2)).any()
