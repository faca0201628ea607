"""CIE 171:2006's analytical test cases that a radiosity model can hold (issue 39), each against its
closed form within 1 % (docs/validation.md, "CIE 171:2006 test cases").

- Area sources (CIE 171's Lambertian surface sources and diffusely lit surfaces, whose reference
  is a configuration factor): a Lambertian rectangle of exitance M over a
  horizontal plane (parallel) and beside a vertical one (perpendicular); a point's illuminance is
  M x the point-to-rectangle configuration factor (Howell B-3, B-2: engine.closed_forms), a patch's
  the mean of it over the patch (8 x 8 Gauss-Legendre points). Held three ways: the emitting face
  through the forward `radiosity` job (ray-cast form factors), through the kernel transport the
  inverse solve uses from lights to targets, and as a Blender Area lamp (engine.lamps).
- Interreflection in an empty room (CIE 171 5.8: a 4 m cube, every surface one reflectance rho):
  the area-mean interreflected illuminance is Phi rho / (S_T (1 - rho)) in any closed enclosure
  (flux conservation), and the cube's radiosity at 6 patches is the 6 x 6 system of Howell's
  exact wall-to-wall form factors (C-11 opposite, C-14 adjacent).
- An internal obstruction (CIE 171 5.7): a partition hides part of the source; the reference is
  the configuration factor of the part each point sees (as Ashdown's CIE 171:2006 errata recompute
  5.7's Table 19).
- The same partition drawn as two coincident faces back to back (engine.coincident).
- Not held, as a strict xfail (it passes when the cause is fixed): 5.9's roof opening under a
  uniform sky.
- The point sources (CIE 171 5.2) are tests/test_photometry.py::test_cie171_point_source_over_a_work_plane.

The report itself was not at hand (it is sold by the CIE): the geometry of 5.8 (a 4 m cube, S_T =
96 m^2) and 5.9 (a 1 m x 1 m roof opening) is CIE 171's as public validation reports give it; the
other cases' sizes are this file's own, the closed forms the ones CIE 171's references use.

Illuminance here is in W/m^2 of each channel (grey light: the three channels are equal); lux is
683 lm/W x that (engine.units), a constant factor the relative errors do not see.
"""
import math

import numpy as np
import pytest

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.formfactors import compute_form_factors
from relight_addon.engine.lamps import Lamp, lamp_irradiance
from relight_addon.engine.lights.area import AREA
from relight_addon.engine.lights.point import POINT
from relight_addon.engine.options import JobOptions
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from relight_addon.pipeline.jobs import run_radiosity

DOWN, X, Y = np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])

# ------------------------------------------------------------------ the area source (5.3, 5.5-5.6)
#: the luminous rectangle: 2 m x 1 m, centred over the origin at 3 m, facing down, exitance M
SRC_U, SRC_V, SRC_Z, M = (-1.0, 1.0), (-0.5, 0.5), 3.0, 100.0
#: the horizontal plane (parallel to the source): 4 m x 4 m at 0.8 m (a work plane's height), 8 x 8
#: patches; the vertical plane (perpendicular): y = 2 m, x in [-2, 2], z in [0.8, 2.8], 8 x 4 patches
PLANE_Z, WALL_Y = 0.8, 2.0
RHO = 0.5  # the receivers' reflectance: their radiosity is RHO x the illuminance (the source is black)
#: rays per patch of the forward job: its largest per-patch error over seeds 0-2 was 0.29 %
#: (parallel) and 0.65 % (perpendicular) at 2^19 rays; 0.73 % and 0.98 % at 2^18
FORWARD_RAYS = 1 << 19
GAUSS = np.polynomial.legendre.leggauss(8)


def _grid(a, b, n, m, point):
    """n x m quads over [a0, a1] x [b0, b1], vertices ``point(s, t)``, in the order point gives."""
    sa, sb = np.linspace(*a, n + 1), np.linspace(*b, m + 1)
    return [np.array([point(sa[i], sb[j]), point(sa[i + 1], sb[j]), point(sa[i + 1], sb[j + 1]),
                      point(sa[i], sb[j + 1])], dtype=np.float64) for j in range(m) for i in range(n)]


def _source():
    (u0, u1), (v0, v1) = SRC_U, SRC_V
    return np.array([[u0, v0, SRC_Z], [u0, v1, SRC_Z], [u1, v1, SRC_Z], [u1, v0, SRC_Z]])  # faces -z


def _receivers(plane):
    if plane == "parallel":  # faces +z
        return _grid((-2.0, 2.0), (-2.0, 2.0), 8, 8, lambda x, y: (x, y, PLANE_Z))
    return _grid((-2.0, 2.0), (PLANE_Z, 2.8), 8, 4, lambda x, z: (x, WALL_Y, z))  # faces -y


def _patch_mean(a, b, f):
    """The mean of f over [a0, a1] x [b0, b1] (8 x 8 Gauss-Legendre)."""
    g, w = GAUSS
    s = a[0] + 0.5 * (g + 1) * (a[1] - a[0])
    t = b[0] + 0.5 * (g + 1) * (b[1] - b[0])
    return sum(wi * wj * f(si, tj) for si, wi in zip(s, w) for tj, wj in zip(t, w)) / 4.0


def _closed_form(plane, quads):
    """Per receiver quad, M x its mean configuration factor to the source (W/m^2)."""
    (u0, u1), (v0, v1) = SRC_U, SRC_V
    out = []
    for q in quads:
        lo, hi = q.min(axis=0), q.max(axis=0)
        if plane == "parallel":
            c = SRC_Z - PLANE_Z
            f = lambda x, y: cf.point_to_parallel_rectangle(u0 - x, u1 - x, v0 - y, v1 - y, c)  # noqa: E731
            out.append(M * _patch_mean((lo[0], hi[0]), (lo[1], hi[1]), f))
        else:  # the source's plane z = SRC_Z is at d = SRC_Z - z from the point; it spans WALL_Y - y in [1.5, 2.5]
            f = lambda x, z: cf.point_to_perpendicular_rectangle(  # noqa: E731
                u0 - x, u1 - x, WALL_Y - v1, WALL_Y - v0, SRC_Z - z)
            out.append(M * _patch_mean((lo[0], hi[0]), (lo[2], hi[2]), f))
    return np.array(out)


def _area_scene(plane, work_plane=False):
    quads = _receivers(plane)
    n = len(quads)
    faces = polygon_faceset([_source()] + quads, reflectance=np.r_[0.0, np.full(n, RHO)],
                            exitance=np.r_[M, np.zeros(n)])
    if work_plane:
        faces.passes = np.r_[False, np.ones(n, dtype=bool)]
    return faces, _closed_form(plane, quads)


def test_point_to_rectangle_closed_forms_against_quadrature():
    """The references themselves: Howell B-3 and B-2 by superposition of signed corners against a
    1500 x 1500 midpoint quadrature of cos cos / (pi r^2) over the rectangle, within 1e-6 relative,
    with the rectangle straddling the normal's foot, beside it, and lifted off the element's plane."""
    m = 1500
    g = (np.arange(m) + 0.5) / m
    for u0, u1, v0, v1, c in [(0, 2, 0, 1, 1.5), (-1, 2, -0.5, 1, 2.2), (0.5, 2, 0.3, 1, 0.7)]:
        U, V = np.meshgrid(u0 + g * (u1 - u0), v0 + g * (v1 - v0))
        q = (c * c / (math.pi * (U * U + V * V + c * c) ** 2)).mean() * (u1 - u0) * (v1 - v0)
        assert cf.point_to_parallel_rectangle(u0, u1, v0, v1, c) == pytest.approx(q, rel=1e-6)
    for u0, u1, h0, h1, d in [(0, 2, 0, 1, 1.5), (-1, 2, 0, 1, 2.2), (-0.5, 2, 0.3, 1.7, 0.7)]:
        U, H = np.meshgrid(u0 + g * (u1 - u0), h0 + g * (h1 - h0))
        r2 = U * U + d * d + H * H
        q = (H * d / (math.pi * r2 * r2)).mean() * (u1 - u0) * (h1 - h0)
        assert cf.point_to_perpendicular_rectangle(u0, u1, h0, h1, d) == pytest.approx(q, rel=1e-6)
    with pytest.raises(ValueError, match="in front of the element"):
        cf.point_to_perpendicular_rectangle(0, 1, 1.0, 0.5, 1.0)


@pytest.mark.parametrize("plane", ["parallel", "perpendicular"])
def test_cie171_area_source_forward_radiosity(plane):
    """The luminous rectangle as an emitting face, the receivers ordinary grey faces (the source
    is black, so a receiver's radiosity is RHO x its illuminance exactly: the receivers of one plane
    do not see each other), through the forward `radiosity` job (run_radiosity, the polygon patch
    model, 2^19 rays per patch): every patch within 1 % of M x its mean configuration factor."""
    faces, ref = _area_scene(plane)
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=10.0,
                                             rays_per_patch=FORWARD_RAYS, threads=2))
    assert res.patches.n_patches == len(ref) + 1
    E = res.face_radiosity[1:] / RHO
    assert np.allclose(E, E[:, :1], rtol=1e-6)  # grey
    rel = np.abs(E[:, 0] - ref) / ref
    print(f"{plane}: {len(ref)} patches, mean {rel.mean():.5f} max {rel.max():.5f}")
    assert rel.max() < 0.01, (rel.max(), rel.mean())
    assert abs(E[:, 0].sum() / ref.sum() - 1) < 0.002  # the plane's flux


@pytest.mark.parametrize("plane", ["parallel", "perpendicular"])
def test_cie171_area_source_kernel_transport(plane):
    """The same source and patches through the transport the inverse solve uses from candidate
    lights to targets (compute_form_factors' kernel pairs: the point-to-polygon kernel x shadow
    rays): every patch within 1e-4 of the closed form (the kernel is analytic; the reference is
    another closed form, Howell's corners, and another quadrature)."""
    faces, ref = _area_scene(plane)
    ps = mesh_patches(faces, 10.0)
    F = compute_form_factors(ps, rays_per_patch=1024, threads=2, kernel_pairs=(np.arange(1, ps.n_patches), [0]))
    E = np.asarray(F.matrix, dtype=np.float64)[1:, 0] * M
    rel = np.abs(E - ref) / ref
    print(f"{plane}: kernel max {rel.max():.2e}")
    assert rel.max() < 1e-4


@pytest.mark.parametrize("plane", ["parallel", "perpendicular"])
def test_cie171_area_source_as_an_area_lamp(plane):
    """The luminous rectangle as a Blender Area lamp (Spread 180 degrees: Lambertian, one-sided,
    power M x its area): engine.lamps' direct irradiance. At 256 points per patch every patch
    within 1 %; at the default (lamps.POINTS_PER_PATCH, 64) the plane's total within 0.1 % and each
    patch within 1.5 % (measured: 0.65 % parallel, 1.4 % perpendicular: the wall's patches the
    rectangle lights at grazing angles)."""
    quads = _receivers(plane)
    ref = _closed_form(plane, quads)
    ps = mesh_patches(polygon_faceset(quads, reflectance=RHO), 10.0)
    area = (SRC_U[1] - SRC_U[0]) * (SRC_V[1] - SRC_V[0])
    lamp = Lamp("panel", AREA, (0.0, 0.0, SRC_Z), DOWN, X, Y, (M * area,) * 3,
                size_u=SRC_U[1] - SRC_U[0], size_v=SRC_V[1] - SRC_V[0])
    fine = lamp_irradiance(ps, [lamp], points_per_patch=256)[:, 0, 0]
    rel = np.abs(fine - ref) / ref
    assert rel.max() < 0.01, rel.max()
    default = lamp_irradiance(ps, [lamp])[:, 0, 0]
    rel_d = np.abs(default - ref) / ref
    print(f"{plane}: 256 points max {rel.max():.5f}; default max {rel_d.max():.5f}")
    assert abs(default.sum() / ref.sum() - 1) < 0.001
    assert rel_d.max() < 0.015


def test_cie171_area_source_on_a_work_plane():
    """The horizontal receivers as a Work Plane (light passes through it; the rays of other patches
    never see it) through the forward job: each patch within 1 % of the closed form. It failed
    (about 6 % low) while the ray-cast form factors' reciprocity weighting averaged the work plane's
    rays with the source's, which count no hit on it (engine.formfactors.weigh_reciprocity now
    keeps a work plane's own rays). The inverse solve's lights -> targets pairs use the kernel
    (test_cie171_area_source_kernel_transport), not these rays."""
    faces, ref = _area_scene("parallel", work_plane=True)
    # 2^18 rays: a work plane's rows are its own rays only (no second estimate to weigh with), so
    # their noise is the rays' (2^16: max 1.4 %, mean -0.02 %; 2^18: max 0.63 %)
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=10.0,
                                             rays_per_patch=1 << 18, threads=2))
    E = res.face_radiosity[1:, 0] / RHO
    assert abs(np.mean(E / ref) - 1) < 0.002  # no bias (it was about -6 %)
    assert np.max(np.abs(E - ref) / ref) < 0.01



# ------------------------------------------------------------------ an internal obstruction (5.7)
#: a black partition in the plane x = 0 standing on the receiving plane, up to PARTITION_TOP (below
#: the source): it hides from a point (x_p, y_p) at PLANE_Z the source's far side beyond
#: x_p (1 - 1/t), t = (PARTITION_TOP - PLANE_Z) / (SRC_Z - PLANE_Z), whatever y: the part it sees
#: is still a rectangle, so the reference stays Howell B-3 (of the unobstructed part, as CIE 171 5.7)
PARTITION_TOP = 2.0


def _seen_part(x):
    """The source's x-interval a point at x on the plane sees over the partition."""
    t = (PARTITION_TOP - PLANE_Z) / (SRC_Z - PLANE_Z)
    return (SRC_U[0], min(SRC_U[1], x * (1 - 1 / t))) if x < 0 else (max(SRC_U[0], x * (1 - 1 / t)), SRC_U[1])


def _obstructed(x, y):
    a, b = _seen_part(x)
    return 0.0 if b <= a else cf.point_to_parallel_rectangle(a - x, b - x, SRC_V[0] - y, SRC_V[1] - y,
                                                             SRC_Z - PLANE_Z)


def _partition_scene(partition):
    """The source, the half plane y in [0, 2] (8 x 4 patches; the other half is its mirror) and
    ``partition`` (faces), black; the closed form per receiver patch (16 x 16 Gauss points: the
    seen part's edge bends the integrand; 8 x 8 differ from 32 x 32 by 2.4e-4, 16 x 16 by 3e-5)."""
    quads = _grid((-2.0, 2.0), (0.0, 2.0), 8, 4, lambda x, y: (x, y, PLANE_Z))
    g, w = np.polynomial.legendre.leggauss(16)
    ref = []
    for q in quads:
        lo, hi = q.min(axis=0), q.max(axis=0)
        s, t = lo[0] + 0.5 * (g + 1) * (hi[0] - lo[0]), lo[1] + 0.5 * (g + 1) * (hi[1] - lo[1])
        ref.append(M * sum(wi * wj * _obstructed(si, tj) for si, wi in zip(s, w) for tj, wj in zip(t, w)) / 4)
    n, k = len(quads), len(partition)
    faces = polygon_faceset([_source()] + quads + partition, reflectance=np.r_[0.0, np.full(n, RHO), np.zeros(k)],
                            exitance=np.r_[M, np.zeros(n + k)])
    return faces, np.array(ref)


#: the partition: one face (occluding from both sides, as Cycles' does), facing -x
PARTITION = np.array([(0, -2.5, PLANE_Z), (0, -2.5, PARTITION_TOP), (0, 2.5, PARTITION_TOP), (0, 2.5, PLANE_Z)],
                     dtype=np.float64)


def test_cie171_area_source_with_an_obstruction():
    """CIE 171 5.7's point: an obstruction hides part of a diffuse source. The partition hides the
    source's far side from each floor patch (fully from the patches next to it, partly further
    out); through the forward job (2^19 rays a patch) every patch within 1 % of M x the
    configuration factor of the part it sees. (The kernel transport the solve uses from lights to
    targets is 3 % to 6 % off at most, 1 % on average, in the partly shadowed patches (seeds 0
    and 1): its shadow rays sample the penumbra; measured, not asserted.)"""
    faces, ref = _partition_scene([PARTITION])
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=10.0,
                                             rays_per_patch=FORWARD_RAYS, threads=2))
    E = res.face_radiosity[1:len(ref) + 1, 0] / RHO
    rel = np.abs(E - ref) / ref
    print(f"obstruction: {len(ref)} patches, mean {rel.mean():.5f} max {rel.max():.5f}")
    assert rel.max() < 0.01
    seen = np.array([_seen_part(x)[1] - _seen_part(x)[0] for x in (-1.75, -0.25)])
    assert seen[1] < 0.65 * seen[0]  # the partition does hide 40 % of it next to it: not the unobstructed case


@pytest.mark.parametrize("first", ["-x", "+x"])
def test_cie171_obstruction_of_two_coincident_faces(first):
    """The same partition drawn as two coincident faces back to back (one facing -x, one +x), as
    a model with both sides of a thin wall has them, listed either way round: every floor patch
    within 2 % of the closed form at 2^16 rays (measured: max 1.3 %, as one face at these rays).
    It failed (strict xfail) while Embree's choice between the coincident faces gave the floor's
    rays a hit on the back of the first listed face, absorbed and counted for no patch, while the
    face that faces the floor counted its own rays' hits on it; weigh_reciprocity's row scaling
    then took 7 % of the light off that side of the floor on average, 20 % next to the partition
    (engine.coincident: a ray now hits the twin facing it; tests/test_engine_coincident.py)."""
    pair = [PARTITION, PARTITION[::-1].copy()]
    faces, ref = _partition_scene(pair if first == "-x" else pair[::-1])
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=10.0,
                                             rays_per_patch=1 << 16, threads=2))
    E = res.face_radiosity[1:len(ref) + 1, 0] / RHO
    rel = np.abs(E - ref) / ref
    print(f"coincident, {first} first: mean {rel.mean():.5f} max {rel.max():.5f}")
    assert rel.max() < 0.02
    assert abs(E.sum() / ref.sum() - 1) < 0.005  # the floor's flux (it was 7 % low on one side)
    assert np.all(res.form_factors.visible == 1.0)  # no floor point reads the twin's back as a solid


# ------------------------------------------------------------------ the empty room (5.8)
ROOM = 4.0  # CIE 171 5.8: a 4 m x 4 m x 4 m room, S_T = 96 m^2
PHI = 1000.0  # the source's flux (W per channel)


@pytest.mark.parametrize("rho", [0.2, 0.5, 0.8])
def test_cie171_empty_room_mean_interreflection(rho):
    """An isotropic point lamp (power PHI) at the centre of the empty 4 m cube, every wall of
    reflectance rho, 96 patches of 1 m (polygon model), automatic rays: the lamp's direct light
    on the walls sums to PHI within 0.1 %, and the area-mean interreflected illuminance (a patch's
    B / rho less its direct light) is Phi rho / (S_T (1 - rho)) within 1 %. Per patch it is not
    uniform in a cube (the formula is uniform only in a sphere): the patches spread a few % about
    it, more where rho is low."""
    faces = polygon_faceset(cf.box_polygons((ROOM,) * 3), reflectance=rho)
    faces.lamps = [Lamp("bulb", POINT, (ROOM / 2,) * 3, DOWN, X, Y, (PHI,) * 3)]
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=1.0, threads=2))
    ps = res.patches
    assert ps.n_patches == 96 and ps.area.sum() == pytest.approx(6 * ROOM * ROOM)
    direct = res.scene_light[:, :, 0].sum(axis=1)
    assert (direct * ps.area).sum() == pytest.approx(PHI, rel=1e-3)
    indirect = res.patch_radiosity[:, 0] / rho - direct
    mean = (indirect * ps.area).sum() / ps.area.sum()
    ref = cf.enclosure_interreflected_illuminance(PHI, 6 * ROOM * ROOM, rho)
    print(f"rho {rho}: mean {mean / ref - 1:+.2e}, patches {indirect.min() / ref:.3f} .. {indirect.max() / ref:.3f}")
    assert mean == pytest.approx(ref, rel=0.01)
    assert np.all(indirect > 0)


@pytest.mark.parametrize("rho", [0.5, 0.8])
def test_cie171_empty_room_six_patches(rho):
    """The 4 m cube lit by its luminous ceiling (exitance 100 W/m^2, reflectance rho like the
    other walls), one patch a wall: the radiosity system B = e + rho F B with Howell's exact
    form factors (C-11 to the opposite wall, C-14 to the four adjacent ones; each row sums to 1)
    solved exactly, against the forward job (2^16 rays per patch): every wall within 1 %."""
    f_opp, f_adj = cf.parallel_rectangles(ROOM, ROOM, ROOM), cf.perpendicular_rectangles(ROOM, ROOM, ROOM)
    opposite = [1, 0, 3, 2, 5, 4]  # box_polygons: floor, ceiling, x=0, x=S, y=0, y=S
    F = np.array([[0.0 if i == j else (f_opp if opposite[i] == j else f_adj) for j in range(6)] for i in range(6)])
    assert F.sum(axis=1) == pytest.approx(np.ones(6), abs=1e-6)
    e = np.zeros(6)
    e[1] = 100.0
    ref = np.linalg.solve(np.eye(6) - rho * F, e)
    faces = polygon_faceset(cf.box_polygons((ROOM,) * 3), reflectance=rho, exitance=e)
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=10.0, rays_per_patch=1 << 16,
                                             threads=2))
    assert res.patches.n_patches == 6
    B = res.patch_radiosity[:, 0]
    rel = np.abs(B - ref) / ref
    print(f"rho {rho}: max {rel.max():.5f}")
    assert rel.max() < 0.01


# ------------------------------------------------------------------ daylight: a roof opening (5.9)
SKY_L = 10.0  # the sky's radiance, W/(m^2 sr) per channel: uniform (CIE general sky type 5)


@pytest.mark.xfail(strict=True, reason="the World's light is cosine-weighted hemisphere rays (engine.world, "
                   "WORLD_RAYS = 1024 a patch): through a 1 m^2 opening 3 m up about 3 % of them escape, "
                   "33 % per patch at most, 10 % on average (not held)")
def test_cie171_roof_opening_under_a_uniform_sky():
    """CIE 171 5.9's case with a sky of uniform luminance: a 1 m x 1 m unglazed opening in the
    middle of the black ceiling of a 4 m x 4 m x 3 m room with black walls; the floor's sky
    component is pi L x the configuration factor to the opening (Howell B-3). Through the forward
    job (the World as a uniform radiance), every floor patch (8 x 8) within 1 %. Fails: measured
    max 33 %, mean 10 %, the floor's total 2.2 % low at the default rays; 3.6 % max at 65536 rays
    a patch (engine.world.world_irradiance called directly)."""
    W, H, o0, o1 = 4.0, 3.0, 1.5, 2.5
    floor = _grid((0, W), (0, W), 8, 8, lambda x, y: (x, y, 0.0))
    ceiling = [np.array(q, dtype=np.float64)[::-1] for q in (  # facing -z, around the opening
        [(0, 0, H), (W, 0, H), (W, o0, H), (0, o0, H)], [(0, o1, H), (W, o1, H), (W, W, H), (0, W, H)],
        [(0, o0, H), (o0, o0, H), (o0, o1, H), (0, o1, H)], [(o1, o0, H), (W, o0, H), (W, o1, H), (o1, o1, H)])]
    polys = floor + ceiling + cf.box_polygons((W, W, H))[2:]
    n = len(floor)
    faces = polygon_faceset(polys, reflectance=np.r_[np.full(n, RHO), np.zeros(len(polys) - n)])
    faces.world_radiance = np.full(3, SKY_L)
    ref = np.array([math.pi * SKY_L * _patch_mean(
        (q.min(axis=0)[0], q.max(axis=0)[0]), (q.min(axis=0)[1], q.max(axis=0)[1]),
        lambda x, y: cf.point_to_parallel_rectangle(o0 - x, o1 - x, o0 - y, o1 - y, H)) for q in floor])
    _, res = run_radiosity(faces, JobOptions(patch_model="polygon", max_patch_size=10.0, threads=2))
    E = res.face_radiosity[:n, 0] / RHO
    assert np.max(np.abs(E - ref) / ref) < 0.01
