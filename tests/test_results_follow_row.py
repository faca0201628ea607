"""The Results panel follows the row shown (issue 36 item 3).

Clicking another row of the curve changed the lights in the scene, but the panel's list of lights
and its predicted illuminance stayed on the final configuration (an artist's classroom: rows 5-18
held a 2 m plane 55 m away emitting 8.4 x 10^8 W that no list showed). Issue 17's gallery, its
floor strip asking 300 lx, solved with the operator; then rows are clicked as in the list.
Evidence, per row: the panel lists exactly the lights the stored row holds (their number, their
total power against the curve's power of that row), the illuminance line gives the lux asked
beside the prediction, and the rows' predictions differ (the panel is not the final row's).
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon.blender import results  # noqa: E402
from relight_addon.blender.ui.panels import photometric_line  # noqa: E402


def _panel(settings):
    lights = [ln.split("\t") for ln in settings.last_lights.split("\n") if ln]
    photometric = {ln.split("\t")[0]: ln.split("\t") for ln in settings.last_photometric.split("\n") if ln}
    return lights, photometric


def test_the_panel_lists_the_row_shown(addon, tmp_path):
    cr.reset_blender()
    obs = artist_scenes.gallery()
    me = obs["Floor"].data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    me.color_attributes["relight_target"].data.foreach_get("color", col.ravel())
    starts = np.zeros(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_start", starts)
    strip = np.flatnonzero(col[starts, 3] >= 0.5)
    col[:] = 0.0
    me.color_attributes["relight_target"].data.foreach_set("color", col.ravel())
    lux = me.attributes.new("relight_target_lux", "FLOAT", "FACE")
    v = np.zeros(len(me.polygons))
    v[strip] = 300.0
    lux.data.foreach_set("value", v)
    settings = bpy.context.scene.relight
    settings.rays_per_patch = 512
    assert bpy.ops.relight.solve() == {"FINISHED"}
    data = results.load_result(bpy.context.scene)
    rows = len(data.n_lights)
    assert rows >= 3
    seen = set()
    for k in [0, rows // 2, rows - 1]:
        settings.curve_index = k  # a click on the row
        assert settings.apply_error == ""
        lights, photometric = _panel(settings)
        on = np.flatnonzero(np.any(data.exitance[k] != 0, axis=1))
        assert len(lights) == len(on) == data.n_lights[k], (k, lights)
        power = sum(float(li[2]) for li in lights)
        assert power == pytest.approx(float(data.curve_power[data.point_index[k]]), rel=1e-4), k
        floor = photometric["Floor"]
        assert float(floor[4]) == pytest.approx(300.0)  # the lux asked, beside the prediction
        assert "(asked 300)" in photometric_line(*floor)
        seen.add(round(float(floor[1]), 6))
    assert len(seen) > 1  # the rows' predictions differ, and the panel showed each
    cr.reset_blender()
