"""Issue 15.2: the registries carry their parameters (engine/registry.py Param, engine/options.py).

References: the declarations themselves (every registered method and every declared option must
reach JobOptions, the CLI and the add-on's properties), and the engine's own least-power
programme (engine.best_lights.least_power_within_tolerance) for the operator's result."""
import os

import numpy as np
import pytest

from conftest import SAMPLES
from relight_addon.engine.options import JOB_PARAMS, METHOD_CHOICES, METHOD_PARAMS, PARAMS, JobOptions


# --------------------------------------------------------------------------- JobOptions (no bpy)

def test_every_declared_option_is_a_jobs_field_with_its_default():
    o = JobOptions()
    for name, p in PARAMS.items():
        assert getattr(o, name) == p.default, name
    for kind, registry in METHOD_CHOICES:
        assert PARAMS[kind].registry is registry
        for m in registry:
            for p in m.params:
                assert p.name in METHOD_PARAMS and (kind, m) in METHOD_PARAMS[p.name][1]


def test_existing_keyword_arguments_keep_working():
    o = JobOptions(selection="least-power", tolerance=0.1).validate()
    assert o.tolerance == 0.1 and o.uses("tolerance")
    o = JobOptions(refine_passes=1).validate()  # the adaptive model is the default
    assert o.refine_passes == 1 and o.param("refine_passes", 0) == 1
    assert JobOptions(selection="least-power").validate().tolerance == 0.1  # the declared default


@pytest.mark.parametrize("kw, words", [
    (dict(tolerance=0.2), ("--tolerance", "least-power selection", "greedy-swap")),
    (dict(refine_passes=1, patch_model="polygon"), ("--refine-passes", "adaptive patch model", "polygon")),
    (dict(light_size=0.5, patch_model="polygon"), ("--light-size", "adaptive patch model")),
    (dict(refine_tolerance=0.1, patch_model="polygon"), ("--refine-tolerance", "adaptive")),
    (dict(distribution="uniform"), ("--distribution", "greedy-swap selection distributes no power")),
    (dict(selection="exitance-elimination", coplanar_tolerance=0.01), ("--coplanar-tolerance", "coplanar")),
    (dict(selection="least-power", max_lights=5), ("--max-lights", "least-power", "tolerance")),
    (dict(selection="least-power", error_threshold=0.1), ("--error-threshold", "least-power")),
])
def test_an_option_the_chosen_methods_do_not_use_is_refused(kw, words):
    with pytest.raises(ValueError) as exc:
        JobOptions(**kw).validate()
    assert all(w in str(exc.value) for w in words), str(exc.value)


def test_an_unused_option_at_its_default_passes_unless_given():
    JobOptions(tolerance=0.1, refine_passes=0, max_lights=3).validate()  # the defaults: nothing set
    with pytest.raises(ValueError, match="--tolerance is used only by the least-power selection"):
        JobOptions(tolerance=0.1).validate(given={"tolerance"})  # the CLI: the flag was given


@pytest.mark.parametrize("kw, message", [
    (dict(rays_per_patch=-1), "rays per patch must be at least 1"),
    (dict(max_patch_size=0.0), "max patch size must be a positive length"),
    (dict(max_patch_size=float("nan")), "max patch size must be a positive length"),
    (dict(seed=-1), "seed must be a non-negative integer"),
    (dict(seed=1.5), "seed not an integer"),
    (dict(max_lights=0), "max lights must be at least 1"),
    (dict(error_threshold=-0.1), "error threshold must be a non-negative number"),
    (dict(selection="least-power", tolerance=-1.0), "tolerance must be a non-negative number"),
    (dict(selection="least-power", tolerance=float("inf")), "tolerance must be a non-negative number"),
    (dict(light_size=0.0), "light size must be a positive length"),
    (dict(refine_passes=-1), "refine passes must be 0 or more"),
    (dict(refine_passes=True), "refine passes must be a number"),
    (dict(require_positive=1), "require positive must be true or false"),
    (dict(selection="magic"), "unknown selection 'magic'; choose one of"),
    (dict(patch_model="voxels"), "unknown patch model 'voxels'"),
])
def test_validate_checks_each_declaration(kw, message):
    with pytest.raises(ValueError, match=message):
        JobOptions(**kw).validate()


def test_report_lists_only_the_parameters_the_job_uses():
    d = JobOptions(patch_model="polygon").validate().to_dict()
    assert d["tolerance"] is None and d["refine_passes"] is None and d["light_size"] is None
    assert JobOptions(**d).validate() == JobOptions(patch_model="polygon").validate()  # round trip
    d = JobOptions(selection="least-power", tolerance=0.25).validate().to_dict()
    assert d["tolerance"] == 0.25


def test_cost_reads_refine_passes_through_the_declaration():
    assert JobOptions(refine_passes=2).validate().param("refine_passes", 0) == 2
    assert JobOptions(patch_model="polygon").validate().param("refine_passes", 0) == 0


# --------------------------------------------------------------------------- the CLI

def test_cli_flags_are_generated_from_the_declarations():
    from relight_addon import cli

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for command in ("solve", "reduce"):
        flags = {opt: a for a in sub[command]._actions for opt in a.option_strings}
        for p in PARAMS.values():
            assert p.cli_flag in flags, (command, p.cli_flag)
            a = flags[p.cli_flag]
            assert a.dest == p.name and (p.type is bool or tuple(a.choices or ()) == p.choices())
    for flag in ("--selection", "--tolerance", "--distribution", "--solver", "--patch-model", "--max-patch-size",
                 "--light-size", "--refine-passes", "--estimator", "--rays-per-patch", "--seed", "--threads",
                 "--max-lights", "--error-threshold", "--allow-negative", "--target-scale"):  # README's
        assert any(flag in a.option_strings for a in sub["solve"]._actions), flag


# --------------------------------------------------------------------------- the add-on

@pytest.fixture(scope="module")
def addon():
    bpy = pytest.importorskip("bpy", reason="the add-on needs bpy")
    import relight_addon

    relight_addon.register()
    yield bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    relight_addon.unregister()


def test_every_method_and_parameter_is_a_property_of_the_sidebar(addon):
    bpy = addon
    props = bpy.types.RELIGHT_SceneSettings.bl_rna.properties if hasattr(bpy.types, "RELIGHT_SceneSettings") \
        else bpy.context.scene.relight.bl_rna.properties
    for kind, registry in METHOD_CHOICES:  # every registered method of every user-facing registry
        assert [i.identifier for i in props[kind].enum_items] == list(registry.names()), kind
        assert props[kind].default == PARAMS[kind].default
    for name, p in PARAMS.items():
        if p.ui == "hidden":  # threads: the add-on's preferences
            assert name not in props
            continue
        assert name in props, name
        rna = props[name]
        if p.ui == "toggle":
            assert props["use_" + name].type == "BOOLEAN"
            assert props["use_" + name].default == (p.default is not None)
        want = {bool: "BOOLEAN", int: "INT", float: "FLOAT", str: "ENUM" if p.registry is not None else "STRING"}[p.type]
        assert rna.type == want, name
        if p.type in (int, float) and p.ui != "zero":
            if p.default is not None:
                assert rna.default == pytest.approx(p.default), name
            if p.min is not None:
                assert rna.hard_min == pytest.approx(p.min), name
        assert rna.description.startswith(p.description), name


def test_panel_rows_follow_the_chosen_methods(addon):
    """The Solve panel's rows: least-power shows its Tolerance; the Model panel the adaptive
    model's parameters (a recording layout: panels draw nothing in background mode)."""
    bpy = addon
    from relight_addon.blender.ui import panels

    class Layout:
        def __init__(self, rows):
            self.rows, self.active, self.scale_y = rows, True, 1

        def column(self, **kw):
            return Layout(self.rows)

        row = box = column

        def prop(self, data, name, **kw):
            self.rows.append(name)

        def label(self, **kw):
            pass

        def operator(self, *a, **kw):
            return type("Op", (), {})()

        def progress(self, **kw):
            pass

    def drawn(panel):
        rows = []
        panel.draw(type("Panel", (), {"layout": Layout(rows)})(), bpy.context)
        return rows

    bpy.ops.wm.read_factory_settings(use_empty=True)
    s = bpy.context.scene.relight
    s.selection = "greedy-swap"
    assert "tolerance" not in drawn(panels.RELIGHT_PT_solve)
    # the artist's choices in view; quality, seed and the paper's internals under Advanced (issue 19),
    # the Distribution only for a selection that distributes power
    assert {"selection", "max_lights", "require_positive"} <= set(drawn(panels.RELIGHT_PT_solve))
    assert not {"solver", "distribution", "rays_per_patch", "seed"} & set(drawn(panels.RELIGHT_PT_solve))
    assert {"rays_per_patch", "seed", "solver"} <= set(drawn(panels.RELIGHT_PT_solve_advanced))
    assert "distribution" not in drawn(panels.RELIGHT_PT_solve_advanced)
    s.selection = "exitance-elimination"
    assert "distribution" in drawn(panels.RELIGHT_PT_solve_advanced)
    # the light colour (issue 21) and, for blackbody lights, their range
    # (Automatic solves with blackbody lights of the range set, unless the targets ask for colours: issue 35)
    assert {"light_colour", "temperature_min", "temperature_max"} <= set(drawn(panels.RELIGHT_PT_solve))
    s.light_colour = "free"
    assert "temperature_min" not in drawn(panels.RELIGHT_PT_solve)
    s.light_colour = "blackbody"
    assert {"light_colour", "temperature_min", "temperature_max"} <= set(drawn(panels.RELIGHT_PT_solve))
    s.selection = "least-power"
    assert {"tolerance", "use_uniformity"} <= set(drawn(panels.RELIGHT_PT_solve))
    assert "max_lights" not in drawn(panels.RELIGHT_PT_solve)  # its tolerance decides
    s.patch_model = "adaptive"
    assert {"patch_model", "estimator", "light_size", "refine_passes", "refine_tolerance"} <= set(
        drawn(panels.RELIGHT_PT_model))
    s.patch_model = "polygon"
    assert "refine_passes" not in drawn(panels.RELIGHT_PT_model)
    # the kinds of candidate lights (issue 17), under Light Candidates
    assert {"surface_lights", "spot_lamps", "area_lamps", "point_lamps", "lamp_drop", "max_lamps"} <= set(
        drawn(panels.RELIGHT_PT_candidates))


def test_sidebar_warnings_are_three_short_lines_with_their_fix(addon):
    """Issues 19 and 36 (item 4): the sidebar shows at most three warnings, the most consequential
    first, each a short line holding its number (the whole text its tooltip), without
    command-line flags, with the button that fixes it under it; the plain facts of the solve are
    not among them; Details lists all."""
    bpy = addon
    from relight_addon.blender.ui import panels
    from relight_addon.pipeline.notes import LINE_CHARS, for_addon, sidebar_lines

    clamp = ("indirect clamping at 10: the lights' radiance reaches 613 W/m^2/sr, so Cycles may render darker "
             "than predicted (clamping effects are not estimated); use Match Cycles Light Paths (--out turns "
             "clamping off)")
    paths = ("Cycles would render the targets about 1.4 % darker than predicted with the scene's light paths "
             "(Diffuse bounces 4, Total 12; up to 3.1 % on a patch); use Match Cycles Light Paths (--out writes them)")
    fact = "3 light(s): relative error 0.0685; no 3 non-negative lights can go below 0.0264"
    colour = "light colour: blackbody (2700-6500 K), chosen automatically: any number of them can reach 0.787"
    far = ("Relight Spot 18 (spot, 1.69e+07 W) sends 0.007% of its light to the painted targets: other candidate "
           "lights send up to 43.53% of theirs")
    bright = ("Cube.002: its targets are already 45 % brighter than painted without any new light (the scene's own "
              "lamps, World and emitters)")
    unknown = ("a warning no rule knows about, long enough to be cut somewhere in its middle, with its number "
               "12.5 at the end")
    warnings = [fact, clamp, colour, paths, unknown, far, bright]
    lines = sidebar_lines(warnings)
    assert [ln.text for ln in lines] == ["Light: 0.007 % on targets", "45 % too bright already",
                                         "Cycles renders 1.4 % darker"], lines
    assert [warnings[ln.index] for ln in lines] == [far, bright, paths]
    assert [ln.fix for ln in lines] == [None, None, "light_paths"]
    for w in warnings:  # every line fits, holds its number, names no flag
        got = sidebar_lines([w], n=1)
        if w in (fact, colour):
            assert got == []  # plain facts: Details and the report only
            continue
        (ln,) = got
        assert len(ln.text) <= LINE_CHARS and "--" not in ln.text, ln
        number = {clamp: "10", paths: "1.4", far: "0.007", bright: "45", unknown: "12.5"}[w]
        assert number in ln.text, ln
    assert for_addon(paths).endswith("use Match Cycles Light Paths") and "--" not in for_addon(clamp)

    drawn = []

    class Row:
        def operator(self, name, **kw):
            drawn.append((name, kw.get("text")))
            return type("Op", (), {})()

        def prop(self, data, name, **kw):
            drawn.append(("prop", name))

    class Layout(Row):
        def row(self, **kw):
            return Row()

        def column(self, **kw):
            return Row()

    s = bpy.context.scene.relight
    panels.draw_warnings(Layout(), s, [fact, clamp, paths])
    assert drawn == [("relight.warning_details", "Cycles renders 1.4 % darker"),
                     ("relight.match_light_paths", "Match Cycles Light Paths"),
                     ("relight.warning_details", "Clamping at 10 darkens"),  # (the same fix: not again)
                     ("relight.warnings_popup", "Details (3)")]
    s.last_warnings = "first\n" + clamp
    from relight_addon.blender.ui.operators import RELIGHT_OT_warning_details

    assert RELIGHT_OT_warning_details.description(bpy.context, type("P", (), {"index": 1})()) == for_addon(clamp)


def test_operator_options_pass_only_the_chosen_methods_parameters(addon):
    bpy = addon
    from relight_addon.blender.ui import operators

    bpy.ops.wm.read_factory_settings(use_empty=True)
    s = bpy.context.scene.relight
    s.selection, s.tolerance, s.max_lights, s.distribution = "greedy-swap", 0.3, 5, "uniform"
    s.patch_model, s.refine_passes = "polygon", 2
    o = operators.job_options(s)  # nothing the sidebar shows is refused
    assert o.distribution == PARAMS["distribution"].default and o.refine_passes == 0 and o.max_lights == 5
    assert o.to_dict()["tolerance"] is None
    s.selection = "least-power"
    o = operators.job_options(s)
    assert o.tolerance == 0.3 and o.max_lights == PARAMS["max_lights"].default  # the tolerance decides
    # the candidate lamps: passed as the sidebar sets them; with the paper's heuristics, cells only
    s.selection, s.spot_lamps, s.point_lamps, s.lamp_drop, s.max_lamps = "greedy-swap", False, True, 0.3, 40
    o = operators.job_options(s)
    assert not o.spot_lamps and o.point_lamps and o.lamp_drop == pytest.approx(0.3) and o.max_lamps == 40
    s.point_lamps = False  # no lamp offered: the lamps' drop and count are moot, at their defaults
    o = operators.job_options(s)
    assert o.lamp_drop is None and o.max_lamps == PARAMS["max_lamps"].default
    s.selection = "exitance-elimination"
    o = operators.job_options(s)  # not refused: the lamp options are moot, at their defaults
    assert o.spot_lamps == PARAMS["spot_lamps"].default and o.lamp_drop is None


def test_least_power_through_the_operator(addon):
    """Solve & Reduce with the sidebar's selection set to least-power and its tolerance: the
    operator's final configuration is the engine's own least-power programme on the same
    problem, and every target is within the tolerance (or within the tolerance the programme
    reports as reachable, when no non-negative lights reach the one asked)."""
    bpy = addon
    from relight_addon.blender import export, results
    from relight_addon.pipeline import model as models, stages
    from relight_addon.engine.best_lights import least_power_within_tolerance

    tol = 0.3
    bpy.ops.wm.open_mainfile(filepath=os.path.join(SAMPLES, "staircase_targets.blend"))
    s = bpy.context.scene.relight
    s.selection, s.tolerance, s.rays_per_patch = "least-power", tol, 512
    assert bpy.ops.relight.solve() == {"FINISHED"}
    data = results.load_result(bpy.context.scene)
    assert data.meta["options"]["selection"] == "least-power"
    assert data.meta["options"]["tolerance"] == pytest.approx(tol)
    k = s.curve_index
    e_op = np.asarray(data.exitance[k], dtype=np.float64)

    # the engine's own programme on the same problem (the operator's options, built independently):
    # it chooses the lights; their direct light by the kernel (stages.direct_stage) changes their columns
    # of T, and the programme on those lights and columns gives their strengths
    exp = export.export_scene()
    opts = JobOptions(selection="least-power", tolerance=tol, rays_per_patch=512).validate()
    model = models.build_inverse_model(exp.faces, opts, exp.settings.get("max_patch_size"))
    p = model.problem
    first = least_power_within_tolerance(p.transfer, p.b_target, p.light_watts, tol)
    red = stages.reduce_stage(model, stages.solve_stage(model, opts)[0], opts)
    assert np.array_equal(np.sort(red.final.lights), first.lights)
    model, red = stages.direct_stage(model, red, opts)
    p = model.problem  # (its T with the direct light: a new problem, the first one kept as it was)
    ids = first.lights
    ref = least_power_within_tolerance([t[:, ids] for t in p.transfer], p.b_target, p.light_watts[ids], tol)
    assert ref.status in ("ok", "partial", "infeasible")
    want = np.zeros((p.n_lights, 3))
    want[ids] = ref.exitance
    assert e_op.shape == want.shape
    scale = max(float(np.abs(want).max()), 1e-12)
    assert np.allclose(e_op, want, rtol=1e-4, atol=1e-5 * scale)  # stored as float32
    assert np.all(e_op >= 0)

    # every target within the band: |B - b| <= x * |b| per target channel (x = the tolerance, or
    # the reachable one); B from the stored final radiosity, b the painted target values
    x = tol if ref.status == "ok" else max(tol, ref.reachable_tolerance or tol)
    B = np.asarray(data.radiosity[k], dtype=np.float64)[data.target_patch]
    b = np.asarray(data.target_value, dtype=np.float64)
    band = x * np.where(b != 0, np.abs(b), ref.zero_band)
    assert np.all(np.abs(B - b) <= band * (1 + 1e-3) + 1e-4 * np.abs(b).max())
