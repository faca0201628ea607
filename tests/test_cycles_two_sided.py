"""Faces seen from their back, rendered by Cycles as Relight predicts them.

Cycles shades both sides of a mesh face alike; Relight's faces are one-sided, so the export
models the side the scene sees (engine/two_sided.faces_seen_from_behind): a room made as many artists
first make it, the default cube scaled up with its normals as added (facing out: the scene sees
the walls' backs), is modelled from the inside; a shelf that is a single plane, lit from above
and seen from below, gets its back side as a face of its own. The floor painted, solved by the
command line, written with --out and baked: every face of the room (but those holding a light), the
shelf and a box on the floor under the shelf within 5 % of the report's radiosity, their mean within 2 % (as the closed loop's,
tests/test_cycles_closed_loop.py). Before, the room's walls were black to Relight: Cycles
rendered the floor 2.3 x brighter than predicted.
"""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="the Cycles reference needs bpy (Blender as a Python module)")

import artist_scenes  # noqa: E402
import bmesh  # noqa: E402
import cycles_reference as cr  # noqa: E402

TARGET = (0.3, 0.28, 0.25)  # radiance painted on the floor (W/m^2/sr)
RAYS_PER_PATCH = 8192
SAMPLES, CELL_PX = 1024, 24
TOL, MEAN_TOL, NOISE_TOL = 0.05, 0.02, 0.03  # as the closed loop's


def build() -> None:
    bpy.context.scene.world = cr.black_world()
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(0.0, 0.0, 1.25))  # normals out, as added
    room = bpy.context.active_object
    room.name = "Room"
    room.scale = (2.0, 1.5, 1.25)  # 4 x 3 x 2.5 m, the scale not applied
    room.data.materials.append(cr._material("walls", (0.75, 0.72, 0.68), lambertian=True))
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(-0.6, -0.3, 0.9))  # a shelf: one plane
    shelf = bpy.context.active_object
    shelf.name = "Shelf"
    shelf.scale = (1.6, 1.0, 1.0)
    shelf.data.materials.append(cr._material("shelf", (0.8, 0.8, 0.8), lambertian=True))
    bpy.ops.mesh.primitive_cube_add(size=0.6, location=(-0.6, -0.3, 0.3))  # a closed box, under the shelf
    box = bpy.context.active_object
    box.name = "Box"
    box.data.materials.append(cr._material("box", (0.5, 0.3, 0.2), lambertian=True))
    for ob in (shelf, box):
        ob["relight_no_lights"] = True
    floor = [p.index for p in room.data.polygons if p.normal.z < -0.5]  # its normal points down, out of the room
    artist_scenes.paint(room, floor, TARGET)
    artist_scenes.forbid(room, floor)


@pytest.fixture(scope="module")
def two_sided(tmp_path_factory):
    report, out = cr.built_and_solved(tmp_path_factory, "two_sided", build, "--rays-per-patch", RAYS_PER_PATCH,
                                      "--seed", 1)
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        obs = [bpy.data.objects[n] for n in ("Room", "Shelf", "Box")]
        # a bake measures the side a face's normal points to: the room's inside (this copy only)
        room = obs[0].data
        bm = bmesh.new()
        bm.from_mesh(room)
        bmesh.ops.reverse_faces(bm, faces=list(bm.faces))
        bm.to_mesh(room)
        bm.free()
        cycles = cr.cycles_face_radiance(samples=SAMPLES, seed=1, cell_px=CELL_PX, objects=obs)
    finally:
        cr.reset_blender()
    yield report, cycles


def test_faces_seen_from_their_back_render_as_predicted(two_sided):
    report, cycles = two_sided
    rows = []
    floor = np.pi * sum(TARGET)  # (the floor's painted radiosity)
    # (the faces that hold a light emit through Relight's emitters in front of them: not compared)
    for name in ("Room", "Shelf", "Box"):
        pred = np.asarray(report["objects"][name]["radiosity"], dtype=float).sum(axis=1)
        cyc = np.pi * cycles[name].radiance.sum(axis=1)
        # relative to the face's own radiosity; a face in the dark (the box's bottom, on the floor)
        # to a tenth of the floor's
        scale = np.maximum(cyc, 0.1 * floor)
        noise = np.pi * cycles[name].std_error.sum(axis=1) / scale
        lit = {i for lt in report["final"]["lights"] if lt.get("object") == name for i in lt.get("polygons") or []}
        rows += [(name, i, e, n) for i, (e, n) in enumerate(zip((pred - cyc) / scale, noise)) if i not in lit]
    err = np.array([r[2] for r in rows])
    noise = np.array([r[3] for r in rows])
    lights = [(lt["kind"], lt.get("object"), lt.get("polygons")) for lt in report["final"]["lights"]]
    summary = (f"{len(rows)} faces: prediction vs Cycles, signed {', '.join(f'{n}[{i}] {e:+.3f}' for n, i, e, _ in rows)};"
               f" Cycles noise max {noise.max():.4f}; lights {lights}; warnings {report['warnings']}")
    print(summary)
    assert any("from their other side" in w for w in report["warnings"]), summary  # said, naming the room
    assert noise.max() < NOISE_TOL, summary
    assert np.abs(err).mean() <= MEAN_TOL and np.all(np.abs(err) <= TOL), summary
