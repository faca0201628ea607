"""Reactor/level door of the Godot TPS demo (CC BY 3.0; Blender 2.83): 27 meshes, among them
collision-only helpers ("-colonly") and impostors that overlap the door, negative scales,
Mirror and Armature modifiers, emissive materials, missing images. Only "doorsimple" and the
collision helpers are rendered (the rest sits in excluded collections): the artist paints the
door's front (facing -Y, the side the player sees) as a "painting on a wall" at grey 0.3 and
forbids the helpers; the frame stays a candidate."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    # Only "doorsimple" and the "-colonly" collision helpers are in the rendered view layer
    # (the reactor door, the impostors and the separate door-leaf meshes are in excluded
    # collections). Paint the door's front (faces facing -Y within the opening, 3.4 x 4.1)
    # as a "painting on a wall" at grey 0.3; forbid the visible collision helpers.
    door = bpy.data.objects["doorsimple"]
    n_t = P.paint(door, lambda c, n, a: n.y < -0.8 and abs(c.x) < 3.4 and 0.0 < c.z < 4.1, (0.3, 0.3, 0.3))
    m.append(f"doorsimple front painted 0.3: {n_t} face(s)")
    for ob in bpy.context.scene.objects:
        if ob.type == "MESH" and "colonly" in ob.name:
            P.forbid(ob)
            m.append(f"no lights on helper {ob.name}")
    return m

P.main(run)
