"""The add-on lists the scene's own light the solve kept (issue 16): each lamp and the World,
with its share of the targets, as the report has it (pipeline.jobs.fixed_light)."""
import pytest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) runs the add-on's operator")

import cycles_reference as cr  # noqa: E402
from lit_rooms import cut_window, lamp_room, paint, uniform_world  # noqa: E402


def test_solve_operator_lists_the_lamps_and_the_world_with_their_shares(tmp_path):
    import relight_addon
    from relight_addon.blender.ui import panels

    blend = tmp_path / "room.blend"
    lamp_room(blend)
    relight_addon.register()
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
        cut_window()
        uniform_world((0.3, 0.4, 0.6))
        objs = bpy.data.objects
        paint(objs["floor"], [5, 6, 9, 10], (2.0, 2.0, 2.0))
        for name in ("floor", "wall_s", "wall_n", "wall_w", "wall_e"):
            objs[name]["relight_no_lights"] = True
        assert bpy.ops.relight.solve() == {"FINISHED"}
        rows = [line.split("\t") for line in bpy.context.scene.relight.last_fixed_light.split("\n")]
        summary = bpy.context.scene.relight.last_summary
        assert bpy.ops.relight.clear_results() == {"FINISHED"}
    finally:
        relight_addon.unregister()
        cr.reset_blender()
    kinds = {name: kind for kind, name, _ in rows}
    assert kinds == {"lamp_point": "point", "lamp_spot": "spot", "sky": "world"}, rows
    shares = {name: float(share) for _, name, share in rows}
    assert all(0 < s < 1 for s in shares.values()), shares
    assert sum(shares.values()) > 0.2, shares  # a large share of the painted light
    assert [panels.fixed_light_icon(kinds[n]) for n in ("lamp_point", "lamp_spot", "sky")] == \
        ["LIGHT_POINT", "LIGHT_SPOT", "WORLD"]
    for name, share in shares.items():  # the same numbers as the summary line
        assert f"{name} {100 * share:.0f} %" in summary, summary
