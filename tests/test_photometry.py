"""Measured photometry (issue 39, items 1-2): the LM-63 and EULUMDAT readers and the LM-63 writer
(engine/photometry/), Cycles' processing and interpolation of a profile (distribution.py), and
the photometric lamp kind (engine/lights/photometric.py) against CIE 171:2006's point source over
a work plane (E = I(theta) cos(theta) / d^2). Against Cycles: tests/test_cycles_photometric.py."""
import math

import numpy as np
import pytest

import photometric_fixtures as pf
from relight_addon.engine.lamps import Lamp, lamp_irradiance
from relight_addon.engine.lights.photometric import PHOTOMETRIC
from relight_addon.engine.photometry import (TYPE_B, CyclesProfile, Photometry, PhotometryError, parse_eulumdat,
                                             parse_lm63, write_lm63)
from relight_addon.engine.scene import mesh_patches, polygon_faceset
from relight_addon.engine.units import (CYCLES_IES_CANDELA_FACTOR, CYCLES_IES_LUMENS_PER_WATT, LUMENS_PER_WATT,
                                        cycles_ies_candela, illuminance_lux)

DOWN, X, Y = np.array([0, 0, -1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])


def _ies(v, h, rows, ptype=1, header="IESNA:LM-63-2002", tilt="TILT=NONE", first="1 1000 1", units=2,
         factors="1 1 50"):
    """LM-63 text of a table (rows: per horizontal angle, one line of candela each)."""
    lines = [header, "[TEST] t", "[MANUFAC] m", tilt] if header else ["[TEST] t", tilt]
    lines.append(f"{first} {len(v)} {len(h)} {ptype} {units} 0.1 0.1 0.05")
    lines.append(factors)
    lines.append(" ".join(f"{x:g}" for x in v))
    lines.append(" ".join(f"{x:g}" for x in h))
    lines += [" ".join(f"{x:g}" for x in r) for r in rows]
    return "\n".join(lines) + "\n"


def _directions(n=400, seed=3):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1)[:, None]


# -- the reader and the writer --------------------------------------------------------------------
@pytest.mark.parametrize("name", list(pf.FIXTURES))
def test_written_files_read_back_to_the_same_distribution(name):
    ph = pf.FIXTURES[name]()
    back = parse_lm63(write_lm63(ph))
    np.testing.assert_allclose(back.v_angles, ph.v_angles)
    np.testing.assert_allclose(back.h_angles, ph.h_angles)
    np.testing.assert_allclose(back.candela, ph.candela, rtol=1e-6, atol=1e-9)
    assert back.photometric_type == 1 and back.tilt == "NONE" and back.notes == ()


@pytest.mark.parametrize("header", ["IESNA:LM-63-1995", "IESNA:LM-63-2002", "IES:LM-63-2019", "IESNA91", None])
def test_every_header_version_reads_alike(header):
    """1986 (no header line), 1991, 1995, 2002 and 2019: the keywords before TILT= are read, the
    table after it alike; commas separate values too."""
    v, h = [0, 45, 90], [0]
    text = _ies(v, h, [[100, 80, 10]], header=header).replace("0 45 90", "0, 45,90")
    ph = parse_lm63(text)
    np.testing.assert_allclose(ph.candela, [[100, 80, 10]])
    assert ph.keywords["TEST"] == "t" and ph.lumens == 1000.0 and ph.watts == 50.0


def test_multipliers_and_units_as_cycles_applies_them():
    """The candela multiplier, ballast factor and ballast-lamp photometric factor multiply the candela
    (Cycles multiplies all three); feet are converted; the lumens field is n_lamps x lumens per lamp."""
    ph = parse_lm63(_ies([0, 90], [0], [[100, 50]], first="2 500 2.0", factors="0.9 0.95 40", units=1))
    np.testing.assert_allclose(ph.candela, [[100 * 2 * 0.9 * 0.95, 50 * 2 * 0.9 * 0.95]])
    assert ph.lumens == 1000.0 and ph.n_lamps == 2
    assert ph.size == pytest.approx((0.1 * 0.3048, 0.1 * 0.3048, 0.05 * 0.3048))
    assert parse_lm63(_ies([0, 90], [0], [[1, 1]], first="1 -1 1")).lumens == -1.0  # absolute photometry


def test_tilt_is_read_and_named_not_applied():
    """TILT=INCLUDE's block is read past (its values do not shift the table) and named; a tilt file too."""
    text = _ies([0, 90], [0], [[100, 50]], tilt="TILT=INCLUDE\n1\n3\n0 45 90\n1.0 0.9 0.8")
    ph = parse_lm63(text)
    np.testing.assert_allclose(ph.candela, [[100, 50]])
    assert ph.tilt == "INCLUDE" and "not applied" in ph.notes[0]
    ph = parse_lm63(_ies([0, 90], [0], [[100, 50]], tilt="TILT=lamp.tlt"))
    assert "lamp.tlt" in ph.notes[0]


def _quadrant_cd(v, h):
    return 500 * np.maximum(np.cos(np.radians(v)), 0) * (1 + 0.4 * np.cos(np.radians(2 * h)))


@pytest.mark.parametrize("h", [[0, 30, 60, 90], [0, 30, 60, 90, 120, 150, 180],
                               list(range(0, 361, 30)), list(range(0, 360, 30))])
def test_symmetric_sets_of_one_two_and_four_quadrants_render_alike(h):
    """A distribution symmetric about C0-C180 and C90-C270 written over one quadrant, two, or the whole
    turn (with and without its 360 entry): Cycles' processing gives the same profile."""
    v = list(range(0, 181, 10))
    full = CyclesProfile.of(parse_lm63(_ies(v, list(range(0, 361, 30)), [_quadrant_cd(np.array(v), a)
                                                                     for a in range(0, 361, 30)])))
    prof = CyclesProfile.of(parse_lm63(_ies(v, h, [_quadrant_cd(np.array(v), a) for a in h])))
    d = _directions()
    np.testing.assert_allclose(prof.along(d), full.along(d), rtol=1e-5, atol=1e-6)


def test_a_90_to_270_file_is_turned_by_90_degrees_as_cycles_does():
    """Cycles shifts a set of 90..270 down by 90 (util/ies.cpp), then mirrors 0..180 to the turn: the
    file's C(h + 90) plane renders at h; named in the notes."""
    v = list(range(0, 181, 10))
    h = list(range(90, 271, 30))
    ph = parse_lm63(_ies(v, h, [_quadrant_cd(np.array(v), a) * (1 + a / 1000) for a in h]))
    assert any("90" in n and "turn" in n for n in ph.notes), ph.notes
    prof = CyclesProfile.of(ph)
    vv, hh = np.meshgrid(np.array(v[:-1], dtype=float), np.array(h, dtype=float) - 90.0, indexing="ij")
    want = _quadrant_cd(vv, hh + 90.0) * (1 + (hh + 90.0) / 1000) * CYCLES_IES_CANDELA_FACTOR
    np.testing.assert_allclose(prof.at(np.radians(hh), np.radians(vv)), want, rtol=1e-5, atol=1e-4)
    mirrored = prof.at(np.radians(360.0 - hh[:, 1:-1]), np.radians(vv[:, 1:-1]))
    np.testing.assert_allclose(mirrored, want[:, 1:-1], rtol=1e-5, atol=1e-4)


def test_one_plane_is_the_same_all_around():
    v = list(range(0, 181, 10))
    prof = CyclesProfile.of(parse_lm63(_ies(v, [0], [pf.downlight_cd(np.array(v, dtype=float))])))
    d = _directions()
    turned = d @ np.array([[math.cos(1.1), -math.sin(1.1), 0], [math.sin(1.1), math.cos(1.1), 0], [0, 0, 1]])
    np.testing.assert_allclose(prof.along(d), prof.along(turned), rtol=1e-6, atol=1e-9)


def test_cycles_interpolation_at_and_between_the_angles():
    """At the table's angles the value is the file's candela x 4 pi / 177.83; between them Catmull-Rom
    (which reproduces a linear function exactly away from the ends); beyond the last vertical angle 0."""
    v = np.arange(0.0, 91.0, 10.0)
    rows = [100 + 2 * v, 100 + 2 * v]
    prof = CyclesProfile.of(parse_lm63(_ies(v, [0, 180], rows)))
    assert CYCLES_IES_CANDELA_FACTOR == pytest.approx(0.0706650768394, rel=1e-11)  # Cycles' literal
    h = np.full(len(v) - 1, 0.7)
    np.testing.assert_allclose(prof.at(h, np.radians(v[:-1])), (100 + 2 * v[:-1]) * CYCLES_IES_CANDELA_FACTOR,
                               rtol=1e-6)
    mid = np.radians(np.array([15.0, 37.0, 64.0, 75.0]))
    np.testing.assert_allclose(prof.at(np.full(4, 2.0), mid), (100 + 2 * np.degrees(mid)) * CYCLES_IES_CANDELA_FACTOR,
                               rtol=1e-5)
    assert np.all(prof.at(np.full(3, 1.0), np.radians([90.01, 120.0, 179.0])) == 0.0)


def test_type_b_is_transposed_as_cycles_does():
    """Type B (horizontal and vertical -90..90): Cycles transposes the table and shifts both axes by 90,
    so the candela of B's (horizontal Hb, vertical Vb) is the profile's value at h = Vb + 90, v = Hb + 90."""
    vb = np.arange(-90.0, 91.0, 15.0)
    hb = np.arange(-90.0, 91.0, 30.0)
    rows = [200 + hh + 0.5 * vb for hh in hb]
    ph = parse_lm63(_ies(vb, hb, rows, ptype=2))
    assert ph.photometric_type == TYPE_B
    prof = CyclesProfile.of(ph)
    H, V = np.meshgrid(hb, vb[:-1], indexing="ij")
    got = prof.at(np.radians(V + 90.0), np.radians(H + 90.0)).reshape(H.shape)
    want = np.array(rows)[:, :-1] * CYCLES_IES_CANDELA_FACTOR
    ok = H < 90.0  # (v = 180 is the table's end: 0, as Cycles)
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-5)


# -- malformed files: each refused, its line named ------------------------------------------------
GOOD = _ies([0, 45, 90], [0, 90], [[100, 80, 10], [100, 70, 5]])


@pytest.mark.parametrize("text, words", [
    (GOOD.replace("3 2 1 2 0.1", "3 2 3 2 0.1"), ["line 5", "type A"]),
    (GOOD.replace("3 2 1 2 0.1", "3 2 7 2 0.1"), ["line 5", "type 7"]),
    (GOOD.replace("3 2 1 2 0.1", "3 2 1 5 0.1"), ["line 5", "units type 5"]),
    (GOOD.replace("TILT=NONE\n", ""), ["no TILT="]),
    ("TILT=NONE\n" + GOOD.split("TILT=NONE\n")[1], ["line 1", "TILT="]),
    (GOOD.rsplit("100 70 5", 1)[0] + "100 70\n", ["ends at line", "truncated"]),
    (GOOD.replace("1 1 50", "1 1"), ["line 6", "missing"]),
    (GOOD.replace("1 1000 1 3 2", "1 1000 3 2"), ["line 5", "missing"]),
    (GOOD.split("1 1 50")[0], ["ends at line", "truncated"]),
    (GOOD.replace("100 70 5", "100 seventy 5"), ["line 10", "'seventy'"]),
    (GOOD.replace("100 70 5", "100 -70 5"), ["line 10", "negative candela"]),
    (GOOD.replace("0 45 90\n", "0 90 45\n"), ["line 7", "does not increase"]),
    (GOOD.replace("0 45 90\n", "0 45 190\n"), ["line 7", "outside"]),
    (GOOD.replace("0 90\n", "0 270\n"), ["line 8", "symmetric"]),
    (GOOD.replace("1 1000 1 3", "1 1000 nan 3"), ["line 5", "finite"]),
    (GOOD.replace("1 1000 1 3", "1.5 1000 1 3"), ["line 5", "whole number"]),
    (GOOD.replace("1 1000 1 3", "1 1000 1 1"), ["line 5", "at least 2"]),
    (GOOD.replace("1 1000 1 3", "1 1000 -2 3"), ["line 5", "negative candela multiplier"]),
])
def test_malformed_lm63_is_refused_naming_its_line(text, words):
    with pytest.raises(PhotometryError) as e:
        parse_lm63(text, "bad.ies")
    msg = str(e.value)
    assert msg.startswith("bad.ies") and "\n" not in msg
    for w in words:
        assert w in msg, msg


# -- EULUMDAT ------------------------------------------------------------------------------------
def _ldt(isym, mc, dc, ng, dg, cd_klm, flux=2000.0, factor=1.0, n_sets=1):
    """EULUMDAT text of intensities cd_klm(c, g) (cd/klm) stored as Isym asks."""
    c = np.arange(mc) * dc
    g = np.arange(ng) * dg
    planes = {0: c, 1: c[:1], 2: c[c <= 180], 3: np.concatenate([c[c >= 270], c[c <= 90]]), 4: c[c <= 90]}[isym]
    lines = ["Relight test", "1", str(isym), str(mc), f"{dc:g}", str(ng), f"{dg:g}", "report", "luminaire", "L-1",
             "t.ldt", "2026", "300", "0", "100", "250", "0", "0", "0", "0", "0", "100", "80", f"{factor:g}", "0",
             str(n_sets)]
    lines += ["1"] * n_sets + ["LED"] * n_sets + [f"{flux / n_sets:g}"] * n_sets + ["3000"] * n_sets + \
        ["90"] * n_sets + ["20"] * n_sets
    lines += ["0.5"] * 10
    lines += [f"{x:g}" for x in c] + [f"{x:g}" for x in g]
    lines += [f"{cd_klm(cc, gg):.6g}" for cc in planes for gg in g]
    return "\r\n".join(lines) + "\r\n"


def _ldt_cd(c, g):
    return 300 * max(math.cos(math.radians(g)), 0) * (1 + 0.3 * math.cos(math.radians(2 * c)))


@pytest.mark.parametrize("isym", [0, 1, 2, 3, 4])
def test_eulumdat_reads_to_the_distribution_it_holds(isym):
    """Each symmetry stores fewer planes; read, the Cycles profile is the closed form's (cd/klm x the
    lamps' flux / 1000 x the conversion factor) in every direction, written as LM-63 and read back alike."""
    cd = (lambda c, g: _ldt_cd(0, g)) if isym == 1 else _ldt_cd
    ph = parse_eulumdat(_ldt(isym, 24, 15.0, 19, 10.0, cd, flux=2000.0, factor=1.1))
    assert ph.lumens == 2000.0 and ph.photometric_type == 1
    prof = CyclesProfile.of(ph)
    full = CyclesProfile.of(Photometry(1, np.arange(0.0, 181, 10), np.arange(0.0, 361, 15),
                                       [[cd(c, g) * 2.0 * 1.1 for g in range(0, 181, 10)] for c in range(0, 361, 15)]))
    d = _directions()
    np.testing.assert_allclose(prof.along(d), full.along(d), rtol=1e-5, atol=1e-6)
    again = CyclesProfile.of(parse_lm63(write_lm63(ph)))
    np.testing.assert_allclose(again.along(d), prof.along(d), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("cut, words", [
    (lambda t: "\r\n".join(t.split("\r\n")[:60]), ["ends at line 60", "truncated"]),
    (lambda t: t.replace("\r\n2\r\n24\r\n", "\r\n7\r\n24\r\n", 1), ["line 3", "Isym"]),
    (lambda t: t.replace("\r\n15\r\n19\r\n", "\r\n15\r\nmany\r\n", 1), ["line 6", "'many'"]),
])
def test_malformed_eulumdat_is_refused_naming_its_line(cut, words):
    with pytest.raises(PhotometryError) as e:
        parse_eulumdat(cut(_ldt(2, 24, 15.0, 19, 10.0, _ldt_cd)), "bad.ldt")
    for w in words:
        assert w in str(e.value), str(e.value)


# -- the lamp: CIE 171:2006's point source over a work plane -------------------------------------
def _plane(n=20, side=4.0):
    s = side / n
    polys = [[(x0, y0, 0.0), (x0 + s, y0, 0.0), (x0 + s, y0 + s, 0.0), (x0, y0 + s, 0.0)]
             for y0 in -side / 2 + s * np.arange(n) for x0 in -side / 2 + s * np.arange(n)]
    return mesh_patches(polygon_faceset(polys, reflectance=0.5), 10.0), s


@pytest.mark.parametrize("name", ["downlight", "batwing", "asymmetric"])
def test_cie171_point_source_over_a_work_plane(name):
    """CIE 171:2006 (5.2-5.4's point sources): a luminaire of a given distribution 1.8 m over a work
    plane; each patch's illuminance (Relight's lx: 683 lm/W, Rec.709) is the closed form
    E = I(theta) cos(theta) / d^2 averaged over the patch, within 1 %, for a lamp of Power
    177.83 / 683 W (Cycles' candela at Relight's lumens: engine.units.cycles_ies_candela)."""
    ph = pf.FIXTURES[name]()
    prof = CyclesProfile.of(ph)
    power = CYCLES_IES_LUMENS_PER_WATT / LUMENS_PER_WATT
    assert cycles_ies_candela([power] * 3, 1.0) == pytest.approx(1.0)
    pos = np.array([0.3, -0.1, 1.8])
    lamp = Lamp("f", PHOTOMETRIC, pos, DOWN, X, Y, (power,) * 3, profile=prof)
    ps, s = _plane()
    lux = illuminance_lux(lamp_irradiance(ps, [lamp], seed=0)[:, 0, :])
    if name == "asymmetric":  # h = atan2(x, y) + pi in the lamp's frame: C0 along -Y, C90 along -X
        def cd(points):
            d = points - pos
            r = np.linalg.norm(d, axis=1)
            return pf.asymmetric_cd(np.degrees(np.arccos(-d[:, 2] / r)),
                                    np.degrees(np.arctan2(d[:, 0], d[:, 1]) + math.pi)) * (-d[:, 2] / r) / r ** 2
    else:
        fun = {"downlight": pf.downlight_cd, "batwing": pf.batwing_cd}[name]

        def cd(points):
            return pf.point_irradiance(fun, pos, points)
    m = 12
    g = (np.arange(m) + 0.5) / m
    ref = np.zeros(ps.n_patches)
    for p in range(ps.n_patches):
        x0, y0 = ps.tri_vertices[ps.tri_patch == p].reshape(-1, 3)[:, :2].min(axis=0)
        xx, yy = np.meshgrid(x0 + g * s, y0 + g * s)
        ref[p] = cd(np.column_stack([xx.ravel(), yy.ravel(), np.zeros(m * m)])).mean()
    lit = ref > 0.02 * ref.max()
    rel = np.abs(lux[lit] - ref[lit]) / ref[lit]
    print(f"{name}: {lit.sum()} patches, mean {rel.mean():.5f} max {rel.max():.5f}")
    assert rel.max() < 0.01, (rel.max(), rel.mean())
    assert np.all(lux[~lit] <= 0.03 * ref.max())


def test_a_downlights_flux_is_its_closed_form():
    """cos^4 below the horizon: flux 2 pi I0 / 5 (lm), integrated from Cycles' profile."""
    ph = pf.FIXTURES["downlight"]()
    assert ph.flux_lm() == pytest.approx(2 * math.pi * pf.DOWNLIGHT_I0 / 5, rel=2e-3)


def test_a_photometric_lamp_needs_its_distribution():
    with pytest.raises(ValueError, match="distribution"):
        Lamp("f", PHOTOMETRIC, (0, 0, 1.0), DOWN, X, Y, (1.0,) * 3)
