"""The smaller defects of the artist's first hour (issue 36 item 7), headless.

- a solve started in Vertex Paint gives the user Vertex Paint back, the target layer active (the
  solve made the radiosity layer active: the next stroke would have painted it);
- Clear Targets is greyed out, saying why, when no object of the scene has targets;
- "1 face selected", not "1 faces selected";
- the progress says "refining lamps" while the lamps are refined (it rested on "reduction 95 %"
  for 30 s), moving within a configuration.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402


def test_a_solve_from_vertex_paint_gives_it_back_with_the_target_layer_active(addon):
    cr.reset_blender()
    obs = artist_scenes.gallery()
    floor = obs["Floor"]
    bpy.context.scene.relight.rays_per_patch = 256
    for o in bpy.context.scene.objects:
        o.select_set(o == floor)
    bpy.context.view_layer.objects.active = floor
    bpy.ops.object.mode_set(mode="VERTEX_PAINT")
    assert bpy.ops.relight.solve() == {"FINISHED"}
    assert bpy.context.mode == "PAINT_VERTEX"
    assert floor.data.color_attributes.active_color.name == "relight_target"
    assert floor.data.color_attributes.get("relight_radiosity") is not None  # the answer is there
    cr.reset_blender()


def test_clear_targets_is_greyed_out_without_targets(addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add()
    assert not bpy.ops.relight.clear_targets.poll()
    bpy.ops.relight.paint_targets()
    bpy.ops.object.mode_set(mode="OBJECT")
    assert bpy.ops.relight.clear_targets.poll()


def test_faces_selected_counts_in_words(addon):
    from relight_addon.blender.ui.panels import faces_selected

    assert [faces_selected(n) for n in (0, 1, 2)] == ["0 faces selected", "1 face selected", "2 faces selected"]


def test_the_progress_says_the_lamps_are_refined_while_they_are():
    from relight_addon.pipeline.stages import _refining

    seen = []
    check = _refining(lambda stage, f: seen.append((stage, f)), None, 1, 4, 2)
    for _ in range(5):
        assert check() is False
    stages, fracs = zip(*seen)
    assert set(stages) == {"refining lamps"}
    assert fracs[0] == pytest.approx(0.95 + 0.03 * 1 / 4) and fracs[-1] == pytest.approx(0.95 + 0.03 * 2 / 4)
    assert np.all(np.diff(fracs) >= 0) and fracs[1] > fracs[0]  # it moves within a configuration
    assert _refining(None, lambda: True, 0, 1, 1)() is True  # the cancel still cancels
