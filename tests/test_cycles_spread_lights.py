"""A light of many patches, rendered by Cycles as Relight predicts it (issue 20's spread-light rule).

A light of cost.DIRECT_SPREAD_PATCHES patches or more keeps the ray-cast form factors' gather of
its direct light: the kernel's correction (pipeline.stages.direct_stage) is skipped for it, measured on the
living room to change such a light's direct light by 1.6-2.3 % (tests/test_engine_kernel_transfer.py
checks the rule on a room's ceiling cells). Here a Cycles bake holds the prediction of a
configuration that has such a light against what Cycles renders: a room drawn as artists draw it
(walls and ceiling one big face each, a floor grid), the whole floor painted one colour, solved by
the command line with the adaptive patch model (its answer: the whole ceiling, 9 m^2, and two whole
walls, 7.2 m^2 each, three lights of 81-100 patches), written with --out and baked: every floor
face within 5 % of the report's radiosity, their mean within 2 % (measured: 0.13 % mean, 0.6 % at
most, Cycles' noise 0.2 %).
"""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="the Cycles reference needs bpy (Blender as a Python module)")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402

W, D, H, N = 3.0, 3.0, 2.4, 6  # the room (m); the floor an N x N grid
TARGET = (0.3, 0.28, 0.25)  # radiance of the painted floor (W/m^2/sr)
RAYS_PER_PATCH = 8192
SAMPLES, CELL_PX = 512, 12
TOL, MEAN_TOL, NOISE_TOL = 0.05, 0.02, 0.03  # as the closed loop's (tests/test_cycles_closed_loop.py)


def build_room() -> None:
    bpy.context.scene.world = cr.black_world()
    v = [(0, 0, 0), (W, 0, 0), (W, D, 0), (0, D, 0), (0, 0, H), (W, 0, H), (W, D, H), (0, D, H)]
    f = [(7, 6, 5, 4), (4, 5, 1, 0), (5, 6, 2, 1), (6, 7, 3, 2), (7, 4, 0, 3)]  # ceiling and walls, inward
    cr.add_mesh_object("Room", v, f, cr._material("walls", (0.7, 0.7, 0.7), lambertian=True))
    gv, gf = cr.grid_quads((0, 0, 0), (W, 0, 0), (0, D, 0), N, N)
    floor = cr.add_mesh_object("Floor", gv, gf, cr._material("floor", (0.5, 0.45, 0.4), lambertian=True))
    every = range(len(floor.data.polygons))
    artist_scenes.paint(floor, every, TARGET)
    artist_scenes.forbid(floor, every)


@pytest.fixture(scope="module")
def spread(tmp_path_factory):
    report, out = cr.built_and_solved(tmp_path_factory, "spread_lights", build_room, "--rays-per-patch",
                                      RAYS_PER_PATCH, "--seed", 1, "--patch-model", "adaptive")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        cycles = cr.cycles_face_radiance(samples=SAMPLES, seed=1, cell_px=CELL_PX, objects=[bpy.data.objects["Floor"]])
    finally:
        cr.reset_blender()
    yield report, cycles


def test_a_light_of_many_patches_renders_as_predicted(spread):
    report, cycles = spread
    kinds = [lt["kind"] for lt in report["final"]["lights"]]
    # the configuration holds a light the rule applies to (the ceiling, one light), and the rule was applied
    assert "polygon" in kinds and report["model"]["direct_light"]["spread_lights"] >= 1, (kinds, report["model"])
    pred = np.asarray(report["objects"]["Floor"]["radiosity"], dtype=float)
    cyc = np.pi * cycles["Floor"].radiance
    noise = cycles["Floor"].std_error.sum(axis=1) / cycles["Floor"].radiance.sum(axis=1)
    err = np.abs(pred - cyc).sum(axis=1) / cyc.sum(axis=1)
    signed = (pred - cyc).sum(axis=1) / cyc.sum(axis=1)
    summary = (f"{len(err)} floor faces, lights {kinds}: prediction vs Cycles mean {err.mean():.4f} max "
               f"{err.max():.4f} signed {signed.mean():+.4f}; Cycles noise mean {noise.mean():.4f} max "
               f"{noise.max():.4f}; relative error to the paint {report['final']['relative_error']:.4f}")
    print(summary)
    assert len(err) == N * N and np.all(np.isfinite(pred)), summary
    assert noise.max() < NOISE_TOL and noise.mean() < MEAN_TOL, summary  # a reference sharper than TOL
    assert err.mean() <= MEAN_TOL and abs(signed.mean()) <= MEAN_TOL, summary
    assert np.all(err <= TOL), summary
