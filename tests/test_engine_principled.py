"""engine/principled.py without Blender: the GGX integrals against a brute-force hemisphere
integral, and properties the model must have. (Against Cycles itself: test_cycles_materials.py.)"""
import numpy as np
import pytest

from relight_addon.engine import principled as P


def ggx_albedo_brute_force(alpha, mu, n=800):
    """int_{H^2} D G2 / (4 mu) dw_o on a (theta_o, phi_o) midpoint grid: independent of the
    visible-normal parametrisation the module integrates with."""
    th = (np.arange(n) + 0.5) / n * np.pi / 2
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    T, Ph = np.meshgrid(th, ph, indexing="ij")
    ox, oy, oz = np.sin(T) * np.cos(Ph), np.sin(T) * np.sin(Ph), np.cos(T)
    hx, hy, hz = ox + np.sqrt(1 - mu * mu), oy, oz + mu
    hz = hz / np.sqrt(hx ** 2 + hy ** 2 + hz ** 2)
    a2 = alpha * alpha
    D = a2 / (np.pi * ((1 - hz ** 2) + a2 * hz ** 2) ** 2)
    lam = lambda c: 0.5 * (np.sqrt(1 + a2 * (1 / c ** 2 - 1)) - 1)  # noqa: E731
    G2 = 1 / (1 + lam(mu) + lam(oz))
    dw = np.sin(T) * (np.pi / 2 / n) * (2 * np.pi / (2 * n))
    return float(np.sum(D * G2 / (4 * mu) * dw))


@pytest.mark.parametrize("roughness", [0.3, 0.5, 1.0])
def test_ggx_albedo_against_brute_force(roughness):
    mus = [0.1, 0.4, 0.8, 1.0]
    got = P.ggx_albedo(roughness, mus)
    ref = [ggx_albedo_brute_force(roughness ** 2, m) for m in mus]
    np.testing.assert_allclose(got, ref, atol=2e-3)
    assert np.all(got < 1.0)  # single scattering loses energy (what Cycles compensates)


def test_fresnel_closed_forms():
    assert P.fresnel_dielectric(1.0, 1.5) == pytest.approx(0.04)
    assert P.fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)
    assert P.fresnel_dielectric(0.3, 1 / 1.5) == 1.0  # total internal reflection (sin > 1/1.5)
    assert float(P.ior_from_F0(P.F0_from_ior(1.45))) == pytest.approx(1.45)
    # Fresnel reflectance under uniform light (published: ~0.092 for n = 1.5)
    assert P.hemispherical_fresnel(1.5) == pytest.approx(0.092, abs=0.001)


def test_specular_level_zero_is_lambert_and_layers_conserve_energy():
    a = P.principled_albedo(base_color=(0.3, 0.5, 0.7), specular_ior_level=0.0)
    np.testing.assert_allclose(a.albedo, [0.3, 0.5, 0.7], atol=1e-12)
    np.testing.assert_allclose(a.specular, 0.0)
    # a white base under a specular layer: the layering gives back (nearly) all the light
    for r in (0.0, 0.5, 1.0):
        w = P.principled_albedo(base_color=(1, 1, 1), roughness=r).albedo
        assert np.all(np.abs(w - 1.0) < 0.005), (r, w)
    # a black base reflects only the specular layer, more at grazing angles than along the normal
    k = P.principled_albedo(base_color=(0, 0, 0), roughness=0.5)
    assert np.all(k.albedo > k.normal) and np.all(k.normal > 0.03)
    # the specular layer adds more than it takes from a dark base, and never creates light
    assert np.all(P.principled_albedo(base_color=(0.1,) * 3).albedo > 0.1)
    assert np.all(P.principled_albedo(base_color=(1.0,) * 3, roughness=0.3).albedo <= 1.0)


def test_f82_tint_definition():
    """F82-tint: Schlick(cos) - b cos (1 - cos)^6 equals Schlick x tint at cos = 1/7."""
    f0, tint = np.array([0.9, 0.6, 0.3]), np.array([0.5, 0.8, 1.0])
    b = P.f82_b(f0, tint)
    c = 1 / 7
    schlick = f0 + (1 - f0) * (1 - c) ** 5
    np.testing.assert_allclose(schlick - b * c * (1 - c) ** 6, schlick * tint)


def test_oren_nayar():
    # sigma 0 is Lambert; the energy-preserving term keeps a white surface near 1
    np.testing.assert_allclose(P.oren_nayar_albedo((0.4, 0.5, 0.6), 0.0), [0.4, 0.5, 0.6])
    white = P.oren_nayar_albedo((1, 1, 1), 1.0)
    assert np.all(np.abs(white - 1) < 0.02), white
    dark = P.oren_nayar_albedo((0.5, 0.5, 0.5), 1.0)
    assert np.all(dark < 0.5)  # multiple scattering does not give back what a grey surface absorbs


def _direct_terms(rough, mus, eta=None, exponents=()):
    """The VNDF averages by the quadrature at this roughness itself (no roughness nodes, no c
    nodes): sums over the samples."""
    c, gw, vw = P._vndf_samples(rough, mus)
    out = {"E": gw.sum(1), "EB5": (gw * (1 - c) ** 5).sum(1), "EB6": (gw * c * (1 - c) ** 6).sum(1)}
    if eta is not None:
        F = P.fresnel_dielectric(c, eta)
        F0 = float(P.F0_from_ior(eta))
        sh = np.clip((F - F0) / (1 - F0), 0, 1)
        out.update(EF=(gw * F).sum(1), ES=(gw * sh).sum(1), S=(vw * sh).sum(1))
    for p in exponents:
        out[f"S{p}"] = (vw * (1 - c) ** p).sum(1)
    return out


def _clear_caches():
    for f in (P._vndf_node, P._node_terms, P._fresnel_on_nodes, P._vndf_terms, P._albedo_cached):
        f.cache_clear()


def test_many_roughnesses_share_the_tabulated_nodes(monkeypatch):
    """Issue 19, case 6: the quadrature runs once per roughness node, not per material: 300
    materials of distinct roughness and IOR cost at most ROUGH_NODES quadratures per set of view
    cosines; and what the nodes give is the quadrature at the material's own roughness, within
    about that quadrature's own error (~1e-3 at a grazing view, a few 1e-4 on an albedo)."""
    _clear_caches()
    calls = []
    samples = P._vndf_samples
    monkeypatch.setattr(P, "_vndf_samples", lambda rough, mus: calls.append(mus) or samples(rough, mus))
    rng = np.random.default_rng(3)
    params = [P.PrincipledParams(base_color=tuple(rng.random(3)), roughness=float(rng.random()),
                                 metallic=float(k % 4 == 0), ior=float(1.3 + 0.4 * rng.random()))
              for k in range(300)]
    got = [P.principled_albedo(p) for p in params]
    per_set = {mus: calls.count(mus) for mus in set(calls)}
    assert max(per_set.values()) <= P.ROUGH_NODES, {len(m): n for m, n in per_set.items()}
    assert len(calls) < 4 * P.ROUGH_NODES  # the Gauss nodes, mu = 1, and Cycles' two table grids

    monkeypatch.setattr(P, "_vndf_terms", _direct_terms)
    P._albedo_cached.cache_clear()
    ref = [P.principled_albedo(p) for p in params[:60]]
    d_rho = max(np.abs(a.albedo - b.albedo).max() for a, b in zip(got, ref))
    d_r1 = max(np.abs(a.normal - b.normal).max() for a, b in zip(got, ref))
    monkeypatch.undo()
    _clear_caches()  # nothing computed with the direct quadrature stays cached
    assert 0 < d_rho < 1e-3 and d_r1 < 2e-3, (d_rho, d_r1)


@pytest.mark.parametrize("rough", [0.0, 0.02, 0.137, 0.5, 0.93, 1.0])
def test_node_interpolation_against_the_direct_quadrature(rough):
    """Every VNDF average, read from the roughness nodes, against the quadrature at that
    roughness: pointwise over the view cosines, including grazing ones."""
    mus = tuple(P._gauss_mu()[0])
    got = P._vndf_terms(rough, mus, 1.45, (4.0,))
    ref = _direct_terms(rough, mus, 1.45, (4.0,))
    assert got.keys() == ref.keys()
    for k in got:
        np.testing.assert_allclose(got[k], ref[k], atol=2e-3, err_msg=k)
