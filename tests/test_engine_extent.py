"""The region that decides the answer (engine/extent.py): the scale of every automatic length.

References: the room's own box (what its painted floor sees), exact areas (a quadtree of a quad
covers it), and scaling (the same scene in centimetres or kilometres gives the same region,
scaled)."""
import numpy as np
import pytest

from relight_addon.engine.extent import Region, decisive_region, face_sizes, far_factor, quad_cells
from relight_addon.engine.geometry import triangle_areas
from relight_addon.engine.scene import default_max_patch_size, mesh_patches, polygon_faceset

ROOM = (5.0, 4.0, 3.0)


def _quad(a, b, c, d):
    return np.array([a, b, c, d], dtype=np.float64)


def room(scale=1.0, ground=0.0, dome=False, roof=True):
    """A room of ROOM (walls facing in; a roof unless ``roof`` is False), its floor painted; a
    ground plane ``ground`` m wide 1 cm under it and a far 'dome' of 8 quads when asked."""
    X, Y, Z = ROOM
    polys = [
        _quad((0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)),  # floor, up
        _quad((0, 0, 0), (0, 0, Z), (X, 0, Z), (X, 0, 0)),  # y = 0 wall, facing +y
        _quad((0, Y, 0), (X, Y, 0), (X, Y, Z), (0, Y, Z)),  # y = Y wall, facing -y
        _quad((0, 0, 0), (0, Y, 0), (0, Y, Z), (0, 0, Z)),  # x = 0 wall, facing +x
        _quad((X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)),  # x = X wall, facing -x
    ]
    if roof:
        polys.append(_quad((0, 0, Z), (0, Y, Z), (X, Y, Z), (X, 0, Z)))  # ceiling, down
    if ground:
        g = ground / 2
        polys.append(_quad((X / 2 - g, Y / 2 - g, -0.01), (X / 2 + g, Y / 2 - g, -0.01),
                           (X / 2 + g, Y / 2 + g, -0.01), (X / 2 - g, Y / 2 + g, -0.01)))
    if dome:
        r = 1000.0
        for k in range(8):
            a0, a1 = 2 * np.pi * k / 8, 2 * np.pi * (k + 1) / 8
            p0 = (X / 2 + r * np.cos(a0), Y / 2 + r * np.sin(a0))
            p1 = (X / 2 + r * np.cos(a1), Y / 2 + r * np.sin(a1))
            polys.append(_quad((*p1, 0), (*p0, 0), (*p0, 500), (*p1, 500)))  # facing the room
    faces = polygon_faceset([p * scale for p in polys])
    faces.target[0] = True
    faces.target_radiosity[0] = 1.0
    return faces


def test_the_region_is_the_room_whatever_surrounds_it():
    """A ground plane 9 km wide under the room and a dome 1 km away change nothing: the region is
    what the painted floor sees (the room), and so is the automatic patch size (its diagonal / 20);
    with the ceiling removed (an open roof) the floor sees the sky and the walls: the same room."""
    plain = decisive_region(room())
    diag = float(np.linalg.norm(ROOM))
    assert plain.seeds == "targets"
    assert plain.diagonal == pytest.approx(diag, rel=1e-6)
    for faces in (room(ground=9000.0), room(ground=9000.0, dome=True), room(roof=False, ground=9000.0)):
        r = decisive_region(faces)
        np.testing.assert_allclose(r.lo, plain.lo, atol=0.02)
        np.testing.assert_allclose(r.hi, plain.hi, atol=0.02)
        assert default_max_patch_size(faces) == pytest.approx(diag / 20, rel=0.01)
        assert r.scene_diagonal > 1000 * r.diagonal


def test_without_targets_the_region_is_what_the_emitters_light():
    faces = room(ground=9000.0)
    faces.target[:] = False
    faces.exitance[5] = 10.0  # the ceiling emits
    r = decisive_region(faces)
    assert r.seeds == "emitters"
    assert r.diagonal == pytest.approx(float(np.linalg.norm(ROOM)), rel=0.01)


@pytest.mark.parametrize("scale", [0.01, 1000.0])
def test_the_region_and_sizes_scale_with_the_scene(scale):
    """The same room with its ground and dome in centimetres or kilometres: the region, the patch
    sizes and the patches, scaled exactly."""
    one, scaled = room(ground=9000.0, dome=True), room(scale=scale, ground=9000.0, dome=True)
    r1, rs = decisive_region(one), decisive_region(scaled)
    np.testing.assert_allclose(rs.lo, r1.lo * scale, rtol=1e-5, atol=1e-6 * scale)
    np.testing.assert_allclose(rs.hi, r1.hi * scale, rtol=1e-5, atol=1e-6 * scale)
    np.testing.assert_allclose(face_sizes(scaled, rs.patch_size), face_sizes(one, r1.patch_size) * scale, rtol=1e-6)
    p1, ps = mesh_patches(one), mesh_patches(scaled)
    assert ps.n_patches == p1.n_patches
    np.testing.assert_allclose(ps.area, p1.area * scale ** 2, rtol=1e-6)


def test_far_geometry_is_modelled_coarsely_not_ignored():
    """The ground plane becomes a quadtree: cells at the patch size under the room, larger away
    from it (beyond half the region's diagonal); they cover the whole plane (areas sum to its area)
    and number about 3,000, not the (9 km / 0.35 m)^2 = 6.6 x 10^8 of a uniform grid; the dome's
    faces, far away, stay whole."""
    faces = room(ground=9000.0, dome=True)
    r = decisive_region(faces)
    p = faces.vertices[faces.loop_vertices[faces.loop_start[6]:faces.loop_start[6] + 4]]
    cells = quad_cells(r, p, r.patch_size)
    area = triangle_areas(cells.reshape(-1, 3, 3)).sum()
    assert area == pytest.approx(9000.0 ** 2, rel=1e-9)
    edge = np.linalg.norm(cells[:, 0, 1] - cells[:, 0, 0], axis=1)
    centre = cells.reshape(len(cells), -1, 3).mean(axis=1)
    under = np.all((centre[:, :2] > r.lo[:2]) & (centre[:, :2] < r.hi[:2]), axis=1)
    assert edge[under].max() <= r.patch_size * 1.000001
    assert edge.max() > 500.0
    assert 100 < len(cells) < 4000, len(cells)
    sizes = face_sizes(faces, r.patch_size)
    assert np.all(sizes[:6] == pytest.approx(r.patch_size))  # the room: the patch size
    assert np.all(sizes[7:] > 1e4 * r.patch_size)  # the dome, 1 km away
    patches = mesh_patches(faces)
    assert patches.n_patches < 4500
    np.testing.assert_allclose(np.bincount(patches.face, weights=patches.area, minlength=faces.n_faces)[6],
                               9000.0 ** 2, rtol=1e-9)


def test_far_factor_grows_with_the_square_of_the_distance_beyond_half_the_diagonal():
    r = Region(np.zeros(3), np.array([2.0, 0.0, 0.0]), "targets", 2.0)  # diagonal 2: half of it 1
    lo = np.array([[0.5, 0, 0], [3.0, 0, 0], [4.0, 0, 0], [12.0, 0, 0]])
    np.testing.assert_allclose(far_factor(r, lo, lo), [1.0, 1.0, 4.0, 100.0])
