"""Grey paint on a coloured surface is a brightness (engine/paint.py). References: the paint's
own luminance (Rec.709), and the automatic light colour's choice on an orange desk painted grey,
read literally and read as a brightness."""
import numpy as np
import pytest

from relight_addon.engine.options import JobOptions
from relight_addon.engine.paint import neutral_as_brightness
from relight_addon.engine.scene import polygon_faceset
from relight_addon.engine.units import luminance_weighted
from relight_addon.pipeline.jobs import run_solve
from test_engine_extent import _quad  # (a quad of 4 corners)

ORANGE = (0.8, 0.4, 0.15)
GREY = 0.35


def desk_room():
    """A 4 x 4 x 3 m white room, an orange desk top 0.75 m high painted grey (radiance 0.35); only
    the ceiling may hold lights."""
    X = Y = 4.0
    Z = 3.0
    polys = [_quad((0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)), _quad((0, 0, 0), (0, 0, Z), (X, 0, Z), (X, 0, 0)),
             _quad((0, Y, 0), (X, Y, 0), (X, Y, Z), (0, Y, Z)), _quad((0, 0, 0), (0, Y, 0), (0, Y, Z), (0, 0, Z)),
             _quad((X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)), _quad((0, 0, Z), (0, Y, Z), (X, Y, Z), (X, 0, Z)),
             _quad((1.5, 1.5, 0.75), (2.5, 1.5, 0.75), (2.5, 2.5, 0.75), (1.5, 2.5, 0.75))]
    rho = np.array([(0.7, 0.7, 0.7)] * 6 + [ORANGE])
    faces = polygon_faceset(polys, reflectance=rho)
    faces.target[6] = True
    faces.target_radiosity[6] = np.pi * GREY
    faces.forbidden[:5] = True
    faces.forbidden[6] = True
    return faces


def test_neutral_paint_keeps_its_luminance_on_the_surface_colour():
    rho = np.array([ORANGE, ORANGE, (0.5, 0.5, 0.5), ORANGE])
    paint = np.array([(0.35, 0.35, 0.35), (0.6, 0.2, 0.2), (0.3, 0.3, 0.3), (0.0, 0.0, 0.0)])
    out = neutral_as_brightness(np.ones(4, dtype=bool), paint, rho)
    np.testing.assert_allclose(luminance_weighted(out[0]), 0.35, rtol=1e-12)  # its luminance kept ...
    np.testing.assert_allclose(out[0] / out[0].max(), np.array(ORANGE) / 0.8, rtol=1e-12)  # ... in the desk's hue
    np.testing.assert_array_equal(out[1:], paint[1:])  # a hue picked, a grey surface, black: as painted
    assert np.array_equal(neutral_as_brightness(np.zeros(4, dtype=bool), paint, rho), paint)  # (unpainted)


def test_grey_paint_on_an_orange_desk_is_answered_with_white_light():
    """Read literally (the desk's radiance grey), the automatic light colour chose free colours and
    saturated blue lights; read as a brightness, blackbody lights, and the desk's predicted
    luminance within 5 % of the painted one (measured: 3 % below, relative error 0.028)."""
    options = JobOptions(spot_lamps=False, max_lights=2, max_patch_size=0.5, seed=1)
    literal = run_solve(desk_room(), options)
    assert "light colour: free, chosen automatically" in " ".join(literal.report["warnings"])
    faces = desk_room()
    faces.target_radiosity = neutral_as_brightness(faces.target, faces.target_radiosity, faces.reflectance)
    out = run_solve(faces, options)
    notes = " ".join(out.report["warnings"])
    assert "light colour: blackbody" in notes, notes
    B = out.report["targets_photometric"]
    (desk,) = B.values()
    assert out.report["final"]["relative_error"] < 0.05
    assert luminance_weighted(np.asarray(desk["radiosity_mean"])) / np.pi == pytest.approx(GREY, rel=0.05)
    for li in out.report["final"]["lights"]:
        e = np.asarray(li["exitance"])
        assert e.min() / e.max() > 0.3, e  # no saturated light
