"""Catalogue fixtures (issue 39, items 3-5): the built-in library (engine/photometry/library.py), a user's
folder, the fixture kind (engine/lights/fixture.py) as the solve offers, transports, dims and reports it.

References independent of the code under test: the closed forms the library tabulates, integrated by a
fine midpoint rule (their flux, a point source's irradiance E = I cos / d^2 on a floor); Cycles' own
normalisation of an IES profile (engine.units.cycles_ies_candela, 177.83 lm/W) for the Power that gives
the predicted light; the LM-63 text read back by the parser.
"""
import math

import numpy as np
import pytest

from relight_addon.engine import closed_forms as cf
from relight_addon.engine.lamps import lamp_irradiance
from relight_addon.engine.lights.fixture import FIXTURE, FixtureProfile, dimming, fixture_lamp
from relight_addon.engine.photometry import CyclesProfile, PhotometryError, parse_lm63
from relight_addon.engine.photometry import library as lib
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from relight_addon.engine.units import CYCLES_IES_CANDELA_FACTOR, LUMENS_PER_WATT, cycles_ies_candela

SPECS = {s[1]: s for s in lib.SPECS}


@pytest.fixture(scope="module")
def builtin():
    return {f.name: f for f in lib.load_library(lib.BUILTIN)}


def test_the_committed_files_are_what_the_generator_writes():
    files = sorted(p.name for p in lib.BUILTIN_DIR.iterdir() if p.name != "README.md")
    assert files == sorted(f"{s[0]}.ies" for s in lib.SPECS)
    for spec in lib.SPECS:
        assert (lib.BUILTIN_DIR / f"{spec[0]}.ies").read_text(encoding="utf-8") == lib.builtin_text(spec), spec[0]


def _closed_form_flux(spec, ph, n=1440):
    """The flux (lm) of a spec's closed form at the table's scale, by the midpoint rule on the sphere
    (n x 2n cells), independent of Cycles' interpolation."""
    form = spec[3]
    v = (np.arange(n) + 0.5) * 180.0 / n
    h = (np.arange(2 * n) + 0.5) * 180.0 / n
    hh, vv = np.meshgrid(h, v, indexing="ij")
    vt, ht = np.meshgrid(ph.v_angles, ph.h_angles)
    shape = form(vt, ht)
    k = ph.candela.max() / shape.max()  # cd per unit of the closed form, as written
    return float(k * np.sum(form(vv, hh) * np.sin(np.radians(vv))) * (math.pi / n) ** 2)


def test_the_builtin_fixtures_have_their_names_ratings_and_flux(builtin):
    assert sorted(builtin) == sorted(SPECS)
    for name, f in builtin.items():
        spec = SPECS[name]
        ph = parse_lm63(f.lm63, name)  # the text written, read back
        assert ph.keywords["LUMCAT"] == name and ph.keywords["LUMINAIRE"] == spec[2] == f.description
        assert ph.lumens == spec[4] and ph.watts == spec[5] == f.watts
        assert f.aimable == spec[6] and f.symmetric == spec[7]
        # Cycles renders the rated lumens from the table (the flux of its interpolation) ...
        assert ph.flux_lm() == pytest.approx(spec[4], rel=2e-4)
        assert f.lumens == pytest.approx(spec[4], rel=2e-4)
        # ... and the closed form the table samples holds them too (the table's sampling: measured <= 0.09 %)
        assert _closed_form_flux(spec, ph) == pytest.approx(spec[4], rel=0.002), name


def _local(v_deg, c_deg):
    """Unit directions in a lamp's frame at vertical angle v from its -Z and C plane c (C0 along -Y,
    C90 along -X: Cycles' h = atan2(x, y) + pi)."""
    v, c = np.radians(v_deg), np.radians(c_deg)
    return np.column_stack([-np.sin(v) * np.sin(c), -np.sin(v) * np.cos(c), -np.cos(v)])


def test_the_builtin_distributions_have_their_shapes(builtin):
    v = np.arange(0.0, 180.0, 0.25)
    # the narrow downlight: half its peak at acos(0.5^(1/30)) = 12.3 degrees; the wide one at 50.9
    for name, half in (("RL-DN15", 12.3), ("RL-DW90", 50.9)):
        i = builtin[name].profile.along(_local(v, np.zeros_like(v)))
        assert v[np.argmax(i < 0.5 * i[0])] == pytest.approx(half, abs=0.5), name
    i = builtin["RL-BW"].profile.along(_local(v, np.zeros_like(v)))
    assert v[np.argmax(i)] == pytest.approx(51.8, abs=0.5) and i[0] < 0.5 * i.max()  # a batwing: dim at the nadir
    assert np.all(i[v > 90.5] == 0)
    # the asymmetric ones: their peak in C0 (the lamp's -Y) at 35 and 130 degrees, none in C180 there
    for name, peak in (("RL-WW35", 35.0), ("RL-UP130", 130.0)):
        prof = builtin[name].profile
        i0 = prof.along(_local(v, np.zeros_like(v)))
        assert v[np.argmax(i0)] == pytest.approx(peak, abs=1.0), name
        assert prof.along(_local(np.array([peak]), np.array([180.0])))[0] < 0.01 * i0.max(), name


def test_a_fixture_at_full_strength_gives_its_rated_lumens_in_cycles(builtin):
    """The fixture's strength is its radiant power per channel: its scaled distribution emits 1 W per W.
    At the strength of 100 % (rated lumens / 683 W) the Power written (strength / gain) makes Cycles
    render, by its own IES normalisation (units.cycles_ies_candela: 177.83 lm/W), the intensity the
    engine transports, in every direction; so its flux is the rated lumens."""
    for f in builtin.values():
        prof = FixtureProfile.of(f)
        assert CyclesProfile(prof.fixture.profile.h, prof.fixture.profile.v,
                             prof.fixture.profile.values * prof.scale).flux() == pytest.approx(4 * math.pi, rel=1e-6)  # (float32)
        s = np.full(3, f.lumens / LUMENS_PER_WATT)
        assert dimming(s, f.lumens) == pytest.approx(1.0)
        lamp = fixture_lamp("f", f, (0, 0, 2), (0, 0, -1))
        power_written = s / lamp.gain
        dirs = _local(np.arange(0.0, 180.0, 7.0), np.full(26, 30.0))
        cd_file = f.profile.along(dirs) / CYCLES_IES_CANDELA_FACTOR  # the file's candela along them (Cycles' factor)
        ours = LUMENS_PER_WATT * s[0] * lamp.profile.along(dirs) / (4 * math.pi)  # cd the engine transports
        np.testing.assert_allclose(cycles_ies_candela(power_written, cd_file), ours, rtol=1e-6, atol=1e-9)
        assert lamp.kind is FIXTURE and lamp.energy == pytest.approx(1.0 / lamp.gain[0])


@pytest.fixture(scope="module")
def box():
    return mesh_patches(polygon_faceset(cf.box_polygons((3.0, 3.0, 2.5)), reflectance=0.5), max_patch_size=0.25)


@pytest.mark.parametrize("name", ["RL-DW90", "RL-DN15", "RL-WW35"])
def test_a_fixture_lights_the_floor_as_its_closed_form(box, builtin, name):
    """Its irradiance per W on the floor's patches against E = I cos / d^2 of the closed form (I per W of
    radiant power: cd / rated lumens x 683 / 683), integrated over each patch (midpoint rule)."""
    f, spec = builtin[name], SPECS[name]
    at = np.array([1.5, 1.5, 2.3])
    lamp = fixture_lamp("f", f, at, (0.0, 0.0, -1.0), towards=(1.0, 0.0, 0.0))  # C0 towards +X
    H = lamp_irradiance(box, [lamp], seed=0, points_per_patch=64)[:, 0, 0]
    floor = np.flatnonzero(box.normal[:, 2] > 0.9)
    vt, ht = np.meshgrid(f.photometry.v_angles, f.photometry.h_angles)
    k = f.photometry.candela.max() / spec[3](vt, ht).max()
    got, want = [], []
    for p in floor:
        vx = box.tri_vertices[box.tri_patch == p].reshape(-1, 3)
        (x0, y0, _), (x1, y1, _) = vx.min(axis=0), vx.max(axis=0)
        m = 24
        gx, gy = np.meshgrid(x0 + (np.arange(m) + 0.5) / m * (x1 - x0), y0 + (np.arange(m) + 0.5) / m * (y1 - y0))
        dx, dy, h = gx - at[0], gy - at[1], at[2]
        d = np.sqrt(dx * dx + dy * dy + h * h)
        v = np.degrees(np.arccos(h / d))
        c = np.degrees(np.arctan2(-dy, dx)) % 360.0  # its C plane: C0 along +X (turned so), Cycles' h = atan2(x, y) + pi
        cd = k * spec[3](v, c)
        want.append(float(np.mean(cd / f.lumens * (h / d) / (d * d))))
        got.append(H[p])
    got, want = np.array(got), np.array(want)
    lit = want > 0.02 * want.max()
    rel = np.abs(got[lit] - want[lit]) / want[lit]
    assert rel.mean() < 0.01 and rel.max() < 0.05, (name, rel.mean(), rel.max())
    # the floor's flux: the closed form's, within the sampling
    assert float(got @ box.area[floor]) == pytest.approx(float(want @ box.area[floor]), rel=0.01)


# -- a user's folder --------------------------------------------------------------------------

def test_a_user_folder_is_read_and_a_bad_file_refused_naming_its_line(tmp_path):
    for spec in lib.SPECS[:2]:
        (tmp_path / f"{spec[0]}.IES").write_text(lib.builtin_text(spec))
    (tmp_path / "notes.txt").write_text("not a fixture")
    got = lib.load_library(tmp_path)
    assert [f.name for f in got] == ["RL-DN15", "RL-DW90"]
    text = lib.builtin_text(lib.SPECS[2]).split("\n")
    (tmp_path / "broken.ies").write_text("\n".join(text[:12]) + "\n")  # truncated in its angles
    with pytest.raises(PhotometryError, match=r"fixtures: broken\.ies: the file ends at line 1[23] .*truncated.*move "
                                              r"it out"):
        lib.load_library(tmp_path)
    bad = list(text)
    bad[9] = bad[9].replace("0 2.5", "0 x2.5", 1)
    (tmp_path / "broken.ies").write_text("\n".join(bad))
    with pytest.raises(PhotometryError, match=r"broken\.ies: line 10: 'x2\.5' is not a number"):
        lib.load_library(tmp_path)
    (tmp_path / "broken.ies").write_text(lib.builtin_text(lib.SPECS[0]))  # a second RL-DN15
    with pytest.raises(PhotometryError, match="both named 'RL-DN15'"):
        lib.load_library(tmp_path)
    with pytest.raises(PhotometryError, match="is no folder"):
        lib.load_library(tmp_path / "none")
    (tmp_path / "empty").mkdir()
    with pytest.raises(PhotometryError, match="holds no .ies or .ldt file"):
        lib.load_library(tmp_path / "empty")


def test_the_option_refuses_a_bad_library_before_any_work(tmp_path):
    from relight_addon.engine.options import JobOptions

    assert JobOptions().fixtures is None  # not offered by default
    JobOptions(fixtures="builtin").validate()
    with pytest.raises(ValueError, match="is no folder"):
        JobOptions(fixtures=str(tmp_path / "none")).validate()
    # offered alone (no cells, no spots): a candidate light is offered
    JobOptions(fixtures="builtin", surface_lights=False, spot_lamps=False).validate()
    from relight_addon.engine.options import check_light_kinds
    check_light_kinds(JobOptions(fixtures="builtin", surface_lights=False, spot_lamps=False).validate())
    with pytest.raises(ValueError, match="no candidate light"):
        check_light_kinds(JobOptions(surface_lights=False, spot_lamps=False).validate())


def test_the_schedule_counts_dims_and_sums():
    from relight_addon.pipeline.report import fixture_schedule, schedule_lines, schedule_notes

    lights = [{"object": "a", "kind": "fixture", "fixture": "X", "fixture_description": "x", "rated_lumens": 1000.0,
               "rated_watts": 10.0, "luminous_flux_lm": 700.0, "location": [0, 0, 1], "direction": [0, 0, -1]},
              {"object": "b", "kind": "spot", "luminous_flux_lm": 50.0},
              {"object": "c", "kind": "fixture", "fixture": "X", "fixture_description": "x", "rated_lumens": 1000.0,
               "rated_watts": 10.0, "luminous_flux_lm": 1000.0, "location": [1, 0, 1], "direction": [0, 0, -1]}]
    (row,) = fixture_schedule(lights)
    assert row["count"] == 2 and row["lumens"] == pytest.approx(1700.0) and row["watts"] == pytest.approx(17.0)
    assert [li["dimming"] for li in row["lights"]] == pytest.approx([0.7, 1.0])
    assert row["at_full"] == ["c"]
    (note,) = schedule_notes([row])
    assert note.startswith("1 x X of the answer's 2 fixtures at 100 % of their rated lumens") and "Max Lights" in note
    (note,) = schedule_notes([row], (12, 0.05, 0.4))
    assert note.endswith("(the curve: relative error 0.4 with 2, 0.05 with 12)")
    assert schedule_lines([row]) == ["2 x X at 70-100 %: 1700 lm, 17.0 W (at full output)",
                                     "in all 2 fixtures: 1700 lm, 17.0 W"]
    lights[2]["luminous_flux_lm"] = 900.0
    (row,) = fixture_schedule(lights)
    assert row["at_full"] == [] and schedule_notes([row]) == []


def test_a_eulumdat_fixture_is_offered_with_its_lm63_for_blenders_node(tmp_path):
    """A .ldt in a user's folder: its name (its luminaire number), its input watts, its rated lumens the
    flux its table renders, and the LM-63 its IES node will hold renders the same distribution."""
    from test_photometry import _directions, _ldt, _ldt_cd

    (tmp_path / "a.ldt").write_text(_ldt(2, 24, 15.0, 19, 10.0, _ldt_cd, flux=2000.0), encoding="latin-1",
                                    newline="")
    (f,) = lib.load_library(tmp_path)
    assert f.name == "L-1" and f.watts == 20.0 and not f.symmetric
    assert f.lumens == pytest.approx(f.photometry.flux_lm())
    d = _directions()
    np.testing.assert_allclose(CyclesProfile.of(parse_lm63(f.lm63)).along(d), f.profile.along(d), rtol=1e-5,
                               atol=1e-6)


@pytest.mark.parametrize("name", ["RL-UP130", "RL-WW35", "RL-BW"])
@pytest.mark.parametrize("gap", [0.05, 0.15])
def test_a_fixture_in_a_closed_box_puts_its_whole_flux_on_the_walls(builtin, name, gap):
    """A closed box receives all of a fixture's 1 W, however close it hangs to a surface (an uplight
    ``gap`` m under the ceiling's 0.5 m patches: its near patches are sampled more, light_patches)."""
    box = mesh_patches(polygon_faceset(cf.box_polygons((4.0, 4.0, 2.5)), reflectance=0.5), max_patch_size=0.5)
    lamp = fixture_lamp("f", builtin[name], (1.7, 2.1, 2.5 - gap), (0.0, 0.0, -1.0), towards=(1.0, 0.3, 0.0))
    H = lamp_irradiance(box, [lamp], seed=0, points_per_patch=16)[:, 0, 0]
    assert float(H @ box.area) == pytest.approx(1.0, abs=0.005)


def test_the_cli_refuses_a_bad_library_in_one_line(tmp_path):
    import os
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "b.ies").write_text("\n".join(lib.builtin_text(lib.SPECS[2]).split("\n")[:12]) + "\n")
    proc = subprocess.run([sys.executable, "-m", "relight_addon", "solve",
                           os.path.join(root, "sample_blends", "staircase_targets.blend"), "--report",
                           str(tmp_path / "r.json"), "--fixtures", str(tmp_path / "lib")], cwd=root,
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": root})
    assert proc.returncode == 2 and proc.stderr.strip().count("\n") == 0, proc.stderr
    assert proc.stderr.startswith("relight: error: fixtures: b.ies: the file ends at line 13") and \
        "move it out of the folder" in proc.stderr
    assert not (tmp_path / "r.json").exists()
