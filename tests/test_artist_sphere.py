"""tests/artist_scenes.py's UV sphere: Blender 5.0's primitive_uv_sphere_add (and
bmesh.ops.create_uvsphere) give its polygons in a different order in each process, which moved the
1M living room's answer between runs (docs/benchmarks.md, "1M cold solve, second part"). The
scene builder's sphere has the operator's vertices and polygon areas, flat shading, and the same
polygons in the same order in two fresh processes."""
import os
import subprocess
import sys

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="needs bpy (Blender as a Python module)")

import artist_scenes  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
CHILD = (f"import sys, hashlib, numpy as np; sys.path.insert(0, {HERE!r}); import bpy, artist_scenes\n"
         "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
         "me = artist_scenes._uv_sphere('Sphere', 0.3, (0, 0, 0)).data\n"
         "lv = np.zeros(len(me.loops), np.int32); me.loops.foreach_get('vertex_index', lv)\n"
         "lt = np.zeros(len(me.polygons), np.int32); me.polygons.foreach_get('loop_total', lt)\n"
         "print('HASH', hashlib.sha1(lv.tobytes() + lt.tobytes()).hexdigest())\n")


def _polys(me):
    a = np.zeros(len(me.polygons))
    me.polygons.foreach_get("area", a)
    co = np.zeros(3 * len(me.vertices))
    me.vertices.foreach_get("co", co)
    sm = np.zeros(len(me.polygons), dtype=bool)
    me.polygons.foreach_get("use_smooth", sm)
    return a, co.reshape(-1, 3), sm


def test_the_sphere_is_the_operators_in_a_fixed_order(bpy_clean):
    mine = artist_scenes._uv_sphere("Sphere", 0.3, (-1.6, 1.2, 0.3))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, radius=0.3, location=(-1.6, 1.2, 0.3))
    op = bpy.context.active_object
    a, v, s = _polys(mine.data)
    b, w, t = _polys(op.data)
    assert len(a) == len(b) == 2048 and np.array_equal(v, w)
    np.testing.assert_allclose(np.sort(a), np.sort(b), rtol=1e-6)
    assert not s.any() and not t.any()
    assert np.allclose(mine.matrix_world, op.matrix_world)
    hashes = set()
    for _ in range(2):
        p = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300)
        hashes |= {ln for ln in p.stdout.splitlines() if ln.startswith("HASH")}
        assert p.returncode == 0, p.stderr[-2000:]
    assert len(hashes) == 1
