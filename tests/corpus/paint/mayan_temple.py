"""Mayan temple (ebabel-eu, Blender 2.76), an exterior with a Sun lamp and no ground: the
temple's top platform painted light grey (a plaza to be lit); the four stairs may hold no
light (they are the walkway); the pyramid's sides stay candidates."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    pyr = bpy.data.objects["Pyramid"]
    top = max((c.z for i, c, n, a in P.faces_world(pyr) if P.up(n)), default=None)
    m.append(f"pyramid top platform at z={top:.3f}")
    m.append("top painted 0.4: %d face(s)" % P.paint(pyr, lambda c, n, a: P.up(n) and c.z > top - 0.05, (0.4, 0.4, 0.4)))
    for name in ("Front stairs", "Back stairs", "Left stairs", "Right stairs"):
        P.forbid(bpy.data.objects[name])
        m.append(f"no lights on {name}")
    return m

P.main(run)
