"""The committed sample scenes open in whichever Blender runs this file: the main .venv (bpy 5.0)
and, through tests/test_compat.py, Blender 4.2 LTS, 4.5 LTS and 5.3. They are written by the
oldest supported Blender (`make samples`, bpy 4.2); a file saved by 5.0 cannot be read by 4.x.

References: the geometry sample_blends/generate.py documents (1451 faces in the staircase,
44 painted target faces, the Cornell box's 9 objects) and the file's own version stamp.
"""
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy", reason="opens .blend files with Blender's bpy module")

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = sorted((ROOT / "sample_blends").glob("*.blend"))


def _targets(ob):
    """Polygons whose relight_target corners have mean alpha >= 0.5 (the add-on's rule)."""
    attr = ob.data.attributes.get("relight_target")
    if attr is None:
        return 0
    n = 0
    for poly in ob.data.polygons:
        alpha = [attr.data[i].color[3] for i in poly.loop_indices]
        n += sum(alpha) / len(alpha) >= 0.5
    return n


def test_samples_are_shipped():
    names = {p.name for p in SAMPLES}
    assert {"cornell_box.blend", "staircase.blend", "staircase_targets.blend"} <= names


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.name)
def test_sample_opens(path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    # bpy.data.version: the Blender version that saved the file; never newer than this one
    assert tuple(bpy.data.version[:2]) <= tuple(bpy.app.version[:2]), bpy.data.version
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    assert meshes and all(len(o.data.polygons) for o in meshes)
    faces = sum(len(o.data.polygons) for o in meshes)
    if path.name.startswith("staircase"):
        assert faces == 1451
        assert bpy.context.scene.get("relight_max_patch_size") == pytest.approx(1.3)
        painted = sum(_targets(o) for o in meshes)
        assert painted == (44 if path.name == "staircase_targets.blend" else 0)
    elif path.name == "cornell_box.blend":
        assert len(bpy.data.objects) == 9
    else:
        assert {o.name for o in meshes} == {"receiver", "emitter"}
