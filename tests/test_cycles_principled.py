"""Predictions against Cycles with the artist's materials and the written file's settings
(issue 9, part 4).

Unlike test_cycles_forward.py / test_cycles_closed_loop.py (which make every material Lambertian
and set the light paths themselves before baking), the scenes here keep default Principled BSDFs
(Base Color only changed: Roughness 0.5, IOR 1.5, Specular IOR Level 0.5) and Cycles bakes the
files exactly as Relight wrote them (``--out``: its light paths, materials untouched;
``cycles_reference.cycles_face_radiance(keep_materials=True, keep_light_paths=True)``; only
emission is made one-sided, as the radiosity model's).

Two predictions are compared per face (docs/validation.md, "Principled materials against Cycles"):
- ``radiance_normal``: what the report predicts a view along the face's normal shows (the bake's
  view): the radiosity's incident light through the material's BSDF (engine/view_radiance.py).
  The issue's tolerances: mean <= 2 %, max <= 5 %. Also asserted: Cycles' noise (mean over
  faces < 1.5 %) and that radiance_normal is closer to Cycles than radiosity/pi.
- ``radiosity / pi``: the Lambertian model's view-averaged radiance. Printed and recorded, not
  asserted: a glossy face does not show its average along its normal.

- Closed loop: a furnished room (4 x 3 x 2.5 m, 0.25 m grid faces, sofa, table, cabinet),
  targets on the floor, the table top and a wall; ``solve --out --patch-model polygon``
  (default estimator).
- Forward: a Cornell box (7 x 7 faces per wall) with default Principled materials,
  ``radiosity --out``; the issue asks for the mean only (mean <= 2 %).
The issue's tolerances are asserted. Measured (docs/validation.md): furnished room 1.65 % mean,
3.9 % max (signed -1.5 %; without engine/incidence.py's first reflection at the albedo of its
incidence 2.27 % / 4.9 % / -2.3 %), Cornell box 1.86 %.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="the Cycles reference needs bpy (Blender as a Python module)")

import cycles_reference as cr  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MEAN_TOL, MAX_TOL = 0.02, 0.05  # the tolerances on target faces
NOISE_TOL = 0.015  # Cycles' own noise on a face mean, averaged over the faces (measured 0.8-1.2 %), stays
# below the 2 % tolerance and well below the errors measured

ROOM = (4.0, 3.0, 2.5)
CELL = 0.25
COLOURS = {"Floor": (0.45, 0.32, 0.22), "Ceiling": (0.85, 0.85, 0.85), "WallS": (0.8, 0.78, 0.72),
           "WallN": (0.8, 0.78, 0.72), "WallW": (0.62, 0.36, 0.3), "WallE": (0.8, 0.78, 0.72),
           "Sofa": (0.2, 0.3, 0.5), "Table": (0.5, 0.36, 0.22), "Cabinet": (0.6, 0.6, 0.55)}
ROOM_SAMPLES, ROOM_RAYS = 1024, 8192  # Cycles' noise on a face mean ~1.1 % (2 % at 256 samples)
CORNELL_N, CORNELL_SAMPLES, CORNELL_RAYS = 7, 192, 16384


def _principled(name, colour):
    """A default Principled BSDF, Base Color only changed."""
    return cr._material(name, colour)


def _box(name, x0, y0, z0, sx, sy, sz, colour, cuts=0):
    """A closed box (6 outward faces), each face cut into (cuts + 1)^2 quads."""
    x1, y1, z1 = x0 + sx, y0 + sy, z0 + sz
    verts = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
             (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    ob = cr.add_mesh_object(name, verts, faces, _principled(name.lower(), colour))
    if cuts:
        cr.subdivide_quads(ob, cuts)
    ob["relight_no_lights"] = True
    return ob


def _paint(ob, polys, rgb):
    me = ob.data
    col = np.zeros((len(me.loops), 4), dtype=np.float32)  # unpainted: alpha 0 (a new layer is opaque black)
    layer = me.color_attributes.get("relight_target")
    if layer is None:
        layer = me.color_attributes.new("relight_target", "FLOAT_COLOR", "CORNER")
    else:
        layer.data.foreach_get("color", col.ravel())
    for p in polys:
        poly = me.polygons[p]
        col[poly.loop_start:poly.loop_start + poly.loop_total] = (*rgb, 1.0)
    layer.data.foreach_set("color", col.ravel())


def build_furnished_room(path: Path) -> None:
    """4 x 3 x 2.5 m room of 0.25 m grid faces (normals inward), a sofa, a table and a cabinet
    (relight_no_lights), the floor forbidden; targets on the floor in front of the sofa, on the
    table top and on the wall behind the sofa. Cycles is the render engine (defaults otherwise)."""
    cr.reset_blender()
    scene = bpy.context.scene
    scene.world = cr.black_world()
    scene.render.engine = "CYCLES"
    W, D, H = ROOM
    nx, ny, nz = round(W / CELL), round(D / CELL), round(H / CELL)
    walls = [("Floor", (0, 0, 0), (W, 0, 0), (0, D, 0), nx, ny), ("Ceiling", (0, 0, H), (0, D, 0), (W, 0, 0), ny, nx),
             ("WallS", (0, 0, 0), (0, 0, H), (W, 0, 0), nz, nx), ("WallN", (0, D, 0), (W, 0, 0), (0, 0, H), nx, nz),
             ("WallW", (0, 0, 0), (0, D, 0), (0, 0, H), ny, nz), ("WallE", (W, 0, 0), (0, 0, H), (0, D, 0), nz, ny)]
    obs = {}
    for name, o, du, dv, nu, nv in walls:
        v, f = cr.grid_quads(o, du, dv, nu, nv)
        obs[name] = cr.add_mesh_object(name, v, f, _principled(name.lower(), COLOURS[name]))
    _box("Sofa", 0.3, 0.6, 0.0, 0.9, 1.8, 0.45, COLOURS["Sofa"], cuts=1)  # against the west wall
    table = _box("Table", 1.7, 1.1, 0.0, 1.0, 0.75, 0.72, COLOURS["Table"], cuts=2)
    _box("Cabinet", 3.5, 2.5, 0.0, 0.5, 0.5, 1.8, COLOURS["Cabinet"], cuts=2)
    # targets: the floor between sofa and table, the table top, the west wall above the sofa
    floor = [j * nx + i for j in range(4, 9) for i in range(5, 7)]  # x 1.25-1.75, y 1.0-2.25
    _paint(obs["Floor"], floor, (0.12, 0.1, 0.08))
    top = [p.index for p in table.data.polygons if p.normal.z > 0.99]
    _paint(table, top, (0.2, 0.16, 0.12))
    wall = [k * ny + j for k in range(4, 6) for j in range(4, 8)]  # z 1.0-1.5, y 1.0-2.0
    _paint(obs["WallW"], wall, (0.25, 0.16, 0.14))
    me = obs["Floor"].data
    me.attributes.new("relight_forbidden", "BOOLEAN", "FACE").data.foreach_set(
        "value", np.ones(len(me.polygons), dtype=bool))
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    cr.reset_blender()


def _cli(*args):
    proc = subprocess.run([sys.executable, "-m", "relight_addon", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def _compare(report, cycles, faces_of):
    """Per compared face: relative errors (RGB-summed) of radiance_normal and of radiosity/pi
    against Cycles, its noise, and printable lines."""
    rows = {"normal": [], "average": [], "noise": []}
    lines = []
    for name, faces in faces_of.items():
        o = report["objects"][name]
        cyc = cycles[name]
        ref = cyc.radiance[faces]
        lum = ref.sum(axis=1)
        normal = np.array([o["radiance_normal"][f] for f in faces], dtype=float)
        avg = np.asarray(o["radiosity"], dtype=float)[faces] / np.pi
        for key, pred in (("normal", normal), ("average", avg)):
            rows[key].append((pred - ref).sum(axis=1) / lum)
        rows["noise"].append(cyc.std_error[faces].sum(axis=1) / lum)
        lines.append(f"{name}: {len(faces)} faces; radiance_normal signed mean {rows['normal'][-1].mean():+.4f} "
                     f"max |.| {np.abs(rows['normal'][-1]).max():.4f}; radiosity/pi signed mean "
                     f"{rows['average'][-1].mean():+.4f} max |.| {np.abs(rows['average'][-1]).max():.4f}")
    out = {k: np.concatenate(v) for k, v in rows.items()}
    n, a = out["normal"], out["average"]
    head = (f"{len(n)} faces: radiance_normal vs Cycles mean {np.abs(n).mean():.4f} max {np.abs(n).max():.4f} "
            f"signed {n.mean():+.4f}; radiosity/pi vs Cycles mean {np.abs(a).mean():.4f} max {np.abs(a).max():.4f} "
            f"signed {a.mean():+.4f}; Cycles noise mean {out['noise'].mean():.4f} max {out['noise'].max():.4f}")
    return out, head + "\n" + "\n".join(lines)


def _check(out, summary, max_tol=MAX_TOL):
    """The issue's tolerances on radiance_normal (``max_tol`` None: the mean only)."""
    print(summary)
    assert out["noise"].mean() < NOISE_TOL, summary
    n, a = np.abs(out["normal"]), np.abs(out["average"])
    # what the report predicts for the bake's view must beat the view-averaged radiance
    assert n.mean() < a.mean(), summary
    assert n.mean() <= MEAN_TOL, summary
    assert max_tol is None or n.max() <= max_tol, summary


@pytest.fixture(scope="module")
def furnished(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("furnished")
    scene, rep, out = tmp / "room.blend", tmp / "report.json", tmp / "room_lit.blend"
    build_furnished_room(scene)
    # the defaults: cells and spots (the answer has a spot): the first reflection of the cells' and of
    # the lamps' light at the albedo of its incidence (engine/incidence.py: first_bounce_matrices,
    # lamp_excess; without the lamps' term it was 2.10 % mean, signed -1.97 %)
    _cli("solve", scene, "--report", rep, "--out", out, "--rays-per-patch", ROOM_RAYS, "--seed", 1,
         "--patch-model", "polygon")
    report = json.loads(rep.read_text())
    faces_of = {name: [i for i, x in enumerate(o.get("radiance_normal") or []) if x is not None]
                for name, o in report["objects"].items()}
    faces_of = {k: v for k, v in faces_of.items() if v}
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        settings = {k: getattr(bpy.context.scene.cycles, k) for k in ("diffuse_bounces", "max_bounces",
                                                                     "sample_clamp_indirect", "blur_glossy")}
        cycles = cr.cycles_face_radiance(samples=ROOM_SAMPLES, seed=1, cell_px=12, keep_materials=True,
                                         keep_light_paths=True, objects=[bpy.data.objects[n] for n in faces_of])
    finally:
        cr.reset_blender()
    yield report, cycles, faces_of, settings


def test_furnished_room_settings_and_report(furnished):
    report, _, faces_of, settings = furnished
    rs = report["render_settings"]
    assert rs["scene"]["diffuse_bounces"] == 4 and not rs["matched"]  # the file had Blender's defaults
    assert rs["written"]["settings"]["diffuse_bounces"] == settings["diffuse_bounces"] >= rs["required_bounces"]
    assert settings["sample_clamp_indirect"] == 0 and settings["blur_glossy"] == 0
    assert rs["estimated_difference"]["mean"] < -0.01  # 4 bounces would render the targets darker
    assert report["final"]["n_negative"] == 0 and 1 <= report["final"]["n_lights"] <= 3
    assert set(faces_of) == {"Floor", "Table", "WallW"}


def test_furnished_room_closed_loop(furnished):
    report, cycles, faces_of, _ = furnished
    out, summary = _compare(report, cycles, faces_of)
    assert len(out["normal"]) == 10 + 9 + 8  # floor, table top (3 x 3), wall
    # per face within 6 % (issue 18's bound): Cycles' own noise reaches 3.1 % on a face here
    _check(out, summary, max_tol=0.06)


@pytest.fixture(scope="module")
def cornell(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cornell_principled")
    scene, rep, out = tmp / "cornell.blend", tmp / "report.json", tmp / "cornell_out.blend"
    cr.build_cornell_box(n=CORNELL_N)  # default Principled BSDFs (Base Color only changed)
    bpy.context.scene.render.engine = "CYCLES"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene))
    cr.reset_blender()
    _cli("radiosity", scene, "--report", rep, "--out", out, "--rays-per-patch", CORNELL_RAYS, "--seed", 1)
    report = json.loads(rep.read_text())
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        cycles = cr.cycles_face_radiance(samples=CORNELL_SAMPLES, seed=1, cell_px=12, keep_materials=True,
                                         keep_light_paths=True)
    finally:
        cr.reset_blender()
    yield report, cycles


def test_forward_cornell_principled(cornell):
    report, cycles = cornell
    faces_of = {}
    for name, cyc in cycles.items():
        lum = cyc.radiance.sum(axis=1)
        if name == "Ceiling":  # the light face is compared for the units only
            pass
        faces_of[name] = [int(f) for f in np.flatnonzero(lum > 0.02 * np.median(lum))]
    centre = (CORNELL_N // 2) * CORNELL_N + CORNELL_N // 2
    light = np.asarray(report["objects"]["Ceiling"]["radiosity"][centre]) / np.pi
    np.testing.assert_allclose(light, cycles["Ceiling"].radiance[centre], rtol=0.01)  # emission-dominated
    faces_of["Ceiling"] = [f for f in faces_of["Ceiling"] if f != centre]
    out, summary = _compare(report, cycles, faces_of)
    assert len(out["normal"]) >= 5 * CORNELL_N ** 2 - 10
    _check(out, summary, max_tol=None)  # the issue: mean <= 2 %


def test_glossy_plane_under_a_lamp(tmp_path):
    """Direct light only: a default Principled floor (7 x 7 faces of 10 cm, Roughness 0.5) under
    a small lamp 0.55 m above its centre. Along the normal the floor shows the lamp's highlight,
    which B/pi (the view average) misses by ~13 % under the lamp; radiance_normal gathers it
    through the GGX lobe: every face within 2 % of Cycles (measured 0.6 % at 65536 rays)."""
    cr.reset_blender()
    bpy.context.scene.world = cr.black_world()
    bpy.context.scene.render.engine = "CYCLES"
    v, f = cr.grid_quads((-0.35, -0.35, 0), (0.7, 0, 0), (0, 0.7, 0), 7, 7)
    cr.add_mesh_object("Floor", v, f, _principled("floor", (0.73, 0.71, 0.68)))
    v, f = cr.grid_quads((-0.04, -0.04, 0.55), (0, 0.08, 0), (0.08, 0, 0), 1, 1)
    cr.add_mesh_object("Lamp", v, f, cr._material("lamp", (0, 0, 0), (1, 1, 1), 10.0, lambertian=True))
    scene, rep, out = tmp_path / "plane.blend", tmp_path / "r.json", tmp_path / "out.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(scene))
    cr.reset_blender()
    _cli("radiosity", scene, "--report", rep, "--out", out, "--rays-per-patch", 65536, "--seed", 1,
         "--max-patch-size", 0.02)
    report = json.loads(rep.read_text())
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        cyc = cr.cycles_face_radiance(samples=64, seed=1, cell_px=12, keep_materials=True, keep_light_paths=True,
                                      objects=[bpy.data.objects["Floor"]])["Floor"]
    finally:
        cr.reset_blender()
    c = cyc.radiance.sum(axis=1)
    normal = np.asarray(report["objects"]["Floor"]["radiance_normal"]).sum(axis=1) / c - 1
    average = np.asarray(report["objects"]["Floor"]["radiosity"]).sum(axis=1) / np.pi / c - 1
    print(f"radiance_normal vs Cycles: mean {np.abs(normal).mean():.4f} max {np.abs(normal).max():.4f}; "
          f"radiosity/pi: under the lamp {average[24]:+.4f}, mean {np.abs(average).mean():.4f}; "
          f"noise {cyc.rel_noise.mean():.4f}")
    assert cyc.rel_noise.mean() < 0.005
    assert average[24] < -0.08  # the highlight the view average misses
    assert np.abs(normal).max() <= 0.02
