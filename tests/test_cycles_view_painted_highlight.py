"""A painted highlight pulls a lamp to where its reflection lands (issue 40's acceptance): the room of
view_rooms.py (matte walls and floor, a glossy table of Roughness 0.25, lights allowed on the ceiling
and the north wall), a camera-view target alone -- a dim uniform radiance over the lower image and a
bright disc of 4 pixels' radius painted on the table top -- solved with the candidate lamps on
(engine.targets.view.highlight_mounts: the camera's ray at the highlight, mirrored by the table,
lands on the north wall, where a mounting position is offered); Cycles renders the table's region of
the written file at the working resolution (480 x 270, cropped), and the brightest pixel of the table
(3 x 3 box mean) is within 3 pixels of the painted disc's centre, in the prediction and in Cycles.

Before the mounts (the lamps offered at the k-means positions and aimed at the view target's patches
only): the answer's spot hung at the south end of the ceiling and the predicted peak was 11 pixels
from the painted one (relative error 0.387; with the mounts 0.355, the peak 1 pixel away)."""

import numpy as np
import pytest

pytestmark = [pytest.mark.cycles, pytest.mark.slow]

bpy = pytest.importorskip("bpy", reason="Cycles renders through bpy")

import view_rooms as vr  # noqa: E402
from test_cycles_view_highlight import _smooth  # noqa: E402

PAINTED = (148, 200)  # (row, column) of the painted highlight's centre in the working image
RADIUS = 4
PEAK_TOL = 3.0
CROP = (150, 330, 100, 200)  # the table top's region (x0, x1, y0, y1), rendered alone
CROP_SAMPLES = 512


def _target():
    H, W = vr.HEIGHT, vr.WIDTH
    rgba = vr.lower_image_target(0.05)
    yy, xx = np.mgrid[0:H, 0:W]
    rgba[(yy - PAINTED[0]) ** 2 + (xx - PAINTED[1]) ** 2 <= RADIUS ** 2, :3] = 2.0
    return rgba


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("painted_highlight")
    vr.build(tmp / "room.blend", patch_size=0.2, lights_on=("ceiling", "wall_n"))
    report, pred = vr.solve_view(tmp, _target())
    crop = vr.render(tmp / "out.blend", tmp / "crop.exr", CROP_SAMPLES, seed=0, border=CROP)
    return report, pred, crop


def _peak(lum):
    return np.array(np.unravel_index(np.argmax(lum), lum.shape))


def test_a_painted_highlight_is_where_cycles_renders_the_answers_highlight(solved):
    report, pred, crop = solved
    x0, x1, y0, y1 = CROP
    kinds = [li["kind"] for li in report["final"]["lights"]]
    lum_c = _smooth(crop[..., :3].sum(axis=2))
    lum_p = _smooth(pred[y0:y1, x0:x1, :3].sum(axis=2))
    painted = np.array(PAINTED) - (y0, x0)
    pc, pp = _peak(lum_c), _peak(lum_p)
    print(f"lights {kinds} (relative error {report['final']['relative_error']:.4f}); highlight peak (row, column): "
          f"painted {PAINTED}, predicted {(pp + (y0, x0)).tolist()} ({np.linalg.norm(pp - painted):.2f} px), "
          f"Cycles {(pc + (y0, x0)).tolist()} ({np.linalg.norm(pc - painted):.2f} px, "
          f"{lum_c.max() / np.median(lum_c):.1f} x the region's median)")
    assert report["model"]["lights_by_kind"]["spot"] > 0  # (lamps offered for a view target alone)
    assert lum_c.max() > 3 * np.median(lum_c)  # (a highlight in Cycles' image)
    assert np.linalg.norm(pp - painted) <= PEAK_TOL
    assert np.linalg.norm(pc - painted) <= PEAK_TOL
