"""Light colour on an artist's scene (issue 21), through the CLI: issue 17's gallery (grey targets
on a warm room, only the ceiling may hold lights) solved with each light colour, and the written
copy reopened.

Evidence: white lights' channels are equal; blackbody lights are a power times Blender's own
blackbody colour of the temperature the report gives, in the range; the automatic choice takes
blackbody lights on grey targets (no light like issue 21's red one) and free colours, with a note,
when the painting is painted red; the written lamps carry Blender's Temperature, and Cycles' gain
(colour x Power x the Temperature's colour, read back by the export as Cycles reads it) is the
strength the report predicted.
"""
import json

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # (whole solves of several scenes: make test-all, not make test)

bpy = pytest.importorskip("bpy")

import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon import cli  # noqa: E402
from relight_addon.engine.light_colour import blackbody_rec709  # noqa: E402

FAST = ["--quiet", "--seed", "1"]


def _solve(blend, folder, name, *extra):
    report, out = folder / f"{name}.json", folder / f"{name}.blend"
    code = cli.main(["solve", str(blend), "--report", str(report), "--out", str(out), *FAST, *extra])
    assert code == 0
    return json.loads(report.read_text()), out


def _save_gallery(path, painting_rgb=None):
    cr.reset_blender()
    try:
        obs = artist_scenes.gallery()
        if painting_rgb is not None:
            artist_scenes.paint(obs["Painting"], [0], painting_rgb)
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        cr.reset_blender()


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("colour")
    grey, red = folder / "gallery.blend", folder / "red.blend"
    _save_gallery(grey)
    _save_gallery(red, (1.2, 0.15, 0.1))
    out = {"folder": folder}
    for mode in ("free", "white", "blackbody", "auto"):
        out[mode] = _solve(grey, folder, mode, "--light-colour", mode)
    out["red"] = _solve(red, folder, "red_auto", "--light-colour", "auto")
    return out


def _colours(report):
    return [np.asarray(li["strength"] if li["exitance"] is None else li["exitance"], dtype=np.float64)
            for li in report["final"]["lights"]]


def test_white_lights_are_white(solved):
    report, _ = solved["white"]
    assert report["light_colour"] == {"mode": "white", "option": "white"}
    for c in _colours(report):
        np.testing.assert_allclose(c, c[0], rtol=1e-12)


def test_blackbody_lights_are_blenders_blackbody(solved):
    report, _ = solved["blackbody"]
    rec = report["light_colour"]
    assert rec["mode"] == "blackbody" and rec["range_K"] == [2700.0, 6500.0]
    for li, c in zip(report["final"]["lights"], _colours(report)):
        t = li["temperature_K"]
        assert 2700.0 - 1e-6 <= t <= 6500.0 + 1e-6
        chi = blackbody_rec709(t)
        np.testing.assert_allclose(c / c.sum(), chi / chi.sum(), rtol=1e-9)
        assert li["luminous_flux_lm"] == pytest.approx(683.0 * float(np.dot(
            c * (1.0 if li["exitance"] is None else li["area"]), (0.2126, 0.7152, 0.0722))), rel=1e-9)


def test_auto_takes_blackbody_on_grey_and_free_on_red(solved):
    """Grey targets: blackbody lights, every light's colour within the locus' (no channel below a
    fifth of the brightest: the red light of issue 21 had two at 0); the error is the blackbody
    solve's. The painting painted red: the targets ask for coloured light: free colours, and the
    note says so and what blackbody lights could reach."""
    auto, _ = solved["auto"]
    bb, _ = solved["blackbody"]
    assert auto["light_colour"] == {**bb["light_colour"], "option": "auto"}
    assert auto["final"]["relative_error"] == pytest.approx(bb["final"]["relative_error"], rel=1e-9)
    for c in _colours(auto):
        assert c.min() >= 0.2 * c.max()
    assert any("chosen automatically" in w for w in auto["warnings"])
    red, _ = solved["red"]
    assert red["light_colour"] == {"mode": "free", "option": "auto"}
    assert any("the targets ask for coloured light" in w for w in red["warnings"])


def _unrefined(report):
    """{n_lights: relative error} of the configurations as the selection chose them, before the
    lamp refinement moved their lamps (the report's lamp_refinement), else as final."""
    out = {c["n_lights"]: c["relative_error"] for c in report["curve"]}
    for p in (report["model"]["lamp_refinement"] or {}).get("points", []):
        out[p["n_lights"]] = p["relative_error_before"]
    return out


def test_free_is_no_worse_than_the_constrained(solved):
    """Free colours never do worse than white or blackbody lights over the same candidates (they
    are constraints of it): the final configurations the selection chose, before the lamp refinement
    (a local search from each solve's own answer, over lamps no longer the candidates: after it,
    free colours' 3 lights were 0.242 and white's 0.241 on the same three lights, 0.263 and 0.265
    before). The constrained solves' certificates are below their own configurations as chosen; a
    refined answer may go below its certificate (of the candidate lights), and its warnings say so
    (with the second round's aim kept, one reached 0.175 under its bound 0.240)."""
    free = _unrefined(solved["free"][0])
    for mode in ("white", "blackbody"):
        r = solved[mode][0]
        mine = _unrefined(r)
        n = r["final"]["n_lights"]  # (other rows: the selection's own heuristic choices may differ)
        assert free[n] <= mine[n] * (1 + 1e-6), (mode, n, free[n], mine[n])
        bound = r["final"]["bound_relative_error"]
        assert bound <= mine[n] * (1 + 1e-9), (mode, bound, mine[n])
        if r["final"]["relative_error"] < bound * (1 - 1e-6):
            assert any("were refined" in w for w in r["warnings"]), (mode, r["warnings"])


def test_written_blackbody_lamps_carry_their_temperature(solved):
    """The written copy's lamps: Use Temperature on, the report's temperature, and Cycles' emission
    (colour x Power x Blender's temperature colour, as the export reads a Light) the report's
    strength; the export of the written copy reads them back at that power."""
    report, out = solved["blackbody"]
    lamps = {li["object"]: li for li in report["final"]["lights"] if li["exitance"] is None}
    if not lamps:
        pytest.skip("the blackbody answer placed no lamp (cells only)")
    from relight_addon.blender.lamps import cycles_gain

    try:
        bpy.ops.wm.open_mainfile(filepath=str(out))
        bpy.context.view_layer.update()
        found = {o.name: o for o in bpy.context.scene.objects if o.type == "LIGHT" and o.name in lamps}
        assert set(found) == set(lamps)
        for name, ob in found.items():
            ld, li = ob.data, lamps[name]
            if hasattr(ld, "use_temperature"):
                assert ld.use_temperature and ld.temperature == pytest.approx(li["temperature_K"], rel=1e-6)
            emitted = np.array(ld.color)[:3] * ld.energy * cycles_gain(ld, np.array(ob.matrix_world))
            np.testing.assert_allclose(emitted, li["strength"], rtol=1e-4)
    finally:
        cr.reset_blender()


def test_targets_illuminance_read_out(solved):
    """The report's predicted illuminance on a target object of one material: the area-weighted
    mean illuminance is 683 lm/W x Rec.709 luminance of its mean radiosity / its reflectance (the
    Canvas material's base colour, Lambertian: B = reflectance x E on a face that does not emit),
    min <= mean <= max, U0 = min / mean; and the sidebar's row of it."""
    from relight_addon.pipeline.report import photometric_rows

    report, _ = solved["free"]
    rec = report["targets_photometric"]["Painting"]
    rho = np.array([0.6, 0.55, 0.5])
    lx = rec["illuminance_lx"]
    expect = 683.0 * float(np.dot(np.asarray(rec["radiosity_mean"]) / rho, (0.2126, 0.7152, 0.0722)))
    assert lx["mean"] == pytest.approx(expect, rel=1e-6)
    assert lx["min"] <= lx["mean"] <= lx["max"] and lx["u0"] == pytest.approx(lx["min"] / lx["mean"], rel=1e-12)
    assert rec["unread_patches"] == 0
    assert any(line.startswith("Painting\t") for line in photometric_rows(report).split("\n"))


@pytest.mark.parametrize("mode", ["white", "blackbody"])
def test_living_room_lights_are_of_their_kind(mode):
    """The living room (22k triangles, the furniture's modifiers): white and blackbody lights are of
    exactly that kind there too (every light's chromaticity: white's equal channels, blackbody's
    its temperature's), and the certificate is below the answer (unless lamps were refined)."""
    from relight_addon.blender import export
    from relight_addon.engine.options import JobOptions
    from relight_addon.pipeline import jobs

    cr.reset_blender()
    try:
        artist_scenes.living_room(2)
        exp = export.export_scene()
    finally:
        cr.reset_blender()
    out = jobs.run_solve(exp.faces, JobOptions(light_colour=mode).validate(),
                         default_max_patch_size=exp.settings.get("max_patch_size"))
    r = out.report
    assert r["light_colour"]["mode"] == mode
    for li, c in zip(r["final"]["lights"], _colours(r)):
        chi = np.ones(3) if mode == "white" else blackbody_rec709(li["temperature_K"])
        np.testing.assert_allclose(c / c.sum(), chi / chi.sum(), rtol=1e-9)
    refined = (out.model.lamp_refinement or {}).get("lamps_refined", 0)
    if not refined:  # (a refined lamp is no candidate: it may go below the candidates' bound)
        assert r["final"]["bound_relative_error"] <= r["final"]["relative_error"] * (1 + 1e-9)
