"""A lamp's highlight on a glossy table in the camera-view target, checked against Cycles (issue 40):
the room of view_rooms.py (matte walls and floor, a glossy table of Roughness 0.25) with a spot lamp
of its own (fixed light, not seen by the camera) behind the table, aimed at it, so the camera sees its
reflection on the table top; painted pixels only (the wall and the table a uniform radiance, the top
rows free); ``solve --view-target --view-prediction --out`` (ceiling cells add the rest); Cycles
renders the written file from the camera.

- the image: the predicted image (the spot's highlight reflected through the table's BSDF,
  engine/view_lamps.py) matches Cycles' within 5 % mean per painted pixel at 64 x 36 (as
  tests/test_cycles_view_target.py compares; Cycles' noise from two seeds, printed);
- the highlight: its peak (the brightest pixel of the table, both images smoothed over 3 x 3) at the
  working resolution (480 x 270; Cycles renders the table's region alone, cropped) within 3 pixels
  of the predicted one.

Measured (h40-highlight, load 5 on 2 shared cores, 5.6 min: the solve, two renders at 64 x 36 and the
crop): 4.38 % mean per painted pixel (median 2.79 %, 95th percentile 14.6 %) over 1,920 pixels,
Cycles' noise 2.27 %; the peak at (148, 240) in Cycles and (148, 239) predicted, 49 x the table
region's median in both (without the highlight term it was not predicted at all).

Measured after the glossy rows stopped counting their first reflection's albedo at incidence twice
(TargetKind.bsdf_rows), load 1-3: 4.57 % (median 3.09 %, 95th percentile 14.1 %), noise 2.18 % at
2 x 16,384 samples; the peak 0 pixels apart. That change moved the answer to three small corner cells
(a cell and two polygons before, 4.19 % with noise 2.27 % at 2 x 4,096), which render noisier: 6.09 %
with noise 4.21 % at 2 x 4,096, hence the samples.

The answer's lights are the ceiling's cells (``--no-spot-lamps``). The default solve adds candidate
spots (engine.targets.view's aims), and its render is 5.22 % from the prediction at load 1 (5.46 %
before the table's glossy rows stopped counting their own first reflection's albedo at incidence
twice, TargetKind.bsdf_rows, which took tests/test_cycles_view_target.py's spot answer from 5.00 % to
3.15 %): above 5 % here, not analysed further (the scene's fixed spot and the answer's spot both
light the glossy table)."""

import numpy as np
import pytest

pytestmark = [pytest.mark.cycles, pytest.mark.slow]

bpy = pytest.importorskip("bpy", reason="Cycles renders through bpy")

import view_rooms as vr  # noqa: E402

SAMPLES = 16384  # per render at 64 x 36; two renders (seeds 0 and 1) are averaged (the answer's three small corner cells render with 4.2 % noise at 2 x 4096)
RENDER = (64, 36)
MEAN_TOL = 0.05
PEAK_TOL = 3.0  # pixels at the working resolution
BASE = 0.05
#: the spot: behind the table (north), low, aimed at the table's middle; its mirror image through the
#: table top is seen by the camera on the table
SPOT = dict(type="SPOT", location=(2.0, 2.85, 1.35), aim=(2.0, 1.9, 0.75), energy=10.0, radius=0.02, size=60.0,
            blend=0.15)
#: the table top's region of the working image (x0, x1, y0, y1; the highlight near row 150, column 240): rendered
#: alone at 480 x 270
CROP = (150, 330, 100, 200)
CROP_SAMPLES = 512


def _target():
    return vr.lower_image_target(BASE)


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("view_highlight")
    vr.build(tmp / "room.blend", patch_size=0.2, lamps=[SPOT])
    report, pred = vr.solve_view(tmp, _target(), "--no-spot-lamps")
    renders = [vr.render(tmp / "out.blend", tmp / f"cycles{s}.exr", SAMPLES, seed=s, size=RENDER) for s in (0, 1)]
    crop = vr.render(tmp / "out.blend", tmp / "crop.exr", CROP_SAMPLES, seed=2, border=CROP)
    return report, pred, renders, crop


def _smooth(img):
    """(h, w) the 3 x 3 box mean of a luminance image (edges: the pixels there are)."""
    p = np.pad(img, 1, mode="edge")
    return sum(p[1 + a:p.shape[0] - 1 + a, 1 + b:p.shape[1] - 1 + b] for a in (-1, 0, 1) for b in (-1, 0, 1)) / 9


def test_cycles_renders_the_predicted_image_with_the_lamps_highlight(solved):
    report, pred, renders, _ = solved
    rel, noise, ok, painted = vr.against_cycles(pred, renders, _target()[..., 3:], RENDER)
    print(vr.cycles_summary(report, rel, noise, ok, SAMPLES, RENDER))
    assert ok.sum() > 0.95 * painted.sum()
    assert rel.mean() <= MEAN_TOL


def test_the_highlights_peak_is_where_cycles_shows_it(solved):
    _, pred, _, crop = solved
    x0, x1, y0, y1 = CROP
    lum_c = _smooth(crop[..., :3].sum(axis=2))
    lum_p = _smooth(pred[y0:y1, x0:x1, :3].sum(axis=2))
    assert lum_c.shape == lum_p.shape
    pc = np.array(np.unravel_index(np.argmax(lum_c), lum_c.shape))
    pp = np.array(np.unravel_index(np.argmax(lum_p), lum_p.shape))
    # (a highlight: the peak well above the table's median, in both)
    print(f"highlight peak (row, column in the working image): Cycles {(pc + (y0, x0)).tolist()} "
          f"({lum_c.max() / np.median(lum_c):.2f} x the region's median), predicted {(pp + (y0, x0)).tolist()} "
          f"({lum_p.max() / np.median(lum_p):.2f} x), {np.linalg.norm(pc - pp):.2f} pixels apart")
    assert lum_c.max() > 2 * np.median(lum_c) and lum_p.max() > 2 * np.median(lum_p)
    assert np.linalg.norm(pc - pp) <= PEAK_TOL
