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
import pytest

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.formfactors import compute_form_factors
from relight_addon.engine.inverse import InverseProblem
from relight_addon.engine.targets import PaintedRadiance
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
    prob = InverseProblem(ff, ps.area, ps.reflectance, [PaintedRadiance.masked(floor, b)],
                          ceiling, ps.center, ps.normal)
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


def test_the_curve_never_rises_after_its_configurations_are_refitted():
    """engine.curve_refits.carry_refined: a configuration refitted worse than the one before it (after the
    kernel's direct light changed some of its columns) takes the one before plus one of its own
    lights when all stay on, or else the one before itself -- fewer lights are allowed at k."""
    from types import SimpleNamespace as NS

    from relight_addon.engine.curve_refits import carry_refined
    from relight_addon.engine.light_colour import fit_lights
    from relight_addon.engine.reduction import CurvePoint

    rng = np.random.default_rng(0)
    t = rng.uniform(0.0, 1.0, (6, 4))
    t[:, 3] = -t[:, 0]  # light 3 only ever takes light 0's light away: NNLS leaves it off beside 0
    problem = NS(transfer=[t, t, t], b_target=np.repeat(t[:, :1] * 2.0, 3, axis=1), target_norm=1.0, colour=None)

    def point(ids, error):
        ids = np.asarray(ids, dtype=np.int64)
        return CurvePoint(len(ids), error, error, 0, ids, np.ones((len(ids), 3)), -1)

    e1, err1 = fit_lights(problem, [0])
    assert err1 < 1e-9  # light 0 alone meets the targets
    curve = [point([0], err1), point([1, 3], 0.5)]  # (the second refitted worse: lights 1 and 3)
    refitted = carry_refined(problem, curve, 0, {}, every=True)
    assert refitted[1] is curve[1] or curve[1].lights.tolist() == [1, 3]  # (the curve given stays as it was)
    second = refitted[1]
    assert second.error <= refitted[0].error + 1e-12
    assert second.n_lights == len(second.lights) and np.all(second.exitance.max(axis=1) > 0)
    assert second.error == pytest.approx(fit_lights(problem, second.lights)[1], abs=1e-12)


def test_the_curve_never_rises_above_a_configuration_improved_by_its_carried_lamps():
    """engine.curve_refits.carry_refined: when the configuration before (the final one, its lamps
    refined by their own programme) ends below every fit of this one's lights, this one becomes
    that configuration (the staircase's k = 18 rose above k = 17 on a compat run before)."""
    from types import SimpleNamespace as NS

    from relight_addon.engine.curve_refits import carry_refined
    from relight_addon.engine.light_colour import fit_lights
    from relight_addon.engine.reduction import CurvePoint

    rng = np.random.default_rng(1)
    t = rng.uniform(0.1, 1.0, (8, 3))
    problem = NS(transfer=[t, t, t], b_target=np.repeat(rng.uniform(0.5, 1.0, (8, 1)), 3, axis=1),
                 target_norm=1.0, colour=None)

    def point(ids, error):
        ids = np.asarray(ids, dtype=np.int64)
        return CurvePoint(len(ids), error, error, 0, ids, np.ones((len(ids), 3)), -1)

    fits = [fit_lights(problem, ids) for ids in ([2, 0], [2, 1])]
    assert all(e.min() > 0 for e, _ in fits)  # (every try keeps its lights on)
    low = 0.5 * min(err for _, err in fits)  # the final configuration: below every fit of the next
    curve = [point([2], low), point([0, 1], 10.0)]
    out = carry_refined(problem, curve, 0, {}, every=False)
    assert out[1].error <= out[0].error and out[1].lights.tolist() == [2] and out[1].n_lights == 1
    assert curve[1].lights.tolist() == [0, 1]  # (the curve given stays as it was)
