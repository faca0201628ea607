"""Stability where the methods fail: finite output or a clear message, never a crash.

Small ray-cast rooms (benchmarks/stability_table.py builds them; the same cases make the
table in docs/stability.md). Every solver x selection x distribution runs on each case
with the CLI's stop criteria. Independent references:
- the Eq. 1 error the engine reports for the final configuration is recomputed with a
  plain dense solve (numpy) of (I - diag(rho) F) B = e;
- which targets are unreachable is known from the geometry: the inner floor of a closed
  box that no candidate is inside;
- a target pattern no positive configuration can give: the NNLS residual (scipy) is a
  lower bound for every positive configuration's error.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import stability_table as st  # noqa: E402
from relight_addon.engine.inverse import InverseError, solve_inverse  # noqa: E402
from relight_addon.engine.radiosity import solve_radiosity  # noqa: E402

CASES = st.case_builders()
COMBOS = list(st.combos())


def forward_targets(prob, e):
    """Radiosity on the targets from a plain dense solve of (I - diag(rho) F) B = e per channel."""
    F = np.asarray(prob.F, dtype=np.float64)
    B = np.stack([np.linalg.solve(np.eye(len(F)) - prob.reflectance[:, c, None] * F, e[:, c]) for c in range(3)],
                 axis=1)
    return B[prob.targets], B


def check_rows(prob, combos, expect_positive=True, error_rtol=1e-6):
    rows = []
    solves = {}
    for solver, sel, dist in combos:
        r = st.run_row(prob, solver, sel, dist, ec_steps=4, solves=solves)
        assert r["ok"], (solver, sel, dist, r["message"])
        red = r["reduction"]
        for p in red.curve:
            assert np.isfinite(p.error) and np.all(np.isfinite(p.exitance))
        fin = red.final
        if expect_positive and sel in ("exitance-elimination", "nnls-greedy"):
            assert fin.n_negative == 0 and fin.n_lights <= 3, (solver, sel, dist)
        # independent check of the reported error: a dense forward solve of the final configuration
        bt, _ = forward_targets(prob, red.patch_exitance(prob))
        err = np.linalg.norm(bt - prob.b_target)
        assert fin.error == pytest.approx(err, rel=error_rtol, abs=1e-9 * prob.target_norm), (solver, sel, dist)
        rows.append(r)
    return rows


@pytest.fixture(scope="module")
def baseline():
    return CASES["room"][1]()


def test_reference_room_every_method(baseline):
    """The reference case: every solver x selection x distribution ends finite, the exact
    solvers reproduce the feasible targets, the positive-by-construction methods end positive."""
    rows = check_rows(baseline, COMBOS)
    assert len(rows) == 3 * (4 * 4 + 3)  # solvers x (paper selections x distributions + 3 non-distributing)
    for r in rows:
        if r["solver"] != "nnls":
            assert r["ex_relative_error"] < 1e-9
        if r["selection"] == "least-power":  # the programme says what it achieved, within its band
            assert r["message"].startswith("every target within ±10 %") and r["positive"], r["message"]
        else:
            assert r["message"] == ""


def test_reflectance_near_one_warns_and_stays_finite():
    prob = CASES["reflectance 1-1e-9"][1]()
    for solver in ("svd", "reduced", "nnls"):
        inv = solve_inverse(prob, solver)
        assert np.all(np.isfinite(inv.exitance))
        assert any("ill-conditioned" in w for w in inv.warnings)
    assert prob.condition > 1e6  # float32 rows of the weighted F: about 1e7 (1e9 with exact ones)
    combos = [c for c in COMBOS if c[1] in ("exitance-elimination", "nnls-greedy") and c[2] == "distance"]
    rows = check_rows(prob, [c for c in combos if c[0] != "svd"], error_rtol=1e-4)
    assert all(r["positive"] for r in rows)
    # the paper formulation's e_x on this system: its total power is not positive in every
    # channel, so exitance-elimination cannot end positive -- and the result says so
    r = st.run_row(prob, "svd", "exitance-elimination", "distance")
    assert r["ok"] and np.isfinite(r["final_relative_error"])
    assert not r["positive"] and "no configuration on this curve is free of negative exitances" in r["message"]
    e_x = r["inverse"].exitance * prob.area[prob.candidates][:, None]
    assert (e_x.sum(axis=0) <= 0).any()  # the power of e_x: the last light cannot be positive


def test_reflectance_one_is_a_clear_error():
    prob = CASES["reflectance 1"][1]()
    r = st.run_row(prob, "reduced", "exitance-elimination", "distance")
    assert not r["ok"] and "InverseError" in r["message"] and "singular" in r["message"]
    for solver in ("svd", "nnls"):  # a fresh problem per solve, as the add-on does
        r = st.run_row(CASES["reflectance 1"][1](), solver, "exitance-elimination", "distance")
        assert not r["ok"] and "singular" in r["message"], r["message"]


def test_reflectance_one_second_solve_repeats_the_message():
    """After a singular LU raised, a second solve on the same problem says the same thing
    (it once crashed on a half-filled factor list)."""
    prob = CASES["reflectance 1"][1]()
    for _ in range(2):
        with pytest.raises(InverseError, match="singular"):
            solve_inverse(prob, "reduced")


def test_occluded_targets_are_named():
    prob = CASES["occluded (some)"][1]()
    p, F, cube = st.room(cube=True)
    hidden = np.flatnonzero(cube & (p.normal[:, 2] > 0.5))  # from the geometry, not from T
    assert len(hidden) > 0 and set(hidden) <= set(prob.targets)
    rows = check_rows(prob, [c for c in COMBOS if c[2] == "distance" or c[1] == "nnls-greedy"])
    # the problem records them (the report names their objects: tests/test_engine_artist_geometry.py)
    assert rows[0]["ok"] and sorted(prob.unmet.tolist()) == sorted(hidden.tolist())
    # the hidden targets stay dark whatever the configuration
    _, B = forward_targets(prob, rows[0]["reduction"].patch_exitance(prob))
    assert np.abs(B[hidden]).max() < 1e-9 * np.abs(B).max()


def test_unreachable_forbidden_or_missing_targets_fail_clearly():
    for name, words in (("occluded (all)", "no candidate light reaches any target"),
                        ("all forbidden", "every face is forbidden"), ("no target", "no target")):
        prob, err = st.build_case(CASES[name][1])
        if prob is not None:  # set up, fails at the solve
            r = st.run_row(prob, "reduced", "exitance-elimination", "distance")
            err = r["message"]
            assert not r["ok"]
        assert err.startswith("InverseError") and words in err, (name, err)


def test_noisy_form_factors_stay_finite(baseline):
    prob = CASES["8 rays/patch"][1]()
    rows = check_rows(prob, [c for c in COMBOS if c[2] in ("distance", "local")])
    assert all(r["ex_relative_error"] < 1e-9 for r in rows if r["solver"] != "nnls")
    # the same lights under the accurate form factors: the noise costs accuracy but stays finite
    for r in rows[:3]:
        e = r["reduction"].patch_exitance(prob)
        B, _ = solve_radiosity(baseline.F, baseline.reflectance, e, method="direct")
        assert np.all(np.isfinite(B))


def test_infeasible_contrast_reports_the_positive_floor():
    prob = CASES["infeasible contrast"][1]()
    rows = check_rows(prob, [c for c in COMBOS if c[2] == "distance"])
    nn = solve_inverse(prob, "nnls")
    assert any("no non-negative configuration meets the targets" in w for w in nn.warnings)
    # no positive configuration does better than the NNLS optimum (up to its tolerance)
    for r in rows:
        if r["positive"]:
            assert r["final_relative_error"] >= nn.relative_error * (1 - 1e-6), (r["solver"], r["selection"])
    # with negatives allowed the exact solvers still meet it: the infeasibility is positivity's
    assert solve_inverse(prob, "reduced").relative_error < 1e-9


def test_the_job_says_when_no_positive_lighting_meets_the_targets():
    """The engine's reductions end positive with a large error and no message of their own; the
    job (what `relight solve` and the add-on run) adds one, with the NNLS bound."""
    from relight_addon.engine.bounds import positive_bound
    from relight_addon.pipeline.notes import positivity_notes
    from relight_addon.engine.reduction import StopCriteria, reduce_lights

    prob = CASES["infeasible contrast"][1]()
    inv = solve_inverse(prob, "reduced")
    red = reduce_lights(prob, inv.exitance, stop=StopCriteria(max_lights=3))
    assert red.final.n_negative == 0 and red.final.relative_error > 0.1
    notes = positivity_notes(positive_bound(prob, inv, red.final), red.final)
    nn = solve_inverse(prob, "nnls")
    assert len(notes) == 1 and "no positive lighting meets these targets" in notes[0]
    assert f"{nn.relative_error:.3g}" in notes[0]
    # from the certificate's own all-lights NNLS (no second NNLS): the same bound and note
    from relight_addon.engine.best_lights import lower_bounds

    shared = positive_bound(prob, inv, red.final, lower_bounds(prob.transfer, prob.b_target, 3))
    assert shared.relative_error == pytest.approx(nn.relative_error, rel=1e-6, abs=1e-9)
    assert positivity_notes(shared, red.final) == notes
    # a feasible room: the note, if any, points to more lights instead
    base = CASES["room"][1]() if "room" in CASES else None
    if base is not None:
        inv2 = solve_inverse(base, "reduced")
        red2 = reduce_lights(base, inv2.exitance, stop=StopCriteria(max_lights=1))
        for note in positivity_notes(positive_bound(base, inv2, red2.final), red2.final):
            assert "allow more lights" in note or "no positive lighting" in note
