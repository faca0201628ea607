"""The curve's lights' direct light by the kernel (issue 18): InverseProblem.correct_direct and
engine.kernel_transfer.lights_direct_correction. Pure engine (no bpy).

A small bright cell's light reaches the targets mostly after a reflection in many scenes (the
staircase's answer: 70 %); ray-cast form factors gather that light on every reflector from a
few rays, and the targets' prediction then moves by a per cent or more from seed to seed. With
the cell's direct light on every patch from the kernel, the prediction is that of a noise-free
first bounce. Checked: T's columns stay the forward solve's (the same quantity both ways), and
the prediction's spread over seeds at a low ray count shrinks while its mean stays at the
high-ray reference.
"""
import numpy as np

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.formfactors import compute_form_factors
from relight_addon.engine.inverse import InverseProblem
from relight_addon.engine.kernel_transfer import lights_direct_correction
from relight_addon.engine.scene import mesh_patches, polygon_faceset

RHO = 0.6


def _room():
    """A closed 3 x 3 x 2.5 m box in 0.75 m patches; targets: the floor; candidates: the ceiling."""
    ps = mesh_patches(polygon_faceset(cf.box_polygons((3.0, 3.0, 2.5)), reflectance=RHO), max_patch_size=0.75)
    floor = ps.face == 0
    ceiling = ps.face == 1
    return ps, floor, ceiling


def _problem(ps, floor, ceiling, rays, seed, corrected):
    ff = compute_form_factors(ps, rays, seed=seed, kernel_pairs=(np.flatnonzero(floor), np.flatnonzero(ceiling)))
    b = np.where(floor[:, None], 1.0, 0.0) * np.ones(3)
    prob = InverseProblem(ff, ps.area, ps.reflectance, floor, b, ceiling, ps.center, ps.normal)
    light = 4  # one ceiling cell (a corner one: its light reaches the far floor after reflections)
    if corrected:
        dH = lights_direct_correction(ps, prob.F, [light], prob.lights.members, ff.send, np.flatnonzero(floor),
                                      seed=seed, sampler=ff.sampler)
        prob.correct_direct([light], dH)
    return prob, light


def test_corrected_columns_are_the_forward_solve():
    ps, floor, ceiling = _room()
    prob, j = _problem(ps, floor, ceiling, 1024, 1, corrected=True)
    s = np.zeros((prob.n_lights, 3))
    s[j] = [1.0, 2.0, 3.0]
    B = prob.configuration_radiosity(s)
    assert np.allclose(prob.target_radiosity_of(s), B[prob.targets], rtol=1e-9, atol=1e-12)
    assert prob.direct_correction is not None and prob.direct_correction[:, j].nnz > 0


def test_the_first_bounce_by_the_kernel_removes_the_ray_noise():
    ps, floor, ceiling = _room()
    ref, j = _problem(ps, floor, ceiling, 65536, 7, corrected=False)
    e = np.zeros((ref.n_lights, 3))
    e[j] = 1.0
    reference = ref.target_radiosity_of(e)[:, 0].sum()
    plain, kernel = [], []
    for seed in range(5):
        for corrected, out in ((False, plain), (True, kernel)):
            prob, _ = _problem(ps, floor, ceiling, 256, seed, corrected)
            out.append(prob.target_radiosity_of(e)[:, 0].sum() / reference - 1)
    plain, kernel = np.array(plain), np.array(kernel)
    print("256 rays, the floor's total against 65536 rays: plain", plain.round(4), "kernel", kernel.round(4))
    assert kernel.std() < 0.5 * plain.std()
    assert abs(kernel.mean()) < 0.01


def test_the_correction_per_emitting_patch_adds_up_to_the_lights():
    """InverseProblem.emitter_direct_correction shares each light's kernel correction among its
    patches: weighted by the configuration's patch exitance it gives back the lights' correction
    (DC @ strength), and a one-cell light's column is its own."""
    ps, floor, ceiling = _room()
    prob, j = _problem(ps, floor, ceiling, 1024, 1, corrected=True)
    k = 7
    dH = lights_direct_correction(ps, prob.F, [k], prob.lights.members, None, np.flatnonzero(floor), seed=1)
    prob.correct_direct([k], dH)
    s = np.zeros((prob.n_lights, 3))
    s[j], s[k] = [1.0, 2.0, 3.0], [0.5, 0.5, 0.5]
    X = prob.emitter_direct_correction(s)
    e = prob.patch_exitance(s)
    np.testing.assert_allclose(X @ e, prob.direct_correction @ s, rtol=1e-9, atol=1e-12)
    (m,) = prob.lights.members(j)
    np.testing.assert_allclose(X[:, m].toarray().ravel(), prob.direct_correction[:, j].toarray().ravel())
    assert prob.emitter_direct_correction(np.zeros_like(s)) is None
