"""The chosen lamps' refinement (engine/lamp_refinement.py, issue 17 item 3): it lowers the true
error, finds at least what an exhaustive grid over a spot's aim and cone finds, keeps every lamp
valid (its cone, its blend, hanging in front of a surface that may hold lights), and is
reproducible.

References, independent of the Nelder-Mead search: an exhaustive grid of aims and cones (each
configuration's error by the same transport, NNLS strengths), the geometry of the room (the
ceiling's height, the drop, where the shelf blocks it), and the unrefined solve of the same scene.
"""
import itertools
import math

import numpy as np
import pytest

from relight_addon.engine import lamp_refinement as lr
from relight_addon.engine.candidate_lamps import LAMP_POINTS
from relight_addon.engine.lamps import lamp_irradiance
from relight_addon.engine.lights.placed import frame
from relight_addon.engine.lights.spot import spot_lamp
from relight_addon.engine.extent import decisive_region
from relight_addon.engine.options import JobOptions
from relight_addon.pipeline.jobs import run_solve

from test_engine_candidate_lamps import D, H, SHELF, room

#: one spot and nothing else: its parameters alone decide the error
ONE_SPOT = dict(spot_lamps=True, surface_lights=False, max_lights=1, seed=3)


def _faces(shelf=False):
    """room()'s FaceSet (the painting the only target, the ceiling the only candidate surface)."""
    import test_engine_candidate_lamps as tc

    captured = {}
    original = tc.AdaptiveModel.mesh

    def mesh(self, faces):
        captured["faces"] = faces
        return original(self, faces)

    tc.AdaptiveModel.mesh = mesh
    try:
        room(shelf)
    finally:
        tc.AdaptiveModel.mesh = original
    return captured["faces"]


@pytest.fixture(scope="module")
def solved():
    faces = _faces()
    opts = dict(ONE_SPOT, max_patch_size=0.25)
    refined = run_solve(faces, JobOptions(**opts))
    plain = run_solve(faces, JobOptions(**opts, refine_lamps=False))
    return faces, refined, plain


def _final_lamp(outcome):
    red, lights = outcome.reduction, outcome.problem.lights
    (j,) = red.final.lights
    return lights.lamp(j), red.final.relative_error


def test_refinement_lowers_the_error_and_says_so(solved):
    _, refined, plain = solved
    lamp, err = _final_lamp(refined)
    lamp0, err0 = _final_lamp(plain)
    info = refined.report["model"]["lamp_refinement"]
    assert info["lamps_refined"] >= 1 and info["evaluations"] > 10
    row = info["points"][-1]
    assert row["relative_error_before"] == pytest.approx(err0, rel=1e-9)  # the same choice, before
    assert row["relative_error_after"] == pytest.approx(err, rel=1e-9)
    assert err < 0.97 * err0, (err, err0)
    # the report's final light is the refined lamp, with the values the transport used
    (rec,) = refined.report["final"]["lights"]
    assert rec["kind"] == "spot"
    np.testing.assert_allclose(rec["location"], lamp.position)
    assert rec["spot_size"] == pytest.approx(lamp.spot_size) and rec["spot_blend"] == pytest.approx(lamp.spot_blend)
    assert not np.allclose(lamp.direction, lamp0.direction) or lamp.spot_size != lamp0.spot_size
    # the offered kinds are counted before the refined lamps joined the lights
    assert refined.report["model"]["lights_by_kind"] == plain.report["model"]["lights_by_kind"]


def test_the_refined_spot_stays_valid(solved):
    faces, refined, _ = solved
    lamp, _ = _final_lamp(refined)
    region = decisive_region(faces)  # the room, as the painting sees it
    assert region.diagonal == pytest.approx(math.sqrt(4.0 ** 2 + 3.0 ** 2 + H ** 2), rel=0.01)
    drop = 0.02 * region.diagonal  # candidate_lamps.DROP_FRACTION of the region's diagonal
    assert lamp.position[2] == pytest.approx(H - drop, abs=1e-9)  # it slid along the ceiling, no lower
    assert 0.0 <= lamp.position[0] <= 4.0 and 0.0 <= lamp.position[1] <= 3.0
    assert 0.0 < lamp.spot_size <= math.pi and 0.0 <= lamp.spot_blend <= 1.0
    assert lamp.direction @ np.array([0.0, 0.0, -1.0]) > 0  # aimed into the room


def test_refinement_finds_at_least_what_an_exhaustive_grid_of_aims_and_cones_finds(solved):
    """From the unrefined spot's position: every aim on a 7 x 7 grid of +-8 degrees about the
    painting's centre and every cone on a grid of 7 sizes, blends 0, 0.3 and 0.6: the best
    configuration's error (by the same transport, NNLS strength) is what a search that also slides
    the spot along the ceiling must reach or beat."""
    _, refined, plain = solved
    problem = plain.problem
    lamp0, err0 = _final_lamp(plain)
    transport = lr.Transport(problem)
    patches = plain.patches
    aim = frame(np.array([2.0, 3.0 - 0.01, 1.5]) - lamp0.position)
    best = math.inf
    for da, db in itertools.product(np.radians(np.linspace(-8, 8, 7)), repeat=2):
        d = aim[0] + math.tan(da) * aim[1] + math.tan(db) * aim[2]
        lamps = [spot_lamp("grid", lamp0.position, d, s, blend)
                 for s in lamp0.spot_size * np.geomspace(0.6, 1.4, 7) for blend in (0.0, 0.3, 0.6)]
        Hs = lamp_irradiance(patches, lamps, seed=5, points_per_patch=LAMP_POINTS)[:, :, 0]
        for h in Hs.T:
            col = transport.column(h)
            err2 = 0.0
            for c in range(3):
                a = col[:, c]
                s = max(float(a @ problem.b_target[:, c]) / max(float(a @ a), 1e-300), 0.0)
                err2 += float(np.sum((a * s - problem.b_target[:, c]) ** 2))
            best = min(best, math.sqrt(err2) / problem.target_norm)
    _, err = _final_lamp(refined)
    print(f"unrefined {err0:.4f}, grid best {best:.4f}, refined {err:.4f}")
    assert best < err0  # the grid is a real improvement to reach
    assert err <= best * 1.02


def test_refinement_is_reproducible_with_a_seed(solved):
    faces, refined, _ = solved
    again = run_solve(faces, JobOptions(**ONE_SPOT, max_patch_size=0.25))
    a, ea = _final_lamp(refined)
    b, eb = _final_lamp(again)
    assert ea == eb
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.direction, b.direction)


def test_a_lamp_hangs_only_in_front_of_a_free_candidate_surface():
    """Mount.holds against the room's geometry: under the ceiling at the drop, yes; under the
    shelf (5 cm below the ceiling, the drop blocked), no; beyond the ceiling's edge (above the
    room: the ray back meets a wall's outside or nothing), no; under the painted wall, no."""
    patches, sampler = room(shelf=True)
    from relight_addon.engine.lights import candidate_mask

    drop = 0.15
    mount = lr.Mount(patches, candidate_mask(patches), drop, sampler)
    up = np.array([0.0, 0.0, -1.0])  # the ceiling's normal
    assert mount.holds(np.array([2.5, 1.5, H - drop]), up)
    x, y = np.mean(np.asarray(SHELF)[:, :2], axis=0)
    assert not mount.holds(np.array([x, y, H - drop]), up)  # the shelf is nearer than the drop
    assert not mount.holds(np.array([4.3, 1.5, H - drop]), up)  # outside the room
    n = mount.normal_at(np.array([2.5, 1.5, H]) + drop * up)
    assert n is not None and n @ up > 0.999
    assert mount.normal_at(np.array([2.5, 1.5, H - 0.5])) is None  # no candidate patch 0.15 m behind it


def test_a_cancel_within_a_lamps_search_stops_the_solve_without_a_half_refined_answer(solved):
    """Issue 37: a newer stroke cancels Live's later answer; the refinement looked at the cancel
    only before each lamp's search (60 evaluations, over a second). It is now heard at the search's
    next evaluation, and the solve raises Cancelled instead of returning a half-refined answer."""
    from relight_addon.engine.sampling import Cancelled
    from relight_addon.engine import lamps as lamps_module

    faces, refined, _ = solved
    n_full = refined.report["model"]["lamp_refinement"]["evaluations"]
    calls = {"irradiance": 0}
    original = lamps_module.lamp_irradiance

    def counting(*a, **kw):
        calls["irradiance"] += 1
        return original(*a, **kw)

    heard = {"at": None}

    def cancel():  # True once the refinement has evaluated 5 lamps
        if heard["at"] is None and calls["irradiance"] >= 5:
            heard["at"] = calls["irradiance"]
        return heard["at"] is not None

    lr.lamp_irradiance = counting
    try:
        with pytest.raises(Cancelled):
            run_solve(faces, JobOptions(**ONE_SPOT, max_patch_size=0.25), cancel=cancel)
    finally:
        lr.lamp_irradiance = original
    assert heard["at"] is not None
    assert calls["irradiance"] <= heard["at"] + 1 < n_full  # (stopped at the next evaluation)


def _gallery_faces():
    """Issue 17's gallery (tests/artist_scenes.gallery) as the export makes it."""
    import bpy  # noqa: F401 (artist_scenes' bmesh comes with it)
    import artist_scenes
    import cycles_reference as cr
    from relight_addon.blender import export

    cr.reset_blender()
    try:
        artist_scenes.gallery()
        return export.export_scene().faces
    finally:
        cr.reset_blender()


@pytest.fixture(scope="module")
def gallery_curve():
    """The gallery solved at seed 0 with the default candidates: its final configuration's spot is
    also in its 2- and 1-light configurations."""
    return run_solve(_gallery_faces(), JobOptions(seed=0))


def test_a_smaller_configuration_starts_from_the_lamp_the_final_one_refined(gallery_curve):
    """A smaller configuration of the curve that holds a lamp the final configuration refined starts
    its search from that refined lamp (when it fits it better than the lamp as offered) and searches
    one round: it ends no worse than that start, which is below the configuration as the selection
    chose it, in at most one round of evaluations a lamp. Reference: the start's error fitted again
    here from the problem's own columns (light_colour.fit_lights), not the search's."""
    from relight_addon.engine.light_colour import fit_lights

    out = gallery_curve
    problem, red, info = out.problem, out.reduction, out.report["model"]["lamp_refinement"]
    lamps = problem.lights.lamps
    offered = problem.n_lights - info["lamps_refined"]  # (the refined lamps are the last lights)
    # the final's refined lamps by name (a lamp keeps its name as it moves)
    final_refined = {lamps[j].name: int(j) for j in red.final.lights if j >= offered}
    assert final_refined, red.final.lights
    rows = [r for r in info["points"] if r.get("lamps_carried")]
    assert [r["n_lights"] for r in rows] == [2, 1], info["points"]
    norm = problem.target_norm
    for r in rows:
        pt = next(p for p in red.curve if p.n_lights == r["n_lights"])
        # its own refined lamp (if the search moved it further) back to the final's: the start
        start = [j if j < offered else final_refined[lamps[j].name] for j in map(int, pt.lights)]
        start_error = fit_lights(problem, np.array(sorted(set(start))))[1] / norm
        assert start_error < r["relative_error_before"], (start_error, r)
        assert pt.relative_error <= start_error * (1 + 1e-9), (pt.relative_error, start_error)
        assert r["relative_error_after"] == pytest.approx(pt.relative_error, rel=1e-9)
        n_lamps = sum(lamps[j] is not None for j in pt.lights)
        assert 0 < r["evaluations"] <= lr.MAX_EVALUATIONS * n_lamps, r
    # the final configuration searched its rounds from the lamp as offered
    assert info["points"][0]["lamps_carried"] == 0 and info["points"][0]["evaluations"] > lr.MAX_EVALUATIONS


def test_a_slid_lamp_keeps_its_aim_in_the_rounds_that_keep_it():
    """A spot under the room's ceiling aimed at the painting: its aimed point is where its axis meets
    the painting (the point it was aimed at); slid along the ceiling with the aim kept
    (AIM_ROUNDS' second round) its axis still meets that point, the aim's angles turning it about
    that line; with the direction kept (the first round) it keeps its direction; unslid, both are
    the lamp as it is (to rounding)."""
    patches, sampler = room()
    from relight_addon.engine.lights import candidate_mask

    drop = 0.15
    mount = lr.Mount(patches, candidate_mask(patches), drop, sampler)
    position = np.array([2.0, 1.0, H - drop])
    target = np.array([2.1, D - 0.01, 1.5])  # on the painting (1 cm off the north wall)
    lamp = spot_lamp("spot", position, target - position, 0.6, 0.2)
    kept = lr._LampParameters(lamp, mount, 0.3, keep_aim=True)
    turned = lr._LampParameters(lamp, mount, 0.3, keep_aim=False)
    np.testing.assert_allclose(kept.aim_point, target, atol=1e-5)
    assert turned.aim_point is None
    names = kept.names
    x0 = np.zeros(len(names))
    for p in (kept, turned):
        same = p.lamp_at(x0)
        np.testing.assert_array_equal(same.position, lamp.position)
        np.testing.assert_allclose(same.direction, lamp.direction, atol=1e-15)
    slid = x0.copy()
    slid[names.index("slide_u")], slid[names.index("slide_v")] = 1.0, -0.5
    a, b = kept.lamp_at(slid), turned.lamp_at(slid)
    np.testing.assert_array_equal(a.position, b.position)
    assert np.linalg.norm(a.position - lamp.position) > 0.3  # (it moved)
    axis = (target - a.position) / np.linalg.norm(target - a.position)
    np.testing.assert_allclose(a.direction, axis, atol=1e-5)
    np.testing.assert_allclose(b.direction, lamp.direction, atol=1e-12)
    aimed = slid.copy()
    aimed[names.index("aim_u")] = 1.0
    c = kept.lamp_at(aimed)
    assert math.acos(min(1.0, float(c.direction @ axis))) == pytest.approx(kept.step_angle, rel=1e-3)
    assert lr.AIM_ROUNDS == (False, True)


def test_the_round_that_keeps_the_aim_finds_the_gallerys_spots_a_lower_error(gallery_curve, monkeypatch):
    """The gallery's spots light its pictures from the ceiling: slid with their direction kept, their
    beams leave the pictures, so its second round searched from the first's lamp in the same
    coordinates and stopped far above where the spots can be. With the aim kept in the second round
    (AIM_ROUNDS), the final error at seed 0 is at least 10 % lower than the same solve's with the
    direction kept in both (0.183 against 0.243 measured)."""
    monkeypatch.setattr(lr, "AIM_ROUNDS", (False, False))
    direction_kept = run_solve(_gallery_faces(), JobOptions(seed=0))
    new, old = gallery_curve.report["final"]["relative_error"], direction_kept.report["final"]["relative_error"]
    assert gallery_curve.report["model"]["lamp_refinement"]["points"][0]["evaluations"] > lr.MAX_EVALUATIONS
    assert new < 0.9 * old, (new, old)
