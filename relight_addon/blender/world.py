"""The scene's World as Cycles lights the scene with it (bpy): an engine.world.EnvironmentMap.

A uniform World (a Background node of unlinked Color and Strength, or the World colour without
nodes) is read directly, one texel. Any other node tree (a Sky Texture, an HDRI in an
Environment Texture, gradients, mixes) is rendered once by Cycles itself to a small
equirectangular map (``render_world_map``): a temporary scene holding only a panoramic camera
and a copy of the World (the user's World and scene are not touched, everything temporary is
removed), box-filtered pixels, so each texel is the mean radiance over its solid angle.

Named in a warning: an image file that its tree reads and that is missing (Cycles renders it
magenta, and so it is read: materials.missing_images), a World whose diffuse visibility is off
(it lights nothing, as in Cycles), a World tree with a Light Path node (the map is what camera
rays see; diffuse rays may see something else), a World volume (not modelled).
"""
from __future__ import annotations

import math
import os
import tempfile

import bpy
import numpy as np

from ..engine.world import Detail, EnvironmentMap, _solid_angles
from .lamps import uses_nodes
from .materials import MISSING_IMAGE, missing_images, tree_output

__all__ = ["world_light", "render_world_map", "MAP_WIDTH", "MAP_SAMPLES", "SUN_SCALE", "SUN_SAMPLES"]

#: the map Cycles renders: MAP_WIDTH x MAP_WIDTH / 2 texels (1.4 degrees at 256), MAP_SAMPLES
#: each; the texels of a sun again, SUN_SCALE times finer, SUN_SAMPLES each
MAP_WIDTH = 256
MAP_SAMPLES = 16
SUN_SCALE = 8
SUN_SAMPLES = 256


def _render(sc, width: int, H: int, samples: int, box=None, scale: int = 1) -> np.ndarray:
    """One Cycles render of the temporary scene ``sc``: (rows, cols, 3) radiance; ``box``
    (row0, row1, col0, col1) renders only those texels (a border, cropped), ``scale`` times finer."""
    r = sc.render
    sc.cycles.samples = samples
    r.resolution_x, r.resolution_y = width * scale, H * scale
    r.use_border = r.use_crop_to_border = box is not None
    if box is not None:
        r0, r1, c0, c1 = box
        r.border_min_y, r.border_max_y = r0 / H, r1 / H
        r.border_min_x, r.border_max_x = c0 / width, c1 / width
    shape = (H, width) if box is None else ((box[1] - box[0]) * scale, (box[3] - box[2]) * scale)
    with tempfile.TemporaryDirectory(prefix="relight-world-") as d:
        r.filepath = os.path.join(d, "world.exr")
        bpy.ops.render.render(write_still=True, scene=sc.name)
        img = bpy.data.images.load(r.filepath, check_existing=False)
        try:
            px = np.empty(len(img.pixels), dtype=np.float32)
            img.pixels.foreach_get(px)
            size, channels = tuple(img.size), img.channels
        finally:
            bpy.data.images.remove(img)
    if size != (shape[1], shape[0]):
        raise RuntimeError(f"the World's map came back {size[0]} x {size[1]}, not {shape[1]} x {shape[0]}")
    return px.reshape(shape[0], shape[1], channels)[..., :3].astype(np.float64)


def render_world_map(world, width: int = MAP_WIDTH, samples: int = MAP_SAMPLES,
                     sun_scale: int = SUN_SCALE, sun_samples: int = SUN_SAMPLES, sun_hints=()) -> EnvironmentMap:
    """The radiance (W/(m^2 sr)) of ``world`` in every direction, width x width / 2 texels,
    rendered by Cycles with an equirectangular camera (engine.world's conventions: row 0 the
    nadir, the centre column along +Y). The texels of a sun (EnvironmentMap.sun_regions), and
    one around them, are rendered again ``sun_scale`` times finer with ``sun_samples`` per
    pixel (engine.world.Detail): a sun disc smaller than a texel is otherwise counted to +-15 %
    at 64 samples, and its direction only to the texel. ``sun_hints``: unit directions where a
    sun is known to be (a Sky Texture's: ``sky_suns``), rendered finer whether the first pass
    found them or not (its samples can all miss a disc smaller than a texel). Temporary data
    only; the user's World is copied, not changed."""
    H = max(width // 2, 1)
    made = {}
    try:
        sc = _map_scene(world, width, H, made)
        radiance = _render(sc, width, H, samples)
        env = EnvironmentMap(radiance)
        details = _sun_details(sc, env, radiance, (H, width), sun_hints, sun_samples, sun_scale)
        return EnvironmentMap(radiance, details)
    finally:
        if "scene" in made:
            bpy.data.scenes.remove(made["scene"])
        if "camera" in made:
            bpy.data.objects.remove(made["camera"])
        if "camera_data" in made:
            bpy.data.cameras.remove(made["camera_data"])
        if "world" in made:
            bpy.data.worlds.remove(made["world"])



def _map_scene(world, width, H, made):
    """A temporary scene that renders a copy of ``world`` with an equirectangular camera, width x
    H pixels (what it makes goes into ``made``: the caller removes it)."""
    made["world"] = w = world.copy()
    if not w.cycles_visibility.camera:
        w.cycles_visibility.camera = True  # the copy is what camera rays see, whatever the user's setting
    # camera rays only: no importance map of the World as a light (Cycles would evaluate the
    # World at its sample_map_resolution first, seconds for an HDRI)
    w.cycles.sampling_method = "NONE"
    made["camera_data"] = cd = bpy.data.cameras.new("relight world map")
    cd.type = "PANO"
    cd.panorama_type = "EQUIRECTANGULAR"
    cd.latitude_min, cd.latitude_max = -0.5 * math.pi, 0.5 * math.pi
    cd.longitude_min, cd.longitude_max = -math.pi, math.pi
    made["camera"] = cam = bpy.data.objects.new("relight world map", cd)
    cam.rotation_euler = (0.5 * math.pi, 0.0, 0.0)  # looking along +Y, its up +Z
    made["scene"] = sc = bpy.data.scenes.new("relight world map")
    sc.collection.objects.link(cam)
    sc.camera = cam
    sc.world = w
    r = sc.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, H, 100
    r.film_transparent = False
    r.use_compositing = False
    r.use_sequencer = False
    c = sc.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.seed = 0
    sc.view_settings.view_transform = "Standard"
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    return sc


def _sun_details(sc, env, radiance, size, sun_hints, sun_samples, sun_scale) -> list:
    """The suns of ``env`` and the hinted directions rendered ``sun_scale`` times finer
    (engine.world.Detail, one per block of texels); ``radiance`` gets each block's fine texels'
    mean over solid angle (``size``: the map's rows and columns)."""
    from scipy import ndimage

    H, width = size
    want = np.zeros((H, width), dtype=bool)  # the texels to render finer: the suns found, and the hinted
    for sel, _, _ in env.sun_regions():
        want |= sel
    for d in sun_hints:
        row, col = env.texel(np.asarray(d, dtype=np.float64).reshape(1, 3))
        want[row[0], col[0]] = True
    details = []
    labels, n = ndimage.label(ndimage.binary_dilation(want, np.ones((3, 3), dtype=bool)))
    for rs, cs in ndimage.find_objects(labels):  # each block: the texels and one around them
        r0, r1, c0, c1 = rs.start, rs.stop, cs.start, cs.stop
        fine = _render(sc, width, H, sun_samples, (r0, r1, c0, c1), sun_scale)
        details.append(Detail(r0, c0, sun_scale, fine))
        om = _solid_angles(H * sun_scale, width * sun_scale, np.arange(r0 * sun_scale, r1 * sun_scale),
                           np.arange(c0 * sun_scale, c1 * sun_scale))
        k, h, w = sun_scale, r1 - r0, c1 - c0  # the block's texels: the fine ones' mean over solid angle
        radiance[r0:r1, c0:c1] = (fine * om[..., None]).reshape(h, k, w, k, 3).sum(axis=(1, 3)) / \
            om.reshape(h, k, w, k).sum(axis=(1, 3))[..., None]
    return details

#: Sky Texture models that draw a sun disc (Blender 4.x: NISHITA; 5.x: the scattering models)
SUN_DISC_SKIES = ("NISHITA", "SINGLE_SCATTERING", "MULTIPLE_SCATTERING")


def sky_suns(tree) -> list:
    """Unit world directions of the sun discs of the tree's Sky Texture nodes (sun disc on, the
    Vector input not linked): (cos e sin r, cos e cos r, sin e) for elevation e and rotation r
    (measured on Cycles' render: rotation 0 is +Y, 90 degrees +X)."""
    out = []
    for n in tree.nodes:
        if n.type != "TEX_SKY" or getattr(n, "sky_type", "") not in SUN_DISC_SKIES or not getattr(n, "sun_disc", False):
            continue
        if any(i.is_linked for i in n.inputs):  # a rotated or mapped sky: its sun is elsewhere
            continue
        e, r = float(n.sun_elevation), float(n.sun_rotation)
        out.append((math.cos(e) * math.sin(r), math.cos(e) * math.cos(r), math.sin(e)))
    return out


def world_light(scene, sees_sky=None) -> tuple:
    """(engine.world.EnvironmentMap or None, the World's name, [warnings]): the World as Cycles
    lights diffuse surfaces with it. ``sees_sky``: a callable, True when some face can see the
    World (engine.world.sees_sky); asked before a textured World is rendered, so a closed scene
    costs no render."""
    world = scene.world
    if world is None:
        return None, "", []
    vis = getattr(world, "cycles_visibility", None)
    if vis is not None and not getattr(vis, "diffuse", True):
        return None, world.name, [f"the World ({world.name!r}) does not light diffuse surfaces (its Ray Visibility > "
                                  "Diffuse is off): left out, as Cycles leaves it out of their light"]
    notes = []
    if uses_nodes(world):
        tree = world.node_tree
        out = tree_output(tree, "ShaderNodeOutputWorld")
        if out is None:
            return None, world.name, []
        if out.inputs["Volume"].is_linked:
            notes.append(f"the World ({world.name!r}) has a volume: not modelled (its scattering and absorption "
                         "are left out)")
        if not out.inputs["Surface"].is_linked:
            return None, world.name, notes
        node = out.inputs["Surface"].links[0].from_node
        if node.type == "BACKGROUND" and not node.inputs["Color"].is_linked and not node.inputs["Strength"].is_linked:
            env = EnvironmentMap.uniform(np.array(node.inputs["Color"].default_value, dtype=np.float64)[:3] * float(
                node.inputs["Strength"].default_value))
        else:
            if any(n.type == "LIGHT_PATH" for n in tree.nodes):
                notes.append(f"the World ({world.name!r}) uses a Light Path node: its light is read as camera rays "
                             "see it; if diffuse rays see something else, Cycles renders a different light")
            missing = missing_images(tree, out)
            if missing:
                notes.append(f"the World ({world.name!r}): {MISSING_IMAGE.format(', '.join(missing))}: its light is "
                             "read as Cycles renders it, magenta; find the file (File > External Data > Find Missing "
                             "Files) or remove the texture")
            if sees_sky is not None and not sees_sky():
                notes.append(f"the World ({world.name!r}) is seen from no face (the scene is closed): it adds no "
                             "light, and its texture was not rendered")
                return None, world.name, notes
            env = render_world_map(world, sun_hints=sky_suns(tree))
    else:
        env = EnvironmentMap.uniform(np.array(world.color, dtype=np.float64)[:3])
    if not np.any(env.radiance > 0):
        return None, world.name, notes
    return env, world.name, notes
