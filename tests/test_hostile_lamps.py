"""The hostile-input catalogue, part 3 (issue 35; docs/reliability.md): the scene's lamps, World
and images, work planes and the options that choose the candidate lights, tried as a new user
would. The harness is tests/test_hostile.py's and tests/test_hostile_everyday.py's (their scenes'
helpers and checks: exit code or operator result, the one-line message, the input's bytes
unchanged, no NaN or inf in the report or the scene, the scene unchanged on refusal)."""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

from conftest import file_digest

from test_hostile import (RAYS, _grid, _mesh, _paint, _reset, _room, _save, addon, assert_scene_finite,  # noqa: F401
                          scene_cache, snapshot)
from test_hostile_everyday import _error_line, _refused, _solve

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")


# ============================================================================ scenes

def _lamp(name, kind="POINT", energy=10.0, location=(0.5, 0.5, 0.8), **settings):
    ld = bpy.data.lights.new(name, kind)
    ld.energy = energy
    for k, v in settings.items():
        setattr(ld, k, v)
    ob = bpy.data.objects.new(name, ld)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _room_lux_plane(paint=False):
    """The room, and a work plane at desk height (no paint: illuminance targets by default)."""
    floor, ceiling = _room()
    v, f = _grid(1, size=0.5, z=0.4, x0=0.25, y0=0.25)
    plane = _mesh("desk", v, f)
    plane["relight_work_plane"] = True
    plane["relight_no_lights"] = True
    if paint:
        _paint(plane, (0.3, 0.3, 0.3))
    return floor, ceiling, plane


def _only_work_plane():  # the ceiling is the work plane: no face may hold lights
    floor, ceiling = _room()
    ceiling["relight_work_plane"] = True


def _negative_lamp():  # a lamp of +20 W and one of -10 W in the same place: Cycles renders 10 W
    _room()
    _lamp("Key", energy=20.0, shadow_soft_size=0.0)
    _lamp("Sink", energy=-10.0, shadow_soft_size=0.0)


def _ten_watts():
    _room()
    _lamp("Key", energy=10.0, shadow_soft_size=0.0)


def _zero_size_area():
    _room()
    _lamp("Panel", "AREA", energy=50.0, location=(0.5, 0.5, 0.9), size=0.0)


def _floor_under_the_sky():
    v, f = _grid(2)
    _mesh("floor", v, f)


def _negative_sun():  # +2 and -1 W/m^2 straight down on an open floor: Cycles renders 1 W/m^2
    _floor_under_the_sky()
    _lamp("Sun", "SUN", energy=2.0, location=(0, 0, 3), angle=0.0)
    _lamp("Shade", "SUN", energy=-1.0, location=(0, 0, 3), angle=0.0)


def _one_sun():
    _floor_under_the_sky()
    _lamp("Sun", "SUN", energy=1.0, location=(0, 0, 3), angle=0.0)


def _zero_height_rectangle():  # a rectangle area lamp of Size Y 0
    _room()
    _lamp("Strip", "AREA", energy=50.0, location=(0.5, 0.5, 0.9), shape="RECTANGLE", size=0.5, size_y=0.0)


def _zero_watts():
    _room()
    _lamp("Key", energy=0.0)
    _lamp("Fill", energy=0.0, location=(0.2, 0.2, 0.8))


def _narrow_spots():  # Size 0 (Blender stores 1 degree) and 3 degrees, pointing down at the floor
    _room()
    _lamp("Pin", "SPOT", energy=50.0, location=(0.3, 0.3, 0.9), spot_size=0.0, spot_blend=0.0, shadow_soft_size=0.0)
    _lamp("Narrow", "SPOT", energy=50.0, location=(0.7, 0.6, 0.9), spot_size=math.radians(3.0), spot_blend=0.0,
          shadow_soft_size=0.0)


SCENES = {
    "room": lambda: _room(),
    "narrow_spots": _narrow_spots,
    "negative_lamp": _negative_lamp,
    "ten_watts": _ten_watts,
    "zero_size_area": _zero_size_area,
    "zero_watts": _zero_watts,
    "negative_sun": _negative_sun,
    "one_sun": _one_sun,
    "zero_height_rectangle": _zero_height_rectangle,
    "only_work_plane": _only_work_plane,
    "painted_work_plane": lambda: _room_lux_plane(paint=True),
}


def build(name, d):
    path = os.path.join(d, f"{name}.blend")
    _reset()
    SCENES[name]()
    _save(path)
    _reset()
    return path


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    return scene_cache(tmp_path_factory, "lamps", build)


def _warned(report, *parts):
    hits = [w for w in report["warnings"] if all(p in w for p in parts)]
    assert hits, report["warnings"]
    return hits


# ============================================================================ options

def test_uniformity_without_illuminance_targets_is_said(run_cli, scenes, tmp_path):
    """Case 11: --uniformity with painted (radiosity) targets only: the selection's note that the
    goal needs illuminance targets reaches the report (direct_stage's re-fit replaced it)."""
    code, report, err = _solve(run_cli, scenes("room"), tmp_path, "--selection", "least-power", "--tolerance",
                               "0.3", "--uniformity", "0.6")
    assert code == 0, err
    _warned(report, "uniformity goal applies to illuminance targets", "there are none")


def test_automatic_light_colour_takes_the_blackbody_range(run_cli, scenes, tmp_path):
    """Case 20: the automatic light colour solves with blackbody lights when the targets allow
    them: the range set (--temperature-min / --temperature-max) is theirs, not refused and then
    replaced by the default range."""
    code, report, err = _solve(run_cli, scenes("room"), tmp_path, "--temperature-min", "6000",
                               "--temperature-max", "7000")
    assert code == 0, err
    _warned(report, "light colour: blackbody (6000-7000 K), chosen automatically")
    temps = [lt["temperature_K"] for lt in report["final"]["lights"]]
    assert temps and all(6000 - 1e-6 <= t <= 7000 + 1e-6 for t in temps), temps
    assert report["options"]["temperature_min"] == 6000


def test_reversed_range_refused_before_work_under_automatic(run_cli, scenes, tmp_path):
    code, _, err = _solve(run_cli, scenes("room"), tmp_path, "--temperature-min", "7000", "--temperature-max", "3000")
    assert code == 2
    assert "the blackbody range must lie within 800-12000 K" in _error_line(err)
    assert not os.listdir(tmp_path)


def test_every_candidate_kind_off_names_them_on_the_cli(run_cli, scenes, tmp_path):
    """Case 18: the cells off and no lamp kind on: refused before any work, naming both."""
    code, _, err = _solve(run_cli, scenes("room"), tmp_path, "--no-surface-lights", "--no-spot-lamps")
    assert code == 2
    line = _error_line(err)
    assert "no candidate light: every kind is off" in line and "--no-surface-lights" in line, line
    assert "--no-spot-lamps given" in line and "--area-lamps and --point-lamps not given" in line, line
    assert not os.listdir(tmp_path)


def test_every_candidate_kind_off_names_the_sidebars_buttons(addon, scenes):
    """Case 18 in the add-on: the message names the Offer row's buttons, not the CLI's flags."""
    bpy.ops.wm.open_mainfile(filepath=scenes("room"))
    s = bpy.context.scene.relight
    s.rays_per_patch = 256
    s.surface_lights = s.spot_lamps = s.area_lamps = s.point_lamps = False
    _refused(lambda: bpy.ops.relight.solve(),
             "no candidate light: every kind under Offer is off (Cells, Spots, Area Lamps, Points): turn one on")
    with pytest.raises(RuntimeError) as info:
        bpy.ops.relight.solve()
    assert "--" not in str(info.value)


# ============================================================================ the scene's lamps

def _radiosity(run_cli, scene, tmp_path):
    code, report, err = run_cli(["radiosity", scene, "--report", tmp_path / "r.json", *RAYS])
    assert code == 0, err
    return report


def test_negative_lamp_is_negative_light(run_cli, scenes, tmp_path):
    """Case 6: a lamp of -10 W beside one of +20 W is rendered by Cycles as 10 W (its light is
    negative): modelled so, and named in a warning (it was left out: twice the light)."""
    neg = _radiosity(run_cli, scenes("negative_lamp"), tmp_path / "a")
    ref = _radiosity(run_cli, scenes("ten_watts"), tmp_path / "b")
    _warned(neg, "lamp 'Sink' has a negative Power (-10 W)", "negative light")
    floor = np.asarray(neg["objects"]["floor"]["radiosity"])
    assert floor.min() > 0
    assert np.allclose(floor, ref["objects"]["floor"]["radiosity"], rtol=1e-3)


def test_negative_sun_is_negative_light(run_cli, scenes, tmp_path):
    """Case 6, a Sun: -1 W/m^2 beside +2 W/m^2 is Cycles' 1 W/m^2."""
    neg = _radiosity(run_cli, scenes("negative_sun"), tmp_path / "a")
    ref = _radiosity(run_cli, scenes("one_sun"), tmp_path / "b")
    _warned(neg, "lamp 'Shade' has a negative Power (-1 W)")
    assert np.min(ref["objects"]["floor"]["radiosity"]) > 0
    assert np.allclose(neg["objects"]["floor"]["radiosity"], ref["objects"]["floor"]["radiosity"], rtol=1e-6)


def test_negative_lamp_is_fixed_light_of_a_solve(run_cli, scenes, tmp_path):
    code, report, err = _solve(run_cli, scenes("negative_lamp"), tmp_path)
    assert code == 0, err
    _warned(report, "lamp 'Sink' has a negative Power")
    rows = {r["name"]: r for r in report["fixed_light"]}
    assert rows["Sink"]["share"] == pytest.approx(-0.5 * rows["Key"]["share"], rel=1e-3)


def test_negative_lamp_is_left_as_it_is_by_reduce(run_cli, scenes, tmp_path):
    code, report, err = run_cli(["reduce", scenes("negative_lamp"), "--report", tmp_path / "r.json", *RAYS,
                                 "--out", tmp_path / "o.blend"])
    assert code == 0, err
    _warned(report, "kept as fixed light", "lamp 'Sink' (negative power)")
    bpy.ops.wm.open_mainfile(filepath=str(tmp_path / "o.blend"))
    assert bpy.data.objects["Sink"].data.energy == -10.0
    assert_scene_finite()


@pytest.mark.parametrize("command", ["solve", "radiosity"])
@pytest.mark.parametrize("scene,name", [("zero_size_area", "Panel"), ("zero_height_rectangle", "Strip")])
def test_zero_size_area_lamp_is_named(run_cli, scenes, tmp_path, command, scene, name):
    """Case 15: an area lamp of size 0 (or a rectangle of Size Y 0) gives no light in Cycles
    (Light::has_contribution): left out with a warning naming it (it was "background irradiance
    contains NaN or infinite values", or "reflectance or exitance contains NaN")."""
    if command == "solve":
        code, report, err = _solve(run_cli, scenes(scene), tmp_path)
        assert code == 0, err
    else:
        report = _radiosity(run_cli, scenes(scene), tmp_path)
    _warned(report, f"lamp '{name}' is an area lamp of size 0", "Cycles renders no light from it")


@pytest.mark.parametrize("scene,names", [("zero_watts", ["'Key' (0 W)", "'Fill' (0 W)"]),
                                         ("zero_size_area", ["'Panel' (an area lamp of size 0)"])])
def test_reduce_names_the_lamps_that_emit_nothing(run_cli, scenes, tmp_path, scene, names):
    """Case 16: reduce on a scene whose lamps are at 0 W (or of size 0) says so, naming them
    (it was "no emitter to reduce (no lamp, ...)")."""
    path = scenes(scene)
    before = file_digest(path)
    code, _, err = run_cli(["reduce", path, "--report", tmp_path / "r.json", *RAYS])
    assert code == 2
    line = _error_line(err)
    assert "no emitter to reduce: no material emits" in line and "emit nothing" in line, line
    assert all(n in line for n in names), line
    assert file_digest(path) == before and not os.listdir(tmp_path)


def test_engine_area_lamp_without_area_is_refused_by_name():
    """Case 15 in the engine: an area Lamp of no area (its radiance P / A) is refused naming it,
    not turned into NaN irradiance."""
    from relight_addon.engine.lamps import Lamp
    from relight_addon.engine.lights.area import AREA

    with pytest.raises(ValueError, match="lamp 'Panel': an area lamp of size 0.0 x 0.5 m has no area"):
        Lamp("Panel", AREA, (0, 0, 1), (0, 0, -1), (1, 0, 0), (0, 1, 0), (10, 10, 10), size_u=0.0, size_v=0.5)


# ============================================================================ work planes

def test_only_candidate_a_work_plane_is_named(run_cli, scenes, tmp_path):
    """Case 17: the only surface that may hold lights is a work plane: the message names it as
    the reason (it said only "every face is forbidden (relight_forbidden, relight_no_lights)")."""
    code, _, err = _solve(run_cli, scenes("only_work_plane"), tmp_path)
    assert code == 2
    line = _error_line(err)
    assert "no candidate light" in line and "a work plane holds no light" in line and ": 'ceiling'" in line, line
    assert not os.listdir(tmp_path)


def test_only_candidate_a_work_plane_in_the_add_on(addon, scenes):
    bpy.ops.wm.open_mainfile(filepath=scenes("only_work_plane"))
    bpy.context.scene.relight.rays_per_patch = 256
    _refused(lambda: bpy.ops.relight.solve(), "a work plane holds no light (light passes through it): 'ceiling'")


def test_radiosity_paint_on_a_work_plane_is_said(run_cli, scenes, tmp_path):
    """Case 19: radiosity paint (relight_target) on a work plane is read as the light a white
    (0.99) surface reflects there, an illuminance: said, naming the plane and that illuminance
    (0.3 painted: a radiosity of 0.3 pi W/m^2, so 0.3 pi / 0.99 W/m^2 x 683 lm/W = 650 lx)."""
    code, report, err = _solve(run_cli, scenes("painted_work_plane"), tmp_path)
    assert code == 0, err
    hit = _warned(report, "work plane(s) 'desk': 1 face(s) painted with a radiosity target", "takes illuminance")[0]
    assert "an illuminance of 650-650 lx" in hit, hit


def test_narrow_spots_light_the_floor_with_their_cones_flux(bpy_clean, scenes):
    """Case 7: a Spot of Size 0 (Blender stores 1 degree) and one of 3 degrees over the floor:
    the floor gets each cone's flux, I 2 pi (1 - cos(size / 2)) (the 1 degree one got nothing:
    the points sampled on the patches missed its footprint; the 3 degree one was 9 % low)."""
    from relight_addon.blender import export
    from relight_addon.engine.lamps import lamp_irradiance
    from relight_addon.engine.options import JobOptions
    from relight_addon.pipeline import meshing

    bpy.ops.wm.open_mainfile(filepath=scenes("narrow_spots"))
    assert bpy.data.lights["Pin"].spot_size == pytest.approx(math.radians(1.0))  # Blender's least size
    exp = export.export_scene()
    patches = meshing.mesh_for_job(exp.faces, JobOptions(), 10.0)
    H = lamp_irradiance(patches, exp.faces.lamps)
    floor = patches.object == exp.faces.object_names.index("floor")
    for i, lamp in enumerate(exp.faces.lamps):
        flux = float(np.sum(H[floor, i, 0] * patches.area[floor]))
        ref = 50.0 / (4 * math.pi) * 2 * math.pi * (1 - math.cos(lamp.spot_size / 2))
        assert flux == pytest.approx(ref, rel=5e-3), lamp.name


# ============================================================================ missing images

def _missing_image(d, name):
    """An image read from a file that is then deleted (as a moved or renamed texture is)."""
    path = os.path.join(d, f"{name}.png")
    img = bpy.data.images.new(name, 4, 4)
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    img = bpy.data.images.load(path, check_existing=False)
    img.name = name
    return img, path


def _world_with_image(img):
    w = bpy.data.worlds.new("Sky")
    bpy.context.scene.world = w
    if bpy.app.version < (5, 0, 0):
        w.use_nodes = True
    nt = w.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = img
    bg = next(n for n in nt.nodes if n.type == "BACKGROUND")
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])


def _texture_material(img, socket):
    m = bpy.data.materials.new("Poster")
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    p = next(n for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    tex = m.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    m.node_tree.links.new(tex.outputs["Color"], p.inputs[socket])
    if socket == "Emission Color":
        p.inputs["Emission Strength"].default_value = 1.0
    return m


def build_missing(name, d):
    path = os.path.join(d, f"{name}.blend")
    _reset()
    floor, ceiling = _room()
    img, file = _missing_image(d, f"{name}_tex")
    if name == "missing_world_image":
        _world_with_image(img)
    else:
        socket = "Emission Color" if name == "missing_emission_image" else "Base Color"
        v, f = _grid(1, size=0.3, z=0.95, x0=0.35, y0=0.35, flip=True)
        _mesh("poster", v, f, material=_texture_material(img, socket))["relight_no_lights"] = True
    _save(path)
    os.remove(file)
    _reset()
    return path


@pytest.fixture(scope="module")
def missing(tmp_path_factory):
    return scene_cache(tmp_path_factory, "missing", build_missing)


@pytest.mark.parametrize("scene,who", [("missing_world_image", "the World ('Sky')"),
                                       ("missing_emission_image", "material 'Poster'"),
                                       ("missing_base_colour_image", "material 'Poster'")])
def test_missing_image_is_named_with_what_it_becomes(run_cli, missing, tmp_path, scene, who):
    """Case 9: an image file that the World or a material reads and that is missing renders
    magenta in Cycles, and is read so (the World's map and an emission bake are Cycles' own): a
    warning names who reads it, the image and its path, and says it is magenta."""
    code, report, err = _solve(run_cli, missing(scene), tmp_path)
    assert code == 0, err
    hit = _warned(report, who, "image file(s) missing, which Cycles renders magenta", f"'{scene}_tex'",
                  f"{scene}_tex.png")[0]
    if scene == "missing_emission_image":
        assert "its emission is baked as Cycles renders it (magenta light)" in hit, hit
    if scene == "missing_base_colour_image":
        assert "its linked colour is read as the viewport colour, where Cycles renders magenta" in hit, hit
    if scene == "missing_world_image":
        assert "its light is read as Cycles renders it, magenta" in hit, hit
