"""Castle (ebabel-eu, Blender 2.76): four walls and four towers, unapplied scales, one Point
lamp, no ground. The wall-walks (tops of the four curtain walls) painted grey 0.35 and a
500 lx illuminance target on the top of one tower base; the conical roofs may hold no light."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    for name in ("Cube.004", "Cube.005", "Cube.006", "Cube.007"):
        ob = bpy.data.objects[name]
        m.append(f"{name} wall-walk painted 0.35: {P.paint(ob, lambda c, n, a: P.up(n), (0.35, 0.35, 0.35))}")
    tower = bpy.data.objects["Cube.001"]
    m.append(f"Cube.001 top: 500 lx on {P.paint_lux(tower, lambda c, n, a: P.up(n), 500.0)} face(s)")
    for ob in bpy.context.scene.objects:
        if ob.type == "MESH" and ob.name.startswith("Cone"):
            P.forbid(ob)
            m.append(f"no lights on {ob.name}")
    return m

P.main(run)
