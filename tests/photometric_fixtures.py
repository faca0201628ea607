"""Closed-form luminaire distributions written as LM-63 by the project's own writer
(engine.photometry.write_lm63), for the photometric tests (tests/test_photometry.py,
tests/test_cycles_photometric.py), and a Blender Point lamp holding one in an IES Texture node."""
import math

import numpy as np

from relight_addon.engine.photometry import Photometry, write_lm63

#: a downlight: I = I0 cos^4(v) below the horizon, 0 above (0..180 by 2.5 degrees; one plane)
DOWNLIGHT_I0 = 1500.0
#: a batwing: I = I0 (0.3 + sin^2(2 v)) cos(v) below the horizon, peaks near 55 degrees, 0 above
BATWING_I0 = 900.0


def downlight_cd(v_deg, h_deg=0.0):
    c = np.cos(np.radians(v_deg))
    return DOWNLIGHT_I0 * np.where(c > 0, c, 0.0) ** 4 + 0.0 * np.asarray(h_deg, dtype=float)


def batwing_cd(v_deg, h_deg=0.0):
    v = np.radians(v_deg)
    return BATWING_I0 * (0.3 + np.sin(2 * v) ** 2) * np.maximum(np.cos(v), 0.0) + 0.0 * np.asarray(h_deg, dtype=float)


def asymmetric_cd(v_deg, h_deg):
    """Lopsided: brighter towards the C0 plane than C180, and more along C90 than C270."""
    v, h = np.radians(v_deg), np.radians(h_deg)
    return 800.0 * np.maximum(np.cos(v), 0.0) * (1.0 + 0.6 * np.cos(h) + 0.3 * np.sin(h))


def photometry(cd, v_step=2.5, h_angles=(0.0,), lumens=-1.0, **kw) -> Photometry:
    """The type C Photometry of ``cd(v, h)`` (degrees) on vertical angles 0..180 by ``v_step``."""
    v = np.arange(0.0, 180.0 + 1e-9, v_step)
    h = np.asarray(h_angles, dtype=float)
    table = np.array([cd(v, hh) for hh in h])
    return Photometry(1, v, h, table, lumens=lumens, **kw)


FIXTURES = {
    "downlight": lambda: photometry(downlight_cd),
    "batwing": lambda: photometry(batwing_cd, h_angles=(0.0, 45.0, 90.0)),  # one quadrant
    "asymmetric": lambda: photometry(asymmetric_cd, v_step=5.0, h_angles=np.arange(0.0, 360.0 + 1e-9, 10.0)),
}


def lm63_text(name) -> str:
    if name in TEXTS:
        return TEXTS[name]()
    return write_lm63(FIXTURES[name](), {"LUMINAIRE": name})


def _tilted_downlight() -> str:
    """The downlight with what Cycles ignores changed: a TILT=INCLUDE block halving every angle's
    intensity, another lumens field, a luminous opening of 0.3 x 0.3 x 0.1 m."""
    text = write_lm63(FIXTURES["downlight"](), {"LUMINAIRE": "tilted"})
    text = text.replace("TILT=NONE\n1 -1 1", "TILT=INCLUDE\n1\n3\n0 45 90\n0.5 0.5 0.5\n1 12345 1")
    return text.replace(" 1 2 0 0 0\n", " 1 2 0.3 0.3 0.1\n")


def type_b_cd(hb, vb):
    return 500.0 * (0.3 + 0.7 * np.cos(np.radians(hb)) ** 2) * (1.0 + 0.5 * np.sin(np.radians(vb)))


def _type_b() -> str:
    """A type B file (horizontal 0..90, mirrored by Cycles; vertical -90..90)."""
    vb = np.arange(-90.0, 90.1, 10.0)
    hb = np.arange(0.0, 90.1, 10.0)
    lines = ["IESNA:LM-63-2002", "[TEST] type B", "TILT=NONE",
             f"1 -1 1 {len(vb)} {len(hb)} 2 2 0 0 0", "1 1 10",
             " ".join(f"{x:g}" for x in vb), " ".join(f"{x:g}" for x in hb)]
    lines += [" ".join(f"{type_b_cd(h, v):.6g}" for v in vb) for h in hb]
    return "\n".join(lines) + "\n"


#: LM-63 texts written by hand (what the writer does not write)
TEXTS = {"tilted downlight": _tilted_downlight, "type B": _type_b}


def ies_point_lamp(bpy, name, location, rotation, text, energy, strength=1.0, color=(1.0, 1.0, 1.0), path=None,
                   radius=0.0, light_type="POINT", **settings):
    """A Point lamp (or ``light_type``, with ``settings``) whose node tree is an IES Texture node
    (internal text, or the file ``path``) feeding its Emission's Strength."""
    ld = bpy.data.lights.new(name, light_type)
    ld.energy, ld.shadow_soft_size = energy, radius
    for k, v in settings.items():
        setattr(ld, k, v)
    ld.use_nodes = True
    nt = ld.node_tree
    em = next(n for n in nt.nodes if n.type == "EMISSION")
    ies = nt.nodes.new("ShaderNodeTexIES")
    if path is None:
        txt = bpy.data.texts.new(f"{name}.ies")
        txt.write(text)
        ies.mode, ies.ies = "INTERNAL", txt
    else:
        ies.mode, ies.filepath = "EXTERNAL", str(path)
    ies.inputs["Strength"].default_value = strength
    em.inputs["Color"].default_value = (*color, 1.0)
    nt.links.new(ies.outputs["Fac"], em.inputs["Strength"])
    ob = bpy.data.objects.new(name, ld)
    bpy.context.scene.collection.objects.link(ob)
    ob.location, ob.rotation_euler = location, rotation
    return ob


def point_irradiance(ph_cd, lamp_pos, points, normal=(0.0, 0.0, 1.0)):
    """CIE 171:2006's point source over a plane (test case 5.x): E = I(theta) cos(theta) / d^2 (lx)
    at ``points`` (n, 3) from a downward lamp at ``lamp_pos``, I(theta) = ph_cd(theta deg)."""
    d = np.asarray(points, dtype=float) - np.asarray(lamp_pos, dtype=float)
    r = np.linalg.norm(d, axis=1)
    theta = np.degrees(np.arccos(np.clip(-d[:, 2] / r, -1, 1)))
    cos_r = np.maximum(-(d @ np.asarray(normal)) / r, 0.0)
    return ph_cd(theta) * cos_r / r ** 2


__all__ = ["FIXTURES", "lm63_text", "ies_point_lamp", "point_irradiance", "photometry", "math"]
