"""Candidate lamps (engine/candidate_lamps.py, issue 17): where they hang, where they aim, how many,
and that Best k Lights with them is never worse than with the cells alone.

References, independent of the engine's lamp code: the geometry itself (every vertex of a target
region inside a spot's cone, by the angles; a cone as large as the region's solid angle, against
Van Oosterom and Strackee's exact solid angle of its triangles), the drop measured from the
surface, and an exhaustive search over the light subsets of a small problem.
"""
import itertools
import math

import numpy as np
import pytest
import scipy.optimize as sopt

from relight_addon.engine import candidate_lamps as cl
from relight_addon.engine.closed_forms import box_polygons
from relight_addon.engine.lamps import lamp_irradiance
from relight_addon.engine.lights.area import AREA
from relight_addon.engine.lights.spot import CONE_MARGIN
from relight_addon.engine.lights import candidate_mask
from relight_addon.engine.options import JobOptions
from relight_addon.engine.patch_models.adaptive import AdaptiveModel
from relight_addon.engine.sampling import SceneSampler
from relight_addon.engine.scene import polygon_faceset

W, D, H = 4.0, 3.0, 2.5
PAINTING = [(1.5, D - 0.01, 1.2), (2.5, D - 0.01, 1.2), (2.5, D - 0.01, 1.8), (1.5, D - 0.01, 1.8)]  # facing -Y
SHELF = [(0.0, 0.0, H - 0.05), (0.0, 0.8, H - 0.05), (0.8, 0.8, H - 0.05), (0.8, 0.0, H - 0.05)]  # under the ceiling
LAMPS = dict(spot_lamps=True, area_lamps=True, point_lamps=True)


def room(shelf=False):
    """A closed 4 x 3 x 2.5 m box (inward faces), a 1 x 0.6 m painting 1 cm off the north wall,
    painted 1.2 (radiance; 3.77 W/m^2); only the ceiling may hold lights; ``shelf``: a panel 5 cm
    under the ceiling's corner (facing down), blocking the drop there."""
    polys = [np.asarray(p) for p in box_polygons((W, D, H))] + [np.asarray(PAINTING)]
    if shelf:
        polys.append(np.asarray(SHELF))
    faces = polygon_faceset(polys, reflectance=0.6)
    n = faces.n_faces
    normal = np.array([np.cross(p[1] - p[0], p[2] - p[0]) for p in map(np.asarray, polys)])
    ceiling = normal[:, 2] < -0.5
    ceiling[len(box_polygons((W, D, H))) + 1:] = False  # the shelf holds no light
    faces.forbidden = ~ceiling
    faces.target = np.zeros(n, bool)
    faces.target[len(box_polygons((W, D, H)))] = True
    faces.target_radiosity = np.where(faces.target[:, None], 1.2 * math.pi, 0.0) * np.ones((n, 3))
    patches = AdaptiveModel(JobOptions(max_patch_size=0.25)).mesh(faces)
    return patches, SceneSampler(patches)


@pytest.fixture(scope="module")
def plain():
    return room()


def _options(**kw):
    return JobOptions(**{**LAMPS, **kw}).validate()


def test_the_box_is_inward_and_only_its_ceiling_holds_lights(plain):
    patches, _ = plain
    cand = candidate_mask(patches)
    assert np.all(patches.normal[cand, 2] < -0.99)  # the ceiling faces down, into the room
    assert np.all(np.abs(patches.center[cand, 2] - H) < 1e-9)
    assert patches.target.sum() >= 2 and np.all(patches.normal[patches.target, 1] < -0.99)


def test_clusters_are_the_painted_region_and_its_halves(plain):
    patches, _ = plain
    clusters = cl.target_clusters(patches)
    tg = set(np.flatnonzero(patches.target).tolist())
    assert set(clusters[0].patches.tolist()) == tg  # the whole painting first: it asks for the most power
    want = patches.area * patches.target_radiosity.sum(axis=1)
    assert clusters[0].power == pytest.approx(want[list(tg)].sum())
    assert len(clusters) == 3  # 1 m wide: split once across its width (above 2 patch sizes), into halves
    halves = [set(c.patches.tolist()) for c in clusters[1:]]
    assert halves[0] | halves[1] == tg and not halves[0] & halves[1]
    np.testing.assert_allclose(clusters[0].center, [2.0, D - 0.01, 1.5], atol=1e-9)


def test_positions_hang_a_drop_in_front_of_the_candidate_surface():
    patches, sampler = room(shelf=True)
    cand = candidate_mask(patches)
    pos, nrm, at = cl.mount_positions(patches, cand, 12, 0.2, sampler)
    assert 1 <= len(pos) <= 12 and len(set(at.tolist())) == len(at)
    assert np.all(cand[at])
    np.testing.assert_allclose(pos[:, 2], H - 0.2, atol=1e-9)  # 0.2 m under the ceiling
    np.testing.assert_allclose(pos, patches.center[at] + 0.2 * patches.normal[at])
    # none above the shelf (its drop is blocked 5 cm down)
    assert not np.any((pos[:, 0] < 0.8) & (pos[:, 1] < 0.8))
    # spread over the ceiling: no two positions closer than a patch
    d = np.linalg.norm(pos[:, None] - pos[None], axis=2) + np.eye(len(pos)) * 9
    assert d.min() > 0.25


def test_a_drop_blocked_everywhere_is_said_not_ignored(plain):
    patches, sampler = plain
    notes = []
    lamps, _ = cl.plan_lamps(patches, candidate_mask(patches), _options(), sampler, drop=3.0, notes=notes)
    assert lamps == [] and len(notes) == 1 and "3 m in front" in notes[0] and "--lamp-drop" in notes[0]


def _solid_angle(tv, x):
    """Exact solid angle of triangles tv (n, 3, 3) seen from x (Van Oosterom and Strackee)."""
    a, b, c = tv[:, 0] - x, tv[:, 1] - x, tv[:, 2] - x
    la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = la * lb * lc + (a * b).sum(1) * lc + (a * c).sum(1) * lb + (b * c).sum(1) * la
    return float(np.abs(2 * np.arctan2(num, den)).sum())


def test_each_spot_just_covers_a_cluster(plain):
    patches, sampler = plain
    lamps, kinds = cl.plan_lamps(patches, candidate_mask(patches), _options(), sampler, drop=0.15)
    spots = [lamp for lamp, k in zip(lamps, kinds) if k == "spot"]
    assert spots and set(kinds) == {"spot", "area", "point"}
    clusters = cl.target_clusters(patches)
    tri = {id(c): patches.tri_vertices[np.isin(patches.tri_patch, c.patches)] for c in clusters}
    covering = equal_area = 0
    for s in spots:
        half = 0.5 * s.spot_size
        for c in clusters:
            v = tri[id(c)].reshape(-1, 3) - s.position
            ang = np.arccos(np.clip(v @ s.direction / np.linalg.norm(v, axis=1), -1, 1))
            if np.all(ang <= half * (1 + 1e-9)) and half <= ang.max() * (1 + CONE_MARGIN) * 1.05:
                covering += 1  # every vertex inside, and no more than a few per cent wider
            omega = _solid_angle(tri[id(c)], s.position)
            if abs(2 * math.pi * (1 - math.cos(half)) - omega) < 0.03 * omega:
                equal_area += 1  # the cone of the cluster's solid angle
    assert covering >= len(spots) // 2 and equal_area >= len(spots) // 3, (covering, equal_area, len(spots))
    for s in spots:  # hung under the ceiling, pointing into the room
        assert s.position[2] == pytest.approx(H - 0.15) and s.direction[2] < 0


def test_area_lamps_come_wide_and_as_a_beam_whose_footprint_holds_a_cluster(plain):
    """Per position and cluster two area lamps: Spread 180 degrees facing the cluster's centre,
    and a beam whose footprint holds the cluster: with Cycles' Spread a lamp point lights the
    directions within half the spread of the axis, so a vertex is lit when the lamp's square
    comes within t tan(spread / 2) of its projection on the lamp's plane (t its depth) -- checked
    by the exact distance to the square -- and the beam is no wider than that needs (its widest
    vertex: the disk of radius size / 2 the square holds just reaches it)."""
    patches, sampler = plain
    lamps, kinds = cl.plan_lamps(patches, candidate_mask(patches), _options(spot_lamps=False, point_lamps=False),
                                 sampler, drop=0.15)
    wide = [a for a in lamps if a.spread == math.pi]
    beams = [a for a in lamps if a.spread < math.pi]
    assert set(kinds) == {"area"} and len(wide) == len(beams) >= 2 and len(wide) + len(beams) == len(lamps)
    clusters = cl.target_clusters(patches)
    for a in wide:  # facing a cluster's centre
        assert any(np.allclose(a.direction, (c.center - a.position) / np.linalg.norm(c.center - a.position))
                   for c in clusters)
    tri = [patches.tri_vertices[np.isin(patches.tri_patch, c.patches)].reshape(-1, 3) for c in clusters]
    for a in beams:
        tan_h, held = math.tan(a.spread / 2), []
        for v in tri:
            d = v - a.position
            t = d @ a.direction
            pu, pv = np.abs(d @ a.axis_u), np.abs(d @ a.axis_v)  # the projection, in the lamp's frame
            gap = np.hypot(np.maximum(pu - a.size_u / 2, 0), np.maximum(pv - a.size_v / 2, 0))
            rho = np.hypot(pu, pv)
            held.append(bool(np.all(gap <= t * tan_h * (1 + 1e-9) + 1e-12)) and
                        np.max((rho - a.size_u / 2) / t) == pytest.approx(tan_h, rel=1e-9))
        assert any(held), math.degrees(a.spread)
        assert a.size_u == a.size_v == wide[0].size_u


def test_the_kinds_and_the_count_follow_the_options(plain):
    patches, sampler = plain
    cand = candidate_mask(patches)
    for kw, kinds in ((dict(area_lamps=False, point_lamps=False), {"spot"}), (dict(spot_lamps=False), {"area", "point"}),
                      (dict(spot_lamps=False, area_lamps=False), {"point"})):
        lamps, names = cl.plan_lamps(patches, cand, _options(**kw), sampler)
        assert set(names) == kinds, kw
    for n in (1, 7, 11, 17, 22, 30, 45):
        o = _options(max_lamps=n)
        lamps, _ = cl.plan_lamps(patches, cand, o, sampler)
        assert 1 <= len(lamps) <= n and len(lamps) <= cl.lamp_bound(patches, cand, o)
        # the receiver-point work the cost estimate counts: an area lamp 4 rays a point, a beam 4 x the points
        work = sum(1 if lamp.kind is not AREA else (4 if lamp.spread == math.pi else 16) for lamp in lamps)
        assert work <= cl.lamp_bound(patches, cand, o, work=True), n
    none = JobOptions(spot_lamps=False, area_lamps=False, point_lamps=False).validate()
    assert cl.offered_kinds(none) == () and cl.plan_lamps(patches, cand, none, sampler) == ([], [])
    assert cl.lamp_bound(patches, cand, none) == 0
    # the paper's heuristics run on single-scale cells: no lamp offered
    assert cl.offered_kinds(JobOptions(selection="exitance-elimination").validate()) == ()
    with pytest.raises(ValueError, match="single-scale light cells"):
        JobOptions(selection="exitance-elimination", spot_lamps=not JobOptions().spot_lamps).validate()


def test_offered_lamps_are_lights_whose_source_is_their_irradiance(plain):
    patches, sampler = plain
    cand = candidate_mask(patches)
    lights, planned = cl.offer_lamps(None, patches, cand, _options(max_lamps=12), sampler, seed=3)
    assert lights.n_lights <= planned <= 12 and lights.basis.shape == (int(cand.sum()), lights.n_lights)
    lamps = [lights.lamp(j) for j in range(lights.n_lights)]
    assert all(lamp is not None for lamp in lamps)
    H = lights.irradiance.toarray()
    assert np.all(H.max(axis=0) > 0)  # each lights some patch
    # a column is the lamp's irradiance per W where its light can reach (all patches here)
    j = lights.kind_names.index("point")
    ref = lamp_irradiance(patches, [lamps[j]], sampler=sampler, seed=11, points_per_patch=256)[:, 0, 0]
    lit = ref > 0.05 * ref.max()
    assert np.abs(H[lit, j] / ref[lit] - 1).mean() < 0.02
    # every patch a spot's cone reaches got its light: nothing left out by the pre-filter
    s = lights.kind_names.index("spot")
    full = lamp_irradiance(patches, [lamps[s]], sampler=sampler, seed=5, points_per_patch=cl.LAMP_POINTS)[:, 0, 0]
    assert H[:, s] @ patches.area == pytest.approx(full @ patches.area, rel=0.02)
    v = patches.tri_vertices - lamps[s].position  # a patch with a vertex inside the cone is lit
    inside = (v @ lamps[s].direction) / np.linalg.norm(v, axis=2) > math.cos(0.5 * lamps[s].spot_size)
    seen = np.zeros(patches.n_patches, bool)
    seen[patches.tri_patch[inside.any(axis=1)]] = True
    front = (patches.normal * (lamps[s].position - patches.center)).sum(axis=1) > 0
    assert np.all(H[seen & front & (full > 0.1 * full.max()), s] > 0)  # (a patch the edge crosses: sampled)
    # an area beam's too: every patch its light reaches (all of them computed) is in its column
    b = next(j for j, lamp in enumerate(lamps) if lamp.kind is AREA and lamp.spread < math.pi)
    full = lamp_irradiance(patches, [lamps[b]], sampler=sampler, seed=5, points_per_patch=cl.LAMP_POINTS)[:, 0, 0]
    assert H[:, b] @ patches.area == pytest.approx(full @ patches.area, rel=0.02)
    assert np.all(H[full > 0.02 * full.max(), b] > 0) and np.count_nonzero(full) < 0.5 * patches.n_patches


def _exhaustive(T, b, k, cols):
    return min(math.sqrt(sum(sopt.nnls(T[c][:, list(S)], b[:, c])[1] ** 2 for c in range(3)))
               for S in itertools.combinations(cols, k))


def test_best_k_with_lamps_is_never_worse_than_cells_alone():
    """A random problem of 14 cells and 10 lamps whose columns are built to mislead greedy
    pursuit: at every k the curve with lamps is at most the cells' own exact optimum."""
    from relight_addon.engine.selections.greedy_swap import never_worse
    from relight_addon.engine.best_lights import best_k_curve, KLightPoint

    rng = np.random.default_rng(4)
    m = 30
    cells = rng.uniform(0, 1, (m, 14)) ** 3
    lamps = 0.5 * (cells[:, :10] + cells[:, 4:14]) + 0.02 * rng.uniform(0, 1, (m, 10))  # plausible decoys
    T = np.hstack([cells, lamps])
    b = np.repeat(cells[:, [1, 6, 11]].sum(axis=1, keepdims=True), 3, axis=1)
    full = best_k_curve(T, b, 4, swap=False)  # greedy only: it can take a decoy
    surface = np.arange(14)
    alone = best_k_curve(T[:, surface], b, 4)
    out = never_worse(full, alone, surface)
    for k, pt in enumerate(out, start=1):
        assert pt.error <= min(full[k - 1].error, alone[k - 1].error) + 1e-12
        # never worse than the best any k cells can do (every subset of the 14, NNLS)
        assert pt.error <= _exhaustive([T] * 3, b, k, range(14)) * (1 + 1e-7) + 1e-12
        fit = math.sqrt(sum(sopt.nnls(T[:, pt.lights], b[:, c])[1] ** 2 for c in range(3)))
        assert fit == pytest.approx(pt.error, rel=1e-7, abs=1e-12)  # its lights, mapped back, give its error
        if k > 1:
            assert pt.error <= out[k - 2].error
    assert any(p.source == "surface" for p in out)  # the decoys did mislead the greedy path
    assert isinstance(out[0], KLightPoint)
