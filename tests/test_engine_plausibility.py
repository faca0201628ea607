"""Lights a designer would hang (engine/plausibility.py). References: the utilisation of a light
computed by hand from its radiosity on the targets (sum of A_t B_t / rho_t over its power), and a
room whose desk sees the only allowed surfaces (walls 20 m away) at grazing angles."""
import numpy as np
import pytest

from relight_addon.engine.options import JobOptions
from relight_addon.engine.plausibility import MIN_UTILISATION, utilisation
from relight_addon.engine.scene import polygon_faceset
from relight_addon.pipeline.jobs import run_solve
from test_engine_extent import _quad  # (a quad of 4 corners)


def hall(ceiling_allowed):
    """A hall of 40 x 40 x 3 m (faces in), a 1 x 1 m desk top 0.75 m high in its middle painted
    grey; the floor and the desk may hold no light, the ceiling only when ``ceiling_allowed``."""
    X = Y = 40.0
    Z = 3.0
    polys = [_quad((0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)), _quad((0, 0, 0), (0, 0, Z), (X, 0, Z), (X, 0, 0)),
             _quad((0, Y, 0), (X, Y, 0), (X, Y, Z), (0, Y, Z)), _quad((0, 0, 0), (0, Y, 0), (0, Y, Z), (0, 0, Z)),
             _quad((X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)), _quad((0, 0, Z), (0, Y, Z), (X, Y, Z), (X, 0, Z)),
             _quad((19.5, 19.5, 0.75), (20.5, 19.5, 0.75), (20.5, 20.5, 0.75), (19.5, 20.5, 0.75))]
    faces = polygon_faceset(polys, reflectance=0.5, object_names=["Hall", "Desk"],
                            face_object=np.array([0, 0, 0, 0, 0, 0, 1]))
    faces.target[6] = True
    faces.target_radiosity[6] = np.pi * 0.35
    faces.forbidden[[0, 6]] = True
    if not ceiling_allowed:
        faces.forbidden[5] = True
    return faces


OPTIONS = dict(spot_lamps=False, max_lights=1, max_patch_size=2.0, seed=1)


def test_a_light_that_sends_almost_nothing_to_the_targets_is_named_with_the_cause():
    out = run_solve(hall(ceiling_allowed=False), JobOptions(**OPTIONS))
    (rec,) = out.report["final"]["lights"]
    problem, j = out.problem, out.reduction.final.lights[0]
    t = problem.targets
    by_hand = sum(float(problem.area[t] @ (problem.transfer[c][:, j] / problem.reflectance[t, c])) * w
                  for c, w in enumerate((0.2126, 0.7152, 0.0722))) / problem.light_watts[j]
    assert rec["utilisation"] == pytest.approx(by_hand, rel=1e-9)
    assert rec["utilisation"] < MIN_UTILISATION
    notes = [w for w in out.report["warnings"] if "of its light to the painted targets" in w]
    assert len(notes) == 1 and rec["object"] in notes[0] and "grazing angles" in notes[0], out.report["warnings"]
    # the best any candidate reaches is low too: the note says no light of the scene reaches them well
    assert utilisation(problem).max() < 10 * MIN_UTILISATION


def test_a_ceiling_above_the_desk_is_not_named():
    out = run_solve(hall(ceiling_allowed=True), JobOptions(**OPTIONS))
    (rec,) = out.report["final"]["lights"]
    assert rec["utilisation"] > 10 * MIN_UTILISATION
    assert not [w for w in out.report["warnings"] if "of its light to the painted targets" in w]


def test_the_positivity_note_never_advises_the_selection_already_used():
    """The note on a final configuration far from what positive lights reach advised 'use the
    greedy-swap selection' to a solve that used it (an artist's castle, chess board, temple)."""
    from types import SimpleNamespace

    from relight_addon.pipeline.notes import BEST_SELECTION, positivity_notes

    bound = SimpleNamespace(relative_error=0.02, exitance=np.ones((96, 3)))
    final = SimpleNamespace(relative_error=0.376, n_lights=3)
    (used,) = positivity_notes(bound, final, selection=BEST_SELECTION)
    assert "allow more lights" in used and BEST_SELECTION not in used and "with 96" in used
    (other,) = positivity_notes(bound, final, selection="exitance-elimination")
    assert f"use the {BEST_SELECTION} selection" in other


def test_far_weak_candidates_are_left_out_when_others_light_the_targets_well():
    """With the ceiling above the desk allowed, the cells of the walls 20 m away and of the
    ceiling far from the desk (each sends less than 0.1 % of its light to it) are left out of the
    candidates: no selection can take them, and the report says so; the cells above the desk stay,
    and the answer is one of them."""
    faces = hall(ceiling_allowed=True)
    out = run_solve(faces, JobOptions(**OPTIONS))
    problem = out.problem
    u = utilisation(problem)  # (after the leave-out: their columns are 0)
    left = problem.implausible
    assert left.any() and not left.all()
    walls = np.abs(problem.light_normal[:, 2]) < 0.5
    assert left[walls].all()
    above = ((problem.light_normal[:, 2] < -0.5) & (np.linalg.norm(problem.light_center[:, :2] - 20.0, axis=1) < 2.0)
             & (problem.light_area < 20.0))  # (the cells and groups there; the whole ceiling is 1,600 m^2)
    assert above.any() and not left[above].any()
    assert not left[out.reduction.final.lights].any()
    assert np.all(u[left] == 0.0)
    assert any("candidate light(s) left out" in w for w in out.report["warnings"])


def test_the_results_list_marks_an_implausible_light():
    """The Results panel's list marks a light that sends under 0.1 % of its light to the targets,
    or whose surface is brighter than 10^7 cd/m^2 (exitance M: L = M / pi, cd = 683 x luminance),
    and leaves a plausible one unmarked."""
    import math

    from relight_addon.engine.plausibility import implausible_mark

    assert implausible_mark({"utilisation": 0.0004, "exitance": [1.0, 1.0, 1.0]}) == "0.04% reaches the targets"
    assert implausible_mark({"utilisation": 0.2, "exitance": [10.0, 10.0, 10.0]}) == ""
    m = 2e7 * math.pi / 683.0  # W/m^2 of white light: 2 x 10^7 cd/m^2
    assert implausible_mark({"utilisation": 0.2, "exitance": [m, m, m]}) == "2e+07 cd/m\u00b2"
    assert implausible_mark({"utilisation": 0.2, "exitance": None}) == ""  # a lamp: no surface
