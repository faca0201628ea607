"""The same scene in centimetres, metres or kilometres gives the same lights, scaled (issue 34:
an artist's file is seldom in metres). Reference: the metre scene's own solve; an exact
similarity (every length x s, every area x s^2, radiance unchanged) leaves the inverse problem's
relative error as it is and multiplies each light's power by s^2."""
import numpy as np
import pytest

pytestmark = pytest.mark.slow  # (whole solves of several scenes: make test-all, not make test)

pytest.importorskip("bpy", reason="bpy (Blender as a Python module) is not installed")
import artist_scenes  # noqa: E402
import cycles_reference as cr  # noqa: E402
from relight_addon.blender import export  # noqa: E402
from relight_addon.engine.options import JobOptions  # noqa: E402
from relight_addon.pipeline import jobs  # noqa: E402


def _solve(scale):
    cr.reset_blender()
    try:
        artist_scenes.living_room(1)
        artist_scenes.scale_scene(scale)
        exp = export.export_scene()
    finally:
        cr.reset_blender()
    return jobs.run_solve(exp.faces, JobOptions().validate(), default_max_patch_size=exp.settings.get("max_patch_size"))


def test_the_living_room_at_a_hundredth_and_a_thousand_times_its_size():
    one = _solve(1.0)
    r1 = one.report["final"]
    for s in (0.01, 1000.0):
        out = _solve(s)
        r = out.report["final"]
        assert out.report["scene"]["patches"] == one.report["scene"]["patches"]
        assert r["relative_error"] == pytest.approx(r1["relative_error"], rel=0.01), s
        assert [li["kind"] for li in r["lights"]] == [li["kind"] for li in r1["lights"]]
        np.testing.assert_allclose([li["power"] for li in r["lights"]],
                                   np.array([li["power"] for li in r1["lights"]]) * s ** 2, rtol=0.02)
        np.testing.assert_allclose([li["center"] for li in r["lights"]],
                                   np.array([li["center"] for li in r1["lights"]]) * s, rtol=1e-3, atol=1e-3 * s)
