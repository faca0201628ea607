"""`reduce` on a room lit by 30 Point lamps, against Cycles (issue 16, build item 3).

A closed room (Lambertian walls, a table casting shadows) lit only by a 6 x 5 grid of Point
lamps under its ceiling, of three powers. `reduce --out` reduces the lamps to a few (the
paper's direct-lighting mode: every face a target at the radiosity the 30 lamps give it) and
writes a copy whose kept lamps have their new Power and whose other lamps are disabled. Cycles
then bakes every face of the written file with its own settings; the report's radiosity / pi
must match the bake. A second configuration of the stored curve, applied to the written file as
the add-on applies a row of its list, is baked and compared too; Clear Results gives every lamp
back as the user set it.

Reference: Cycles' COMBINED bake (tests/cycles_reference.py), an independent path tracer.
"""
import math

import numpy as np
import pytest

pytestmark = pytest.mark.cycles  # (a Cycles closed loop: make test-all, not make test)

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is needed to bake with Cycles")

import cycles_reference as cr  # noqa: E402
import relight_scene  # noqa: E402

W, D, H = 4.0, 3.0, 2.5
GRID = (6, 5)  # lamps along x and y
POWERS = (15.0, 40.0, 90.0)  # W, a few distinct powers so that the reduction has a choice
SAMPLES = 128
THREADS = 2


def lamp_power(i, j):
    """The power (W) of grid lamp (i, j): brighter towards one corner, with a ripple."""
    return POWERS[(i + 2 * j) % 3] if (i + j) % 4 else POWERS[2]


def build_room(path):
    """The room (inward-facing walls, 4 x 4 quads each; a table top of 1 x 0.8 m at 0.7 m, 5 cm
    thick, its sides open) and the 30 Point lamps (radius 5 cm) 0.3 m under the ceiling; saved
    to ``path``."""
    cr.reset_blender()
    bpy.context.scene.world = None  # no World light: only the lamps
    walls = cr._material("walls", (0.6, 0.6, 0.6), lambertian=True)
    floor_m = cr._material("floor", (0.45, 0.45, 0.45), lambertian=True)
    table_m = cr._material("table", (0.3, 0.3, 0.3), lambertian=True)
    n = 4
    quads = [
        ("floor", (0, 0, 0), (W, 0, 0), (0, D, 0), floor_m, n),
        ("ceiling", (0, D, H), (W, 0, 0), (0, -D, 0), walls, n),
        ("wall_s", (0, 0, 0), (0, 0, H), (W, 0, 0), walls, n),
        ("wall_n", (0, D, 0), (W, 0, 0), (0, 0, H), walls, n),
        ("wall_w", (0, 0, 0), (0, D, 0), (0, 0, H), walls, n),
        ("wall_e", (W, 0, 0), (0, 0, H), (0, D, 0), walls, n),
        ("table", (1.2, 1.0, 0.75), (1.0, 0, 0), (0, 0.8, 0), table_m, 2),  # its top, facing up
        ("table_under", (1.2, 1.0, 0.7), (0, 0.8, 0), (1.0, 0, 0), table_m, 2),  # its underside
    ]
    for name, o, du, dv, m, k in quads:
        v, f = cr.grid_quads(o, du, dv, k, k)
        cr.add_mesh_object(name, v, f, m)
    nx, ny = GRID
    for j in range(ny):
        for i in range(nx):
            ld = bpy.data.lights.new(f"lamp_{i}_{j}", "POINT")
            ld.energy = lamp_power(i, j)
            ld.shadow_soft_size = 0.05
            ob = bpy.data.objects.new(ld.name, ld)
            bpy.context.scene.collection.objects.link(ob)
            ob.location = (W * (i + 0.5) / nx, D * (j + 0.5) / ny, H - 0.3)
    bpy.context.scene["relight_max_patch_size"] = 0.5
    bpy.ops.wm.save_as_mainfile(filepath=str(path))


def _against_cycles(predicted, baked, what):
    """Per face (every baked object), the predicted radiosity / pi against Cycles' radiance,
    channels summed: (relative errors, signed errors, a summary printed and returned)."""
    rel, signed, lines = [], [], []
    for name, cyc in baked.items():
        ours = np.asarray(predicted[name], dtype=np.float64) / math.pi
        lum = cyc.radiance.sum(axis=1)
        s = (ours.sum(axis=1) - lum) / lum
        rel.append(np.abs(s))
        signed.append(s)
        lines.append(f"  {name}: mean {rel[-1].mean():.4f} max {rel[-1].max():.4f} signed {s.mean():+.4f} "
                     f"(Cycles noise {np.mean(cyc.rel_noise):.4f})")
    rel, signed = np.concatenate(rel), np.concatenate(signed)
    summary = f"{what}: {len(rel)} faces, mean {rel.mean():.4f} max {rel.max():.4f} signed {signed.mean():+.4f}\n" + \
        "\n".join(lines)
    print(summary)
    return rel, signed, summary


@pytest.mark.parametrize("selection", ["greedy-swap", "exitance-elimination"])
def test_reduce_thirty_point_lamps_rendered_by_cycles_as_predicted(tmp_path, selection):
    """The final configuration (written by --out) and a second one of the curve (applied to the
    written file as the add-on applies a row) against Cycles bakes of the file, every face;
    the report's lamps as the file has them; Clear Results gives every lamp back."""
    from relight_addon.blender import results

    extra = ["--distribution", "distance"] if selection == "exitance-elimination" else []
    report, out, original = relight_scene.reduce_built(build_room, tmp_path, "--selection", selection, *extra,
                                                       "--quiet")
    nx, ny = GRID
    assert report["model"]["lights_by_kind"]["lamp"] == nx * ny >= 30
    every = [c for c in report["curve"] if c["n_lights"] == 30]  # e_x: the scene's own lamps, exact
    assert every and min(c["relative_error"] for c in every) < 1e-9
    fin = report["final"]
    assert fin["n_lights"] == 3 and fin["n_negative"] == 0
    lamps = {r["name"]: r for r in report["lamps"]}
    assert len(lamps) == 30 and sum(r["kept"] for r in lamps.values()) == 3
    for name, r in lamps.items():  # power before = the lamp as set; a white lamp stays white
        i, j = map(int, name.split("_")[1:])
        assert r["energy_before"] == pytest.approx(lamp_power(i, j)) and r["color_after"] == [1.0, 1.0, 1.0]
    # the written copy: the kept lamps at their new Power, the others disabled, every one restorable
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        for name, (_, energy, _, hide_render, hide_viewport, props) in relight_scene.lamps(bpy.data).items():
            r = lamps[name]
            assert props == ["relight_lamp_original"]
            if r["kept"]:
                assert energy == pytest.approx(r["energy_after"], rel=1e-5) and not (hide_render or hide_viewport)
            else:
                assert energy == pytest.approx(r["energy_before"], rel=1e-5) and hide_render and hide_viewport
        baked = cr.cycles_face_radiance(samples=SAMPLES, seed=1, threads=THREADS, keep_light_paths=True,
                                        keep_world=True)
    finally:
        cr.reset_blender()
    predicted = {name: o["radiosity"] for name, o in report["objects"].items()}
    rel, signed, summary = _against_cycles(predicted, baked, f"{selection}, final ({fin['n_lights']} lamps)")
    assert rel.mean() < 0.02 and abs(signed.mean()) < 0.01 and rel.max() < 0.08, summary

    # a second configuration of the curve, applied to the written file (the add-on's row click)
    second = tmp_path / "second.blend"
    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        scene = bpy.context.scene
        data = results.load_result(scene)
        row = int(np.flatnonzero(data.n_lights == 10)[0])
        shown = results.apply_stored_point(scene, row)
        assert shown["skipped"] == []
        on = {o.name for o in bpy.data.objects if o.type == "LIGHT" and not o.hide_render}
        assert len(on) == 10
        rows = results.polygon_rows(data, data.radiosity[row].astype(np.float64))
        off = data.polygon_offset
        predicted = {name: rows[off[k]:off[k + 1]] for k, name in enumerate(data.objects)}
        bpy.ops.wm.save_as_mainfile(filepath=str(second))
        baked = cr.cycles_face_radiance(samples=SAMPLES, seed=2, threads=THREADS, keep_light_paths=True,
                                        keep_world=True)
    finally:
        cr.reset_blender()
    rel, signed, summary = _against_cycles(predicted, baked, f"{selection}, curve row {row} (10 lamps)")
    assert rel.mean() < 0.02 and abs(signed.mean()) < 0.01 and rel.max() < 0.08, summary

    # Clear Results: every lamp back as the user set it, no trace left
    try:
        bpy.ops.wm.open_mainfile(filepath=str(second))
        results.clear_results(bpy.context.scene)
        assert relight_scene.lamps(bpy.data) == original
    finally:
        cr.reset_blender()
