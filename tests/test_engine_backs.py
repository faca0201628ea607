"""What each side of a face sees (engine.backs.sides_view) against the closed form of two
parallel squares: a cosine-weighted ray leaving a face reaches the other square with the
probability of their form factor."""
import numpy as np
import pytest

from relight_addon.engine.backs import sides_view
from relight_addon.engine.closed_forms import parallel_rectangles

H = 0.5  # the squares' distance (m); 1 x 1 m each
RAYS = 8192


def _two_squares(top_faces_down=True):
    """Face 0: the unit square at z = 0 facing up; face 1: the one at z = H, facing down (towards
    face 0) or up (away from it). Objects 0 and 1."""
    v = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, H), (1, 0, H), (1, 1, H), (0, 1, H)], float)
    top = [(4, 6, 5), (4, 7, 6)] if top_faces_down else [(4, 5, 6), (4, 6, 7)]
    tris = np.array([(0, 1, 2), (0, 2, 3)] + top)
    return v, tris, np.array([0, 0, 1, 1]), np.array([0, 1])


@pytest.mark.parametrize("down", [True, False])
def test_each_side_sees_the_other_square_as_often_as_their_form_factor(down):
    F = parallel_rectangles(1.0, 1.0, H)
    sigma = np.sqrt(F * (1 - F) / RAYS)
    v, tris, tri_face, obj = _two_squares(down)
    view = sides_view(v, tris, tri_face, obj, np.array([0, 1]), gap=0.0, rays_per_face=RAYS, seed=3)
    # the floor square: its front sees the top one (either side of it), its back nothing
    assert view.front[0] == pytest.approx(F, abs=5 * sigma) and view.back[0] == 0.0
    if down:  # the top square faces the floor: the same, from above
        assert view.front[1] == pytest.approx(F, abs=5 * sigma) and view.back[1] == 0.0
    else:  # it faces away: its front sees nothing, its back the floor's front (another object's)
        assert view.front[1] == 0.0
        assert view.back[1] == pytest.approx(F, abs=5 * sigma) and view.back_other[1] == view.back[1]
    # the floor's back sees no front at all, whichever way the top one faces
    assert view.back_other[0] == 0.0


def test_a_side_against_a_surface_sees_nothing_closer_than_its_gap():
    """A ray that reaches a surface nearer than the gap (a floor laid on a ground) does not count:
    with the gap above the squares' farthest corners no ray counts; with the gap at 2 H only the
    slanted ones, whose length H / cos(theta) reaches 2 H (cos(theta) <= 1/2: at most a quarter of
    the cosine-weighted rays, fewer of those that reach the square), some but less than half."""
    v, tris, tri_face, obj = _two_squares(True)
    view = sides_view(v, tris, tri_face, obj, np.array([0, 1]), gap=10 * H, rays_per_face=2048, seed=1)
    assert np.all(view.front == 0.0)
    near = sides_view(v, tris, tri_face, obj, np.array([0]), gap=0.0, rays_per_face=RAYS, seed=2).front[0]
    far = sides_view(v, tris, tri_face, obj, np.array([0]), gap=2 * H, rays_per_face=RAYS, seed=2).front[0]
    assert 0 < far < 0.5 * near


def test_a_back_counts_only_the_fronts_outside_its_box():
    """The top square facing away from the floor: its back sees the floor; given a box around it
    alone (a shelf's), the floor lies outside and counts; given one holding the floor too (a block
    standing on a floor, looking at the floor inside it), nothing counts."""
    v, tris, tri_face, obj = _two_squares(False)
    own = np.array([[[0.0, 0.0, H - 0.01], [1.0, 1.0, H + 0.01]]])
    both = np.array([[[-0.01, -0.01, -0.01], [1.01, 1.01, H + 0.01]]])
    plain = sides_view(v, tris, tri_face, obj, np.array([1]), gap=0.0, rays_per_face=2048, seed=4)
    alone = sides_view(v, tris, tri_face, obj, np.array([1]), gap=0.0, rays_per_face=2048, seed=4, box=own)
    closed = sides_view(v, tris, tri_face, obj, np.array([1]), gap=0.0, rays_per_face=2048, seed=4, box=both)
    assert plain.back[0] > 0.3 and alone.back[0] == plain.back[0] and closed.back[0] == 0.0
    # what it sees inside the box: the floor, counted by back_in (and nothing by front_in, the front
    # facing away); outside, nothing
    assert closed.back_in[0] == plain.back[0] and alone.back_in[0] == 0.0
    assert closed.front_in[0] == 0.0 and plain.front_in[0] == 0.0


def test_a_front_counts_what_it_reaches_inside_its_box():
    """Issue 35, case 12: front_in counts the front's rays that reach a face inside the box (a
    room's fronts see its inside; a ground plane or a garden outside its box does not count),
    front everything it reaches."""
    v, tris, tri_face, obj = _two_squares(True)
    both = np.array([[[-0.01, -0.01, -0.01], [1.01, 1.01, H + 0.01]]])
    own = np.array([[[-0.01, -0.01, -0.01], [1.01, 1.01, 0.01]]])  # the floor square's alone
    inside = sides_view(v, tris, tri_face, obj, np.array([0]), gap=0.0, rays_per_face=2048, seed=5, box=both)
    outside = sides_view(v, tris, tri_face, obj, np.array([0]), gap=0.0, rays_per_face=2048, seed=5, box=own)
    assert inside.front[0] > 0.3 and inside.front_in[0] == inside.front[0]
    assert outside.front[0] == inside.front[0] and outside.front_in[0] == 0.0
