"""The scene's own emission as Cycles renders it (issue 16), at export: linked emission inputs
baked per face (blender/emission_bake.py), the back side of open emitters (engine/two_sided.emitting_backs,
engine/backs.py), and the warnings for what is not modelled (volumes, shadow catchers, holdouts).
References: textures of known mean (two-colour images, a linear gradient, face attributes),
geometry (the back faces), and the scene data before and after (nothing left behind). Against
Cycles' renders: tests/test_cycles_emission.py."""
import math

import numpy as np
import pytest

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
from relight_addon.blender import emission_bake, export  # noqa: E402
from relight_addon.engine import two_sided  # noqa: E402
from test_export import add_mesh, emission_material, principled  # noqa: E402

DATA = ("objects", "meshes", "materials", "images", "scenes", "node_groups", "worlds", "cameras", "lights")


def data_state(bpy):
    """Every datablock's name, per kind, every mesh's UV maps and attributes, every material's
    nodes: what a bake must leave as it was."""
    state = {k: sorted(i.name for i in getattr(bpy.data, k)) for k in DATA}
    state["mesh layers"] = {m.name: (sorted(u.name for u in m.uv_layers), sorted(a.name for a in m.attributes))
                            for m in bpy.data.meshes}
    state["nodes"] = {m.name: sorted(n.name for n in m.node_tree.nodes) for m in bpy.data.materials if m.node_tree}
    state["scene"] = [(s.name, s.render.engine, s.cycles.samples) for s in bpy.data.scenes]
    return state


def grid(bpy, name, nu, nv, size=(1.0, 1.0), z=0.0, down=False, mat=None, uv=True):
    """An nu x nv grid of quads over [0, size] at height z, normal +z (-z when ``down``), its UV map
    spanning [0, 1]^2 (none when not ``uv``)."""
    verts = [(size[0] * i / nu, size[1] * j / nv, z) for j in range(nv + 1) for i in range(nu + 1)]
    faces = [(j * (nu + 1) + i, j * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i + 1, (j + 1) * (nu + 1) + i)
             for j in range(nv) for i in range(nu)]
    if down:
        faces = [f[::-1] for f in faces]
    ob = add_mesh(bpy, name, verts, faces, mat)
    if uv:
        me = ob.data
        layer = me.uv_layers.new(name="UVMap")
        co = np.array([v.co[:2] for v in me.vertices]) / np.array(size)
        lv = np.array([lp.vertex_index for lp in me.loops])
        layer.data.foreach_set("uv", co[lv].ravel())
    return ob


def image(bpy, pixels, name="tex"):
    """A float, Non-Color image of ``pixels`` (h, w, 4), read by Closest interpolation."""
    h, w, _ = np.shape(pixels)
    img = bpy.data.images.new(name, w, h, float_buffer=True)
    img.colorspace_settings.name = "Non-Color"
    img.pixels.foreach_set(np.asarray(pixels, dtype=np.float32).ravel())
    return img


def textured(m, img, strength):
    """Material ``m`` (a Principled BSDF) with an image (Closest) on its Emission Color, Emission
    Strength ``strength``."""
    nt = m.node_tree
    p = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    t = nt.nodes.new("ShaderNodeTexImage")
    t.image, t.interpolation = img, "Closest"
    nt.links.new(t.outputs["Color"], p.inputs["Emission Color"])
    p.inputs["Emission Strength"].default_value = strength
    return m


def textured_principled(bpy, img, strength, name="textured"):
    """A default Principled BSDF (base colour 0.5) emitting an image x ``strength``."""
    return textured(principled(bpy, name, (0.5, 0.5, 0.5)), img, strength)


def emission_of(exp, name):
    """(front exitance per base polygon (n, 3), the FaceSet rows of the object's back faces)."""
    f = exp.faces
    oi = f.object_names.index(name)
    own = f.face_object == oi
    front = own & (f.face_index >= 0)
    order = np.argsort(f.face_index[front])
    return f.exitance[front][order], np.flatnonzero(own & (f.face_index < 0))


def test_image_texture_emission_is_each_faces_mean(bpy_clean):
    """Two faces, each over one texel of a 2 x 1 image (red, blue-green): each emits its texel x
    strength; a 4 x 1 grid under a linear Gradient Texture on Emission Strength (an Emission shader,
    Generated coordinates): face k emits (k + 1/2)/4, the gradient's mean over it. Nothing of the
    user's data changes, and no warning."""
    bpy = bpy_clean
    texels = [[[1.0, 0.0, 0.0, 1.0], [0.0, 0.5, 1.0, 1.0]]]
    panel = grid(bpy, "panel", 2, 1, size=(2.0, 1.0), mat=textured_principled(bpy, image(bpy, texels), 3.0))
    m = emission_material(bpy, 1.0, "ramp")
    nt = m.node_tree
    em = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeEmission")
    coords, ramp = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeTexGradient")
    nt.links.new(coords.outputs["Generated"], ramp.inputs["Vector"])
    nt.links.new(ramp.outputs["Fac"], em.inputs["Strength"])
    grid(bpy, "ramp", 4, 1, size=(4.0, 1.0), z=-3.0, down=True, mat=m, uv=False)  # back to back with the panel
    before = data_state(bpy)
    exp = export.export_scene()
    assert data_state(bpy) == before
    assert panel.data.uv_layers.active.name == "UVMap"
    e, backs = emission_of(exp, "panel")
    np.testing.assert_allclose(e, math.pi * 3.0 * np.array([[1.0, 0.0, 0.0], [0.0, 0.5, 1.0]]), atol=1e-5)
    assert len(backs) == 0  # the backs face away from everything: nothing to model
    e, _ = emission_of(exp, "ramp")
    np.testing.assert_allclose(e[:, 0] / math.pi, (np.arange(4) + 0.5) / 4, rtol=0.01)
    np.testing.assert_allclose(e[:, 1:], e[:, :1].repeat(2, axis=1))
    assert not [w for w in exp.faces.warnings if "emission" in w], exp.faces.warnings


def test_attributes_mix_factor_and_modifiers(bpy_clean):
    """A face colour attribute on an Emission shader's Color (a mesh without UV map); a Mix Shader
    whose factor is a face attribute, between a Diffuse BSDF and an Emission (strength 2): each
    face emits 2 x its factor; the textured panel under a Subdivision modifier: each of the 8
    faces emits its half's texel."""
    bpy = bpy_clean
    colours = np.array([[0.2, 0.4, 0.6], [1.0, 0.0, 0.5], [0.0, 0.0, 0.0]])
    m = emission_material(bpy, 1.5, "by_attribute")
    nt = m.node_tree
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "glow"
    emit = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeEmission")
    nt.links.new(attr.outputs["Color"], emit.inputs["Color"])
    ob = grid(bpy, "painted", 3, 1, size=(3.0, 1.0), mat=m, uv=False)
    a = ob.data.attributes.new("glow", "FLOAT_COLOR", "FACE")
    a.data.foreach_set("color", np.concatenate([colours, np.ones((3, 1))], axis=1).astype(np.float32).ravel())
    mix_m = bpy.data.materials.new("mixed")
    if bpy.app.version < (5, 0, 0):
        mix_m.use_nodes = True
    nt = mix_m.node_tree
    out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    nt.nodes.remove(next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"))
    dif, emi, mix = (nt.nodes.new(k) for k in ("ShaderNodeBsdfDiffuse", "ShaderNodeEmission", "ShaderNodeMixShader"))
    emi.inputs["Strength"].default_value = 2.0
    fac = nt.nodes.new("ShaderNodeAttribute")
    fac.attribute_name = "fac"
    nt.links.new(fac.outputs["Fac"], mix.inputs[0])
    nt.links.new(dif.outputs[0], mix.inputs[1])
    nt.links.new(emi.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    ob2 = grid(bpy, "mixed", 3, 1, size=(3.0, 1.0), z=-2.0, mat=mix_m)
    f = ob2.data.attributes.new("fac", "FLOAT", "FACE")
    f.data.foreach_set("value", [0.0, 1.0, 0.25])
    texels = [[[1.0, 0.0, 0.0, 1.0], [0.0, 0.5, 1.0, 1.0]]]
    panel = grid(bpy, "panel", 2, 1, size=(2.0, 1.0), z=-4.0, mat=textured_principled(bpy, image(bpy, texels), 1.0))
    sub = panel.modifiers.new("sub", "SUBSURF")
    sub.subdivision_type, sub.levels = "SIMPLE", 1
    before = data_state(bpy)
    exp = export.export_scene()
    assert data_state(bpy) == before
    assert len(ob.data.uv_layers) == 0
    e, _ = emission_of(exp, "painted")
    np.testing.assert_allclose(e, math.pi * 1.5 * colours, atol=1e-5)
    e, _ = emission_of(exp, "mixed")
    np.testing.assert_allclose(e, math.pi * 2.0 * np.array([0.0, 1.0, 0.25])[:, None].repeat(3, axis=1), atol=1e-5)
    fs = exp.faces
    on = fs.face_object == fs.object_names.index("panel")
    assert on.sum() == 8
    left = np.array([fs.vertices[fs.face_loops[i]].mean(axis=0)[0] < 1.0 for i in np.flatnonzero(on)])
    np.testing.assert_allclose(fs.exitance[on][left], [[math.pi, 0, 0]] * 4, atol=1e-5)
    np.testing.assert_allclose(fs.exitance[on][~left], [[0, 0.5 * math.pi, math.pi]] * 4, atol=1e-5)


def hanging_room(bpy, lamp_mat, gap=0.8, size=0.6):
    """A 3 x 3 m floor and ceiling 2.5 m apart (grids, facing each other) and a square plane lamp
    of side ``size`` facing down, ``gap`` m under the ceiling."""
    grid(bpy, "floor", 3, 3, size=(3.0, 3.0), mat=principled(bpy, "grey", (0.5, 0.5, 0.5)))
    grid(bpy, "ceiling", 3, 3, size=(3.0, 3.0), z=2.5, down=True, mat=bpy.data.materials["grey"])
    lamp = grid(bpy, "lamp", 1, 1, size=(size, size), z=2.5 - gap, down=True, mat=lamp_mat)
    lamp.location = (1.5 - size / 2, 1.5 - size / 2, 0.0)
    return lamp


def test_back_of_a_hanging_plane_is_a_face_of_its_own(bpy_clean):
    """A plane lamp hanging 0.8 m under the ceiling: its back becomes a face of its own (the same
    polygon reversed, set BACK_OFFSET x the diagonal behind it, the same exitance and reflectance,
    never a target or a light, not reported); a closed cube lamp gets none (its backs face its
    inside); a lamp 1 mm under the ceiling is named in a warning (what it lies against, the light
    leaking from the gap) and gets none."""
    bpy = bpy_clean
    lamp_mat = principled(bpy, "lamp", (0.3, 0.3, 0.3), (1.0, 0.9, 0.8), 5.0)
    hanging_room(bpy, lamp_mat)
    cube = add_mesh(bpy, "cube", [(x, y, z) for z in (0.2, 0.4) for y in (0.2, 0.4) for x in (0.2, 0.4)],
                    [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)], lamp_mat)
    exp = export.export_scene()
    fs = exp.faces
    front, backs = emission_of(exp, "lamp")
    assert len(backs) == 1 and not exp.backs
    b = backs[0]
    assert fs.face_index[b] == -1 and fs.forbidden[b] and not fs.target[b]
    lamp_face = np.flatnonzero((fs.face_object == fs.object_names.index("lamp")) & (fs.face_index == 0))[0]
    np.testing.assert_allclose(fs.exitance[b], fs.exitance[lamp_face])
    np.testing.assert_allclose(fs.reflectance[b], fs.reflectance[lamp_face])
    assert fs.face_material[b] == fs.face_material[lamp_face]
    tv = fs.vertices[fs.triangles[fs.triangle_face == b]]
    n = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
    assert np.all(n[:, 2] > 0)  # the lamp faces down, its back up
    diag = np.linalg.norm(fs.vertices.max(axis=0) - fs.vertices.min(axis=0))
    np.testing.assert_allclose(tv[..., 2], 1.7 + two_sided.BACK_OFFSET * diag, rtol=1e-7)  # float32 vertices
    assert 0.5 * np.linalg.norm(n, axis=1).sum() == pytest.approx(0.36)
    _, cube_backs = emission_of(exp, "cube")
    assert len(cube_backs) == 0
    assert not [w for w in fs.warnings if "back side" in w], fs.warnings
    # the same lamp 1 mm under the ceiling: against a surface
    bpy.data.objects["lamp"].location.z = 0.8 - 0.001
    exp = export.export_scene()
    _, backs = emission_of(exp, "lamp")
    assert len(backs) == 0
    (row,) = exp.backs
    assert row["object"] == "lamp" and row["near"] == ["ceiling"] and 0.001 <= row["distance"] < 0.003, row
    power = float(np.sum(math.pi * 5.0 * np.array([1.0, 0.9, 0.8]) * 0.36))
    assert row["power"] == pytest.approx(power, rel=1e-6)
    assert 0 < row["leak"][0] < row["leak"][1] < 0.1 * power, row
    (w,) = [w for w in exp.faces.warnings if "back side" in w]
    assert "'lamp'" in w and "'ceiling'" in w and "not modelled" in w, w


def test_backfacing_emission_gives_each_side_its_own(bpy_clean):
    """An emission strength of s x Backfacing (the back emits, the front not) and of
    s x (1 - Backfacing) (one-sided): the bake gives the front 0 and s, the back face s and none."""
    bpy = bpy_clean

    def sided(name, back_only):
        m = principled(bpy, name, (0.2, 0.2, 0.2), (1.0, 1.0, 1.0), 1.0)
        nt = m.node_tree
        p = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        geo, op = nt.nodes.new("ShaderNodeNewGeometry"), nt.nodes.new("ShaderNodeMath")
        op.operation = "MULTIPLY_ADD"  # backfacing x a + b
        op.inputs[1].default_value, op.inputs[2].default_value = (4.0, 0.0) if back_only else (-4.0, 4.0)
        nt.links.new(geo.outputs["Backfacing"], op.inputs[0])
        nt.links.new(op.outputs["Value"], p.inputs["Emission Strength"])
        return m

    lamp = hanging_room(bpy, sided("back_only", True))
    one = grid(bpy, "one_sided", 1, 1, size=(0.6, 0.6), z=1.7, down=True, mat=sided("one_sided", False))
    one.location = (0.2, 0.2, 0.0)
    lamp.location.x = 2.0
    exp = export.export_scene()
    fs = exp.faces
    front, backs = emission_of(exp, "lamp")
    np.testing.assert_allclose(front, 0.0, atol=1e-6)
    assert len(backs) == 1
    np.testing.assert_allclose(fs.exitance[backs[0]], [4 * math.pi] * 3, rtol=1e-5)
    front, backs = emission_of(exp, "one_sided")
    np.testing.assert_allclose(front, [[4 * math.pi] * 3], rtol=1e-5)
    assert len(backs) == 0


def test_what_cannot_be_baked_is_named_and_nothing_is_left(bpy_clean, monkeypatch):
    """A bake that fails (here: made to fail after its copies exist) leaves the scene's data as it
    was, and the warning names the material and the linked input; an instanced object with a
    linked emission is named (instances are not baked)."""
    bpy = bpy_clean
    texels = [[[1.0, 1.0, 1.0, 1.0]]]
    grid(bpy, "panel", 1, 1, mat=textured_principled(bpy, image(bpy, texels), 2.0, name="glowing"))
    before = data_state(bpy)

    def broken(*args, **kwargs):
        raise RuntimeError("no bake today")

    monkeypatch.setattr(emission_bake, "_bake", broken)
    exp = export.export_scene()
    assert data_state(bpy) == before
    (w,) = [w for w in exp.faces.warnings if "could not be evaluated" in w]
    assert "'glowing'" in w and "Emission Color" in w and "no bake today" in w, w
    e, _ = emission_of(exp, "panel")
    np.testing.assert_allclose(e, 0.0)
    monkeypatch.undo()
    src = bpy.data.objects["panel"]
    coll = bpy.data.collections.new("lamps")
    bpy.context.scene.collection.objects.unlink(src)
    coll.objects.link(src)
    inst = bpy.data.objects.new("instancer", None)
    inst.instance_type, inst.instance_collection = "COLLECTION", coll
    bpy.context.scene.collection.objects.link(inst)
    exp = export.export_scene()
    (w,) = [w for w in exp.faces.warnings if "instanced objects" in w]
    assert "'instancer/panel'" in w and "'glowing'" in w, w


def test_what_is_not_modelled_is_named(bpy_clean):
    """Volumes (a material's Volume output, a volume object, a World volume), a shadow catcher and a
    holdout object are each named in a warning; the same scene without them has none of these."""
    bpy = bpy_clean
    grid(bpy, "floor", 2, 2, mat=principled(bpy, "grey", (0.5, 0.5, 0.5)))
    box = grid(bpy, "box", 1, 1, z=1.0, down=True, mat=principled(bpy, "lamp", (0.5,) * 3, (1, 1, 1), 2.0))
    catcher = grid(bpy, "catcher", 1, 1, z=-1.0, mat=bpy.data.materials["grey"])
    holdout = grid(bpy, "holdout", 1, 1, z=-2.0, mat=bpy.data.materials["grey"])
    words = ("volume", "Volume", "Shadow Catcher", "Holdout")
    exp = export.export_scene()
    assert not [w for w in exp.faces.warnings if any(k in w for k in words)], exp.faces.warnings
    fog = principled(bpy, "fog", (0.5, 0.5, 0.5))
    nt = fog.node_tree
    vol = nt.nodes.new("ShaderNodeVolumePrincipled")
    out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    nt.links.new(vol.outputs[0], out.inputs["Volume"])
    box.data.materials.append(fog)
    box.data.polygons[0].material_index = 1
    vdata = bpy.data.volumes.new("smoke")
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("smoke", vdata))
    world = bpy.data.worlds.new("hazy")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    wt = world.node_tree
    wvol = wt.nodes.new("ShaderNodeVolumeScatter")
    wt.links.new(wvol.outputs[0], next(n for n in wt.nodes if n.bl_idname == "ShaderNodeOutputWorld").inputs["Volume"])
    bpy.context.scene.world = world
    catcher.is_shadow_catcher = True
    holdout.is_holdout = True
    warnings = export.export_scene().faces.warnings
    text = "\n".join(warnings)
    assert any("'fog'" in w and "Volume output" in w for w in warnings), text
    assert any("'smoke'" in w and "volume" in w for w in warnings), text
    assert any("'hazy'" in w and "volume" in w for w in warnings), text  # blender/world.py's
    assert any("'catcher'" in w and "Shadow Catcher" in w for w in warnings), text
    assert any("'holdout'" in w and "Holdout" in w for w in warnings), text
    # the volume object is named once, as a volume (not as a mesh-like occluder)
    assert not any("'smoke'" in w and "occluders" in w for w in warnings), text
