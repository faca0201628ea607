"""engine/view_radiance.py: the radiance a patch shows along a view, gathered from the form
factors through the material's BSDF (the value against Cycles: test_cycles_principled.py)."""
import numpy as np

from relight_addon.engine.principled import PrincipledParams, principled_albedo
from relight_addon.engine.view_radiance import view_radiance


def _closed_scene(P=60, seed=2):
    rng = np.random.default_rng(seed)
    center = rng.normal(size=(P, 3))
    normal = -center / np.linalg.norm(center, axis=1, keepdims=True)  # points on a sphere, facing in
    F = rng.random((P, P))
    np.fill_diagonal(F, 0)
    F /= F.sum(axis=1, keepdims=True)
    return center, normal, F


def test_lambertian_view_radiance_is_b_over_pi():
    center, normal, F = _closed_scene()
    P = len(F)
    rho = np.full((P, 3), 0.6)
    e = np.zeros((P, 3))
    e[:5] = 3.0
    B = np.stack([np.linalg.solve(np.eye(P) - 0.6 * F, e[:, c]) for c in range(3)], axis=1)
    lobes = [[(1.0, "diffuse", (np.full(3, 0.6), 0.0))]]
    L = view_radiance(F, B, rho, center, normal, np.arange(P), np.zeros(P, dtype=int), lobes)
    np.testing.assert_allclose(L, B / np.pi, rtol=1e-9)


def test_uniform_light_shows_the_directional_albedo():
    """Under uniform incident radiance (every source of radiosity 1, seen over a full
    hemisphere of many small patches), a glossy patch shows R(mu = 1)/pi along its normal."""
    n = 60  # sources on a hemisphere of directions, cosine-weighted form factors
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, Ph = np.meshgrid(th, ph, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(Ph), np.sin(T) * np.sin(Ph), np.cos(T)], -1).reshape(-1, 3)
    dw = (np.sin(T) * (np.pi / 2 / n) * (2 * np.pi / (2 * n))).ravel()
    P = len(dirs) + 1
    center = np.vstack([[0, 0, 0], 10 * dirs])
    normal = np.vstack([[0, 0, 1], -dirs])
    F = np.zeros((P, P))
    F[0, 1:] = dirs[:, 2] * dw / np.pi
    B = np.ones((P, 3))
    B[0] = 0.0
    params = PrincipledParams(base_color=(0.5, 0.3, 0.1))
    lobes = [[(1.0, "principled", params)], [(1.0, "diffuse", (np.zeros(3), 0.0))]]
    material = np.r_[0, np.ones(P - 1, dtype=int)]
    rho = np.zeros((P, 3))  # so that e_0 = B_0 - rho F B = 0
    L = view_radiance(F, B, rho, center, normal, [0], material, lobes)
    np.testing.assert_allclose(L[0] * np.pi, principled_albedo(params).normal, rtol=0.01)


def test_lamp_lit_lambertian_view_radiance_is_b_over_pi():
    """Lit by emitters and by lamps (direct irradiance H, B = A^-1 (e + rho H)), a Lambertian
    scene shows B / pi whichever way the sources' light is gathered: the lamps' light reflected
    by the neighbours counts as much as the emitters' (it was left out of the glossy gathering)."""
    center, normal, F = _closed_scene()
    P = len(F)
    rho = np.full((P, 3), 0.6)
    e = np.zeros((P, 3))
    e[:5] = 3.0
    rng = np.random.default_rng(4)
    H1, H2 = rng.random((P, 3)) * 2.0, rng.random((P, 3))
    B = np.stack([np.linalg.solve(np.eye(P) - 0.6 * F, e[:, c] + 0.6 * (H1 + H2)[:, c]) for c in range(3)], axis=1)
    lobes = [[(1.0, "diffuse", (np.full(3, 0.6), 0.0))]]
    lamp = center[0] * 0.2
    towards = (lamp - center) / np.linalg.norm(lamp - center, axis=1, keepdims=True)
    for glossy in (True, False):
        L = view_radiance(F, B, rho, center, normal, np.arange(P), np.zeros(P, dtype=int), lobes, exitance=e,
                          source_glossy=glossy, lamp_light=[(towards, H1), (None, H2)])
        np.testing.assert_allclose(L, B / np.pi, rtol=1e-9)


def test_the_kernel_correction_reaches_the_sources_glossy_reflection():
    """``direct_correction`` X (the kernel's direct light beyond F's gather) counts in the sources'
    glossy reflection of the emitters exactly as if F's emitter columns were F + X (for viewed
    patches whose own rows X leaves alone), and it changes what a glossy scene shows."""
    import scipy.sparse as sp

    center, normal, F = _closed_scene()
    P = len(F)
    rho = np.full((P, 3), 0.5)
    rho[:5] = 0.0  # black emitters: F + X then gathers e from them, as the correction does
    e = np.zeros((P, 3))
    e[:5] = 3.0
    B = np.stack([np.linalg.solve(np.eye(P) - rho[:, c:c + 1] * F, e[:, c]) for c in range(3)], axis=1)
    lobes = [[(1.0, "principled", PrincipledParams(base_color=(0.6, 0.6, 0.6), roughness=0.3))]]
    X = np.zeros((P, P))
    X[20:, :5] = np.random.default_rng(3).random((P - 20, 5)) * 0.02
    viewed = np.arange(5, 20)
    args = (rho, center, normal, viewed, np.zeros(P, dtype=int), lobes)
    L0 = view_radiance(F, B, *args, exitance=e)
    L1 = view_radiance(F, B, *args, exitance=e, direct_correction=sp.csc_matrix(X))
    L2 = view_radiance(F + X, B, *args, exitance=e)
    np.testing.assert_allclose(L1, L2, rtol=1e-9)
    assert np.max(np.abs(L1 / L0 - 1)) > 1e-3
