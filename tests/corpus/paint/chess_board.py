"""Chess scene (ebabel-eu, Blender 2.76): a 54-unit board (scale 24 x 24 x 0.1 unapplied),
32 pieces, two Sun lamps, a missing image. The centre of the board (the squares within 12
units of the centre) painted grey 0.35; every piece may hold no light (props); the board's
rim and sides stay candidates."""
import os, sys
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
import paintlib as P  # noqa: E402
import bpy  # noqa: E402


def run():
    m = []
    board = bpy.data.objects["Chessboard"]
    # the 64 squares are the faces facing straight up at z = 0 (the rim's bevel is at z 0.2)
    n_p = P.paint(board, lambda c, n, a: n.z > 0.995 and abs(c.z) < 0.05 and abs(c.x) < 12 and abs(c.y) < 12, (0.35, 0.35, 0.35))
    m.append(f"board centre (16 squares) painted 0.35: {n_p} face(s)")
    for ob in bpy.context.scene.objects:
        if ob.type == "MESH" and ob.name != "Chessboard":
            P.forbid(ob)
    m.append("no lights on the 32 pieces")
    return m

P.main(run)
