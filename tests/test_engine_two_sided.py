"""engine.two_sided on numpy geometry (no bpy): which side of each face the scene sees
(faces_seen_from_behind) and the back side of emitters (emitting_backs), on chunks of boxes and
cards built here (engine.face_chunks.FaceChunks)."""
import numpy as np
import pytest

pytest.importorskip("embreex", reason="embreex (Embree) casts the rays")

from relight_addon.engine import two_sided  # noqa: E402
from relight_addon.engine.face_chunks import FaceChunks  # noqa: E402
from relight_addon.engine.geometry import triangle_cross  # noqa: E402


def mesh(vertices, polygons) -> dict:
    """A chunk's local geometry (engine.face_chunks' keys) of ``polygons`` (vertex index lists)."""
    loop_total = np.array([len(p) for p in polygons])
    edges, loop_edge, lt, lt_poly = {}, [], [], []
    for k, p in enumerate(polygons):
        for i in range(len(p)):
            loop_edge.append(edges.setdefault(tuple(sorted((p[i], p[(i + 1) % len(p)]))), len(edges)))
        for i in range(1, len(p) - 1):  # a fan keeps the polygon's winding
            lt.append((p[0], p[i], p[i + 1]))
            lt_poly.append(k)
    return {"V": np.asarray(vertices, dtype=np.float64), "lt": np.array(lt), "lt_poly": np.array(lt_poly),
            "loop_vert": np.concatenate([np.asarray(p) for p in polygons]),
            "loop_poly": np.repeat(np.arange(len(polygons)), loop_total),
            "loop_start": np.concatenate([[0], np.cumsum(loop_total)[:-1]]), "loop_total": loop_total,
            "loop_edge": np.array(loop_edge), "n_edges": len(edges), "mat_index": np.zeros(len(polygons), int),
            "slots": []}


def box(lo, hi, inward=False) -> dict:
    """A closed box of six quads, their normals out of it (or into it)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    V = np.array([[(hi if i >> a & 1 else lo)[a] for a in range(3)] for i in range(8)])
    quads = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    centre = 0.5 * (lo + hi)
    out = []
    for q in quads:
        P = V[q]
        n = np.cross(P[1] - P[0], P[2] - P[0])
        if (n @ (P.mean(axis=0) - centre) < 0) != inward:
            q = q[::-1]
        out.append(q)
    return mesh(V, out)


def card(z, size, up, centre=(0.0, 0.0)) -> dict:
    """A single horizontal quad at height ``z`` facing up (+z) or down."""
    x, y, h = centre[0], centre[1], 0.5 * size
    V = [[x - h, y - h, z], [x + h, y - h, z], [x + h, y + h, z], [x - h, y + h, z]]
    return mesh(V, [[0, 1, 2, 3] if up else [0, 3, 2, 1]])


def chunks(*objects) -> FaceChunks:
    """FaceChunks of ``(name, geometry, exitance (3,) of its faces)``, one object each, at identity."""
    b = FaceChunks()
    for oi, (name, geo, e) in enumerate(objects):
        n = len(geo["loop_start"])
        b.names.append(name)
        b.add_geometry(geo, np.eye(4), name)
        b.add_faces(oi, np.arange(n), np.zeros(n, dtype=bool), np.zeros((n, 3)), np.zeros(n, dtype=bool), None,
                    np.full((n, 3), 0.5), np.tile(np.asarray(e, dtype=np.float64), (n, 1)), np.zeros(n, dtype=bool),
                    np.zeros(n, dtype=np.int64))
    return b


def normals(b, ci) -> np.ndarray:
    """The unit normals of chunk ``ci``'s triangles, as they are now."""
    n = triangle_cross(b.verts[ci][b.tris[ci] - b.base[ci][0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


DARK = (0.0, 0.0, 0.0)
ROOM = ((-2.0, -2.0, 0.0), (2.0, 2.0, 3.0))


def test_a_closed_box_has_no_face_seen_from_behind():
    b = chunks(("Room", box(*ROOM, inward=True), DARK), ("Crate", box((-0.75, -0.75, 0.1), (0.75, 0.75, 1.3)), DARK))
    tris = [t.copy() for t in b.tris]
    assert two_sided.faces_seen_from_behind(b) == []
    assert all(np.array_equal(t, u) for t, u in zip(tris, b.tris))
    assert b.nf == 12


def test_a_room_whose_normals_point_out_is_turned_in():
    b = chunks(("Room", box(*ROOM), DARK), ("Crate", box((-0.75, -0.75, 0.1), (0.75, 0.75, 1.3)), DARK))
    warnings = two_sided.faces_seen_from_behind(b)
    assert len(warnings) == 1 and "6 face(s) (6 of 'Room')" in warnings[0] and "face away" in warnings[0]
    centre = np.array([0.0, 0.0, 1.5])
    tri_centre = b.verts[0][b.tris[0]].mean(axis=1)
    assert np.all(np.sum(normals(b, 0) * (centre - tri_centre), axis=1) > 0)  # every face now faces in
    crate = b.verts[1][b.tris[1] - b.base[1][0]].mean(axis=1)
    assert np.all(np.sum(normals(b, 1) * (crate - [0.0, 0.0, 0.7]), axis=1) > 0)  # the crate as it was
    assert b.nf == 12  # turned, not doubled


def test_a_card_seen_from_behind_by_the_floor_is_turned():
    b = chunks(("Floor", card(0.0, 10.0, up=True), DARK), ("Card", card(1.0, 1.0, up=True), DARK))
    warnings = two_sided.faces_seen_from_behind(b)
    assert len(warnings) == 1 and "of 'Card'" in warnings[0] and "Floor" not in warnings[0]
    assert normals(b, 1)[:, 2] == pytest.approx(-1.0)  # it faces the floor that sees it
    assert normals(b, 0)[:, 2] == pytest.approx(1.0)


def test_a_card_in_a_room_seen_from_both_sides_is_doubled():
    b = chunks(("Room", box(*ROOM, inward=True), DARK), ("Shelf", card(1.5, 1.0, up=True), DARK))
    warnings = two_sided.faces_seen_from_behind(b)
    assert len(warnings) == 1 and "1 face(s) (1 of 'Shelf') are seen from both sides" in warnings[0]
    assert b.nf == 8 and len(b.e) == 3
    assert normals(b, 2)[:, 2] == pytest.approx(-1.0)  # its back: a face of its own, facing down
    assert b.forb[2].all() and (b.f_idx[2] == -1).all() and (b.f_obj[2] == 1).all()
    diag = np.linalg.norm([4.0, 4.0, 3.0])
    assert b.verts[2][:, 2] == pytest.approx(1.5 - two_sided.BACK_OFFSET * diag)


def test_an_emitting_back_that_sees_the_room_is_modelled():
    e = (10.0, 8.0, 6.0)
    b = chunks(("Room", box(*ROOM, inward=True), DARK), ("Lamp", card(1.5, 1.0, up=False), e))
    assert two_sided.emitting_backs(b) == ([], [])
    assert b.nf == 8  # the lamp's back became a face
    np.testing.assert_array_equal(b.e[2], [e])
    assert normals(b, 2)[:, 2] == pytest.approx(1.0)  # facing up, towards the ceiling
    assert b.forb[2].all() and (b.f_idx[2] == -1).all()
    diag = np.linalg.norm([4.0, 4.0, 3.0])
    assert b.verts[2][:, 2] == pytest.approx(1.5 + two_sided.BACK_OFFSET * diag)


def test_an_emitting_back_against_the_ceiling_is_counted_not_modelled():
    e = (10.0, 10.0, 10.0)
    b = chunks(("Room", box(*ROOM, inward=True), DARK), ("Lamp", card(2.998, 1.0, up=False), e))
    warnings, rows = two_sided.emitting_backs(b)
    assert b.nf == 7  # no back face: the light caught in the gap is not modelled
    assert len(warnings) == 1 and "'Lamp'" in warnings[0] and "from 'Room'" in warnings[0]
    (row,) = rows
    assert row["object"] == "Lamp" and row["near"] == ["Room"]
    assert row["power"] == pytest.approx(30.0) and row["emitted"] == pytest.approx(30.0)  # W: 3 x 10 W/m^2 x 1 m^2
    # the median length of cosine-weighted rays to a parallel plane 2 mm away: cos^2 is uniform, so
    # the median cosine is 1/sqrt(2)
    assert row["distance"] == pytest.approx(0.002 * np.sqrt(2.0), rel=0.1)
    low, high = row["leak"]
    assert 0.0 < low <= high < row["power"]


def test_a_closed_emitter_keeps_its_back_inside():
    b = chunks(("Room", box(*ROOM, inward=True), DARK), ("Bulb", box((-0.2, -0.2, 1.3), (0.2, 0.2, 1.7)), (5.0,) * 3))
    assert two_sided.emitting_backs(b) == ([], [])
    assert b.nf == 12


def test_open_faces_and_mixed_orientation():
    room = box(*ROOM, inward=True)
    is_open, island = two_sided.open_faces(room)
    assert not is_open.any() and len(set(island)) == 1
    assert not two_sided.mixed_orientation(room, island).any()
    flipped = box(*ROOM, inward=True)
    flipped["loop_vert"][:4] = flipped["loop_vert"][:4][::-1]  # one face turned by hand
    assert two_sided.mixed_orientation(flipped, two_sided.open_faces(flipped)[1]).all()
    is_open, _ = two_sided.open_faces(card(1.0, 1.0, up=True))
    assert is_open.all()


def test_the_same_chunks_checked_again_cast_no_ray_and_a_moved_card_casts_them(monkeypatch):
    """The ray checks' answers are kept by the content of what they read (engine.by_content): the
    same scene exported again (Solve & Reduce after Live's strokes) turns and doubles the same
    faces without a ray; a face moved by a millimetre is cast again."""
    def room(z):
        return chunks(("Room", box(*ROOM, inward=True), DARK), ("Shelf", card(z, 1.0, up=True), DARK),
                      ("Card", card(0.25, 0.5, up=True, centre=(1.2, 1.2)), DARK),
                      ("Under", card(0.25, 0.5, up=False, centre=(1.2, 1.2)), DARK))  # (back to back)

    first = room(1.37)
    said = two_sided.faces_seen_from_behind(first)
    built = []
    real = two_sided.embree_scene
    monkeypatch.setattr(two_sided, "embree_scene", lambda *a: built.append(1) or real(*a))
    again = room(1.37)
    assert two_sided.faces_seen_from_behind(again) == said and not built
    assert again.nf == first.nf and all(np.array_equal(x, y) for x, y in zip(again.tris, first.tris))
    assert said == ["1 face(s) (1 of 'Shelf') are seen from both sides (single planes lit on one side, seen from "
                    "the other): their back sides are modelled as faces of their own (never targets or lights)"]
    moved = room(1.371)
    assert two_sided.faces_seen_from_behind(moved) == said and built  # (the same answer: cast again)


def test_an_answer_kept_by_content_is_read_only_and_follows_its_arguments():
    from relight_addon.engine import by_content
    from relight_addon.engine.by_content import kept_by_content

    calls = []

    @kept_by_content(kept=2)
    def doubled(x, scene=None):
        calls.append(1)
        return 2 * x

    x = np.arange(4.0)
    a = doubled(x, scene=lambda: pytest.fail("not keyed"))
    assert doubled(x.copy(), scene=None) is a and len(calls) == 1  # (the content, not the array object)
    with pytest.raises(ValueError):
        a[0] = 5.0  # (shared by the calls that take it)
    x[0] = 1.0  # changed in place: computed anew
    assert doubled(x)[0] == 2.0 and len(calls) == 2
    doubled(x + 1), doubled(x + 2)  # only the last two are kept
    assert doubled(np.arange(4.0))[1] == 2.0 and len(calls) == 5
    doubled(x + 2)
    assert len(calls) == 5
    by_content.forget()  # (a benchmark's cold run)
    doubled(x + 2)
    assert len(calls) == 6
