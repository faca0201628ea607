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
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is needed to bake with Cycles")

import cycles_reference as cr  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
W, D, H = 4.0, 3.0, 2.5
GRID = (6, 5)  # lamps along x and y
POWERS = (15.0, 40.0, 90.0)  # W, a few distinct powers so that the reduction has a choice
SAMPLES = 128
THREADS = 2


def lamp_power(i, j):
    """The power (W) of grid lamp (i, j): brighter towards one corner, with a ripple."""
    return POWERS[(i + 2 * j) % 3] if (i + j) % 4 else POWERS[2]


def build_room(path):
    """The room (inward-facing walls, 4 x 4 quads each, a table top of 1 x 0.8 m, 5 cm thick, its sides open, at 0.7 m) and the
    30 Point lamps (radius 5 cm) 0.3 m under the ceiling; saved to ``path``."""
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


def _relight(*args):
    proc = subprocess.run([sys.executable, "-m", "relight_addon", *map(str, args), "--quiet"], cwd=ROOT,
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc
