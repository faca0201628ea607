"""Helpers for the corpus painting scripts: paint as an artist would, with Relight's attributes.

- relight_target: FLOAT_COLOR on CORNER, RGB = target radiance, alpha 1 on painted corners,
  alpha 0 elsewhere.
- relight_target_lux: FLOAT on FACE, lux (0 = none).
- relight_no_lights: object custom property (True) on furniture and props.
Faces are chosen by geometry in world space (centre, normal, area), on the base mesh
(the polygons Relight reports; modifiers' faces map back to them).
"""
import os
import sys

_here = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") not in (_here,)]

import bpy  # noqa: E402
from mathutils import Vector  # noqa: E402


def open_blend(path):
    bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    # A file saved in Edit Mode opens with its mesh in Edit Mode (attributes then read as
    # empty): leave it, as the artist would before painting in Vertex Paint.
    for ob in bpy.context.view_layer.objects:
        if ob.mode != "OBJECT":
            bpy.context.view_layer.objects.active = ob
            bpy.ops.object.mode_set(mode="OBJECT")
            print("paint: left", ob.mode, "mode on", ob.name)


def save_blend(path):
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path), copy=True, compress=True)


def faces_world(ob):
    """(index, centre, normal, area) of every base polygon, in world space."""
    M = ob.matrix_world
    N = M.inverted_safe().transposed().to_3x3()
    sx = abs(M.determinant()) ** (1.0 / 3.0) if M.determinant() != 0 else 1.0
    out = []
    for p in ob.data.polygons:
        c = M @ p.center
        n = (N @ p.normal)
        if n.length > 0:
            n.normalize()
        # world area of the polygon (exact, from its world vertices)
        vs = [M @ ob.data.vertices[v].co for v in p.vertices]
        a = Vector((0, 0, 0))
        for i in range(1, len(vs) - 1):
            a += (vs[i] - vs[0]).cross(vs[i + 1] - vs[0])
        out.append((p.index, c, n, a.length / 2.0))
    return out


def _target_layer(me):
    attr = me.attributes.get("relight_target")
    if attr is None:
        attr = me.attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
        for d in attr.data:
            d.color = (0.0, 0.0, 0.0, 0.0)
    return attr


def paint(ob, pred, rgb):
    """Paint the polygons of `ob` for which pred(centre, normal, area) holds. Returns count."""
    me = ob.data
    sel = [i for i, c, n, a in faces_world(ob) if pred(c, n, a)]
    if not sel:
        return 0
    attr = _target_layer(me)
    col = (rgb[0], rgb[1], rgb[2], 1.0)
    for i in sel:
        p = me.polygons[i]
        for li in p.loop_indices:
            attr.data[li].color = col
    me.color_attributes.active_color = attr
    return len(sel)


def paint_lux(ob, pred, lux):
    me = ob.data
    sel = [i for i, c, n, a in faces_world(ob) if pred(c, n, a)]
    if not sel:
        return 0
    attr = me.attributes.get("relight_target_lux")
    if attr is None:
        attr = me.attributes.new("relight_target_lux", "FLOAT", "FACE")
    for i in sel:
        attr.data[i].value = float(lux)
    return len(sel)


def forbid(ob):
    ob["relight_no_lights"] = True


def up(n, cos=0.9):
    return n.z >= cos


def down(n, cos=0.9):
    return n.z <= -cos


def report(msgs):
    for m in msgs:
        print("paint:", m)


def main(fn):
    """Run fn() between opening argv[1] and saving argv[2]."""
    argv = sys.argv
    if "--" in argv:
        argv = argv[argv.index("--"):]
    inp, out = argv[-2], argv[-1]
    open_blend(inp)
    msgs = fn()
    report(msgs)
    save_blend(out)
    print("paint: saved", out)
