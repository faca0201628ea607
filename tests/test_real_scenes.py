"""Real scenes: modifiers, parenting, collection instances, hidden objects, untargeted
reflectors, and the cost estimate of large solves.

References: Howell's closed-form form factors (engine/closed_forms.py) through the
radiosity of a plate lit by a non-reflecting emitter (B = rho e F exactly for single
patches), and measured time/memory of a small solve for the cost estimate.
"""
import math
import tracemalloc

import numpy as np
import pytest

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
from relight_addon.blender import export, layers
from relight_addon.pipeline import jobs  # noqa: E402
from test_export import emission_material  # noqa: E402
from relight_addon.engine import closed_forms as cf  # noqa: E402
from relight_addon.engine.cost import estimate_cost, estimate_patches_cost  # noqa: E402
from relight_addon.engine.lights import candidate_mask  # noqa: E402
from relight_addon.engine.formfactors import compute_form_factors  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.engine.scene import mesh_patches  # noqa: E402

RAYS = 16384
E_RADIANCE = 2.0  # emitter radiance; exitance pi * 2 W/m^2
ONE_PATCH = 100.0  # max patch size (m): every face stays one patch


def quad(bpy, name, size=(1.0, 1.0), z=0.0, down=False, offset=(0.0, 0.0), mat=None, coll=None):
    (sx, sy), (ox, oy) = size, offset
    v = [(ox, oy, z), (ox + sx, oy, z), (ox + sx, oy + sy, z), (ox, oy + sy, z)]
    f = [(0, 3, 2, 1)] if down else [(0, 1, 2, 3)]
    me = bpy.data.meshes.new(name)
    me.from_pydata(v, [], f)
    me.update()
    if mat is not None:
        me.materials.append(mat)
    ob = bpy.data.objects.new(name, me)
    (coll or bpy.context.scene.collection).objects.link(ob)
    return ob


def diffuse(bpy, name, rho):
    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    p = next(n for n in m.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    p.inputs["Base Color"].default_value = (rho, rho, rho, 1)
    p.inputs["Specular IOR Level"].default_value = 0.0  # no specular layer: Lambert, albedo rho
    return m


def emitter(bpy, strength=E_RADIANCE):
    """Emission shader: reflectance 0, exitance pi * strength."""
    return emission_material(bpy, strength)


def paint_target(ob, polys, rgb=(0.5, 0.5, 0.5)):
    me = ob.data
    a = layers.ensure_target_layer(me)
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    for p in polys:
        poly = me.polygons[p]
        col[poly.loop_start:poly.loop_start + poly.loop_total] = (*rgb, 1.0)
    a.data.foreach_set("color", col.ravel())


# ---------------------------------------------------------------- modifiers
def test_subsurf_and_array_map_targets_to_base_polygons(bpy_clean):
    bpy = bpy_clean
    ob = quad(bpy, "grid", size=(1, 1))
    me = bpy.data.meshes.new("grid2")  # two unit quads side by side, x in [0, 2]
    me.from_pydata([(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)], [],
                   [(0, 1, 4, 3), (1, 2, 5, 4)])
    ob.data = me
    paint_target(ob, [0], rgb=(0.2, 0.4, 0.6))
    sub = ob.modifiers.new("sub", "SUBSURF")
    sub.subdivision_type = "SIMPLE"
    sub.levels = 1
    arr = ob.modifiers.new("arr", "ARRAY")
    arr.count = 3  # relative offset 1: copies at x + 2, x + 4
    quad(bpy, "lamp", size=(6, 1), z=1.0, down=True, mat=emitter(bpy))
    exp = export.export_scene()
    f = exp.faces
    grid = f.face_object == f.object_names.index("grid")
    assert grid.sum() == 2 * 4 * 3  # 2 polygons x 4 (subdivision) x 3 (array)
    assert np.bincount(f.face_index[grid]).tolist() == [12, 12]
    cx = np.array([f.vertices[lp].mean(axis=0)[0] for lp in f.face_loops])
    # polygon 0 is x in [0, 1] of each copy (copies every 2 m): exactly those faces are targets
    from_poly0 = grid & (np.floor(cx) % 2 == 0)
    assert np.array_equal(f.face_index[grid] == 0, from_poly0[grid])
    assert np.array_equal(f.target, from_poly0)
    assert f.target_radiosity[from_poly0] == pytest.approx(np.tile(math.pi * np.array([0.2, 0.4, 0.6]), (12, 1)))
    v = f.vertices[f.triangles]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    assert area[grid[f.triangle_face]].sum() == pytest.approx(6.0)  # 3 copies of 2 m^2
    # the report has one row per base polygon, and it is the area-weighted mean of its faces
    report, res = jobs.run_radiosity(f, JobOptions(rays_per_patch=256, max_patch_size=ONE_PATCH), **export.job_inputs(exp))
    rows = np.array(report["objects"]["grid"]["radiosity"])
    assert rows.shape == (2, 3)
    for p in (0, 1):
        sel = grid & (f.face_index == p)
        a = np.bincount(f.triangle_face, weights=area, minlength=f.n_faces)[sel]
        assert rows[p] == pytest.approx((res.face_radiosity[sel] * a[:, None]).sum(axis=0) / a.sum(), rel=1e-9)
    assert np.all(rows > 0)


# ---------------------------------------------------------------- transforms
def test_parented_rotated_scaled_plates_match_closed_form(bpy_clean):
    bpy = bpy_clean
    a, b, c = 1.0, 2.0, 0.5
    grand = bpy.data.objects.new("grand", None)
    bpy.context.scene.collection.objects.link(grand)
    grand.location = (3.0, -1.0, 2.0)
    grand.rotation_euler = (0.3, -0.5, 1.1)
    grand.scale = (2.0, 2.0, 2.0)
    parent = bpy.data.objects.new("parent", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.parent = grand
    parent.rotation_euler = (0.0, 0.7, 0.0)
    parent.scale = (0.25, 0.25, 0.25)  # with grand's 2: world scale 0.5
    lo = quad(bpy, "lo", size=(2, 2), offset=(-1, -1))  # unit-half-size square at the origin
    hi = quad(bpy, "hi", size=(2, 2), offset=(-1, -1))
    for ob, z, flip in ((lo, 0.0, 0.0), (hi, c, math.pi)):
        ob.parent = parent
        ob.location = (0.0, 0.0, 2 * z)  # local units: world = 0.5 x local
        ob.rotation_euler = (flip, 0.0, 0.0)  # hi faces lo
        ob.scale = (a, b, 1.0)  # 2 x (a, b) local -> (a, b) in world
    bpy.context.view_layer.update()
    f = export.export_faceset()
    v = f.vertices[f.triangles]
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    assert np.bincount(f.triangle_face, weights=area) == pytest.approx([a * b, a * b])
    patches = mesh_patches(f, ONE_PATCH)
    assert patches.n_patches == 2
    assert np.dot(patches.normal[0], patches.normal[1]) == pytest.approx(-1.0)
    assert np.linalg.norm(patches.center[1] - patches.center[0]) == pytest.approx(c)
    F = compute_form_factors(patches, rays_per_patch=RAYS, seed=1).to_dense()
    ref = cf.parallel_rectangles(a, b, c)
    assert F[0, 1] == pytest.approx(ref, rel=0.03)
    assert F[1, 0] == pytest.approx(ref, rel=0.03)


# ---------------------------------------------------------------- instances (CLI)
def plates_scene(bpy, occluder=None, occluder_size=3.0):
    """Emitter 1 x 1 at z=0 facing up (reflectance 0), grey plate B (rho 0.5) at z=1 facing
    down; ``occluder``: None, "real" or "instance" (a square at z=0.5 facing down)."""
    quad(bpy, "A", mat=emitter(bpy))
    quad(bpy, "B", z=1.0, down=True, mat=diffuse(bpy, "grey", 0.5))
    if occluder is None:
        return
    o = (0.5 - occluder_size / 2, 0.5 - occluder_size / 2)
    if occluder == "real":
        quad(bpy, "occ", size=(occluder_size, occluder_size), z=0.5, down=True, offset=o,
             mat=diffuse(bpy, "dark", 0.3))
        return
    coll = bpy.data.collections.new("occluders")
    bpy.context.scene.collection.children.link(coll)
    # the source sits elsewhere (z = 10, out of the way) in an excluded collection
    quad(bpy, "occ", size=(occluder_size, occluder_size), z=10.0, down=True, offset=o,
         mat=diffuse(bpy, "dark", 0.3), coll=coll)
    bpy.context.view_layer.layer_collection.children["occluders"].exclude = True
    inst = bpy.data.objects.new("holder", None)
    inst.instance_type = "COLLECTION"
    inst.instance_collection = coll
    inst.location = (0.0, 0.0, -9.5)  # the instance is at z = 0.5
    bpy.context.scene.collection.objects.link(inst)


def cli_plate_radiosity(bpy, run_cli, tmp_path, tag):
    path = tmp_path / f"{tag}.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    rep = tmp_path / f"{tag}.json"
    code, report, err = run_cli(["radiosity", path, "--report", rep, "--rays-per-patch", RAYS,
                                 "--max-patch-size", ONE_PATCH, "--seed", 3])
    assert code == 0, err
    return report


def test_collection_instance_occludes_like_a_real_object(bpy_clean, run_cli, tmp_path):
    bpy = bpy_clean
    e = math.pi * E_RADIANCE
    out = {}
    for kind in (None, "real", "instance"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        plates_scene(bpy, kind)
        out[kind] = cli_plate_radiosity(bpy, run_cli, tmp_path, str(kind))
    f_open = np.array(out[None]["objects"]["B"]["radiosity"][0]) / (0.5 * e)
    assert f_open == pytest.approx([cf.parallel_rectangles(1, 1, 1)] * 3, rel=0.03)
    for kind in ("real", "instance"):
        f_blocked = np.array(out[kind]["objects"]["B"]["radiosity"][0]) / (0.5 * e)
        assert np.all(f_blocked < 0.01 * f_open), kind
    rep = out["instance"]
    assert "holder/occ" not in rep["objects"]  # instance groups are not reported (no polygons of their own)
    assert rep["scene"]["faces"] == 3
    assert any("instanced" in w for w in rep["warnings"])
    # a partial occluder (0.6 x 0.6, centred): instance and real object block the same light
    part = {}
    for kind in ("real", "instance"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        plates_scene(bpy, kind, occluder_size=0.6)
        part[kind] = np.array(cli_plate_radiosity(bpy, run_cli, tmp_path, f"part_{kind}")["objects"]["B"]["radiosity"][0])
    assert 0.2 * 0.5 * e * f_open[0] < part["real"][0] < 0.8 * 0.5 * e * f_open[0]
    assert part["instance"] == pytest.approx(part["real"], rel=0.05)


def test_instance_faces_are_forbidden_non_targets(bpy_clean):
    bpy = bpy_clean
    plates_scene(bpy, "instance")
    paint_target(bpy.data.objects["occ"], [0])  # painted on the source: not per instance
    f = export.export_faceset()
    assert f.object_names == ["A", "B", "holder/occ"]
    inst = f.face_object == 2
    assert inst.sum() == 1
    assert f.face_index[inst].tolist() == [-1]
    assert f.forbidden[inst].all() and not f.target[inst].any()
    z = f.vertices[f.face_loops[int(np.flatnonzero(inst)[0])], 2]
    assert z == pytest.approx([0.5] * 4)
    assert f.reflectance[inst][0] == pytest.approx([0.3] * 3)


# ---------------------------------------------------------------- hidden from render
def test_hidden_from_render_is_ignored(bpy_clean):
    bpy = bpy_clean
    plates_scene(bpy, "real")
    bpy.data.objects["occ"].hide_render = True
    assert export.export_faceset().object_names == ["A", "B"]
    # hidden through its collection
    bpy.data.objects["occ"].hide_render = False
    coll = bpy.data.collections.new("hidden")
    bpy.context.scene.collection.children.link(coll)
    coll.objects.link(bpy.data.objects["occ"])
    bpy.context.scene.collection.objects.unlink(bpy.data.objects["occ"])
    coll.hide_render = True
    assert export.export_faceset().object_names == ["A", "B"]
    coll.hide_render = False
    assert export.export_faceset().object_names == ["A", "B", "occ"]
    # an instancer hidden from render instances nothing
    bpy.ops.wm.read_factory_settings(use_empty=True)
    plates_scene(bpy, "instance")
    bpy.data.objects["holder"].hide_render = True
    assert export.export_faceset().object_names == ["A", "B"]


# ---------------------------------------------------------------- untargeted reflectors
def test_wall_without_targets_reflects_onto_a_target(bpy_clean):
    """Emitter A and target T side by side (coplanar: no direct light), a grey wall W
    2 x 1 above both. Single patches: F_AW = F_TW = f (Howell C-11 for the 2 x 1 pair, by
    symmetry), and B_W = rho_W (e f + B_T f) / 2, B_T = rho_T f B_W."""
    bpy = bpy_clean
    rho_t, rho_w = 0.5, 0.8
    quad(bpy, "A", mat=emitter(bpy))
    t = quad(bpy, "T", offset=(1.0, 0.0), mat=diffuse(bpy, "t", rho_t))
    paint_target(t, [0])
    opts = JobOptions(rays_per_patch=RAYS, max_patch_size=ONE_PATCH, seed=2)
    exp = export.export_scene()
    rep0, _ = jobs.run_radiosity(exp.faces, opts, **export.job_inputs(exp))
    assert rep0["objects"]["T"]["radiosity"][0] == [0.0, 0.0, 0.0]
    quad(bpy, "W", size=(2, 1), z=1.0, down=True, mat=diffuse(bpy, "w", rho_w))
    exp = export.export_scene()
    assert not exp.faces.target[exp.faces.face_object == exp.faces.object_names.index("W")].any()
    rep1, _ = jobs.run_radiosity(exp.faces, opts, **export.job_inputs(exp))
    e = math.pi * E_RADIANCE
    f = cf.parallel_rectangles(2, 1, 1)
    # B_T = rho_T f rho_W (e f + B_T f) / 2
    b_t = rho_t * rho_w * f * f * e / 2 / (1 - rho_t * rho_w * f * f / 2)
    assert np.array(rep1["objects"]["T"]["radiosity"][0]) == pytest.approx([b_t] * 3, rel=0.06)


# ---------------------------------------------------------------- cost estimate
def test_cost_thresholds():
    from relight_addon.engine import cost
    from relight_addon.engine.formfactors import CHUNK_RAYS

    small = estimate_cost(200, 1024, 150, 50, threads=1)
    assert small["warnings"] == []
    # F dense float32 up to 6000 patches, CSR above (at most min(P, rays) entries a row)
    assert estimate_cost(6000, 1024, 10, 10)["parts"]["form_factors"][0] == 4 * 6000 ** 2
    assert estimate_cost(6001, 1024, 10, 10)["parts"]["form_factors"][0] < 1e9 / 10
    # A factorised (dense LU, 8 P^2 per channel group + a working copy) up to 6000 patches ...
    lu = estimate_cost(6000, 1024, 10, 10, channel_groups=1)["parts"]["lu"][0]
    assert lu == 2 * 8 * 6000 ** 2
    assert estimate_cost(6000, 1024, 10, 10, channel_groups=3)["parts"]["lu"][0] == 4 * 8 * 6000 ** 2
    # ... never above: 20000 patches stay far below the 12.8 GB dense factors would need
    big = estimate_cost(20000, 1024, 20000, 1000)
    assert big["parts"]["lu"][0] < 1e9
    assert any(" s (" in w for w in big["warnings"])  # but it takes time: iterative sweeps
    assert any("memory" in w for w in estimate_cost(60000, 65536, 1000, 1000)["warnings"])
    # ray casting's working set: at least one patch's rays in flight per thread (1e11 rays: ~10 TB)
    assert estimate_cost(8, 10 ** 11, 0, 0, threads=1)["parts"]["rays"][0] == cost.RAY_BYTES * 1e11
    assert estimate_cost(8, 1024, 0, 0, threads=2)["parts"]["rays"][0] == cost.RAY_BYTES * CHUNK_RAYS * 2
    # time only: 1000 patches x 65536 rays / 3 M rays/s = 22 s -> no warning; 4 x that -> warning
    assert estimate_cost(1000, 65536, 10, 10)["warnings"] == []
    w = estimate_cost(1000, 4 * 65536, 10, 10)["warnings"]
    assert len(w) == 1 and "rays per patch" in w[0]
    # refinement passes add a quarter of the rays each; triangles add meshing memory
    base = estimate_cost(1000, 4096, 10, 10)
    assert estimate_cost(1000, 4096, 10, 10, refine_passes=2)["parts"]["form_factors"][1] == pytest.approx(
        1.5 * base["parts"]["form_factors"][1])
    assert estimate_cost(1000, 4096, 10, 10, n_triangles=10 ** 6)["memory_bytes"] > base["memory_bytes"] + 1e8
    for bad in (-1, 1.5, "x"):
        with pytest.raises(ValueError):
            estimate_cost(bad, 1024, 10, 10)


def test_cost_estimate_matches_a_measured_solve():
    """A 1000-patch room: the traced peak memory of run_solve within a factor of 3 of the estimate.
    (Time against the estimate is a benchmark, not a timed test: benchmarks/bench_cost.py.)"""
    from relight_addon.engine.scene import polygon_faceset

    faces = polygon_faceset(cf.box_polygons((4.0, 3.0, 2.5)), reflectance=0.6)
    faces.target[0] = True  # the floor
    faces.target_radiosity[0] = 10.0
    faces.forbidden[:] = True
    faces.forbidden[1] = False  # the ceiling holds the candidates
    opts = JobOptions(rays_per_patch=1024, max_patch_size=0.25, seed=0, max_lights=3, patch_model="polygon",
                      estimator="raycast")
    patches = mesh_patches(faces, 0.25)
    P = patches.n_patches
    assert 700 < P < 1500
    est = estimate_cost(P, 1024, int(candidate_mask(patches).sum()), int(patches.target.sum()), channel_groups=1)
    assert estimate_patches_cost(patches, 1024) == est
    tracemalloc.start()
    out = jobs.run_solve(faces, opts)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert out.report["scene"]["patches"] == P
    arrays = est["memory_bytes"] - est["parts"]["scene"][0]  # tracemalloc sees the arrays, not the modules
    assert arrays / 3 < peak < 3 * arrays, (peak, est)
