"""The parts of Blender's Python API that Relight's contract (docs/architecture.md, Units)
relies on, checked on whichever bpy runs this file: the main .venv (bpy 5.0) and the
Blender 4.2 LTS compatibility venv (tests/test_compat.py runs this file there).

References are independent of Relight: values written through the API must read back
unchanged, and Cycles' EMIT bake of a Principled emission must equal
Emission Color x Emission Strength (the radiance L_e the add-on maps to exitance pi*L_e).
"""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="these tests exercise Blender's bpy module")


@pytest.fixture
def empty_scene():
    """The current scene, with everything this test creates removed afterwards and the
    settings it changes restored (no factory reset: other tests share this bpy session)."""
    scene = bpy.context.scene
    before = {attr: set(getattr(bpy.data, attr)) for attr in ("objects", "meshes", "materials")}
    saved = (scene.render.engine, [o for o in scene.objects if o.select_get()],
             bpy.context.view_layer.objects.active)
    for o in scene.objects:
        o.select_set(False)
    yield scene
    for attr in ("objects", "meshes", "materials"):
        collection = getattr(bpy.data, attr)
        for block in set(collection) - before[attr]:
            collection.remove(block)
    scene.render.engine = saved[0]
    for o in saved[1]:
        o.select_set(True)
    bpy.context.view_layer.objects.active = saved[2]


def _plane(name="plane", size=2.0):
    h = size / 2
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([(-h, -h, 0), (h, -h, 0), (h, h, 0), (-h, h, 0)], [], [(0, 1, 2, 3)])
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _principled(name, base=(0.8, 0.8, 0.8), emission=(0, 0, 0), strength=0.0):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # Blender < 5.0; `use_nodes` is deprecated from 5.0 (removal in 6.0)
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    return mat, bsdf


def test_principled_inputs_used_by_export(empty_scene):
    """Base Color / Emission Color / Emission Strength exist under these names and keep values."""
    mat, bsdf = _principled("m", base=(0.25, 0.5, 0.75), emission=(1.0, 0.5, 0.25), strength=3.5)
    assert tuple(bsdf.inputs["Base Color"].default_value)[:3] == pytest.approx((0.25, 0.5, 0.75))
    assert tuple(bsdf.inputs["Emission Color"].default_value)[:3] == pytest.approx((1.0, 0.5, 0.25))
    assert bsdf.inputs["Emission Strength"].default_value == pytest.approx(3.5)
    # Fallback reflectance: the material's viewport colour.
    mat.diffuse_color = (0.1, 0.2, 0.3, 1.0)
    assert tuple(mat.diffuse_color)[:3] == pytest.approx((0.1, 0.2, 0.3))


def test_float_color_corner_attribute_roundtrip(empty_scene):
    """A FLOAT_COLOR attribute on the CORNER domain stores unclamped float RGBA per loop
    (radiance B/pi can exceed 1)."""
    obj = _plane()
    mesh = obj.data
    attr = mesh.color_attributes.new("relight_radiosity", "FLOAT_COLOR", "CORNER")
    values = np.linspace(0.0, 7.5, 4 * len(mesh.loops), dtype=np.float32)
    attr.data.foreach_set("color", values)
    back = np.empty_like(values)
    mesh.color_attributes["relight_radiosity"].data.foreach_get("color", back)
    assert attr.domain == "CORNER" and attr.data_type == "FLOAT_COLOR"
    assert len(attr.data) == len(mesh.loops) == 4
    np.testing.assert_array_equal(back, values)


def test_view_settings_the_false_colour_views_set_and_give_back(empty_scene):
    """The scene's view transform, look, exposure and gamma (ui/display.py sets Standard, None, 0, 1
    for a false-colour view and gives back what was there) read back as written; a second colour
    attribute made active leaves the render colour where it was."""
    vs = empty_scene.view_settings
    saved = (vs.view_transform, vs.look, vs.exposure, vs.gamma)
    try:
        for transform, look, exposure, gamma in (("AgX", "None", 1.5, 1.2), ("Standard", "None", 0.0, 1.0)):
            vs.view_transform, vs.look, vs.exposure, vs.gamma = transform, look, exposure, gamma
            assert (vs.view_transform, vs.look) == (transform, look)
            assert (vs.exposure, vs.gamma) == pytest.approx((exposure, gamma))
    finally:
        vs.view_transform, vs.look, vs.exposure, vs.gamma = saved
    colors = _plane().data.color_attributes
    first = colors.new("relight_radiosity", "FLOAT_COLOR", "CORNER")
    colors.active_color = first
    colors.render_color_index = colors.find("relight_radiosity")
    second = colors.new("relight_display", "FLOAT_COLOR", "CORNER")
    colors.active_color = second
    assert colors.active_color_name == "relight_display"
    assert colors.render_color_index == colors.find("relight_radiosity")


def test_cycles_emit_bake_is_emission_radiance(empty_scene):
    """Cycles bakes an emissive Principled surface to Emission Color x Strength (radiance),
    into a FLOAT_COLOR corner attribute: the convention Relight's bake comparison uses."""
    scene = empty_scene
    scene.render.engine = "CYCLES"
    samples, device = scene.cycles.samples, scene.cycles.device
    scene.cycles.device, scene.cycles.samples = "CPU", 1
    obj = _plane()
    colour, strength = (0.8, 0.4, 0.2), 2.5
    mat, _ = _principled("emitter", emission=colour, strength=strength)
    obj.data.materials.append(mat)
    obj.data.color_attributes.new("bake", "FLOAT_COLOR", "CORNER")
    obj.data.color_attributes.active_color = obj.data.color_attributes["bake"]
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    try:
        assert bpy.ops.object.bake(type="EMIT", target="VERTEX_COLORS") == {"FINISHED"}
    finally:
        scene.cycles.samples, scene.cycles.device = samples, device
    baked = np.empty(4 * len(obj.data.loops), dtype=np.float32)
    obj.data.color_attributes["bake"].data.foreach_get("color", baked)
    rgb = baked.reshape(-1, 4)[:, :3]
    np.testing.assert_allclose(rgb, np.tile(np.array(colour) * strength, (4, 1)), rtol=1e-4)
