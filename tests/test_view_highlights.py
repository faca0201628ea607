"""Lamps' highlights in the camera-view target (issue 40; engine/view_lamps.py, engine/targets/view.py):
the reflection of a lamp's direct light through a glossy BSDF towards the camera, forward and in the
inverse problem's transfer, on numpy scenes (no bpy). References: the inverse-square law and the
BSDF table evaluated here in a frame of the test's own (a) ; a matte surface shows no highlight
(exactly 0); the transfer's lamp column is the forward model's rows (linear in the strength); a
painted highlight picks, of two candidate lamps, the one whose reflection it is. Cycles:
tests/test_cycles_view_highlight.py."""
import copy
import math

import numpy as np
import pytest
from scipy.optimize import nnls

from relight_addon.engine.formfactors import QUALITY, compute_form_factors
from relight_addon.engine.inverse import InverseProblem
from relight_addon.engine.lamp_refinement import Transport
from relight_addon.engine.lamps import Lamp, lamp_irradiance
from relight_addon.engine.lights import append_lamps
from relight_addon.engine.lights.point import POINT
from relight_addon.engine.principled import BRDFTable, PrincipledParams
from relight_addon.engine.scene import mesh_patches
from relight_addon.engine.targets import scene_targets
from relight_addon.engine.targets.view import Camera, ViewSpec, ViewTarget
from test_view_target import box_faces

SIZE = (4.0, 3.0, 2.5)
#: the glossy floor: Roughness 0.3, Specular IOR Level 0.5 (the brief's plane)
GLOSSY = PrincipledParams(base_color=(0.4, 0.4, 0.4), roughness=0.3, specular_ior_level=0.5)
DOWN, X, Y = np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
ORIGIN = np.array([2.0, 0.3, 1.6])


def camera(width=96, height=54, target=(2.0, 2.0, 0.0), fov=1.0):
    back = ORIGIN - np.asarray(target, float)
    back /= np.linalg.norm(back)
    right = np.cross((0.0, 0.0, 1.0), back)
    right /= np.linalg.norm(right)
    half = np.tan(fov / 2) * np.array([1.0, height / width])
    return Camera(ORIGIN, np.stack([right, np.cross(back, right), back]), width, height, half)


def room(glossy=True, size=0.4, lamps=()):
    """The box room (floor glossy or matte: material 1 / 0, the rest matte 0.6 grey), its scene lamps ``lamps``."""
    faces = box_faces(glossy, GLOSSY, SIZE)
    faces.lamps = list(lamps)
    patches = mesh_patches(faces, max_patch_size=size)
    F = compute_form_factors(patches, QUALITY["default"], seed=1)
    return faces, patches, F


def point_lamp(position, power=40.0, name="p"):
    return Lamp(name, POINT, position, DOWN, X, Y, (power, power, power))


def _target(faces, patches, F, painted=None, radiance=None):
    cam = camera()
    painted = np.ones((cam.height, cam.width), bool) if painted is None else painted
    radiance = np.full((cam.height, cam.width, 3), 0.1) if radiance is None else radiance
    faces.view_target = ViewSpec(cam, radiance, painted, "test")
    return ViewTarget.from_scene(faces, patches, F)


def _closed_form(lamp, point, view, rho):
    """(n, 3) the highlight's radiance (f(l, v) - rho / pi) E at floor points (normal +z): E the
    inverse-square law P cos / (4 pi d^2), f the floor's BSDF table in a frame of the floor's own."""
    d = lamp.position - point
    dist = np.linalg.norm(d, axis=1)
    l = d / dist[:, None]
    E = lamp.power[None, :] * (l[:, 2] / (4 * math.pi * dist ** 2))[:, None]
    # the floor's frame: x = Y, y = -X, z = +z (any frame about the normal: the BSDF is isotropic)
    to_local = np.stack([Y, -X, np.array([0, 0, 1.0])])
    f = BRDFTable([(1.0, "principled", GLOSSY)])((-view) @ to_local.T, l @ to_local.T)
    return (f - np.asarray(rho) / math.pi) * E


def test_a_point_lamps_highlight_is_the_inverse_square_law_through_the_bsdf():
    """At every pixel on the glossy floor the forward highlight (the scene lamp's) is (f - (rho + x)/pi) E
    to 1e-6, x the albedo of the lamp's first reflection beyond rho that B holds (engine.incidence, at
    the patch's incidence: B shows (rho + x) E / pi, the BSDF f E); a highlight there (up to several x
    the Lambertian radiance), nothing on the matte walls."""
    from relight_addon.engine.first_reflection import incidence_of
    from relight_addon.engine.incidence import lamp_albedo_excess

    lamp = point_lamp((2.2, 2.1, 2.2))
    faces, patches, F = room(lamps=[lamp])
    t = _target(faces, patches, F)
    hl = t._highlights(t.hits, [])
    floor = patches.face[t.hits.patch] == 0
    assert floor.sum() > 1000 and (~floor).sum() > 300
    on = t.hits.patch[floor]
    x = lamp_albedo_excess(lamp, patches.center, patches.normal, *incidence_of(faces, patches), patches=on)
    assert np.abs(x).max() > 1e-3  # (the glossy floor's albedo depends on the incidence)
    ref = _closed_form(lamp, t.hits.point[floor], t.hits.direction[floor], patches.reflectance[on] + x)
    np.testing.assert_allclose(hl[floor], ref, rtol=1e-6, atol=1e-9 * np.abs(ref).max())
    assert np.all(hl[~floor] == 0.0)
    fE = _closed_form(lamp, t.hits.point[floor], t.hits.direction[floor], np.zeros(3))  # f E alone
    peak = np.argmax(ref.sum(axis=1))
    assert fE[peak].sum() > 2 * (fE[peak] - ref[peak]).sum()  # (a real highlight: f E > 2 x rho E / pi)
    assert np.any(ref.sum(axis=1) < 0)  # (away from the mirror direction the floor shows less than rho E / pi)


def test_a_matte_floor_shows_no_highlight():
    """A Lambertian floor (pi f = rho): no glossy row, lamp_terms None, the highlight exactly 0."""
    lamp = point_lamp((2.2, 2.1, 2.2))
    faces, patches, F = room(glossy=False, lamps=[lamp])
    t = _target(faces, patches, F)
    assert t.lamp_terms([lamp]) is None and t.fixed_light() is None
    assert np.all(t._highlights(t.hits, [(lamp, np.ones(3))]) == 0.0)


def _problem(faces, patches, F, lamps):
    P = patches.n_patches
    H = lamp_irradiance(patches, lamps, sampler=F.sampler, seed=0)[:, :, 0]
    lights = append_lamps(None, np.zeros(0, dtype=np.int64), P, lamps, ["point"] * len(lamps), H, np.zeros(len(lamps)))
    return InverseProblem(F, patches.area, patches.reflectance, scene_targets(faces, patches, F),
                          np.zeros(P, bool), patches.center, patches.normal, lights=lights), H


def _lamp_radiosity(patches, F, h):
    """B = A^-1 rho h per channel (dense: the reference of the transfer's own solves)."""
    M = F.matrix.toarray() if hasattr(F.matrix, "toarray") else np.asarray(F.matrix)
    rho = patches.reflectance
    return np.stack([np.linalg.solve(np.eye(len(h)) - rho[:, c:c + 1] * M, rho[:, c] * h) for c in range(3)], axis=1)


def test_the_transfers_lamp_column_is_the_forward_rows():
    """A candidate lamp's column of T on the view rows is R A^-1 rho H + its highlight on the rows
    (linear: the same per unit strength), and so is the lamp refinement's column of it
    (lamp_refinement.Transport: of a moved lamp, with the moved lamp's highlight); the highlight
    alone is what the rows of B miss: up to a third of the floor's rows."""
    lamps = [point_lamp((2.2, 2.1, 2.2), 1.0, "a"), point_lamp((1.0, 1.0, 2.2), 1.0, "b")]
    faces, patches, F = room()
    _target(faces, patches, F)
    prob, H = _problem(faces, patches, F, lamps)
    T = prob.transfer
    t = prob.target_rows.targets[0]
    X = t.lamp_terms(lamps)
    for k in range(2):
        B = _lamp_radiosity(patches, F, H[:, k])
        for c in range(3):
            np.testing.assert_allclose(T[c][:, k], t.matrix @ B[:, c] + X[:, k, c], rtol=1e-8,
                                       atol=1e-10 * np.abs(T[c][:, k]).max())
    # the lamp refinement's column of a lamp (moved: its highlight computed for it as it is) is the same
    transport = Transport(prob)
    for k in range(2):
        col = transport.column(H[:, k], lamps[k])
        np.testing.assert_allclose(col, np.stack([T[c][:, k] for c in range(3)], 1), rtol=1e-8,
                                   atol=1e-10 * np.abs(col).max())
    moved = point_lamp((2.6, 2.0, 2.2), 1.0, "a moved")
    h = lamp_irradiance(patches, [moved], sampler=F.sampler, seed=0)[:, 0, 0]
    B = _lamp_radiosity(patches, F, h)
    np.testing.assert_allclose(transport.column(h, moved), t.matrix @ B + t.lamp_terms([moved])[:, 0], rtol=1e-8,
                               atol=1e-10 * np.abs(t.matrix @ B).max())
    g = t.glossy_rows[0]  # (lamp a: up to a third more on the floor than B shows)
    ratio = X[g, 0, 0] / (t.matrix @ B)[g, 0]
    print(f"lamp a's highlight / the rows of B on the floor: max {ratio.max():.3f}, min {ratio.min():.3f}")
    assert ratio.max() > 0.25 and ratio.min() < 0
    assert np.all(np.delete(X, g, axis=0) == 0.0)  # (the matte rows: none)


def test_a_painted_highlight_picks_the_lamp_whose_reflection_it_is():
    """The view target painted with what lamp a shows (B's rows and its highlight, per pixel): of
    lamps a and b (both above the floor, their highlights apart), NNLS on T takes a at its strength
    (3 %) and leaves b; the rows' relative error within 5 % (measured 3.9 %: the rows at their tiles'
    mean points, the target per pixel) and at most half the error without the highlight term in T
    (the rows of B alone: measured 7.9 %, a at 25.4 and b at 4.0)."""
    lamps = [point_lamp((2.0, 2.3, 2.2), 1.0, "a"), point_lamp((2.0, 1.2, 2.2), 1.0, "b")]
    faces, patches, F = room(size=0.3)
    _target(faces, patches, F)
    prob0, H = _problem(faces, patches, F, lamps)
    t0 = prob0.target_rows.targets[0]
    B = _lamp_radiosity(patches, F, 30.0 * H[:, 0])
    cam = t0.spec.camera
    radiance = np.zeros((cam.height, cam.width, 3))
    radiance.reshape(-1, 3)[t0.hits.pixel] = t0.predict(B, [(lamps[0], np.full(3, 30.0))])
    painted = np.zeros((cam.height, cam.width), bool)
    painted.reshape(-1)[t0.hits.pixel] = True
    _target(faces, patches, F, painted, radiance)
    prob, _ = _problem(faces, patches, F, lamps)
    T, b = prob.transfer, prob.b_target
    s = np.stack([nnls(T[c], b[:, c])[0] for c in range(3)], axis=1)
    err = np.linalg.norm(np.stack([T[c] @ s[:, c] for c in range(3)], 1) - b) / np.linalg.norm(b)
    print(f"with the highlights: strengths {s[:, 0].round(3).tolist()}, relative error {err:.4f}")
    assert s[0, 0] == pytest.approx(30.0, rel=0.03) and s[1].max() < 0.05 * s[0].max()
    X = prob.lamp_view_terms(prob.target_rows)[1]
    Tb = [T[c] - X[:, :, c] for c in range(3)]  # (B's rows alone: the lamps seen Lambertian)
    sb = np.stack([nnls(Tb[c], b[:, c])[0] for c in range(3)], axis=1)
    err_b = np.linalg.norm(np.stack([Tb[c] @ sb[:, c] for c in range(3)], 1) - b) / np.linalg.norm(b)
    print(f"without: strengths {sb[:, 0].round(3).tolist()}, relative error {err_b:.4f}")
    assert err < 0.05 and err_b > 2 * err


def test_a_painted_highlight_gives_a_mounting_position_where_its_mirror_ray_lands():
    """view.highlight_mounts: a bright pixel painted on the glossy floor of the box room (the rest
    dim) gives one mount, the point where the camera's ray mirrored by the floor (z = 0) meets the
    room (closed form: the first of the box's planes along the reflected ray), on that wall's
    patch; a matte floor gives none; TargetAims of the view target carries it, and the patches
    the painted pixels see get their mean pi x radiance (channels summed)."""
    from relight_addon.engine.sampling import SceneSampler
    from relight_addon.engine.targets import target_aims

    for glossy in (True, False):
        faces, patches, F = room(glossy=glossy)
        cam = camera()
        radiance = np.full((cam.height, cam.width, 3), 0.05)
        radiance[40, 48] = 2.0  # (a pixel on the floor: the camera looks down at it)
        faces.view_target = ViewSpec(cam, radiance, np.ones((cam.height, cam.width), bool), "t")
        aims = target_aims(faces, patches, SceneSampler(patches))
        if not glossy:
            assert len(aims.mounts) == 0
            continue
        assert len(aims.mounts) == 1
        d = cam.directions([40 * cam.width + 48])[0]
        p = cam.origin + (-cam.origin[2] / d[2]) * d  # the floor's point
        r = d * np.array([1.0, 1.0, -1.0])
        t = min(((lim - p[k]) / r[k] for k, lim in ((0, SIZE[0]), (0, 0.0), (1, SIZE[1]), (1, 0.0), (2, SIZE[2]))
                 if (lim - p[k]) / r[k] > 1e-9 if abs(r[k]) > 1e-12), default=np.inf)
        np.testing.assert_allclose(aims.mounts[0], p + t * r, atol=1e-4)
        on = patches.tri_vertices[patches.tri_patch == aims.mount_patches[0]].reshape(-1, 3)
        assert np.all(on.min(axis=0) - 1e-6 <= aims.mounts[0]) and np.all(aims.mounts[0] <= on.max(axis=0) + 1e-6)
        seen = aims.radiosity[aims.radiosity > 0]  # (pi x 3 x 0.05 on a patch of dim pixels only)
        assert len(seen) > 10 and np.median(seen) == pytest.approx(np.pi * 0.15)


def test_a_strokes_retarget_takes_the_lamps_highlights_once():
    """The lamps' highlights on a kept view target's rows (TargetRows.lamp_terms: a shadow ray per
    glossy row, lamp and sample) are computed once per problem and lights (lamp_view_terms with
    ``kept``): a second stroke asks the view target for none, and T is the first's, bit for bit;
    lights appended (a refined lamp) make them anew."""
    lamps = [point_lamp((2.2, 2.1, 2.2), 1.0, "a"), point_lamp((1.0, 1.0, 2.2), 1.0, "b")]
    faces, patches, F = room()
    t = _target(faces, patches, F)
    prob, H = _problem(faces, patches, F, lamps)
    t = prob.target_rows.targets[0]
    prob.all_rows_transfer()
    calls = []
    real = t.lamp_terms
    t.lamp_terms = lambda *a, **k: calls.append(1) or real(*a, **k)
    first = prob.retarget([t])
    again = prob.retarget([t])
    assert len(calls) == 1
    for c in range(3):
        assert np.array_equal(first.transfer[c], again.transfer[c])
        np.testing.assert_allclose(first.transfer[c], prob.transfer[c], rtol=1e-9, atol=1e-12 * np.abs(prob.transfer[c]).max())
    moved = point_lamp((2.6, 2.0, 2.2), 1.0, "c")
    h = lamp_irradiance(patches, [moved], sampler=F.sampler, seed=0)[:, 0, :]
    more = copy.copy(prob)
    more.add_lights(append_lamps(prob.lights, prob.lights.patches, patches.n_patches, [moved], ["point"], h[:, :1],
                                 np.zeros(1)), [np.asarray(Transport(prob).column(h[:, 0], moved)[:, c:c + 1])
                                                 for c in range(3)])
    n = len(calls)
    more.retarget([t])
    more.retarget([t])
    assert len(calls) == n + 1
