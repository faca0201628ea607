"""Closed loop: solve -> Cycles (issue 3, "against something we did not write").

A closed room built here in bpy (no emitter of its own) gets painted targets on the floor
and a wall; ``python -m relight_addon solve ... --out OUT.blend`` (the real command line)
chooses the lights and writes them into OUT.blend as Relight's emitters object (the light
cells' triangles in front of the walls, one material: the cell's reflectance + Emission of
Attribute ``relight_emission`` x (1 - Backfacing)). Cycles then bakes OUT.blend with that as
the only light, and the target faces must show the radiosity the report predicts
(``objects.<name>.radiosity``, W/m^2 = pi x Cycles' outgoing radiance) within 5 %, each face
and on average. The emitting cells themselves must bake to their predicted radiosity / pi.
Both patch models: whole-polygon lights, and the adaptive model's sub-polygon light cells.

How close the prediction is to the painted target is the reduction's error, not a rendering
check: it is printed and recorded in docs/validation.md, "Closed loop: solve -> Cycles".
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="the Cycles reference needs bpy (Blender as a Python module)")

import cycles_reference as cr  # noqa: E402  (tests/ is on sys.path: pytest's rootdir-relative import)


# Settings and tolerances (measurements: docs/validation.md, "Closed loop: solve -> Cycles").
RAYS_PER_PATCH = 8192  # engine side (x 4 patches per polygon: the same rays as 32768 per polygon)
# The default meshing (scene diagonal / 20 = 0.16 m) splits every 0.25 m polygon into 2 x 2
# patches; a light is a whole polygon (all its patches share one exitance), as --out shows it.
# (Before lights were grouped per polygon, the reduction lit single patches and --out spread
# their power over the polygon: up to 7.6 % off, docs/validation.md.)
MAX_PATCH_SIZE = None
CYCLES_SAMPLES = {"polygon": 512, "adaptive": 1024}  # smaller lights: noisier in Cycles
CELL_PX = 12  # 10 x 10 texels per face
TOL = 0.05  # the issue: every target face within 5 % of the prediction
MEAN_TOL = 0.02  # mean over target faces (measured ~1 %): catches a systematic error
# Cycles' own noise (standard error of a face mean) must stay below the tolerance tested. Measured at
# 512 samples: 0.4 % to 2.1 % mean depending on the lights the solve picks (small lights in the
# ceiling's corners are the noisiest for Cycles' light sampling); 4x the samples halves it.
NOISE_TOL = 0.03

# Room (metres): x, y in [0, W], z in [0, H]; every wall an N x N grid of quads, normals inward.
W, H, N = 2.0, 1.5, 8
COLOURS = {"Floor": (0.55, 0.5, 0.45), "Ceiling": (0.8, 0.8, 0.8), "WallS": (0.7, 0.7, 0.7),
           "WallN": (0.7, 0.7, 0.7), "WallW": (0.75, 0.35, 0.25), "WallE": (0.3, 0.55, 0.7),
           "Block": (0.6, 0.6, 0.6)}
# Painted targets: radiance (= target radiosity / pi) per polygon index j * N + i (i along du).
FLOOR_TARGETS = ({j * N + i: (0.30, 0.28, 0.25) for j in range(3) for i in range(3)}  # corner x, y < 0.75
                 | {j * N + 3: (0.25, 0.24, 0.22) for j in range(3)})
WALLS_TARGETS = {3 * N + 2: (0.2, 0.1, 0.07), 3 * N + 3: (0.2, 0.1, 0.07)}  # WallW (red), mid-height


def build_room(path: Path) -> None:
    """Write the test room to ``path``: 6 walls (N x N quads each, Principled with Specular IOR
    Level 0 -- Lambert, as the bake below makes every material -- plain base colours, no emission), a 0.5 m block on the floor, targets painted in the
    ``relight_target`` corner layer, floor and block forbidden as light positions."""
    cr.reset_blender()
    bpy.context.scene.world = cr.black_world()
    walls = [  # name, origin, du, dv with du x dv pointing into the room
        ("Floor", (0, 0, 0), (W, 0, 0), (0, W, 0)),
        ("Ceiling", (0, 0, H), (0, W, 0), (W, 0, 0)),
        ("WallS", (0, 0, 0), (0, 0, H), (W, 0, 0)),
        ("WallN", (0, W, 0), (W, 0, 0), (0, 0, H)),
        ("WallW", (0, 0, 0), (0, W, 0), (0, 0, H)),
        ("WallE", (W, 0, 0), (0, 0, H), (0, W, 0)),
    ]
    objs = {}
    for name, o, du, dv in walls:
        v, f = cr.grid_quads(o, du, dv, N, N)
        objs[name] = cr.add_mesh_object(name, v, f, cr._material(name.lower(), COLOURS[name], lambertian=True))
    x0, y0, s = 1.1, 1.1, 0.5  # block away from the targets (floor's x, y < 1.5 corner)
    verts = [(x0, y0, 0), (x0 + s, y0, 0), (x0 + s, y0 + s, 0), (x0, y0 + s, 0),
             (x0, y0, s), (x0 + s, y0, s), (x0 + s, y0 + s, s), (x0, y0 + s, s)]
    faces = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]  # outward
    objs["Block"] = cr.add_mesh_object("Block", verts, faces, cr._material("block", COLOURS["Block"], lambertian=True))
    objs["Block"]["relight_no_lights"] = True
    for name, targets in (("Floor", FLOOR_TARGETS), ("WallW", WALLS_TARGETS)):
        me = objs[name].data
        layer = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
        col = np.zeros((len(me.loops), 4), dtype=np.float32)
        for p, rgb in targets.items():
            poly = me.polygons[p]
            col[poly.loop_start:poly.loop_start + poly.loop_total] = (*rgb, 1.0)
        layer.data.foreach_set("color", col.ravel())
    me = objs["Floor"].data
    forb = me.attributes.new("relight_forbidden", "BOOLEAN", "FACE")
    forb.data.foreach_set("value", np.ones(len(me.polygons), dtype=bool))
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    cr.reset_blender()


def run_solve(scene: Path, report: Path, out: Path, patch_model: str) -> dict:
    args = ["--rays-per-patch", RAYS_PER_PATCH, "--seed", 1, "--patch-model", patch_model]
    return cr.solve_cli(scene, report, out, *args, *([] if MAX_PATCH_SIZE is None else
                                                      ["--max-patch-size", MAX_PATCH_SIZE]))


def emissive_materials() -> list[str]:
    """Names of materials in the open file that can emit (non-zero Principled/Emission
    strength, or a linked strength)."""
    names = []
    for mat in bpy.data.materials:
        if mat.node_tree is None or mat.users == 0:
            continue
        for node in mat.node_tree.nodes:
            sock = {"BSDF_PRINCIPLED": "Emission Strength", "EMISSION": "Strength"}.get(node.type)
            if sock and (node.inputs[sock].is_linked or node.inputs[sock].default_value != 0.0):
                names.append(mat.name)
                break
    return names


@pytest.fixture(scope="module", params=["polygon", "adaptive"])
def closed_loop(request, tmp_path_factory):
    """polygon: a light is a whole 0.25 m polygon. adaptive: the default patch size (0.16 m)
    cuts the walls into light cells smaller than the artist's polygons, shown by the emitters
    object without touching the artist's faces."""
    tmp = tmp_path_factory.mktemp(f"closed_loop_{request.param}")
    scene, report_path, out = tmp / "room.blend", tmp / "report.json", tmp / "room_lit.blend"
    build_room(scene)
    report = run_solve(scene, report_path, out, request.param)
    try:  # the bake changes the open file (UVs, materials); OUT.blend on disk is never saved
        bpy.ops.wm.open_mainfile(filepath=str(out))
        emitters = emissive_materials()
        emitter_obj = next(o for o in bpy.context.scene.objects if o.get("relight_owner"))
        me = emitter_obj.data
        emission = np.zeros(4 * len(me.polygons), dtype=np.float32)
        me.attributes["relight_emission"].data.foreach_get("color", emission)
        predicted = np.zeros(4 * len(me.loops), dtype=np.float32)  # the cells' radiosity / pi, per corner
        me.color_attributes["relight_radiosity"].data.foreach_get("color", predicted)
        cell = np.zeros(len(me.polygons), dtype=np.int32)
        me.attributes["relight_cell"].data.foreach_get("value", cell)
        area = np.zeros(len(me.polygons))
        me.polygons.foreach_get("area", area)
        cells = {"name": emitter_obj.name, "emission": emission.reshape(-1, 4)[:, :3], "cell": cell, "area": area,
                 "predicted": predicted.reshape(-1, 3, 4)[:, 0, :3],
                 "owned": {m.name for m in bpy.data.materials if m.get("relight_owner")}}
        names = sorted({n for n, o in report["objects"].items() if any(t is not None for t in o["target"] or [])})
        cycles = cr.cycles_face_radiance(samples=CYCLES_SAMPLES[request.param], seed=1, cell_px=CELL_PX,
                                         objects=[bpy.data.objects[n] for n in names] + [emitter_obj])
    finally:
        cr.reset_blender()
    yield report, cycles, emitters, cells


def test_only_relight_lights(closed_loop):
    """The light in OUT.blend is exactly Relight's emitters object (its one material)."""
    report, cycles, emitters, cells = closed_loop
    lights = report["final"]["lights"]
    assert 1 <= len(lights) <= 3 and report["final"]["n_negative"] == 0, report["final"]
    assert cells["owned"] and set(emitters) == cells["owned"], (emitters, cells["owned"])
    if report["options"]["patch_model"] == "adaptive":  # lights smaller than the artist's polygons
        assert min(li["area"] for li in lights) < 0.25 ** 2


def test_light_faces_emit_reported_exitance(closed_loop):
    """Each emitting cell bakes to its exitance / pi (+ the light it reflects): its predicted
    radiosity / pi, stored on the emitters object, within TOL. The emission is exact; the reflected
    part is a patch-constant average, which at a concave corner (a light cell next to a wall it
    lights) misses part of the adjacent wall's brightest strip (measured: 2.9 % of the total on a
    corner cell, the reflected part 50 % higher in Cycles)."""
    report, cycles, _, cells = closed_loop
    got = cycles[cells["name"]].radiance  # per triangle of the emitters object
    assert np.all(got >= cells["emission"] * 0.999), (got, cells["emission"])
    # per cell (the radiosity element): the area-weighted mean of its triangles
    _, c = np.unique(cells["cell"], return_inverse=True)
    w = cells["area"][:, None]
    mean = np.stack([np.bincount(c, weights=(got * w)[:, k]) for k in range(3)], axis=1) / np.bincount(c, weights=cells["area"])[:, None]
    first = np.unique(c, return_index=True)[1]
    pred, emit = cells["predicted"][first], cells["emission"][first]
    rel = np.abs(mean - pred).sum(axis=1) / pred.sum(axis=1)
    assert np.all(rel <= TOL), (rel, mean, pred, emit)


def test_targets_show_predicted_radiosity(closed_loop):
    """Cycles' radiosity (pi x baked radiance) of every target face vs the report's prediction."""
    report, cycles, _, _ = closed_loop
    err, signed, noise, vs_target, lines = [], [], [], [], []
    for name, o in report["objects"].items():
        tgt = np.array([[np.nan] * 3 if t is None else t for t in o["target"] or []], dtype=float)
        if not np.isfinite(tgt).any():
            continue
        faces = np.flatnonzero(np.all(np.isfinite(tgt), axis=1))
        pred = np.asarray(o["radiosity"], dtype=float)[faces]
        cyc = np.pi * cycles[name].radiance[faces]
        assert np.all(np.isfinite(pred)) and np.all(pred.sum(axis=1) > 0), name
        e = np.abs(pred - cyc).sum(axis=1) / cyc.sum(axis=1)
        err.append(e)
        signed.append((pred - cyc).sum(axis=1) / cyc.sum(axis=1))
        noise.append(cycles[name].std_error[faces].sum(axis=1) / cycles[name].radiance[faces].sum(axis=1))
        vs_target.append(np.abs(pred - tgt[faces]).sum(axis=1) / tgt[faces].sum(axis=1))
        for k, f in enumerate(faces):
            lines.append(f"{name}[{f}]: predicted {np.round(pred[k], 4)} Cycles {np.round(cyc[k], 4)} "
                         f"target {np.round(tgt[f], 4)} error {e[k]:.4f} noise {noise[-1][k]:.4f}")
    err, signed, noise, vs_target = map(np.concatenate, (err, signed, noise, vs_target))
    summary = (f"{len(err)} target faces, {report['final']['n_lights']} lights: prediction vs Cycles "
               f"mean {err.mean():.4f} max {err.max():.4f} signed {signed.mean():+.4f}; Cycles noise "
               f"mean {noise.mean():.4f} max {noise.max():.4f}; prediction vs painted target mean "
               f"{vs_target.mean():.4f} max {vs_target.max():.4f}\n" + "\n".join(lines))
    print(summary)
    assert len(err) == len(FLOOR_TARGETS) + len(WALLS_TARGETS), summary
    assert noise.max() < NOISE_TOL and noise.mean() < MEAN_TOL, summary  # a reference sharper than TOL
    assert err.mean() <= MEAN_TOL and abs(signed.mean()) <= MEAN_TOL, summary
    assert np.all(err <= TOL), summary
