"""Every layer Relight creates starts unpainted (issue 36 item 1), whatever path creates it.

The first Fill Selected on an object with no target layer made every face a target: BMesh starts
a new colour layer at (1, 1, 1, 1), which Relight reads as painted white (a cube: 2 faces filled,
6 targets; an artist's desks: 54 filled, 738 targets). Each path that creates a layer (Fill
Selected with the colour, with the lux, Forbid Selected, Paint Targets) is run on fresh cubes,
one alone and two together in Edit Mode (multi-object editing), with a few faces selected on
each: exactly the selected faces change (layers.face_flags reads what a solve reads), and Paint
Targets, which selects nothing, leaves no face painted.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from relight_addon.blender import layers  # noqa: E402

CHOSEN = {"A": [0, 3], "B": [1, 2, 5]}  # the faces selected on each cube


def _cubes(names):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    obs = []
    for k, name in enumerate(names):
        bpy.ops.mesh.primitive_cube_add(location=(3.0 * k, 0.0, 0.0))
        ob = bpy.context.active_object
        ob.name = name
        me = ob.data  # (the face selection alone: no vertex or edge selected, face select mode)
        me.vertices.foreach_set("select", [False] * len(me.vertices))
        me.edges.foreach_set("select", [False] * len(me.edges))
        me.polygons.foreach_set("select", [p in CHOSEN[name] for p in range(len(me.polygons))])
        obs.append(ob)
    for ob in obs:
        ob.select_set(True)
    bpy.context.view_layer.objects.active = obs[0]
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    bpy.ops.object.mode_set(mode="EDIT")  # every selected mesh in Edit Mode, its face selection kept
    return obs


@pytest.mark.parametrize("names", [("A",), ("A", "B")], ids=["one object", "two in Edit Mode"])
@pytest.mark.parametrize("path", ["fill", "fill_lx", "forbid"])
def test_a_new_layer_changes_exactly_the_selected_faces(addon, names, path):
    obs = _cubes(names)
    assert all(ob.data.attributes.get(n) is None for ob in obs
               for n in (layers.TARGET_ATTRIBUTE, layers.LUX_ATTRIBUTE, layers.FORBIDDEN_ATTRIBUTE))
    if path == "forbid":
        assert bpy.ops.relight.forbid_faces() == {"FINISHED"}
    else:
        assert bpy.ops.relight.fill_targets(illuminance=path == "fill_lx") == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    flag = "forbidden" if path == "forbid" else "target"
    for ob in obs:
        assert list(np.flatnonzero(layers.face_flags(ob, flag))) == CHOSEN[ob.name], (ob.name, path)
        other = "target" if flag == "forbidden" else "forbidden"
        assert not layers.face_flags(ob, other).any(), (ob.name, path)


def test_paint_targets_creates_an_unpainted_layer(addon):
    (ob,) = _cubes(("A",))
    bpy.ops.object.mode_set(mode="OBJECT")
    assert bpy.ops.relight.paint_targets() == {"FINISHED"}
    assert bpy.context.mode == "PAINT_VERTEX"
    assert ob.data.color_attributes.get(layers.TARGET_ATTRIBUTE) is not None
    bpy.ops.object.mode_set(mode="OBJECT")
    assert not layers.face_flags(ob, "target").any()


def test_the_sidebar_counts_targets_in_edit_mode_as_a_solve_reads_them():
    """The panel's counts in Edit Mode are read from the BMesh (panels.object_counts): painted
    faces (a colour layer, and a lux layer's) counted as layers.face_flags counts them in Object
    Mode. (A local name shadowing the layers module broke this path with an AttributeError in the
    window; no headless test drew the panel in Edit Mode.)"""
    from artist_scenes import paint
    from relight_addon.blender.ui import panels

    obs = _cubes(("A",))
    bpy.ops.object.mode_set(mode="OBJECT")
    paint(obs[0], [0, 4], (0.5, 0.5, 0.5))
    want = int(layers.face_flags(obs[0], "target").sum())
    assert want == 2
    bpy.ops.object.mode_set(mode="EDIT")
    t, c, f, note = panels.object_counts(obs[0])
    assert (t, f) == (want, 6), (t, c, f, note)
    bpy.ops.object.mode_set(mode="OBJECT")
