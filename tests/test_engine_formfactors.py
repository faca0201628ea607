"""Ray-cast form factors against closed forms (Howell) and the laws form factors obey.

Pure engine (no bpy). Scenes come from scene.polygon_faceset + mesh_patches.
"""
import numpy as np
import pytest
import scipy.sparse as sp

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.formfactors import (
    BURIED_POINTS,
    BURIED_RAYS,
    QUALITY,
    FormFactors,
    compute_form_factors,
    weigh_reciprocity,
)
from relight_addon.engine.sampling import Cancelled
from relight_addon.engine.scene import mesh_patches, polygon_faceset

# (name, polygons, closed form F_12); several aspect ratios per configuration.
# Disks: 256-gons of the disks' areas; the polygon changes the area-equivalent
# form factor by far less than 0.1 % (see closed_forms.coaxial_disks_polygons).
CONFIGS = [
    ("parallel 1x1 at 1", cf.parallel_rectangles_polygons(1, 1, 1), cf.parallel_rectangles(1, 1, 1)),
    ("parallel 2x1 at 0.5", cf.parallel_rectangles_polygons(2, 1, 0.5), cf.parallel_rectangles(2, 1, 0.5)),
    ("parallel 1x0.25 at 2", cf.parallel_rectangles_polygons(1, 0.25, 2), cf.parallel_rectangles(1, 0.25, 2)),
    ("perpendicular l1 w1 h1", cf.perpendicular_rectangles_polygons(1, 1, 1), cf.perpendicular_rectangles(1, 1, 1)),
    ("perpendicular l1 w2 h0.5", cf.perpendicular_rectangles_polygons(1, 2, 0.5), cf.perpendicular_rectangles(1, 2, 0.5)),
    ("perpendicular l2 w0.5 h1", cf.perpendicular_rectangles_polygons(2, 0.5, 1), cf.perpendicular_rectangles(2, 0.5, 1)),
    ("disks r1 r1 h1", cf.coaxial_disks_polygons(1, 1, 1), cf.coaxial_disks(1, 1, 1)),
    ("disks r1 r0.5 h0.5", cf.coaxial_disks_polygons(1, 0.5, 0.5), cf.coaxial_disks(1, 0.5, 0.5)),
    ("disks r0.5 r1.5 h1", cf.coaxial_disks_polygons(0.5, 1.5, 1), cf.coaxial_disks(0.5, 1.5, 1)),
]


def two_patches(polys):
    # max_patch_size large: each surface is one patch (one emitter, one receiver)
    return mesh_patches(polygon_faceset(polys), max_patch_size=1e3)


def box(n_per_side, size=(1.0, 1.0, 1.0)):
    return mesh_patches(polygon_faceset(cf.box_polygons(size)), max_patch_size=max(size) / n_per_side)


def test_closed_forms_obey_summation_rule_in_a_cube():
    # Independent check of the catalogue formulas: from one face of a cube,
    # 1 opposite face + 4 adjacent faces = the whole enclosure.
    total = cf.parallel_rectangles(1, 1, 1) + 4 * cf.perpendicular_rectangles(1, 1, 1)
    assert total == pytest.approx(1.0, abs=1e-9)
    # and for a 1 x 2 x 3 box, from the 1 x 2 face
    a = cf.parallel_rectangles(1, 2, 3) + 2 * cf.perpendicular_rectangles(2, 1, 3) + 2 * cf.perpendicular_rectangles(1, 2, 3)
    assert a == pytest.approx(1.0, abs=1e-9)
    # disks: r2 -> infinity sees everything
    assert cf.coaxial_disks(1, 1e4, 1) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("quality,tol,seeds", [("default", 0.02, 4), ("high", 0.005, 2)])
def test_form_factors_match_closed_forms(quality, tol, seeds):
    # Error of F_12 relative to max(F_12, 0.05), RMS over a few seeds per configuration
    # (one seed is a single draw of a randomised estimator). Below F = 0.05 the bound is
    # absolute (tol * 0.05): the 1 x 0.25 rectangles 2 apart (F = 0.018, ~300 hits at
    # "default") have an RMS relative error of about 2 % and single-seed errors up to
    # ~5 % at "default" (docs/benchmarks.md, "Form factors").
    rms = {}
    for name, polys, ref in CONFIGS:
        ps = two_patches(polys)
        e = [(float(compute_form_factors(ps, QUALITY[quality], seed=s).matrix[0, 1]) - ref) / max(ref, 0.05)
             for s in range(seeds)]
        rms[name] = float(np.sqrt(np.mean(np.square(e))))
    worst = max(rms, key=rms.get)
    assert rms[worst] < tol, f"{worst}: RMS error {rms[worst]:.4f} ({rms})"


def test_reciprocity_two_surfaces_of_different_area():
    # each row from its own patch's rays: two independent estimates that reciprocity relates
    ps = two_patches(cf.perpendicular_rectangles_polygons(1, 2, 0.5))
    ff = compute_form_factors(ps, QUALITY["default"], reciprocity="rays")
    a1f12 = ps.area[0] * ff.matrix[0, 1]
    a2f21 = ps.area[1] * ff.matrix[1, 0]
    assert a1f12 == pytest.approx(a2f21, rel=0.02)
    assert ff.reciprocity_error(ps.area, "max") == pytest.approx(abs(a1f12 - a2f21) / (0.5 * (a1f12 + a2f21)))


def test_weighted_reciprocity_takes_the_smaller_patch_rays():
    # A small disk under a large one: F_21 (large -> small, 0.075) is a few hits of the large
    # disk's rays, while the small disk's rays measure the same exchange well. The weighted
    # estimate (inverse variance of the two counts) must cut F_21's error several times without
    # harming F_12; both against the closed form, 16 seeds.
    ps = two_patches(cf.coaxial_disks_polygons(0.5, 1.5, 1))
    ref12 = cf.coaxial_disks(0.5, 1.5, 1)
    ref21 = ref12 * ps.area[0] / ps.area[1]
    err = {}
    for mode in ("rays", "weighted"):
        m = [compute_form_factors(ps, 1024, seed=s, reciprocity=mode).matrix for s in range(16)]
        e12 = [M[0, 1] / ref12 - 1 for M in m]
        e21 = [M[1, 0] / ref21 - 1 for M in m]
        err[mode] = (float(np.sqrt(np.mean(np.square(e12)))), float(np.sqrt(np.mean(np.square(e21)))))
        assert max(M.sum(axis=1).max() for M in m) <= 1 + 1e-6  # never more power out than in
    assert err["weighted"][1] < err["rays"][1] / 3, err
    assert err["weighted"][0] < err["rays"][0] * 1.2, err
    with pytest.raises(ValueError, match="reciprocity"):
        compute_form_factors(ps, 64, reciprocity="mean")


def test_reciprocity_error_in_subdivided_box_shrinks_with_rays():
    ps = box(4)
    e_low = compute_form_factors(ps, 256, reciprocity="rays").reciprocity_error(ps.area)
    e_high = compute_form_factors(ps, 16384, reciprocity="rays").reciprocity_error(ps.area)
    assert e_high < 0.03
    assert e_high < e_low / 3
    # the weighted estimate is reciprocal up to its row scale (closed box: the rays' row sums, 1)
    ff = compute_form_factors(ps, 256)
    assert ff.reciprocity == "weighted"
    assert ff.reciprocity_error(ps.area) < e_low / 5  # measured: 0.021 against 0.197
    assert np.abs(ff.row_sums() - 1).max() < 1e-5


def test_closed_box_row_sums_are_one_and_open_scene_loses_rays():
    ps = box(5)
    ff = compute_form_factors(ps, 1024)
    assert np.abs(ff.row_sums() - 1).max() < 1e-6  # every ray hits a wall
    assert np.all(ff.to_dense().diagonal() == 0)  # planar patches never see themselves
    # a patch on a wall sees nothing on its own wall
    same_wall = ps.face[:, None] == ps.face[None, :]
    assert ff.to_dense()[same_wall].max() == 0
    ps2 = two_patches(cf.parallel_rectangles_polygons(1, 1, 1))
    ff2 = compute_form_factors(ps2, QUALITY["default"])
    assert np.allclose(ff2.row_sums(), np.diag(ff2.matrix[:, ::-1]))  # only the other patch is hit


def test_back_side_hits_absorb():
    lo, hi = cf.parallel_rectangles_polygons(1, 1, 1)
    ps = two_patches([lo, hi[::-1]])  # receiver now faces away (+z)
    ff = compute_form_factors(ps, 4096)
    assert ff.matrix[0, 1] == 0
    assert ff.matrix[1, 0] == 0  # the receiver shoots away from the emitter


def test_box_matches_closed_form_per_wall():
    # 1 x 1 x 1 box meshed 3 x 3: the floor -> ceiling factor summed over patches
    # (area-weighted) is the whole-face closed form.
    ps = box(3)
    F = compute_form_factors(ps, 16384).to_dense()
    floor, ceil = ps.face == 0, ps.face == 1
    f_fc = (ps.area[floor] @ F[np.ix_(floor, ceil)].sum(axis=1)) / ps.area[floor].sum()
    assert f_fc == pytest.approx(cf.parallel_rectangles(1, 1, 1), rel=0.01)


def test_seed_determinism_and_thread_independence():
    ps = box(4)
    a = compute_form_factors(ps, 512, seed=3, threads=1)
    b = compute_form_factors(ps, 512, seed=3, threads=2)
    c = compute_form_factors(ps, 512, seed=3, threads=2)
    d = compute_form_factors(ps, 512, seed=4, threads=2)
    assert np.array_equal(a.matrix, b.matrix) and np.array_equal(b.matrix, c.matrix)
    assert not np.array_equal(a.matrix, d.matrix)


def test_sparse_storage_equals_dense():
    ps = box(4)
    dense = compute_form_factors(ps, 256, seed=2)
    sparse = compute_form_factors(ps, 256, seed=2, dense_limit=10)
    assert isinstance(dense.matrix, np.ndarray) and dense.matrix.dtype == np.float32
    assert sp.isspmatrix_csr(sparse.matrix) and sparse.matrix.dtype == np.float32
    assert np.allclose(sparse.to_dense(), dense.matrix, atol=1e-6)
    x = np.random.default_rng(0).random((ps.n_patches, 3))
    assert np.allclose(sparse.matvec(x), dense.matvec(x), rtol=1e-5)
    assert np.allclose(sparse.row_sums(), dense.row_sums())
    assert sparse.reciprocity_error(ps.area) == pytest.approx(dense.reciprocity_error(ps.area), rel=1e-4)
    assert sparse.reciprocity_error(ps.area, "max") == pytest.approx(dense.reciprocity_error(ps.area, "max"), rel=1e-4)
    raw_d = compute_form_factors(ps, 256, seed=2, reciprocity="rays")
    raw_s = compute_form_factors(ps, 256, seed=2, reciprocity="rays", dense_limit=10)
    s = weigh_reciprocity(raw_s.matrix, ps.area, 256)
    assert sp.isspmatrix_csr(s)
    assert np.allclose(s.toarray(), weigh_reciprocity(raw_d.matrix, ps.area, 256), atol=1e-6)
    assert np.allclose(s.toarray(), dense.matrix, atol=1e-6)


def test_samplers_all_unbiased_and_sobol_is_most_accurate():
    name, polys, ref = CONFIGS[0]
    ps = two_patches(polys)
    err = {}
    for s in ("random", "stratified", "sobol"):
        e = [compute_form_factors(ps, 4096, seed=k, sampling=s).matrix[0, 1] / ref - 1 for k in range(6)]
        err[s] = float(np.sqrt(np.mean(np.square(e))))
        assert abs(np.mean(e)) < 0.03, (s, e)
    assert err["sobol"] < err["random"], err


def test_progress_and_cancel():
    ps = box(6)
    seen = []
    compute_form_factors(ps, 8192, progress=seen.append)
    assert seen and seen[-1] == 1.0 and all(np.diff(seen) > 0)
    with pytest.raises(Cancelled):
        compute_form_factors(ps, 8192, cancel=lambda: True)
    calls = []

    def cancel_later():
        calls.append(1)
        return len(calls) > 1

    with pytest.raises(Cancelled):
        compute_form_factors(ps, 8192, cancel=cancel_later)


def test_bad_input_messages():
    ps = box(2)
    with pytest.raises(ValueError, match="rays per patch"):
        compute_form_factors(ps, 0)
    with pytest.raises(ValueError, match="sampling"):
        compute_form_factors(ps, 16, sampling="halton")
    with pytest.raises(ValueError, match="quality"):
        compute_form_factors(ps, "ultra")
    assert compute_form_factors(ps, "draft").rays_per_patch == QUALITY["draft"]
    ff = compute_form_factors(ps, 16)
    assert isinstance(ff, FormFactors) and ff.n_rays == (16 + BURIED_POINTS * BURIED_RAYS) * ps.n_patches
    with pytest.raises(ValueError, match="area"):
        ff.reciprocity_error(ps.area[:-1])


def test_job_options_default_rays_is_the_form_factor_default():
    # the add-on's "Rays per Patch" default and the CLI's come from options.py
    from relight_addon.engine import formfactors, options

    # the job default is the automatic quality, which gives small scenes the tested default
    assert options.DEFAULT_RAYS_PER_PATCH == 0 and options.JobOptions(rays_per_patch=0).validate().rays_per_patch is None
    assert formfactors.auto_rays_per_patch(2) == QUALITY["default"]
    assert formfactors.auto_rays_per_patch(10 ** 6) == QUALITY["draft"]
    assert formfactors.auto_rays_per_patch(1451) == 2048
    # with kernel pairs (the default solve) half the budget: the staircase's 943 adaptive patches
    assert formfactors.auto_rays_per_patch(943) == 4096 and formfactors.auto_rays_per_patch(943, kernel=True) == 2048


def _room_with_slab(open_card=False):
    """A closed 1 m box room (one patch per wall) and, on the floor's half x < 0.5, a closed 0.1 m
    slab (outward faces, its bottom coincident with the floor, its sides with three walls), or
    (``open_card``) a one-sided 0.5 m card half-way up, facing up."""
    room = cf.box_polygons()
    if open_card:
        extra = [np.array([[0.25, 0.25, 0.5], [0.75, 0.25, 0.5], [0.75, 0.75, 0.5], [0.25, 0.75, 0.5]],
                          dtype=np.float64)]
    else:
        extra = [p[::-1] for p in cf.box_polygons((0.5, 1.0, 0.1))]  # outward: the inward box reversed
    return mesh_patches(polygon_faceset(room + extra), max_patch_size=1e3)


def test_a_partly_buried_patch_sends_its_light_from_its_visible_part():
    # the floor's half under the slab is buried: its rays start inside the slab. Its radiosity stays
    # its whole area's mean (a bake's face mean: the buried half black), and its light leaves from the
    # visible half: the power the room receives from it, sum_j A_j F_j,floor B_floor, is A_floor
    # B_floor (it was half: the buried half's share absorbed by the slab's insides)
    ps = _room_with_slab()
    ff = compute_form_factors(ps, 8192, seed=1)
    assert ff.visible[0] == pytest.approx(0.5, abs=0.1)  # 36 points
    assert ff.visible[1] == ff.visible[3] == 1.0  # the ceiling and the far wall touch nothing
    assert np.all(ff.visible[[2, 4, 5]] > 0.8)  # the walls behind the slab's sides: 5-10 % buried
    F = ff.to_dense()
    assert 0.45 < ff.row_sums()[0] < 0.65  # what the floor gathers: its whole area's mean (half)
    assert ps.area @ F[:, 0] == pytest.approx(ps.area[0], rel=0.1)  # the visible share: 36 points


def test_a_patch_under_an_open_card_is_not_buried():
    # a one-sided card over the floor's centre: the floor's points under it see past its edges, so
    # none is buried, and the rays that reach the card's back are absorbed as before (row sum below 1)
    ps = _room_with_slab(open_card=True)
    ff = compute_form_factors(ps, 8192, seed=1)
    assert np.all(ff.visible == 1.0)
    assert ff.row_sums()[0] < 0.95


def test_reciprocity_keeps_a_work_planes_own_rays_dense_and_sparse():
    """Rays pass through a work plane: no other patch's ray counts a hit on it. Its row keeps its
    own rays (not averaged with the zeros of the others'), the others are weighed among themselves
    exactly as without it, and the dense and sparse forms agree."""
    import scipy.sparse as sp

    from relight_addon.engine.formfactors import weigh_reciprocity

    rng = np.random.default_rng(3)
    P = 7
    M = rng.uniform(0.0, 0.15, (P, P)).astype(np.float32)
    np.fill_diagonal(M, 0.0)
    passes = np.zeros(P, dtype=bool)
    passes[[2, 5]] = True
    M[:, passes] = 0.0  # nothing sees a work plane
    area = rng.uniform(0.5, 2.0, P)
    W = weigh_reciprocity(M, area, 4096, passes=passes)
    np.testing.assert_array_equal(W[passes], M[passes])
    assert not W[:, passes].any()
    keep = ~passes
    np.testing.assert_allclose(W[np.ix_(keep, keep)], weigh_reciprocity(M[np.ix_(keep, keep)], area[keep], 4096),
                               rtol=0, atol=0)
    S = weigh_reciprocity(sp.csr_matrix(M), area, 4096, passes=passes)
    np.testing.assert_allclose(S.toarray(), W, rtol=1e-6, atol=1e-7)
    # without the mask, the work plane's row is pulled toward the others' zeros (the old bias)
    assert weigh_reciprocity(M, area, 4096)[passes].sum() < 0.9 * M[passes].sum()


def test_a_cancel_does_not_wait_for_the_chunks_running():
    """sampling.run_chunks raises Cancelled while a chunk still runs (it ends in the background at
    its next look at ``stop``): a newer Live stroke is not kept waiting by the chunks of the answer
    it cancels (issue 37). The chunk here runs until the test releases it, after the raise."""
    import threading

    from relight_addon.engine.sampling import run_chunks

    started, release, stop = threading.Event(), threading.Event(), threading.Event()
    ended = []

    def work(ci):
        if ci == 0:
            started.set()
            release.wait(30.0)
        ended.append(ci)

    with pytest.raises(Cancelled):
        run_chunks(work, 2, 2, stop, cancel=started.is_set)
    assert stop.is_set() and 0 not in ended  # (raised while chunk 0 still ran)
    release.set()


def test_a_cancel_does_not_wait_for_one_long_call():
    """sampling.run_cancellable raises Cancelled while its call (a channel's LU: one LAPACK call,
    0.2-0.3 s on 2,305 patches) still runs, which ends in the background, its answer dropped: a
    newer Live stroke is not kept waiting by a later answer's factorisation (issue 37). Without a
    cancel it is the call's answer, and the call's error is raised as it is."""
    import threading
    import time

    from relight_addon.engine.sampling import run_cancellable

    started, release = threading.Event(), threading.Event()
    ended = []

    def call():
        started.set()
        release.wait(30.0)
        ended.append(1)
        return 7

    t0 = time.perf_counter()
    with pytest.raises(Cancelled, match="solve cancelled"):
        run_cancellable(call, started.is_set, "solve cancelled")
    assert time.perf_counter() - t0 < 5.0 and not ended  # (raised while the call still ran)
    release.set()
    assert run_cancellable(lambda: 7, lambda: False) == 7 and run_cancellable(lambda: 8) == 8
    with pytest.raises(ZeroDivisionError):
        run_cancellable(lambda: 1 / 0, lambda: False)
