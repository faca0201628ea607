"""zdm2 (Cube 2: Sauerbraten map, converted; CC BY 4.0): one 29k-polygon mesh with
Triangulate and Geometry Nodes modifiers, no materials, no lamps. The main floor (upward
faces at z 8.5-9.5, within 15 m of its centre) painted grey 0.3, and a lower floor
(z -2.5 to -1.5) given a 300 lx illuminance target. The architecture holds every candidate."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    ob = bpy.data.objects["zdm2"]
    fw = P.faces_world(ob)
    main = [c for i, c, n, a in fw if P.up(n) and 8.5 < c.z < 9.5]
    cx = sum(c.x for c in main) / len(main)
    cy = sum(c.y for c in main) / len(main)
    m.append(f"main floor centre ({cx:.1f}, {cy:.1f})")
    n1 = P.paint(ob, lambda c, n, a: P.up(n) and 8.5 < c.z < 9.5 and (c.x - cx) ** 2 + (c.y - cy) ** 2 < 15 ** 2, (0.3, 0.3, 0.3))
    m.append(f"main floor painted 0.3: {n1} face(s)")
    n2 = P.paint_lux(ob, lambda c, n, a: P.up(n) and -2.5 < c.z < -1.5, 300.0)
    m.append(f"lower floor 300 lx: {n2} face(s)")
    return m

P.main(run)
