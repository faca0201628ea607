"""pipeline/prepared.py: a stroke re-solved from the prepared state against a cold solve of the
same scene (issue 20, item 1), and the changes it cannot follow, named."""
import os
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
import bpy  # noqa: E402

from artist_scenes import paint  # noqa: E402
from relight_addon.blender import blend_files, export  # noqa: E402
from relight_addon.engine import best_lights as bl, kernel_transfer  # noqa: E402
from relight_addon.engine.by_content import digest  # noqa: E402
from relight_addon.engine.estimators import kernel as kernel_estimator  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.pipeline import jobs, prepared  # noqa: E402

SAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "sample_blends")
OPTIONS = dict(patch_model="polygon", seed=3)


def _final(outcome):
    f = outcome.report["final"]
    return f["n_lights"], f["relative_error"]


def _stroke(n=12, name=None, avoid=()):
    """Paint ``n`` more polygons of object ``name`` (default: the first painted one), those
    nearest its painted ones and not in ``avoid``, at the colour they already ask for (as a brush
    stroke would), in the bpy session."""
    ob = bpy.data.objects[name] if name else next(
        o for o in bpy.context.scene.objects if o.type == "MESH" and "relight_target" in o.data.color_attributes)
    me = ob.data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    me.color_attributes["relight_target"].data.foreach_get("color", col.ravel())
    starts = np.array([p.loop_start for p in me.polygons])
    painted = col[starts, 3] >= 0.5
    centres = np.array([p.center for p in me.polygons])
    first = np.flatnonzero(painted)[0]
    free = np.array([k for k in np.flatnonzero(~painted) if k not in set(avoid)])
    near = free[np.argsort(np.linalg.norm(centres[free] - centres[first], axis=1))[:n]]
    paint(ob, near.tolist(), tuple(col[starts[first], :3]))
    return ob.name, near


def _counting(monkeypatch):
    """Record the kernel's rows computed and refuse any hemisphere ray cast."""
    rows = []
    kernel = kernel_transfer.kernel_form_factors
    monkeypatch.setattr(prepared, "kernel_form_factors", lambda p, rec, src, **kw: rows.append(len(rec))
                        or kernel(p, rec, src, **kw))
    monkeypatch.setattr(prepared, "compute_form_factors", lambda *a, **k: pytest.fail("rays cast again"))
    monkeypatch.setattr(kernel_estimator, "compute_form_factors", lambda *a, **k: pytest.fail("rays cast again"))
    return rows


def _prepared_staircase(options):
    """The shipped staircase opened and exported, ``options`` validated, and its PreparedScene (nothing
    solved yet): (the export, the options, the scene's default patch size, the state)."""
    blend_files.open_blend(os.path.join(SAMPLES, "staircase_targets.blend"))
    exp = export.export_scene()
    options = options.validate()
    size = exp.settings.get("max_patch_size")
    return exp, options, size, prepared.PreparedScene.prepare(exp.faces, options, size)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["polygon", "adaptive"])
def test_a_stroke_is_re_solved_from_the_prepared_state_like_a_cold_solve(monkeypatch, model):
    exp, options, size, state = _prepared_staircase(JobOptions(**{**OPTIONS, "patch_model": model}))
    assert state.stale_reason(exp.faces, options, size) is None
    first = state.solve(exp.faces)  # nothing kept yet: from scratch, through the state
    assert state.reason == "nothing is kept yet" and state.patches is first.patches
    cold = jobs.run_solve(exp.faces, options, default_max_patch_size=size)
    assert _final(first)[0] == _final(cold)[0]
    assert _final(first)[1] == pytest.approx(_final(cold)[1], rel=1e-4)
    n_before = len(state.kernel_rows)

    # the stroke: on the polygon model anywhere; on the adaptive one, where it keeps faces whole (it
    # clusters the floor's unpainted faces: a stroke there solves from scratch, tested below)
    on = "flight_1"
    o = exp.faces.object_names.index(on)
    clustered = prepared.clustered_faces(state.patches) & (exp.faces.face_object == o)
    name, near = _stroke(12, on, exp.faces.face_index[clustered].tolist())
    exp2 = export.export_scene()
    assert exp2.faces.target.sum() == exp.faces.target.sum() + len(near)
    assert state.stale_reason(exp2.faces, options, size) is None  # only the paint changed
    assert state.unmappable(exp2.faces) is None  # the stroke's faces are not clustered

    # from the kept state no hemisphere ray is cast again (the adaptive model's refinement passes
    # included), and the kernel draws the new target patches' rows only (each pair samples on a
    # stream of its own: the entries the cold solve's one draw gives; the painted patches are no
    # sources any more, so no kept row has a new source)
    rows = _counting(monkeypatch)
    warm = state.solve(exp2.faces)
    monkeypatch.undo()
    assert state.reason is None and state.warm == 1
    n_rows = int(warm.patches.target.sum())
    assert rows == [n_rows - n_before] and rows[0] >= len(near)
    assert warm.report["timings_s"]["form_factors"] == pytest.approx(state.seconds["kernel rows"])
    account = warm.report["prepared"]  # what the warm solve did not recompute, in its report
    assert account["from_prepared_state"] and account["kept"]["form factors (hemisphere rays)"]
    assert account["kept"]["kernel rows"] == n_before and account["computed"]["kernel rows"] == rows[0]
    assert account["kept"]["kernel pairs"] > 0 and account["computed"]["kernel pairs"] > 0
    assert account["computed"]["rays cast"] == 0
    # the warm solve's kernel entries are the cold solve's, to the bit (the same mesh: the polygon
    # model's; the adaptive model's when the stroke's faces are meshed alone, as here)
    rec = np.flatnonzero(warm.patches.target)
    src = warm.model.lights.patches  # (the candidate patches: the kernel's sources)
    cold_K = kernel_transfer.kernel_form_factors(warm.patches, rec, src, seed=options.seed)
    assert np.array_equal(np.stack([state.kernel_rows[int(r)][src] for r in rec]), cold_K)
    assert first.report["prepared"]["computed"]["rays cast"] > 0 and not first.report["prepared"]["kept"]["kernel rows"]
    # a lux fill (the same target patches at another radiosity): no kernel row drawn again, and no
    # candidate lamp's irradiance computed again (the same plan: the lamps of the stroke's solve)
    brighter = replace(exp2.faces, target_radiosity=1.5 * exp2.faces.target_radiosity)
    rows = _counting(monkeypatch)
    lux = state.solve(brighter)
    monkeypatch.undo()
    assert state.reason is None and rows == []
    assert lux.report["prepared"]["computed"]["candidate lamps' irradiance"] == 0
    assert lux.report["prepared"]["kept"]["candidate lamps' irradiance"] > 0

    # the warm solve against a cold solve of the painted file. On the polygon model, whose mesh is
    # the cold solve's: within 1 % (kernel pairs and lamps drawn per pair and per lamp: what is kept
    # is what the cold solve computes; but the kept rays were cast with the first paint's decisive
    # region's offset: engine.extent, PatchSet.ray_scale; the lamps hang at the new paint's drop). On
    # the adaptive model the kept mesh is not the one a cold solve makes for the new paint: the warm solve is the cold solve
    # *of the kept mesh* (to 1e-6: nothing it kept is another sample), and how far that mesh is
    # from the re-meshed cold solve is the adaptive model's own open question (issue 37; seed 3:
    # 0.1849 against 0.1476, 1.25 x, for this stroke and its lux fill; docs/benchmarks.md)
    for faces in (exp2.faces, brighter):
        warm = state.solve(faces)
        if model == "polygon":
            cold2 = jobs.run_solve(faces, options, default_max_patch_size=size)
            assert _final(warm)[0] == _final(cold2)[0]
            assert _final(warm)[1] <= 1.01 * _final(cold2)[1], (_final(warm), _final(cold2))
        else:
            cold2 = jobs.run_solve(faces, replace(options, refine_passes=0), patches=state.painted(faces),
                                   default_max_patch_size=size)
            assert _final(warm)[0] == _final(cold2)[0]
            assert _final(warm)[1] == pytest.approx(_final(cold2)[1], rel=1e-6), (_final(warm), _final(cold2))
        assert np.all(np.isfinite(warm.stored.exitance))


def test_a_stroke_is_re_solved_live_from_the_prepared_model(monkeypatch):
    """Live mode's re-solve (PreparedScene.live): the last solve's model retargeted on its transfer
    to every patch, without a ray, a kernel row or a factorisation, gives an answer no more than 10 %
    worse than a cold solve's, and changes nothing kept."""
    from relight_addon.engine import inverse

    exp, options, size, state = _prepared_staircase(JobOptions(**OPTIONS))
    assert state.live(exp.faces) is None and state.reason == "nothing is solved yet"
    first = state.solve(exp.faces)
    problem = first.model.problem  # with the kernel's direct light and the refined lamps added
    assert problem.direct_correction is not None and first.model.lamp_refinement["lamps_refined"] > 0
    T_all = problem.all_rows_transfer()  # columns of A^-1 (every patch), against rows of it (the targets)
    for c in range(3):
        assert np.allclose(T_all[c][problem.targets], problem.transfer[c], rtol=1e-9,
                           atol=1e-12 * np.abs(problem.transfer[c]).max())
    kept = (state.model, state.patches, state.paint[0].copy())

    _stroke(12, "flight_1")
    exp2 = export.export_scene()
    rows = _counting(monkeypatch)
    monkeypatch.setattr(inverse, "_Factor", lambda *a: pytest.fail("factorised again"))
    live = state.live(exp2.faces)
    monkeypatch.undo()
    assert state.reason is None and rows == [] and state.live_solves == 1
    assert state.model is kept[0] and state.patches is kept[1] and np.array_equal(state.paint[0], kept[2])
    assert live.problem.m == int(live.patches.target.sum()) > problem.m
    final = live.reduction.final
    assert final.n_negative == 0 and final.n_lights <= options.max_lights
    assert final.error == pytest.approx(live.problem.error(_full(live.problem, final)), rel=1e-9)
    assert np.all(np.isfinite(live.stored.radiosity)) and any("live answer" in w for w in live.warnings)
    # Best k Lights never reads the inverse solution: a stroke makes none (the report says so), and no
    # per-face rows (the scene holds them); the certificate's NNLS started from the solve's
    assert live.inverse is None and live.report["inverse"]["solved"] is False
    assert live.report["inverse"]["relative_error"] is None and live.report["objects"] is None
    assert first.report["inverse"]["solved"] is True and first.report["objects"]
    assert live.reduction.certificate.nnls == pytest.approx(
        bl.lower_bounds(live.problem.transfer, live.problem.b_target, 1).nnls, rel=1e-9)
    # the layer (every patch's radiosity, from the kept transfer) against a forward solve of the answer
    B = live.problem.configuration_radiosity(_full(live.problem, final)) + live.problem.background_radiosity
    np.testing.assert_allclose(live.stored.radiosity[live.final_index], B, rtol=1e-5, atol=1e-6 * np.abs(B).max())
    # the stroke's light-paths check from the products with F of every light's column, made once
    # (ColumnProducts.table), is the check from its radiosity itself; a second time, no product at all
    import bpy

    from relight_addon.blender import light_paths
    from relight_addon.engine import bounces

    settings = light_paths.snapshot(bpy.context.scene)
    plain = light_paths.assess_solve(None, live, settings)
    products = state.column_products()
    assert products is not None and light_paths.assess_solve(None, live, settings, products=None) == plain
    # (Live's, before the first stroke)
    light_paths.prepare_stroke_checks(products, settings, live.patches.reflectance, live.problem.background_radiosity)
    calls = []
    real = bounces.matvec
    monkeypatch.setattr(bounces, "matvec", lambda F, x: calls.append(1) or real(F, x))
    block, warns = light_paths.assess_solve(None, live, settings, products=products)
    monkeypatch.undo()
    d, want = block["estimated_difference"], plain[0]["estimated_difference"]
    assert want is not None and d["reflections"] == want["reflections"]
    # (the tables are float32, their sums over the lights' columns too: 1e-5, ten float32 epsilons x the lights)
    assert d["mean"] == pytest.approx(want["mean"], rel=1e-5) and d["min"] == pytest.approx(want["min"], rel=1e-5)
    assert warns == plain[1] and not calls  # (no product with F in the stroke)
    # as good as a cold solve of the same paint: not worse than it by more than 10 % (here, on an AMD
    # EPYC, Live's answer is better: 0.148 against the cold solve's 0.188, whose lamps, refined for the
    # stroked paint, end in a worse optimum than the ones Live kept; issue 37)
    cold = jobs.run_solve(exp2.faces, options, default_max_patch_size=size)
    assert _final(live)[1] <= 1.1 * _final(cold)[1], (_final(live), _final(cold))
    moved = replace(exp2.faces, vertices=exp2.faces.vertices * 1.01)
    assert state.live(moved) is None and state.reason == "the geometry changed since it was prepared"


def _strokes(faces, name, avoid):
    """Four strokes on object ``name``, each on the paint the previous left, as (kind, faces):
    ``extend`` its 12 unpainted faces nearest its painted ones (not in ``avoid``), ``new spot`` 12
    nearest a point away from the paint, ``erase`` the extension unpainted, ``lux fill`` the
    extension back and both at 1.5 x the paint's radiosity (as Fill Selected (lx) sets a value)."""
    on = faces.face_object == faces.object_names.index(name)
    cen = np.zeros((faces.n_faces, 3))
    np.add.at(cen, faces.triangle_face, faces.vertices[faces.triangles].mean(axis=1))
    cen /= np.maximum(np.bincount(faces.triangle_face, minlength=faces.n_faces), 1)[:, None]
    hub = cen[faces.target & on].mean(axis=0)
    rgb = faces.target_radiosity[np.flatnonzero(faces.target & on)[0]]
    free = np.flatnonzero(on & ~faces.target & ~avoid)
    ext = free[np.argsort(np.linalg.norm(cen[free] - hub, axis=1))[:12]]
    rest = np.setdiff1d(free, ext)
    far = rest[np.argmax(np.linalg.norm(cen[rest] - hub, axis=1))]
    spot = rest[np.argsort(np.linalg.norm(cen[rest] - (0.7 * cen[far] + 0.3 * hub), axis=1))[:12]]
    t, r, out = faces.target.copy(), faces.target_radiosity.copy(), []
    for kind, ids, on_, value in (("extend", ext, True, rgb), ("new spot", spot, True, rgb),
                                  ("erase", ext, False, 0.0), ("lux fill", np.r_[ext, spot], True, 1.5 * rgb)):
        t[ids], r[ids] = on_, value
        out.append((kind, replace(faces, target=t.copy(), target_radiosity=r.copy())))
    return out


@pytest.mark.slow
def test_every_kind_of_stroke_is_answered_live_as_well_as_a_cold_solve():
    """Live's answer to each kind of stroke (extend, a new spot, erase, a lux fill), from the
    prepared state (its quick answer, then its second, PreparedScene.refine_live: the lamps refined
    for the stroke's targets, kept when better), within 5 % of a cold solve of the same paint."""
    exp, options, size, state = _prepared_staircase(JobOptions(**OPTIONS))
    state.solve(exp.faces)
    state.prepare_live(exp.faces)
    kept = (state.model, state.patches)
    worse = {}
    for kind, faces in _strokes(exp.faces, "flight_1", np.zeros(exp.faces.n_faces, dtype=bool)):
        quick = state.live(faces)
        assert state.reason is None, (kind, state.reason)  # answered from the prepared state
        answer = quick
        for step in range(len(prepared.REFINE_STEPS)):  # (Live's answers after the quick one, each kept if better)
            better = state.refine_live(answer, step)
            assert better is None or _final(better)[1] < _final(answer)[1]
            answer = better or answer
        cold = jobs.run_solve(faces, options, default_max_patch_size=size)
        worse[kind] = (_final(quick)[1], _final(answer)[1], _final(cold)[1])
    assert state.model is kept[0] and state.patches is kept[1] and state.refined_solves == 8
    assert all(answer <= 1.05 * cold for _, answer, cold in worse.values()), worse


@pytest.mark.slow
def test_the_button_after_each_kind_of_stroke_gives_the_cold_solve_reusing_the_state():
    """Solve & Reduce after a stroke (PreparedScene.solve) on the polygon model, whose mesh is the
    cold solve's: after each kind of stroke (extend, a new spot, erase, a lux fill; each on the
    paint the one before left) an answer as good as the cold solve's within 1 % (the same number of lights; the
    kernel's pairs and the lamps' irradiance are drawn per pair and per lamp, so what is kept is
    what the cold solve computes; the kept rays' offset is the first paint's decisive region's,
    slightly other than the cold solve's; the lamps hang at the new paint's drop, as its), having
    cast no hemisphere ray, drawn only the kernel pairs it did not have and computed only the
    lamps it did not have; its report says what it kept."""
    exp, options, size, state = _prepared_staircase(JobOptions(**OPTIONS))
    state.solve(exp.faces)
    lamps_kept = 0
    for kind, faces in _strokes(exp.faces, "flight_1", np.zeros(exp.faces.n_faces, dtype=bool)):
        warm = state.solve(faces)
        cold = jobs.run_solve(faces, options, default_max_patch_size=size)
        assert _final(warm)[0] == _final(cold)[0], kind
        # as good as the cold solve, within 1 % (bench_warm: 0.963-0.993 x its error on these strokes)
        assert _final(warm)[1] <= 1.01 * _final(cold)[1], (kind, _final(warm), _final(cold))
        assert np.all(np.isfinite(warm.stored.exitance))
        account = warm.report["prepared"]
        kept, computed = account["kept"], account["computed"]
        assert account["from_prepared_state"] and kept["form factors (hemisphere rays)"] and computed["rays cast"] == 0
        pairs = int(warm.patches.target.sum()) * len(warm.model.lights.patches)
        assert kept["kernel pairs"] + computed["kernel pairs"] == pairs, kind
        if kind in ("extend", "new spot"):  # new target patches: their rows, and nothing else
            assert computed["kernel rows"] > 0 and kept["kernel pairs"] > computed["kernel pairs"] > 0, (kind, account)
        else:  # erase: rows kept (the erased patches' pairs of the new spot's rows drawn); lux fill: all kept
            assert computed["kernel rows"] == 0, (kind, account)
        if kind == "lux fill":
            assert computed["kernel pairs"] == 0, account
        assert account["computed anew"] and all(isinstance(x, str) for x in account["computed anew"])
        lamps_kept += kept["candidate lamps' irradiance"]
    assert lamps_kept > 0


def test_the_button_takes_the_answer_lives_warm_solve_made_for_the_same_paint(monkeypatch):
    """Solve & Reduce after Live's warm solve of a stroke (PreparedScene.refine_live, its last
    step) takes that answer whole: nothing solved again, the same lights and strengths to the bit
    as that solve and as the same solve computed again, its report and warnings saying whose answer
    it is (issue 37: the button uses what Live prepared); another paint, lux, view target or a
    lamp moved (the state's key) is another solve's input."""
    exp, options, size, state = _prepared_staircase(JobOptions(**OPTIONS))
    state.solve(exp.faces)
    state.prepare_live(exp.faces)
    _, faces = _strokes(exp.faces, "flight_1", np.zeros(exp.faces.n_faces, dtype=bool))[0]
    quick = state.live(faces)
    state.refine_live(quick, prepared.REFINE_STEPS.index("warm solve"))  # (its answer, shown only if better)
    inputs, made, by, _ = state.answer
    assert by == "Live's warm solve" and inputs == state.answer_inputs(faces)
    monkeypatch.setattr(jobs, "run_solve", lambda *a, **k: pytest.fail("solved again"))
    taken = state.solve(faces)
    monkeypatch.undo()
    assert state.reason is None and state.model is made.model and state.patches is made.patches
    assert "Live's warm solve" in taken.report["prepared"]["taken"] and taken.report["prepared"]["kept"]
    assert taken.report["prepared"]["taken"] in taken.warnings and taken.report["prepared"]["taken"] in \
        taken.report["warnings"]
    assert not any("taken whole" in w for w in made.warnings + made.report["warnings"])  # (a copy's own)
    assert taken.report["final"] == made.report["final"] and taken.final_index == made.final_index
    assert np.array_equal(taken.stored.exitance[taken.final_index], made.stored.exitance[made.final_index])
    # the same solve computed again (nothing kept to take): the answer taken, to the bit
    state.answer = None
    again = state.solve(faces)
    assert "taken" not in again.report["prepared"] and again.report["final"] == taken.report["final"]
    assert np.array_equal(again.stored.exitance[again.final_index], taken.stored.exitance[taken.final_index])
    # what else a solve reads: the paint, the lux, the view target, the scene's key
    lux = np.where(faces.target, 100.0, 0.0)
    other = {"paint": replace(faces, target_radiosity=faces.target_radiosity * 1.01),
             "lux": replace(faces, target_lux=lux), "view target": replace(faces, view_target=object())}
    digests = {name: state.answer_inputs(f) for name, f in other.items()}
    assert inputs not in digests.values() and len(set(digests.values())) == 3, digests
    state.key = {**state.key, "lamps and World": "moved"}
    assert state.answer_inputs(faces) != inputs


def test_kept_lamps_compute_what_offer_lamps_computes_and_only_the_lamps_not_kept(monkeypatch):
    """The warm solve's candidate lamps (prepared.KeptLamps.offer): with nothing kept, the lights
    offer_lamps makes, the same numbers; offered again for the same plan, no lamp computed and the
    same lights; in another plan every lamp, kept or computed, is offer_lamps' number for it bit for
    bit (each lamp on its own seed, keyed by its geometry, not its place: issue 37), and only the
    lamps not kept are computed."""
    from relight_addon.engine import candidate_lamps
    from relight_addon.engine.lights import candidate_mask
    from relight_addon.engine.sampling import SceneSampler
    from relight_addon.pipeline.meshing import mesh_for_job

    blend_files.open_blend(os.path.join(SAMPLES, "staircase_targets.blend"))
    exp = export.export_scene()
    options = JobOptions(**OPTIONS).validate()
    patches = mesh_for_job(exp.faces, options, exp.settings.get("max_patch_size"))
    mask, sampler = candidate_mask(patches, "inverse"), SceneSampler(patches)
    cold, n_cold = candidate_lamps.offer_lamps(None, patches, mask, options, sampler, options.seed)
    kept = prepared.KeptLamps()
    warm, n_warm = kept.offer(None, patches, mask, options, sampler, options.seed)
    assert n_cold == n_warm > 0 and kept.computed == n_cold and kept.reused == 0
    assert list(map(digest, warm.lamps)) == list(map(digest, cold.lamps))
    assert (warm.irradiance != cold.irradiance).nnz == 0  # bit for bit
    calls = []
    real = prepared.lamps_irradiance
    monkeypatch.setattr(prepared, "lamps_irradiance", lambda *a, **k: calls.append(len(a[1])) or real(*a, **k))
    again, _ = kept.offer(None, patches, mask, options, sampler, options.seed)
    assert calls == [0] and kept.reused == n_cold and kept.computed == 0
    assert (again.irradiance != cold.irradiance).nnz == 0
    # another plan (half the paint erased: other clusters, other aims; painted patches are candidates
    # again): only its new lamps computed, and every lamp offer_lamps' number for it
    t = exp.faces.target.copy()
    t[np.flatnonzero(t)[: max(1, int(t.sum()) // 2)]] = False
    other = replace(patches, target=t[patches.face])
    mask2 = candidate_mask(other, "inverse")
    fresh, n_fresh = candidate_lamps.offer_lamps(None, other, mask2, options, sampler, options.seed)
    calls.clear()
    moved, n_moved = kept.offer(None, other, mask2, options, sampler, options.seed)
    before = set(map(candidate_lamps.lamp_key, cold.lamps))
    new = [lamp for lamp in moved.lamps if candidate_lamps.lamp_key(lamp) not in before]
    assert n_moved == n_fresh and kept.computed + kept.reused == n_fresh and 0 < len(new) <= kept.computed
    assert kept.reused > 0 and calls == [kept.computed]
    assert list(map(digest, moved.lamps)) == list(map(digest, fresh.lamps))
    assert (moved.irradiance != fresh.irradiance).nnz == 0  # bit for bit, kept lamps included


def _full(problem, point):
    e = np.zeros((problem.n_lights, 3))
    e[point.lights] = point.exitance
    return e


def test_what_the_prepared_state_cannot_follow_is_named():
    exp, options, size, state = _prepared_staircase(JobOptions(**OPTIONS))
    faces = exp.faces
    moved = replace(faces, vertices=faces.vertices + np.array([0.0, 0.0, 0.01]))
    assert state.stale_reason(moved, options, size) == "the geometry changed since it was prepared"
    forbid = faces.forbidden.copy()
    forbid[np.flatnonzero(~forbid)[0]] = True
    assert "forbidden faces" in state.stale_reason(replace(faces, forbidden=forbid), options, size)
    grey = replace(faces, reflectance=faces.reflectance * 0.9)
    assert "materials" in state.stale_reason(grey, options, size)
    assert "options" in state.stale_reason(faces, replace(options, seed=4), size)
    with pytest.raises(ValueError, match="the prepared scene is stale: the geometry changed"):
        state.solve(moved)


def _clustered_stroke(faces, patches, n=12):
    """``faces`` with ``n`` more faces painted: unpainted faces the patches cluster with others, on
    the object with the most of them that is painted, nearest its paint, at its paint's colour."""
    free = prepared.clustered_faces(patches) & ~faces.target
    objs = np.unique(faces.face_object[faces.target])
    o = max(objs, key=lambda k: int(np.sum(free & (faces.face_object == k))))
    cen = np.zeros((faces.n_faces, 3))
    np.add.at(cen, faces.triangle_face, faces.vertices[faces.triangles].mean(axis=1))
    cen /= np.maximum(np.bincount(faces.triangle_face, minlength=faces.n_faces), 1)[:, None]
    painted = np.flatnonzero(faces.target & (faces.face_object == o))
    ids = np.flatnonzero(free & (faces.face_object == o))
    ids = ids[np.argsort(np.linalg.norm(cen[ids] - cen[painted].mean(axis=0), axis=1))[:n]]
    target, radiosity = faces.target.copy(), faces.target_radiosity.copy()
    target[ids], radiosity[ids] = True, faces.target_radiosity[painted[0]]
    return replace(faces, target=target, target_radiosity=radiosity), ids


def _face_error(outcome, faces):
    """The painted-face relative error of the final configuration: sqrt(sum a_f |B_f - T_f|^2 /
    sum a_f |T_f|^2) over the painted faces f, B_f its patches' radiosity averaged over the face
    (the same measure for any mesh: benchmarks/bench_live_quality.py)."""
    from relight_addon.engine.scene import face_mean
    from relight_addon.pipeline.checks import face_areas

    B = face_mean(outcome.patches, outcome.stored.radiosity[outcome.final_index])
    t = faces.target
    a = face_areas(faces)[t][:, None]
    d = B[t] - faces.target_radiosity[t]
    return float(np.sqrt((a * d * d).sum() / (a * faces.target_radiosity[t] ** 2).sum()))


def test_paint_on_clustered_faces_maps_onto_the_kept_clusters():
    """The adaptive model clusters the staircase's unpainted faces; paint that lands on them maps
    onto the kept patches (issue 37: every stroke answered from the prepared state): a cluster is a
    target when any of its faces is painted, at their area-weighted mean radiosity;
    a patch of one face keeps its face's target; a lux fill there maps too (the cluster asks for its
    faces' area-weighted lux); a cluster asked for lux on some faces and a radiosity on others
    cannot be mapped (one patch, one target) and is named."""
    from relight_addon.engine.geometry import triangle_areas

    exp, options, size, state = _prepared_staircase(JobOptions(seed=3))  # the default patch model: adaptive
    state.solve(exp.faces)
    faces, ids = _clustered_stroke(exp.faces, state.patches)
    assert state.unmappable(faces) is None
    mapped = state.painted(faces)
    ps = state.patches
    clustered = prepared.clustered_faces(ps)
    single = ~np.isin(np.arange(ps.n_patches), ps.tri_patch[clustered[ps.tri_face]])
    assert np.array_equal(mapped.target[single], faces.target[ps.face[single]])
    assert np.array_equal(mapped.target_radiosity[single], faces.target_radiosity[ps.face[single]])
    # each cluster the stroke touched, from its own triangles
    area = triangle_areas(ps.tri_vertices)
    touched = np.unique(ps.tri_patch[np.isin(ps.tri_face, ids)])
    assert len(touched) > 0
    for p in touched:
        tri = ps.tri_patch == p
        on = faces.target[ps.tri_face[tri]]
        assert mapped.target[p] == on.any()
        if mapped.target[p]:
            want = (area[tri][on, None] * faces.target_radiosity[ps.tri_face[tri][on]]).sum(0) / area[tri][on].sum()
            np.testing.assert_allclose(mapped.target_radiosity[p], want, rtol=1e-12)
        else:
            assert not mapped.target_radiosity[p].any()
    assert mapped.target[touched].all()
    # a lux fill on the stroke's faces: each touched cluster an illuminance target at its faces' lux
    lux = np.zeros(faces.n_faces)
    lux[ids] = np.linspace(200.0, 400.0, len(ids))
    rho = faces.reflectance[ids].mean(axis=1, keepdims=True)
    radiosity = faces.target_radiosity.copy()
    radiosity[ids] = rho * lux[ids, None] / 683.0  # (white light: the export's irradiance_from_lux)
    filled = replace(faces, target_lux=lux, target_radiosity=radiosity)
    assert state.unmappable(filled) is None
    mapped = state.painted(filled)
    assert np.array_equal(mapped.target, state.painted(faces).target)
    from relight_addon.engine.targets import Illuminance, PaintedRadiance
    asked = Illuminance.from_scene(filled, mapped)
    assert set(asked.patches.tolist()) == set(touched.tolist())  # the clusters, and no other patch
    for p, got in zip(asked.patches, asked.lux):
        tri = ps.tri_patch == p
        w = area[tri] * filled.target[ps.tri_face[tri]]
        assert got == pytest.approx((w * lux[ps.tri_face[tri]]).sum() / w.sum(), rel=1e-12)
    assert not np.isin(PaintedRadiance.from_scene(filled, mapped).patches, touched).any()
    # one cluster asked for lux on a face and a radiosity on another: named, solved from scratch
    both = next(p for p in touched if len(np.unique(ps.tri_face[(ps.tri_patch == p)
                                                                  & filled.target[ps.tri_face]])) > 1)
    on = np.intersect1d(ps.tri_face[ps.tri_patch == both], ids)
    lux2 = lux.copy()
    lux2[on[0]] = 0.0
    obj = faces.object_names[faces.face_object[on[0]]]
    n_faces = len(np.intersect1d(ps.tri_face[ps.tri_patch == both], np.flatnonzero(filled.target)))
    assert state.unmappable(replace(filled, target_lux=lux2)) == (
        f"an illuminance target (lx) and a painted radiosity on {n_faces} face(s) the patch model had clustered "
        f"together (1 patch(es); objects: {obj})")


def _lux_fill(faces, ids):
    """``faces`` with faces ``ids`` asked for the illuminance (lx) of their painted radiosity under
    white light (the export's: radiosity = reflectance x lux / 683), a Fill Selected in lx."""
    rho = faces.reflectance[ids].mean(axis=1)
    lux = np.zeros(faces.n_faces)
    lux[ids] = 683.0 * faces.target_radiosity[ids].mean(axis=1) / rho
    radiosity = faces.target_radiosity.copy()
    radiosity[ids] = rho[:, None] * lux[ids, None] / 683.0
    return replace(faces, target_lux=lux, target_radiosity=radiosity)


@pytest.mark.slow
def test_paint_on_clustered_faces_is_solved_from_the_prepared_state_within_a_quarter_of_cold():
    """A stroke of 12 faces the adaptive model had clustered, solved from the prepared state (the
    paint mapped onto the kept clusters, no ray cast) against a cold solve of the same paint (its
    mesh meshes them at the patch size). Issue 37 asks the painted-face error within 5 %: not met
    in general (open). Measured at seeds 0-5 (docs/benchmarks.md): 1.18 / 1.16 / 1.02 / 1.06 /
    1.19 / 1.22 x (this seed 3: 0.0782 against 0.0738), before the refinement's per-patch draws
    1.18 / 1.16 / 1.01 / 0.98 / 1.14 / 1.21 x (the cold solves 2 % worse on average): the bound
    here, 1.25 x, holds the warm answer to what it does at every seed measured."""
    exp, options, size, state = _prepared_staircase(JobOptions(seed=3))
    state.solve(exp.faces)
    faces, _ = _clustered_stroke(exp.faces, state.patches)
    warm = state.solve(faces)
    assert state.reason is None and state.warm == 1 and warm.report["prepared"]["computed"]["rays cast"] == 0
    cold = jobs.run_solve(faces, options, default_max_patch_size=size)
    assert cold.patches.n_patches > warm.patches.n_patches  # (the cold mesh meshes the new paint finer)
    e_warm, e_cold = _face_error(warm, faces), _face_error(cold, faces)
    assert e_warm <= 1.25 * e_cold, (e_warm, e_cold, _final(warm), _final(cold))


@pytest.mark.slow
def test_a_lux_fill_on_clustered_faces_is_answered_from_the_prepared_state():
    """A Fill Selected in lx on 12 faces the adaptive model had clustered: answered from the
    prepared state (no ray cast, not from scratch), as the same radiosity painted there is: the
    same answer to the bit (an illuminance target is a row of radiosity reflectance x E; the
    cluster's, its faces' area-weighted mean), the lux asked reported on the filled object. Against
    a cold solve, which meshes the filled faces at the patch size, the painted-face error is 1.13 x
    its (0.0892 against 0.0789): the clusters' limit, the same for that radiosity painted
    (docs/benchmarks.md, "Paint on clustered faces: a lux fill")."""
    exp, options, size, state = _prepared_staircase(JobOptions(seed=3))
    state.solve(exp.faces)
    faces, ids = _clustered_stroke(exp.faces, state.patches)
    filled = _lux_fill(faces, ids)
    lux = state.solve(filled)
    assert state.reason is None and lux.report["prepared"]["computed"]["rays cast"] == 0
    grey = state.solve(replace(filled, target_lux=None))
    assert _final(lux) == _final(grey)
    name = filled.object_names[filled.face_object[ids[0]]]
    assert lux.report["targets_photometric"][name]["target_lx"] > 0  # (the clusters' lux, read from them)
    assert "target_lx" not in grey.report["targets_photometric"][name]


def _clustered_polygons(state, name):
    """The polygons of object ``name`` that the state's patches cluster with others."""
    exp = export.export_scene()
    o = exp.faces.object_names.index(name)
    return exp.faces.face_index[prepared.clustered_faces(state.patches) & (exp.faces.face_object == o)].tolist()


def test_the_add_on_re_solves_a_stroke_from_its_session(addon, monkeypatch):
    """Solve & Reduce, a stroke, Solve & Reduce: the second solve starts from the scene's prepared
    state (no hemisphere ray again, nothing meshed for the operator's estimate); after an object
    moved, it is meshed and solved from scratch, and the panel's warnings say why."""
    from relight_addon.blender import preparation

    preparation.PREPARED.clear()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    scene = bpy.context.scene
    assert scene.relight.patch_model == "adaptive"  # the default, as an artist has it
    assert bpy.ops.relight.solve() == {"FINISHED"}
    state = preparation.PREPARED[scene.name]
    assert state.solves == 1
    _stroke(12, "flight_1", _clustered_polygons(state, "flight_1"))  # where the adaptive model keeps faces whole
    monkeypatch.setattr(prepared, "compute_form_factors", lambda *a, **k: pytest.fail("rays cast again"))
    monkeypatch.setattr(kernel_estimator, "compute_form_factors", lambda *a, **k: pytest.fail("rays cast again"))
    # (nor meshed: the operator's cost estimate is the kept patches', with the stroke's paint)
    monkeypatch.setattr(preparation.meshing, "mesh_for_job", lambda *a, **k: pytest.fail("meshed again"))
    assert bpy.ops.relight.solve() == {"FINISHED"}
    monkeypatch.undo()
    assert preparation.PREPARED[scene.name] is state and state.solves == 2 and state.warm == 1
    assert "solved from scratch" not in scene.relight.last_warnings
    bpy.data.objects["ceiling"].location.z += 0.05
    meshed = []
    real = preparation.meshing.mesh_for_job
    monkeypatch.setattr(preparation.meshing, "mesh_for_job", lambda *a, **k: meshed.append(1) or real(*a, **k))
    assert bpy.ops.relight.solve() == {"FINISHED"}
    monkeypatch.undo()
    assert meshed == [1]  # (a scene the state does not serve: meshed, its cost estimated, as before)
    assert preparation.PREPARED[scene.name] is not state
    assert "solved from scratch: the geometry changed since it was prepared" in scene.relight.last_warnings
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    assert not preparation.PREPARED  # another file: the session lets the state go


def test_a_strokes_quick_curve_ends_near_the_max_lights_with_the_answer_a_longer_one_gives(monkeypatch):
    """A stroke's quick answer computes its curve to the Max Lights and LIVE_CURVE_EXTRA more (the
    chart's neighbourhood; the later answers bring the whole curve): its final configuration is the
    one the curve computed further gives, to the bit (the stop criteria keep it within the Max
    Lights; the curve is built upward), only the points beyond are left to the later answers."""
    exp, options, size, state = _prepared_staircase(JobOptions(**OPTIONS))
    state.solve(exp.faces)
    state.prepare_live(exp.faces)
    strokes = _strokes(exp.faces, "flight_1", np.zeros(exp.faces.n_faces, dtype=bool))[:2]
    answers, quick = [], jobs.LIVE_CURVE_EXTRA
    for extra in (quick, quick + 4):
        monkeypatch.setattr(jobs, "LIVE_CURVE_EXTRA", extra)
        out = []
        for kind, faces in strokes:
            out.append(state.live(faces))
            assert state.reason is None, (kind, state.reason)
        answers.append(out)
    for a, b in zip(*answers):
        fa, fb = a.reduction.final, b.reduction.final
        assert fa.n_lights <= options.max_lights
        assert np.array_equal(fa.lights, fb.lights) and np.array_equal(fa.exitance, fb.exitance)
        assert fa.error == fb.error
        ks = [len(p.lights) for p in a.reduction.curve]
        assert len(a.reduction.curve) < len(b.reduction.curve)
        assert max(ks) <= options.max_lights + quick
        assert [p.error for p in a.reduction.curve] == [p.error for p in b.reduction.curve][:len(a.reduction.curve)]
