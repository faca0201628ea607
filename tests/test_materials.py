"""materials.py: reading node trees (bpy, no rendering). The values themselves are checked
against Cycles in test_cycles_materials.py; here: which node is read, links, notes."""
import numpy as np
import pytest

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
from relight_addon.blender import export, exported_materials, materials  # noqa: E402
from relight_addon.engine.principled import principled_albedo  # noqa: E402


def new_material(bpy, name="m"):
    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    return m


def nodes(m):
    nt = m.node_tree
    return nt, next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial"), \
        next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")


def test_default_principled_has_no_note(bpy_clean):
    m = new_material(bpy_clean)
    _, _, p = nodes(m)
    p.inputs["Base Color"].default_value = (0.5, 0.4, 0.3, 1)
    rho, rad, note = exported_materials.material_properties(m)
    assert note is None
    np.testing.assert_allclose(rho, principled_albedo(base_color=(0.5, 0.4, 0.3)).albedo, rtol=1e-6)
    np.testing.assert_allclose(rad, 0)


def test_mix_with_linked_factor_reroute_and_mute(bpy_clean):
    bpy = bpy_clean
    m = new_material(bpy)
    nt, out, p = nodes(m)
    p.inputs["Specular IOR Level"].default_value = 0.0
    p.inputs["Base Color"].default_value = (0.2, 0.2, 0.2, 1)
    d = nt.nodes.new("ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (0.6, 0.6, 0.6, 1)
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(p.outputs[0], mix.inputs[1])
    nt.links.new(d.outputs[0], mix.inputs[2])
    reroute = nt.nodes.new("NodeReroute")
    nt.links.new(mix.outputs[0], reroute.inputs[0])
    nt.links.new(reroute.outputs[0], out.inputs["Surface"])
    mix.inputs[0].default_value = 0.25
    rho, _, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rho, 0.75 * 0.2 + 0.25 * 0.6)
    assert note is None
    tex = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(tex.outputs[0], mix.inputs[0])
    rho, _, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rho, 0.5 * 0.2 + 0.5 * 0.6)
    assert "factor is linked, taken as 0.5" in note
    mix.mute = True  # a muted Mix Shader passes its first shader through
    rho, _, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rho, 0.2)


def test_add_emission_and_linked_inputs(bpy_clean):
    bpy = bpy_clean
    m = new_material(bpy)
    nt, out, p = nodes(m)
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (1, 0.5, 0.25, 1)
    e.inputs["Strength"].default_value = 2.0
    add = nt.nodes.new("ShaderNodeAddShader")
    nt.links.new(p.outputs[0], add.inputs[0])
    nt.links.new(e.outputs[0], add.inputs[1])
    nt.links.new(add.outputs[0], out.inputs["Surface"])
    tex = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(tex.outputs["Fac"], p.inputs["Roughness"])
    rho, rad, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rad, [2, 1, 0.5])
    np.testing.assert_allclose(rho, principled_albedo(base_color=(0.8,) * 3, roughness=0.5).albedo, rtol=1e-6)
    assert "Roughness is linked, using its unlinked value" in note
    # a linked Coat Roughness does not matter while the coat is off
    nt.links.new(tex.outputs["Fac"], p.inputs["Coat Roughness"])
    assert "Coat Roughness" not in exported_materials.material_properties(m)[2]


def test_unread_shaders_fall_back_with_a_note(bpy_clean):
    bpy = bpy_clean
    m = new_material(bpy)
    m.diffuse_color = (0.3, 0.6, 0.9, 1)
    nt, out, p = nodes(m)
    toon = nt.nodes.new("ShaderNodeBsdfToon")
    nt.links.new(toon.outputs[0], out.inputs["Surface"])
    rho, rad, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rho, [0.3, 0.6, 0.9], rtol=1e-6)
    assert "Toon BSDF is not read, using the viewport colour" in note
    tr = nt.nodes.new("ShaderNodeBsdfTransparent")
    nt.links.new(tr.outputs[0], out.inputs["Surface"])
    rho, _, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rho, 0)
    assert "treated as lost" in note
    nt.links.remove(out.inputs["Surface"].links[0])
    rho, _, note = exported_materials.material_properties(m)
    np.testing.assert_allclose(rho, [0.3, 0.6, 0.9], rtol=1e-6)
    assert "no surface shader" in note


def test_approximations_are_named(bpy_clean):
    m = new_material(bpy_clean)
    _, _, p = nodes(m)
    for name, word in (("Metallic", "metallic"), ("Transmission Weight", "transmission"),
                       ("Coat Weight", "coat"), ("Sheen Weight", "sheen"), ("Subsurface Weight", "subsurface")):
        p.inputs[name].default_value = 0.5
        note = exported_materials.material_properties(m)[2]
        assert note is not None and word in note, (name, note)
        p.inputs[name].default_value = 0.0
    p.inputs["Transmission Weight"].default_value = 1.0  # a glass: only its Fresnel reflection
    rho = exported_materials.material_properties(m)[0]
    assert np.all(rho < 0.1) and np.all(rho > 0.03)
    assert materials.surface_node(m) == p


def test_a_note_many_materials_share_is_one_warning(bpy_clean):
    """Issue 19, case 6: 1,000 metallic materials give one warning, not 1,000: it names three of
    them and counts the rest; a material with a note of its own keeps its own warning."""
    bpy = bpy_clean
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=3, size=2)
    me = bpy.context.object.data
    for k in range(6):
        m = new_material(bpy, f"metal{k}")
        nodes(m)[2].inputs["Metallic"].default_value = 1.0 if k < 5 else 0.5
        me.materials.append(m)
    me.polygons.foreach_set("material_index", np.arange(len(me.polygons), dtype=np.int32) % 6)
    warnings = export.export_scene().faces.warnings
    shared = [w for w in warnings if "metallic 1:" in w]
    assert shared == [w for w in shared if w.startswith("5 materials ('metal0', 'metal1', 'metal2' and 2 more): "
                                                        "metallic 1: ")] and len(shared) == 1, warnings
    assert [w for w in warnings if w.startswith("material 'metal5': metallic 0.5: ")], warnings
