"""A reference image to match (issue 40, acceptance): Cycles renders the camera's image of the room
of view_rooms.py lit by a known configuration of 3 emitting ceiling polygons; the same room without
them is solved with that image as its view target (`solve --view-target REF.exr`: an OpenEXR,
linear, every pixel painted); Cycles renders the written file from the camera, and its image is
within 5 % of the reference, mean per pixel, with at most 3 lights. The images are rendered at
64 x 36 (view_target's RENDER: the noise of a pixel falls with its samples, not its size), the
reference read at the working resolution (480 x 270, box-resampled); Cycles' noise is measured from
two renders of different seeds of each image and printed with the error.

The reference is rendered with light paths that carry the light to convergence (a photograph's:
``match_light_paths`` for the room's largest reflectance, 0.7: 13 bounces, no clamping, no Filter
Glossy), as the written file is (``--out`` writes the same). With the file's defaults (4 diffuse
bounces, Clamp Indirect 10) the reference lacks about 6 % of the room's light, unevenly (more where
the light has bounced more), which no configuration rendered with complete light paths can give:
the render of the answer was then 6.9 % from it (the test's first form, an xfail)."""
import json

import numpy as np
import pytest

pytestmark = [pytest.mark.cycles, pytest.mark.slow]

bpy = pytest.importorskip("bpy", reason="Cycles renders through bpy")

import view_rooms as vr  # noqa: E402

SAMPLES = 2048  # per render; two renders (seeds 0 and 1) of each image, averaged
RENDER = (64, 36)
#: the known configuration: ceiling polygons (column, row of its 8 x 8 grid) and Emission Strengths
EMITTERS = [(1, 2, 8.0), (4, 1, 12.0), (6, 5, 6.0)]
MEAN_TOL = 0.05


#: the room's largest reflectance (view_rooms: walls and ceiling 0.7)
RHO_MAX = 0.7


def _complete_light_paths(blend, rho_max):
    """The file's Cycles light paths set as Relight's Match Cycles Light Paths sets them (the
    written file's), saved."""
    from relight_addon.blender.light_paths import match_light_paths

    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert match_light_paths(bpy.context.scene, rho_max)  # (the defaults differ: something changed)
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))


def _noise(a, b, lum):
    return (np.abs(a[..., :3] - b[..., :3]).sum(axis=2) / 2) / lum


@pytest.fixture(scope="module")
def matched(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("view_reference")
    vr.build(tmp / "lit.blend", patch_size=0.2, emitters=EMITTERS)
    _complete_light_paths(tmp / "lit.blend", RHO_MAX)
    ref = [vr.render(tmp / "lit.blend", tmp / f"ref{s}.exr", SAMPLES, seed=s, size=RENDER) for s in (0, 1)]
    rgba = (ref[0] + ref[1]) / 2
    rgba[..., 3] = 1.0  # (every pixel painted)
    vr.write_exr(tmp / "reference.exr", rgba)
    vr.build(tmp / "room.blend", patch_size=0.2)
    code, err = vr.relight_cli("solve", tmp / "room.blend", "--report", tmp / "r.json", "--out", tmp / "out.blend",
                               "--view-target", tmp / "reference.exr", "--quiet")
    assert code == 0, err[-2000:]
    report = json.loads((tmp / "r.json").read_text())
    out = [vr.render(tmp / "out.blend", tmp / f"out{s}.exr", SAMPLES, seed=s, size=RENDER) for s in (0, 1)]
    return report, ref, out


def test_the_solve_matches_a_reference_of_three_lights(matched):
    report, ref, out = matched
    r = (ref[0][..., :3] + ref[1][..., :3]).sum(axis=2) / 2
    o = (out[0][..., :3] + out[1][..., :3]).sum(axis=2) / 2
    ok = r > 0
    rel = np.abs(o - r)[ok] / r[ok]
    n_ref, n_out = _noise(*ref, r)[ok], _noise(*out, np.maximum(o, 1e-30))[ok]
    print(f"view target: {report['view_target']}; {report['final']['n_lights']} lights; Cycles 2 x {SAMPLES} "
          f"samples at {RENDER[0]} x {RENDER[1]}: pixel noise {n_ref.mean():.4f} (reference), {n_out.mean():.4f} "
          f"(the written file) (mean, relative); render of the written file vs the reference over {ok.sum()} pixels: "
          f"mean {rel.mean():.4f}, median {np.median(rel):.4f}, 95th percentile {np.quantile(rel, 0.95):.4f}, "
          f"signed {np.mean((o - r)[ok] / r[ok]):+.4f}")
    assert report["final"]["n_lights"] <= 3
    assert ok.sum() == r.size  # (every pixel sees the room)
    assert rel.mean() <= MEAN_TOL
