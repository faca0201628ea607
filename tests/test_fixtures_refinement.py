"""Fixtures refined as a lighting designer moves them (issue 39, open point 2): a fixture that is not
aimable (a downlight, a batwing) keeps hanging along its mounting normal and is refined only in its
position on the mounting surface (and its turn about its axis when asymmetric); an aimable one is aimed
too. The rule is the kind's (FixtureKind.refinement_parameters), not a switch in engine/lamp_refinement.

On room() of test_engine_candidate_lamps (a box, a painting on the north wall the only target, the
ceiling the only candidate surface), fixtures of the built-in library the only candidates.
"""
import math

import numpy as np
import pytest

from relight_addon.engine import lamp_refinement as lr
from relight_addon.engine.candidate_lamps import default_drop
from relight_addon.engine.lights.fixture import FIXTURE, TURN_STEP, fixture_lamp
from relight_addon.engine.options import JobOptions
from relight_addon.engine.photometry import library as lib
from relight_addon.engine.sampling import SceneSampler
from relight_addon.pipeline.jobs import run_solve

from test_engine_candidate_lamps import D, H, W
from test_engine_lamp_refinement import _faces

DOWN = np.array([0.0, 0.0, -1.0])
FIXTURES = dict(fixtures="builtin", spot_lamps=False, surface_lights=False, seed=3, max_patch_size=0.25)


@pytest.fixture(scope="module")
def builtin():
    return {f.name: f for f in lib.load_library(lib.BUILTIN)}


@pytest.fixture(scope="module")
def ceiling():
    """The room's patches and a Mount on its ceiling (the solve's drop)."""
    from test_engine_candidate_lamps import room

    patches, sampler = room()
    cand = ~patches.forbidden & ~patches.target
    return patches, lr.Mount(patches, cand, default_drop(patches), sampler)


def _kinds(builtin):
    aimable = next(f for f in builtin.values() if f.aimable)
    down = next(f for f in builtin.values() if f.symmetric and not f.aimable)
    asym = next(f for f in builtin.values() if not f.symmetric and not f.aimable)
    return aimable, down, asym


def test_each_fixture_refines_what_a_designer_may_change(builtin, ceiling):
    """The parameters per fixture, and at any parameters a non-aimable fixture still hangs along the
    ceiling's normal (its C0 plane turned by ``turn`` when asymmetric) while an aimable one is aimed."""
    patches, mount = ceiling
    at = np.array([W / 2, D / 2, H - mount.drop])
    aimable, down, asym = _kinds(builtin)
    rng = np.random.default_rng(0)
    for f, names in ((aimable, ("aim_u", "aim_v", "slide_u", "slide_v")), (down, ("slide_u", "slide_v")),
                     (asym, ("slide_u", "slide_v", "turn"))):
        lamp = fixture_lamp("f", f, at, DOWN, towards=np.array([0.0, 1.0, 0.0]))
        assert FIXTURE.refinement_parameters(lamp) == names
        params = lr._LampParameters(lamp, mount, 0.5)
        assert params.names == names  # (on the ceiling: it may slide)
        moved = 0
        for _ in range(20):
            x = rng.uniform(-1.0, 1.0, len(names))
            got = params.lamp_at(x)
            if got is None:
                continue  # slid off the ceiling
            moved += 1
            assert got.position[2] == pytest.approx(H - mount.drop)  # on the mounting surface's drop
            if f.aimable:
                assert got.direction @ DOWN < 1 - 1e-6  # aimed
            else:
                np.testing.assert_allclose(got.direction, DOWN, atol=1e-12)  # hanging along the normal
            if not f.symmetric:  # its C0 plane (-Y) turned about its axis by turn x TURN_STEP
                c = float(np.clip(got.axis_v @ lamp.axis_v, -1, 1))
                assert math.acos(c) == pytest.approx(abs(x[names.index("turn")]) * TURN_STEP, abs=1e-9)
        assert moved >= 5


@pytest.mark.slow
def test_a_solve_keeps_its_downlights_hanging_and_moves_them(builtin):
    """A whole solve: every non-aimable fixture of the answer hangs along the ceiling's normal; the
    refinement did move one (its position none of the offered fixtures'), so the check sees a refined lamp."""
    out = run_solve(_faces(), JobOptions(**FIXTURES, max_lights=3))
    lights = out.problem.lights
    offered = sum(out.report["model"]["lights_by_kind"].values())
    assert out.report["model"]["lamp_refinement"]["lamps_refined"] >= 1
    at = {tuple(np.round(lights.lamp(j).position, 9)) for j in range(offered) if lights.lamp(j) is not None}
    lamps = [lights.lamp(j) for j in out.reduction.final.lights]
    assert any(tuple(np.round(lp.position, 9)) not in at for lp in lamps)  # a refined lamp in the answer
    hanging = [lp for lp in lamps if not lp.profile.fixture.aimable]
    assert hanging, [lp.profile.fixture.name for lp in lamps]
    for lamp in hanging:
        np.testing.assert_allclose(lamp.direction, DOWN, atol=1e-12)
    for row in out.report["fixture_schedule"]:
        assert all(x["dimming"] <= 1.0 + 1e-9 for x in row["lights"])
