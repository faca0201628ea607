"""Bowling alley (ebabel-eu, Blender 2.76): the lane floor painted mid grey, as the area the
artist wants lit; the pins and the ball may hold no light (props); walls and ceiling stay
candidates."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    lane = bpy.data.objects["Bowling alley"]
    # the lane: the upward face at floor level whose material is "Alley" (face 0, 10.5 x 180 units)
    def lane_face(c, n, a):
        return P.up(n) and abs(c.z) < 0.05 and c.y < 0
    m.append(f"lane floor painted 0.3: {P.paint(lane, lane_face, (0.3, 0.3, 0.3))} face(s)")
    for ob in bpy.context.scene.objects:
        if ob.type == "MESH" and (ob.name.startswith("Bowling pin") or ob.name == "Bowling ball"):
            P.forbid(ob)
            m.append(f"no lights on {ob.name}")
    return m

P.main(run)
