"""The add-on as users get it: the built zip installed into bpy, driven through its operators.

The scenario (tests/addon_scenario.py) runs in a child process with temporary Blender user
directories and only bpy + numpy on its path, like a Blender release. References:
- the painted targets themselves (the inverse solution e_x reproduces feasible targets);
- the stored curve the solve wrote (what each row must show when applied);
- a snapshot of the scene before the solve (what Clear Results must give back).
"""
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_extension_install import _isolated_pythonpath, linux_zip  # noqa: F401  (fixture)

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "tests" / "addon_scenario.py"


@pytest.fixture(scope="module")
def samples_dir():
    """The committed sample files: saved by Blender 4.2 LTS (`make samples`), so every supported
    Blender opens them (tests/compat/test_shipped_samples.py checks it on each version)."""
    pytest.importorskip("bpy", reason="the add-on needs bpy")
    return ROOT / "sample_blends"


@pytest.fixture(scope="module")
def scenario(linux_zip, samples_dir, tmp_path_factory):  # noqa: F811
    tmp = tmp_path_factory.mktemp("addon")
    home = tmp / "home"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("BLENDER_", "PYTHON"))}
    env.update(HOME=str(home), BLENDER_USER_RESOURCES=str(home / "blender"),
               BLENDER_USER_CONFIG=str(home / "blender" / "config"),
               BLENDER_USER_SCRIPTS=str(home / "blender" / "scripts"),
               BLENDER_USER_DATAFILES=str(home / "blender" / "datafiles"),
               BLENDER_USER_EXTENSIONS=str(home / "blender" / "extensions"),
               PYTHONPATH=str(_isolated_pythonpath(tmp)), PYTHONNOUSERSITE="1")
    proc = subprocess.run([sys.executable, "-S", str(SCENARIO), str(linux_zip), str(samples_dir)],
                          env=env, capture_output=True, text=True, timeout=900, cwd=tmp)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, f"scenario failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    return json.loads(lines[-1][len("RESULT "):])


def test_installed_and_enabled(scenario):
    assert scenario["install"] == ["FINISHED"] and scenario["enabled"]


def test_scene_without_targets_is_an_error_report_and_changes_nothing(scenario):
    status, message = scenario["no_target"]
    assert status == ["CANCELLED"] and message and "no target" in message
    assert scenario["no_target_unchanged"]


def test_target_tools(scenario):
    assert scenario["paint_op"][0] == ["FINISHED"] and scenario["paint_mode"] == "PAINT_VERTEX"
    assert scenario["paint_layer"] == ["CORNER", "FLOAT_COLOR", "relight_target"]
    assert scenario["paint_alpha_max"] == 0.0  # a new layer is all unpainted
    assert scenario["fill_op"][0] == ["FINISHED"] and scenario["select_op"][0] == ["FINISHED"]
    assert scenario["selected_targets"] == [0, 2]  # exactly the faces Fill painted
    assert scenario["clear_targets_op"][0] == ["FINISHED"] and not scenario["target_layer_after_clear"]


def test_forbid_operator_writes_the_face_attribute(scenario):
    assert scenario["forbid"][0] == ["FINISHED"]
    # exactly the 10 selected faces, on top of what the sample already forbade on that wall
    assert set(range(10)) <= set(scenario["forbidden_faces"])
    assert set(scenario["forbidden_faces"]) - set(range(10)) == set(scenario["forbidden_before"]) - set(range(10))


def test_solve_fills_the_curve_and_ends_as_the_stop_criteria_say(scenario):
    assert scenario["solve"][0] == ["FINISHED"], scenario["solve"]
    rows = scenario["rows"]
    assert scenario["curve_rows"] == len(scenario["stored_n_lights"]) >= 2
    # the default selection (Best k Lights): one row per number of lights, never worse with more
    # lights, never a negative light
    n = [r[0] for r in rows]
    err = [r[1] for r in rows]
    assert n == sorted(n) and all(b <= a * (1 + 1e-9) + 1e-12 for a, b in zip(err, err[1:]))
    assert all(r[2] == 0 for r in rows)
    n_final, neg_final = scenario["final_row"]
    assert neg_final == 0 and n_final == 3  # defaults: at most 3 lights, the most allowed
    assert rows[scenario["curve_index"]][0] == n_final
    # the list is a subset of the whole curve, in curve order
    idx = [r[3] for r in rows]
    assert idx == sorted(idx) and idx[-1] < scenario["whole_curve_points"]


def test_stored_radiosity_on_targets_gives_the_rows_error(scenario):
    """Eq. 1 recomputed from what the file stores (the final configuration's radiosity on the
    painted patches against their painted radiosity) is the row's error; per painted polygon
    (through the polygon weights) it is close to it."""
    assert scenario["stored_eq1_relative"] == pytest.approx(scenario["final_relative_error"], rel=1e-4)
    got = np.array(scenario["final_targets"])
    want = np.array(scenario["target_radiance"])
    rel = np.linalg.norm(got - want[None, :]) / np.linalg.norm(np.broadcast_to(want, got.shape))
    assert rel == pytest.approx(scenario["final_relative_error"], rel=0.25)


def _compare(state, expected):
    """The emitters object against the stored configuration: power per channel and area."""
    (p_got, a_got, n_faces), (p_want, a_want, n_lights, _) = state, expected
    np.testing.assert_allclose(p_got, p_want, rtol=1e-4, atol=1e-9)
    assert a_got == pytest.approx(a_want, rel=1e-4)
    assert (n_faces > 0) == (n_lights > 0)


def test_final_configuration_is_shown_by_the_emitters_object(scenario):
    _compare(scenario["final_state"], scenario["final_expected"])
    assert sum(scenario["final_expected"][2:]) == scenario["final_row"][0]  # its cells and lamps
    assert scenario["select_lights_op"][0] == ["FINISHED"]
    name, selected = scenario["selected_lights"]
    want = sorted({p for o, polys in scenario["final_lights"] if o == name for p in polys})
    assert selected == want and selected
    assert scenario["active_color"] == "relight_radiosity"
    chart = scenario["chart"]
    assert chart["shape"] == [204, 240, 4] and chart["marker"]
    assert chart["current"] == chart["final_curve_index"]  # the marker is on the configuration shown
    summary, warnings = scenario["summary"]
    n = scenario["final_row"][0]
    assert summary.startswith(f"{n} lights, relative error ")  # what the Results panel shows
    assert "; offered " in summary and "; chose " in summary  # the kinds of light offered and chosen
    assert isinstance(warnings, str)


def test_apply_configuration_k_matches_its_row(scenario):
    assert scenario["apply_k"][0] == ["FINISHED"]
    _compare(scenario["k_state"], scenario["k_expected"])
    n, neg = scenario["k_row"]
    assert sum(scenario["k_expected"][2:]) == n - neg  # negative exitances cannot be shown
    _compare(scenario["back_to_final_state"], scenario["final_expected"])


def test_area_lights_and_clear_restore_the_scene_exactly(scenario):
    assert scenario["area_lights"][0] == ["FINISHED"]
    assert scenario["n_area_lights"] >= scenario["final_row"][0]  # one per emitting cell
    assert scenario["area_light_power"] == pytest.approx(scenario["emitted_power"], rel=1e-4)  # per channel
    assert scenario["relight_lights_left"] == [0, 0]  # converted: the row's light renders once, not twice
    assert scenario["clear"][0] == ["FINISHED"]
    assert scenario["area_lights_kept"] and scenario["artist_collection_kept"]
    assert scenario["emitters_after_clear"] == 0
    assert scenario["clear_restores"], scenario.get("clear_diff")
    assert scenario["view_transform_to_restore"] == ""  # the View's settings hold nothing of the scene's after Clear


def test_solving_again_and_after_an_edit(scenario):
    assert scenario["solve2"][0] == ["FINISHED"] and scenario["solve3"][0] == ["FINISHED"], (scenario["solve2"], scenario["solve3"])
    generated = [m for m in scenario["materials_after_two"] if m.startswith("Relight Emitter")]
    assert len(generated) <= 1  # one emitter material, no pile-up across solves
    assert scenario["solve_after_edit"][0] == ["FINISHED"]
    # the extra (dimmer) targets count: ||b_P|| grows by their norm
    extra = scenario["targets_after_edit"] - scenario["targets_before_edit"]
    assert extra > 0
    assert scenario["target_norm_after"] > scenario["target_norm_before"]
    assert scenario["clear2"][0] == ["FINISHED"] and scenario["clear2_restores"]


def test_automatic_options_show_the_value_the_solve_used(scenario):
    """Issue 36 item 5: "Lamp Drop: Auto 0 m" while the solve used 188 m. The sidebar's label of
    an option left automatic gives the value the last solve used (its stored result's options)."""
    auto = scenario["auto"]
    assert auto["settings"][0] == 0.0  # Max Patch Size left automatic (the scenario sets 512 rays)
    size, rays = auto["stored"]["max_patch_size"], auto["stored"]["rays_per_patch"]
    assert size > 0 and rays > 0
    text = f"{size * 100:.3g} cm" if size < 1 else f"{size:.3g} m"
    assert auto["labels"]["max_patch_size"] == f"Max Patch Size: Auto ({text})", auto
    assert auto["labels"]["rays_per_patch"] == f"Rays per Patch: Auto ({rays:g})", auto
