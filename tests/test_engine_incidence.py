"""engine/incidence.py: the lights' first reflection with the albedo of its incidence.

References: Cycles' BSDF (engine/principled.py's BRDFTable) integrated by brute force over the
outgoing directions, the white-furnace albedo (the table's cosine-weighted mean), Lambert (no
dependence at all), and the
inverse problem's own identities (T e and the forward solve agree; the paper's substitution
meets the targets exactly).
"""
import numpy as np
import pytest

from relight_addon.engine.incidence import INCIDENCE_MU, first_bounce_matrices, incidence_tables
from relight_addon.engine.inverse import InverseProblem, solve_inverse
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.principled import BRDFTable, PrincipledParams, principled_albedo


def _table(**kw):
    return incidence_tables([[(1.0, "principled", PrincipledParams(**kw))]])[0]


def _mean(t):
    return 2 * np.trapz(t * INCIDENCE_MU[:, None], INCIDENCE_MU, axis=0)


def _integrated(params, mu, n_mu=96, n_phi=192):
    """The reference: Cycles' BSDF (engine.principled.BRDFTable) for light incident at cosine mu,
    integrated over the outgoing directions (Gauss-Legendre in cos, uniform in azimuth)."""
    x, w = np.polynomial.legendre.leggauss(n_mu)
    mo, wmo = (x + 1) / 2, w / 2
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    MU, PHI = np.meshgrid(mo, phi, indexing="ij")
    s = np.sqrt(1 - MU ** 2)
    V = np.stack([s * np.cos(PHI), s * np.sin(PHI), MU], -1).reshape(-1, 3)
    W = (wmo[:, None] * MU * 2 * np.pi / n_phi).reshape(-1)
    brdf = BRDFTable([(1.0, "principled", params)])
    l = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    return (brdf(V, np.broadcast_to(l, V.shape)) * W[:, None]).sum(axis=0)


@pytest.mark.parametrize("kw", [{}, {"base_color": (0.45, 0.32, 0.22)}, {"base_color": (0.0, 0.0, 0.0)},
                                {"base_color": (0.1, 0.6, 0.9), "roughness": 0.3}, {"roughness": 0.7},
                                {"base_color": (0.8, 0.8, 0.8), "roughness": 0.9, "ior": 1.45}])
def test_table_is_the_bsdf_integrated_over_outgoing_directions(kw):
    t = _table(**kw)
    np.testing.assert_allclose(_mean(t), principled_albedo(PrincipledParams(**kw)).albedo, rtol=1e-9)
    for mu in (0.2, 0.5, 0.8, 1.0):
        ref = _integrated(PrincipledParams(**kw), mu)
        got = np.array([np.interp(mu, INCIDENCE_MU, t[:, c]) for c in range(3)])
        # absolute: Cycles' energy compensation is not exactly reciprocal (~1 % of the lobe)
        np.testing.assert_allclose(got, ref, atol=0.006, err_msg=f"mu {mu}")


def test_grazing_light_is_reflected_more():
    t = _table(base_color=(0.45, 0.32, 0.22))
    assert np.all(t[2] > t[-1] + 0.05)  # mu = 0.05 against mu = 1: the specular layer's Fresnel
    assert np.all(np.diff(t[5:, 0]) < 0)  # decreasing from grazing to normal incidence


def test_lambertian_materials_have_no_table():
    assert incidence_tables([[(1.0, "diffuse", (np.array([0.5, 0.4, 0.3]), 0.0))],
                             [(1.0, "principled", PrincipledParams(specular_ior_level=0.0))]]) == [None, None]


def _two_walls():
    """A floor patch (0) lit by a small lamp (1) at 30 degrees elevation, plus a third patch."""
    center = np.array([[0.0, 0, 0], [np.cos(np.pi / 6) * 2, 0, np.sin(np.pi / 6) * 2], [0, 3, 1]])
    normal = np.array([[0.0, 0, 1], [-1.0, 0, 0], [0, -1.0, 0]])
    F = np.array([[0.0, 0.01, 0.2], [0.3, 0.0, 0.1], [0.2, 0.05, 0.0]])
    return center, normal, F


def test_first_bounce_matrix_entries():
    center, normal, F = _two_walls()
    p = PrincipledParams(base_color=(0.45, 0.32, 0.22))
    tables = incidence_tables([[(1.0, "principled", p)]])
    rho = np.tile(principled_albedo(p).albedo, (3, 1))
    D = first_bounce_matrices(F, center, normal, np.zeros(3, int), tables, [1])
    mu = float(np.dot((center[1] - center[0]) / np.linalg.norm(center[1] - center[0]), normal[0]))
    R = np.array([np.interp(mu, INCIDENCE_MU, tables[0][:, c]) for c in range(3)])
    for c in range(3):
        assert D[c][0, 1] == pytest.approx((R[c] - _mean(tables[0])[c]) * F[0, 1], rel=1e-6)  # float32
        assert D[c][0, 1] == pytest.approx((R[c] - rho[0, c]) * F[0, 1], rel=1e-6)  # mean = rho
        assert D[c][:, [0, 2]].nnz == 0  # only the source column
    assert first_bounce_matrices(F, center, normal, np.zeros(3, int), [None], [1]) is None


def test_inverse_problem_with_first_bounce_is_consistent():
    rng = np.random.default_rng(3)
    n = 40
    F = rng.random((n, n)) * (rng.random((n, n)) < 0.3)
    np.fill_diagonal(F, 0)
    F /= F.sum(axis=1, keepdims=True) * 1.05
    rho = rng.uniform(0.3, 0.8, (n, 3))
    target = np.zeros(n, bool)
    target[:6] = True
    cand = np.zeros(n, bool)
    cand[20:] = True
    b = np.zeros((n, 3))
    b[:6] = rng.uniform(1, 2, (6, 3))
    prob = InverseProblem(F, np.ones(n), rho, [PaintedRadiance.masked(target, b)], cand)
    D = [np.zeros((n, n)) for _ in range(3)]
    for c in range(3):
        D[c][:, 20:] = 0.1 * F[:, 20:] * (c + 1)
    import scipy.sparse as sp
    prob.first_bounce = [sp.csr_matrix(d) for d in D]
    e = rng.uniform(0, 5, (prob.n_lights, 3))
    B = prob.forward_radiosity(prob.patch_exitance(e))
    np.testing.assert_allclose(prob.target_radiosity_of(e), B[:6], rtol=1e-9)
    # the forward solve is A B = e + D e
    ef = prob.patch_exitance(e)
    for c in range(3):
        A = np.eye(n) - rho[:, c:c + 1] * F
        np.testing.assert_allclose(A @ B[:, c], ef[:, c] + D[c] @ ef[:, c], atol=1e-9)
    # both unconstrained formulations meet the targets exactly, with the same correction
    for solver in ("svd", "reduced"):
        res = solve_inverse(prob, solver=solver)
        assert prob.relative_error(res.exitance) < 1e-8, solver


def test_chunks_and_storage_do_not_change_d(monkeypatch):
    """Sparse or dense F, whole or by chunks of columns: the same D."""
    import scipy.sparse as sp

    from relight_addon.engine import incidence

    rng = np.random.default_rng(5)
    n = 30
    F = rng.random((n, n)) * (rng.random((n, n)) < 0.4)
    center = rng.normal(size=(n, 3))
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    tables = incidence_tables([[(1.0, "principled", PrincipledParams(base_color=(0.3, 0.5, 0.7)))],
                               [(1.0, "diffuse", (np.array([0.5, 0.5, 0.5]), 0.0))]])
    material = rng.integers(0, 2, n)
    sources = rng.choice(n, 12, replace=False)
    whole = first_bounce_matrices(F, center, normal, material, tables, sources)
    monkeypatch.setattr(incidence, "CHUNK_ENTRIES", 7)
    chunked = first_bounce_matrices(sp.csr_matrix(F), center, normal, material, tables, sources)
    for a, b in zip(whole, chunked):
        np.testing.assert_array_equal(a.toarray(), b.toarray())
        assert a.nnz > 0
        cols = np.flatnonzero(np.abs(a.toarray()).sum(axis=0))
        assert set(cols) <= set(sources)  # only the sources' columns
        rows = np.flatnonzero(np.abs(a.toarray()).sum(axis=1))
        assert np.all(material[rows] == 0)  # only glossy receivers
