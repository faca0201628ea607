"""Desk lamp (ebabel-eu, Blender 2.76): an emissive bulb in a lamp shade, curves and an
armature, on a ground plane scaled 127.5 (255 x 255 units). An artist wants the ground
under the shade lit: the ground is one quad, so the target is 300 lx on it is not local;
instead its area within reach is all there is. We paint the whole ground grey 0.2 (the only
surface to paint) and forbid light on every part of the lamp (a prop) but its shade, where an
artist looks for the light (a painted face holds no light: the ground cannot)."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    g = bpy.data.objects["Ground to see shadow of lamp"]
    m.append(f"ground painted 0.2: {P.paint(g, lambda c, n, a: True, (0.2, 0.2, 0.2))} face(s)")
    for ob in bpy.context.scene.objects:
        if ob.type in ("MESH", "CURVE") and ob is not g and ob.name != "Lamp Shade":
            P.forbid(ob)
            m.append(f"no lights on {ob.name}")
    return m

P.main(run)
