"""engine/cost.py's model (no bpy): each stage is counted when it runs and grows with what it
works on. Its constants against measured solves: benchmarks/bench_cost.py (docs/benchmarks.md)."""
import numpy as np

from relight_addon.engine import cost
from relight_addon.engine.patch_models.polygon import PolygonModel


def _parts(**kw):
    args = dict(n_patches=2000, rays_per_patch=256, n_candidates=800, n_targets=60)
    args.update(kw)
    return cost.estimate_cost(**args)["parts"]


def test_the_stages_of_a_solve_are_counted_when_they_run():
    assert "direct_light" not in _parts() and "lamp_refinement" not in _parts(n_lamps=10)
    assert "direct_light" in _parts(kernel=True) and "lamp_refinement" in _parts(n_lamps=10, lamp_refinements=3)


def test_the_direct_light_grows_with_the_lights_size_and_the_triangles():
    base = _parts(kernel=True)["direct_light"][1]
    polygons = _parts(kernel=True, patches_per_light=10)["direct_light"][1]
    dense = _parts(kernel=True, n_triangles=1_000_000)["direct_light"][1]
    more = _parts(kernel=True, max_lights=8)["direct_light"][1]
    assert base < polygons and base < dense and base < more
    # Max Lights + 1 lights of 10 patches, each gathered on all 2000 patches, plus the fixed parts
    want = 2000 * 4 * 10 * cost.KERNEL_SECONDS_PER_PAIR + 4 * cost.DIRECT_SECONDS_PER_LIGHT
    assert np.isclose(polygons, want)
    # a spread light (DIRECT_SPREAD_PATCHES patches or more) keeps the ray-cast gather: never
    # counted above the largest light the kernel takes
    spread = _parts(kernel=True, patches_per_light=40)["direct_light"][1]
    largest = _parts(kernel=True, patches_per_light=cost.DIRECT_SPREAD_PATCHES - 1)["direct_light"][1]
    assert polygons < largest and np.isclose(spread, largest)


def test_the_lamp_refinement_counts_triangles_and_at_most_its_expected_evaluations():
    one = _parts(n_lamps=10, lamp_refinements=1)["lamp_refinement"][1]
    six = _parts(n_lamps=10, lamp_refinements=6)["lamp_refinement"][1]
    dense = _parts(n_lamps=10, lamp_refinements=6, n_triangles=260_000)["lamp_refinement"][1]
    assert one < six <= cost.REFINE_EVALUATIONS_EXPECTED * cost.REFINE_SECONDS_PER_PATCH * 2000 * (1 + 1e-12)
    assert np.isclose(dense - six, cost.REFINE_EVALUATIONS_EXPECTED * cost.REFINE_SECONDS_PER_TRIANGLE * 260_000)


class _Patches:
    face = np.array([0, 0, 0, 0, 1, 2, 2, 3])


def test_a_polygon_light_holds_its_polygons_patches():
    mask = np.array([1, 1, 1, 1, 1, 1, 1, 0], dtype=bool)  # polygons 0 (4 patches), 1 (1), 2 (2)
    assert PolygonModel.patches_per_light(_Patches, mask) == 7 / 3


def test_the_blackbody_relaxation_is_counted_for_the_modes_that_run_it():
    # Automatic and Blackbody run light_colour.relaxed_bound: its stacked columns (3 m x
    # CONE_POINTS L, capped at RELAXATION_BYTES) a few times in memory, and time per entry
    from relight_addon.engine.light_colour import CONE_POINTS, RELAXATION_BYTES
    from relight_addon.engine.registry import LIGHT_COLOURS

    assert "light_colour" not in _parts() and "light_colour" in _parts(colour_relaxation=True)
    b, s = _parts(colour_relaxation=True)["light_colour"]
    entries = 3 * 60 * CONE_POINTS * 800
    assert np.isclose(b, cost.RELAXATION_COPIES * 8 * entries) and np.isclose(s, cost.RELAXATION_SECONDS_PER_ENTRY * entries)
    big, _ = _parts(colour_relaxation=True, n_targets=100_000)["light_colour"]
    assert np.isclose(big, cost.RELAXATION_COPIES * RELAXATION_BYTES)  # (a coarser cone beyond)
    assert {m.name for m in LIGHT_COLOURS if m.traits.relaxation} == {"auto", "blackbody"}
