"""Lighthouse (ebabel-eu, Blender 2.76): a base, a tower and a lantern, four 0.1-unit Area
lamps of 78.5 W inside the lantern, no materials. The base's top (the gallery around the
tower) painted grey 0.3; the lantern may hold no light (the lamps are there already)."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    base = bpy.data.objects["Cube"]
    m.append(f"base top painted 0.3: {P.paint(base, lambda c, n, a: P.up(n) and c.z > 0.95, (0.3, 0.3, 0.3))} face(s)")
    P.forbid(bpy.data.objects["Cube.002"])
    m.append("no lights on the lantern (Cube.002)")
    return m

P.main(run)
