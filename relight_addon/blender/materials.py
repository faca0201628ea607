"""Blender materials -> the engine's Lambertian reflectance and emission, as Cycles renders them (bpy).

``material_properties(mat)`` returns ``(reflectance (3,), radiance (3,), note or None)``:
the effective Lambertian reflectance is the material's **white-furnace albedo** in Cycles (how
much of the light falling on it, uniformly from every direction, it sends back, per RGB channel;
see engine/principled.py for the Principled BSDF's layers), and ``radiance`` the emitted
radiance L_e (W m^-2 sr^-1; the engine's exitance is pi L_e, one-sided).

The surface shader is the node linked to the active Material Output's Surface (output target
All or Cycles), read through reroutes and muted nodes:

- **Principled BSDF**: Base Color, Roughness, IOR, Specular IOR Level, Specular Tint and the
  distribution (Multiscatter GGX / GGX) exactly as Cycles layers them; Metallic, Transmission,
  Coat, Sheen, Subsurface, Alpha, thin film and anisotropy by the approximations of
  engine/principled.py, each named in the note. Emission Color x Emission Strength (attenuated
  by the coat).
- **Diffuse BSDF**: Color (Lambert), or its Oren-Nayar albedo when Roughness > 0.
- **Emission**: reflectance 0, L_e = Color x Strength.
- **Mix Shader**: (1 - Fac) x first + Fac x second, Fac clamped to [0, 1]; a linked Fac is
  taken as 0.5, with a note. **Add Shader**: the sum.
- **Transparent BSDF** and **Holdout**: reflect nothing here (light through a transparent
  surface is treated as lost), with a note.
- Anything else (other shaders, node groups), and a linked Base Color / Color: the material's
  viewport colour ``Material.diffuse_color`` (as a Lambertian reflectance, or as the Principled
  BSDF's Base Color), with a note. Other linked inputs (a texture on Roughness, ...) use the
  socket's own unlinked value, with a note.
- A material without a node tree: its viewport colour. No material: handled by the caller.
- An image that an Image or Environment Texture node feeding the output reads from a file that
  is not there (``missing_images``): Cycles renders it magenta (1, 0, 1); named in the note (a
  baked emission is then magenta, as Cycles renders it; a linked colour is the viewport colour).

Linked emission (an Emission Color / Strength or Emission shader Color / Strength fed by a
texture, a procedural, an attribute..., or a Mix Shader with a linked factor over a branch that
emits) cannot be read from the node tree: the Closure lists it in ``linked_emission`` ("node:
input") and leaves it out of ``radiance`` (a linked Mix factor stays 0.5 there); export.py gets
each face's mean emitted radiance from a Cycles bake instead (emission_bake.py). An emission
input that is linked while its partner is an unlinked zero (a texture on Emission Color with
Emission Strength 0) emits nothing and is not listed.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..engine.principled import PrincipledParams, oren_nayar_albedo, principled_albedo

__all__ = ["material_properties", "surface_node", "active_output", "Closure", "surface_closure"]

_MAX_DEPTH = 64


@dataclass
class Closure:
    """What a shader (sub)tree amounts to for the radiosity engine."""

    reflectance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    radiance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    specular: np.ndarray = field(default_factory=lambda: np.zeros(3))  # glossy share of reflectance
    notes: list = field(default_factory=list)
    #: the BSDFs it sums, for view-dependent radiance (engine.principled.lobes_brdf):
    #: (weight, "principled", PrincipledParams) | (weight, "diffuse", (colour, roughness))
    lobes: list = field(default_factory=list)
    #: the linked inputs that make the emission vary ("node: input"), left out of ``radiance``
    #: (export.py bakes them: emission_bake.py)
    linked_emission: list = field(default_factory=list)

    def scaled(self, k):
        return Closure(self.reflectance * k, self.radiance * k, self.specular * k, list(self.notes),
                       [(w * k, kind, d) for w, kind, d in self.lobes],
                       list(self.linked_emission) if k > 0 else [])

    def __add__(self, other):
        return Closure(self.reflectance + other.reflectance, self.radiance + other.radiance,
                       self.specular + other.specular, _merge(self.notes, other.notes), self.lobes + other.lobes,
                       _merge(self.linked_emission, other.linked_emission))

    @property
    def emits(self) -> bool:
        """Whether it emits anything (a radiance or a linked emission)."""
        return bool(np.any(self.radiance > 0) or self.linked_emission)


def _merge(a, b):
    return list(a) + [n for n in b if n not in a]


def _rgb(socket):
    return np.asarray(socket.default_value[:3], dtype=np.float64)


def _value(node, name, default, notes):
    """An input's unlinked value (float or RGB tuple); a linked input is noted."""
    sock = node.inputs.get(name)
    if sock is None:
        return default
    if _linked(sock):
        notes.append(f"{node.name}: {name} is linked, using its unlinked value")
    v = sock.default_value
    try:
        return tuple(float(x) for x in v[:3])
    except TypeError:
        return float(v)


def _linked(sock) -> bool:
    return any(not link.is_muted for link in sock.links)


def _source(sock):
    """The node feeding ``sock`` through reroutes (None when unlinked)."""
    for _ in range(_MAX_DEPTH):
        links = [link for link in sock.links if not link.is_muted]
        if not links:
            return None
        node = links[0].from_node
        if node.bl_idname == "NodeReroute":
            sock = node.inputs[0]
            continue
        if node.mute:  # a muted node passes its first linked input of the same kind through
            passed = next((l.from_socket for l in node.internal_links if l.to_socket == links[0].from_socket), None)
            if passed is None:
                return None
            sock = passed
            continue
        return node
    return None


def active_output(mat):
    """The material's active Material Output node (target All or Cycles), or None."""
    tree = getattr(mat, "node_tree", None)
    if tree is None:
        return None
    if bpy.app.version < (5, 0, 0) and not mat.use_nodes:
        return None
    return tree_output(tree, "ShaderNodeOutputMaterial")


def tree_output(tree, bl_idname: str):
    """The tree's active output node of type ``bl_idname`` (a Material or World Output), target
    All or Cycles first, or None."""
    outputs = [n for n in tree.nodes if n.bl_idname == bl_idname]
    if not outputs:
        return None
    active = [n for n in outputs if n.is_active_output] or outputs
    return next((n for n in active if n.target in ("ALL", "CYCLES")), active[0])


def surface_node(mat):
    """The shader node linked to the material's active output (All or Cycles), or None."""
    out = active_output(mat)
    return None if out is None else _source(out.inputs["Surface"])


def _viewport(mat):
    return np.asarray(mat.diffuse_color[:3], dtype=np.float64)


#: Principled inputs read (keyword of PrincipledParams: (socket name, default))
_ALWAYS = {"roughness": ("Roughness", 0.5), "ior": ("IOR", 1.5), "specular_ior_level": ("Specular IOR Level", 0.5),
           "specular_tint": ("Specular Tint", (1.0,) * 3), "metallic": ("Metallic", 0.0),
           "transmission": ("Transmission Weight", 0.0), "coat_weight": ("Coat Weight", 0.0),
           "sheen_weight": ("Sheen Weight", 0.0), "subsurface_weight": ("Subsurface Weight", 0.0),
           "alpha": ("Alpha", 1.0), "thin_film_thickness": ("Thin Film Thickness", 0.0),
           "anisotropic": ("Anisotropic", 0.0), "diffuse_roughness": ("Diffuse Roughness", 0.0)}
_LAYERS = {"coat_weight": {"coat_roughness": ("Coat Roughness", 0.03), "coat_ior": ("Coat IOR", 1.5),
                           "coat_tint": ("Coat Tint", (1.0,) * 3)}}


def _principled(node, mat) -> Closure:
    notes = []
    base_sock = node.inputs["Base Color"]
    if _linked(base_sock):
        base = tuple(_viewport(mat))
        notes.append(f"{node.name}: Base Color is linked, using the viewport colour")
    else:
        base = tuple(float(x) for x in base_sock.default_value[:3])
    kw = {k: _value(node, name, d, notes) for k, (name, d) in _ALWAYS.items()}
    for gate, inputs in _LAYERS.items():  # a layer's other inputs only matter when it is on
        if kw[gate] > 0:
            kw.update({k: _value(node, name, d, notes) for k, (name, d) in inputs.items()})
    params = PrincipledParams(base_color=base, multiscatter=getattr(node, "distribution", "MULTI_GGX") != "GGX",
                              **kw)
    res = principled_albedo(params)
    notes.extend(res.notes)
    radiance, linked = _emission(node, "Emission Color", "Emission Strength")
    return Closure(res.albedo, radiance * res.emission, res.specular, notes, [(1.0, "principled", params)],
                   linked_emission=linked)


def _emission(node, color_name, strength_name):
    """(radiance (3,) of the unlinked inputs, [linked inputs "node: input"]): a linked input is
    listed unless its partner is an unlinked zero (nothing emitted then)."""
    c, s = node.inputs[color_name], node.inputs[strength_name]
    lc, ls = _linked(c), _linked(s)
    if not lc and not ls:
        return _rgb(c) * float(s.default_value), []
    if (not ls and float(s.default_value) == 0.0) or (not lc and not np.any(_rgb(c) != 0)):
        return np.zeros(3), []
    return np.zeros(3), [f"{node.name}: {name}" for name, lk in ((color_name, lc), (strength_name, ls)) if lk]


def _eval(node, mat, depth=0) -> Closure:
    if node is None:
        return Closure()
    if depth > _MAX_DEPTH:
        return Closure(notes=["the shader tree is too deep, the rest is ignored"])
    kind = node.bl_idname
    if kind == "ShaderNodeBsdfPrincipled":
        return _principled(node, mat)
    if kind == "ShaderNodeBsdfDiffuse":
        c = node.inputs["Color"]
        if _linked(c):
            return _fallback(mat, f"{node.name}: Color is linked, using the viewport colour")
        sigma = _value(node, "Roughness", 0.0, notes := [])
        color = np.maximum(_rgb(c), 0.0)
        return Closure(oren_nayar_albedo(color, sigma), notes=notes, lobes=[(1.0, "diffuse", (color, sigma))])
    if kind == "ShaderNodeEmission":
        radiance, linked = _emission(node, "Color", "Strength")
        return Closure(radiance=radiance, linked_emission=linked)
    if kind == "ShaderNodeMixShader":
        fac_sock = node.inputs[0]
        notes = []
        if _linked(fac_sock):
            fac = 0.5
            notes.append(f"{node.name}: its factor is linked, taken as 0.5")
        else:
            fac = float(np.clip(fac_sock.default_value, 0.0, 1.0))
        a0, b0 = _eval(_source(node.inputs[1]), mat, depth + 1), _eval(_source(node.inputs[2]), mat, depth + 1)
        out = a0.scaled(1.0 - fac) + b0.scaled(fac)
        out.notes = _merge(notes, out.notes)
        if _linked(fac_sock) and (a0.emits or b0.emits):  # the emission varies with the factor: baked
            out.linked_emission = _merge(out.linked_emission, [f"{node.name}: Fac"])
        return out
    if kind == "ShaderNodeAddShader":
        return _eval(_source(node.inputs[0]), mat, depth + 1) + _eval(_source(node.inputs[1]), mat, depth + 1)
    if kind == "ShaderNodeBsdfTransparent":
        return Closure(notes=[f"{node.name}: light passing through is treated as lost"])
    if kind == "ShaderNodeHoldout":
        return Closure(notes=[f"{node.name}: a holdout reflects nothing"])
    label = getattr(node, "bl_label", kind) or kind
    return _fallback(mat, f"{label} is not read, using the viewport colour")


def _fallback(mat, note=None):
    c = np.maximum(_viewport(mat), 0.0)
    return Closure(c, notes=[note] if note else [], lobes=[(1.0, "diffuse", (c, 0.0))])


def surface_closure(mat) -> Closure:
    """The material's Closure (see the module docstring); ``mat`` must not be None. A missing
    image it reads is named in its notes (``missing_images``)."""
    node = surface_node(mat)
    if node is None:
        if getattr(mat, "node_tree", None) is None:
            return _fallback(mat)  # a plain (non-node) material: its colour
        return _fallback(mat, "no surface shader, using the viewport colour")
    c = _eval(node, mat)
    missing = missing_images(mat.node_tree, active_output(mat))
    if missing:
        colour = any("linked, using the viewport colour" in n for n in c.notes)
        c.notes = _merge(c.notes, [
            f"{MISSING_IMAGE.format(', '.join(missing))}: "
            + ("its emission is baked as Cycles renders it (magenta light); " if c.linked_emission else "")
            + ("its linked colour is read as the viewport colour, where Cycles renders magenta; " if colour else "")
            + "find the file (File > External Data > Find Missing Files) or remove the texture"])
    return c


#: what a missing image becomes in Cycles (its magenta, 1, 0, 1): the start of every warning naming one
MISSING_IMAGE = "image file(s) missing, which Cycles renders magenta (1, 0, 1): {}"


def _image_missing(img) -> bool:
    """Whether Cycles finds no pixels for ``img``: read from a file (not packed, not generated)
    that is not there."""
    if img is None or img.packed_file is not None or img.source not in ("FILE", "SEQUENCE", "MOVIE"):
        return False
    path = bpy.path.abspath(img.filepath, library=img.library)
    return not os.path.exists(path)


def missing_images(tree, output=None) -> list:
    """"'name' (path)" of each image an Image or Environment Texture node feeding ``output`` (a
    node of ``tree``; None: any node) reads from a file that is not there, through reroutes and
    node groups (a group's nodes that feed its Group Output)."""
    found, seen = [], set()

    def visit(tree, starts, depth=0):
        stack = list(starts)
        while stack:
            node = stack.pop()
            if (id(tree), node.name) in seen or depth > _MAX_DEPTH:
                continue
            seen.add((id(tree), node.name))
            img = getattr(node, "image", None) if node.bl_idname in ("ShaderNodeTexImage",
                                                                     "ShaderNodeTexEnvironment") else None
            if _image_missing(img):
                text = f"{img.name!r} ({img.filepath})"
                if text not in found:
                    found.append(text)
            sub = getattr(node, "node_tree", None)
            if node.bl_idname == "ShaderNodeGroup" and sub is not None:
                visit(sub, [n for n in sub.nodes if n.bl_idname == "NodeGroupOutput"], depth + 1)
            for sock in node.inputs:
                stack.extend(link.from_node for link in sock.links if not link.is_muted)

    if tree is not None:
        visit(tree, [output] if output is not None else list(tree.nodes))
    return found


def material_properties(mat):
    """(reflectance (3,), radiance (3,), note or None) of a non-None material. A linked emission
    is not in ``radiance`` (export.py bakes it per face), and the note says so."""
    c = surface_closure(mat)
    notes = c.notes + ([f"linked emission ({', '.join(c.linked_emission)}) is not included (export bakes it "
                        "per face)"] if c.linked_emission else [])
    note = f"material {mat.name!r}: " + "; ".join(notes) if notes else None
    return c.reflectance, c.radiance, note
