"""Render settings (issue 9, part 3): the bounces Cycles needs, what fewer cost, and the settings
written by --out and by "Match Cycles Light Paths".

References: the Neumann series of a closed scene of uniform reflectance and emission (any
row-stochastic F: B_n = e sum_{k<=n} rho^k), and Cycles itself (a closed emitting box baked
with bounce limits 1 and 2 shows exactly the terms the engine keeps for them)."""
import json
import os

import numpy as np
import pytest

from conftest import SAMPLES
from relight_addon.engine import bounces


def test_required_bounces_leave_less_than_the_tail():
    for rho in (0.3, 0.5, 0.7, 0.8, 0.9, 0.99):
        d = bounces.required_bounces(rho)
        assert rho ** (d + 2) <= bounces.TAIL < rho ** (d + 1) or d == 1, (rho, d)
    assert bounces.required_bounces(0.0) == 1 and bounces.required_bounces(1.0) == bounces.MAX_BOUNCES


def test_truncated_radiosity_is_the_neumann_series():
    rng = np.random.default_rng(3)
    P, rho = 40, 0.7
    F = rng.random((P, P))
    np.fill_diagonal(F, 0)
    F /= F.sum(axis=1, keepdims=True)  # closed: every row sums to 1
    e = np.ones((P, 3))
    R = np.full((P, 3), rho)
    B = np.stack([np.linalg.solve(np.eye(P) - rho * F, e[:, c]) for c in range(3)], axis=1)
    for n in (0, 1, 4, 20):
        np.testing.assert_allclose(bounces.truncated_radiosity(F, R, B, n), (1 - rho ** (n + 1)) / (1 - rho), rtol=1e-10)
    d = bounces.bounce_deficit(F, R, B, 5, mask=np.arange(P) < 10)
    assert d["mean"] == pytest.approx(-rho ** 6) and d["min"] == pytest.approx(-rho ** 6)


def test_cycles_bounce_limit_keeps_limit_plus_one_reflections(bpy_clean):
    """A closed cube (Lambert, reflectance 0.7, every face emitting radiance 1) baked by Cycles
    with Diffuse = Total bounces = D shows 1 + rho + ... + rho^(D+1): kept_terms(D) = D + 1."""
    import cycles_reference as cr  # a test module of this suite: an import error must fail, not skip
    bpy = bpy_clean
    rho = 0.7
    walls = [((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((0, 0, 1), (0, 1, 0), (1, 0, 0)), ((0, 0, 0), (0, 0, 1), (1, 0, 0)),
             ((0, 1, 0), (1, 0, 0), (0, 0, 1)), ((0, 0, 0), (0, 1, 0), (0, 0, 1)), ((1, 0, 0), (0, 0, 1), (0, 1, 0))]
    for D in (1, 2):
        cr.reset_blender()
        bpy.context.scene.world = cr.black_world("W")
        mat = cr._material("box", (rho,) * 3, (1, 1, 1), 1.0)
        mat.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
        verts, faces = [], []
        for o, du, dv in walls:
            v, f = cr.grid_quads(o, du, dv, 1, 1)
            faces += [tuple(i + len(verts) for i in q) for q in f]
            verts += v
        ob = cr.add_mesh_object("cube", verts, faces, mat)
        c = bpy.context.scene.cycles
        c.diffuse_bounces = c.max_bounces = D
        c.sample_clamp_indirect = 0.0
        got = cr.cycles_face_radiance(samples=16, seed=1, cell_px=12, objects=[ob], keep_light_paths=True)["cube"]
        n = bounces.kept_terms(D)
        want = (1 - rho ** (n + 1)) / (1 - rho)
        other = (1 - rho ** n) / (1 - rho)  # one reflection fewer
        assert np.all(np.abs(got.radiance - want) < 0.25 * (want - other)), (D, got.radiance.mean(), want)


def test_solve_reports_and_out_writes_light_paths(run_cli, tmp_path):
    import bpy

    scene = os.path.join(SAMPLES, "staircase_targets.blend")
    out = tmp_path / "out.blend"
    code, r, err = run_cli(["solve", scene, "--report", tmp_path / "r.json", "--out", out,
                            "--rays-per-patch", "2048"])
    assert code == 0, err
    rs = r["render_settings"]
    # the sample keeps Blender's defaults: 4 diffuse bounces, indirect clamp 10
    assert rs["scene"]["diffuse_bounces"] == 4 and rs["scene"]["sample_clamp_indirect"] == 10
    assert not rs["matched"]
    need = bounces.required_bounces(rs["max_reflectance"])
    assert rs["required_bounces"] == need and rs["max_reflectance"] == pytest.approx(0.7, abs=1e-6)
    d = rs["estimated_difference"]
    assert d["reflections"] == 5 and d["bounce_limit"] == 4 and -0.2 < d["mean"] < -0.01 and d["min"] <= d["mean"]
    assert any("darker than predicted" in w and "estimated" in w for w in r["warnings"])
    assert any("clamping at 10" in w and "not estimated" in w for w in r["warnings"])
    written = rs["written"]["settings"]
    bpy.ops.wm.open_mainfile(filepath=str(out))
    c = bpy.context.scene.cycles
    assert c.sample_clamp_indirect == 0 and c.sample_clamp_direct == 0 and c.caustics_reflective and c.blur_glossy == 0
    assert c.diffuse_bounces == c.glossy_bounces == c.max_bounces == need == written["diffuse_bounces"]
    assert set(rs["written"]["changed"]) == {"sample_clamp_indirect", "diffuse_bounces", "glossy_bounces",
                                             "max_bounces", "blur_glossy"}
    assert rs["filter_glossy"] is None  # the sample's materials have no specular layer: no warning


def test_match_light_paths_operator(bpy_clean):
    import relight_addon
    from relight_addon.blender import light_paths

    bpy = bpy_clean
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    relight_addon.register()
    try:
        rho = light_paths.scene_max_reflectance()
        assert rho == pytest.approx(0.7, abs=1e-6)  # the sample's materials: Lambert (Specular IOR Level 0)
        assert bpy.ops.relight.match_light_paths() == {"FINISHED"}
        c = bpy.context.scene.cycles
        n = bounces.required_bounces(rho)
        assert (c.diffuse_bounces, c.glossy_bounces, c.max_bounces) == (n, n, n)
        assert c.sample_clamp_indirect == 0 and c.sample_clamp_direct == 0 and c.blur_glossy == 0
        c.max_bounces = 100  # higher limits are kept
        assert light_paths.match_light_paths(bpy.context.scene, rho) == {}
        assert c.max_bounces == 100
    finally:
        relight_addon.unregister()
