"""A Light's IES Texture node read as Cycles renders it (bpy): the measured distribution of a
scene's luminaire (engine/photometry/, engine/lights/photometric.py).

Read: a Point, Spot or Area lamp whose node tree is an IES Texture node (its file from disk, relative paths
against the .blend, or its internal text) whose Fac feeds an Emission's Strength, the Emission
into the Light Output; the IES node's Vector unlinked (the direction the light leaves, in the
lamp's frame, as Cycles takes it by default). Cycles' emission is then colour x Power x the
lamp's gain x the Emission's Color x the IES node's Strength x the profile's value, so those two
(unlinked) are a factor of the lamp's gain. On an Area lamp the profile multiplies its Lambertian
emission along each direction (engine/lights/photometric_area.py). Any other tree with an IES
node (a Math node between, a linked Strength or Vector) is not reduced: ``photometric`` returns None
and the lamp is named as today (its light nodes not modelled). A missing or unreadable file is
refused, named.
"""
from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from ..engine.lights.photometric import measured_kind
from ..engine.photometry import CyclesProfile, PhotometryError, parse_lm63
from ..engine.scene import SceneError

__all__ = ["IESLight", "photometric", "has_ies", "write_ies"]

#: (an IES node on a Point lamp: engine/lights/photometric.py; on a Spot lamp: photometric_spot.py; on an
#: Area lamp: photometric_area.py)

#: the node types of a tree read as a photometric lamp
IES, EMISSION, OUTPUT = "TEX_IES", "EMISSION", "OUTPUT_LIGHT"


@dataclass
class IESLight:
    """A Light's IES node read: its lamp kind, its Cycles profile, the factor (3,) it adds to the lamp's gain (the
    Emission's Color x the node's Strength), notes on what is not modelled, the file's name."""

    kind: object  # its lamp kind (engine.lights.photometric.measured_kind)
    profile: CyclesProfile
    gain: np.ndarray
    notes: list
    source: str


def has_ies(ld) -> bool:
    """Whether the Light ``ld``'s node tree holds an IES Texture node."""
    tree = getattr(ld, "node_tree", None)
    return tree is not None and any(n.type == IES for n in tree.nodes)


def _text(node, lamp_name) -> tuple:
    """(the IES text, its name) of an IES node: its internal Text or its file (SceneError when missing)."""
    if node.mode == "INTERNAL":
        if node.ies is None:
            raise SceneError(f"lamp {lamp_name!r}: its IES Texture node has no text (Internal, none chosen): choose "
                             "one or remove the node")
        return node.ies.as_string(), node.ies.name
    path = bpy.path.abspath(node.filepath)
    try:
        with open(path, "rb") as f:
            return f.read(), node.filepath
    except OSError:
        raise SceneError(f"lamp {lamp_name!r}: its IES file {node.filepath!r} is missing or cannot be read ({path}): "
                         "give the node an existing file, or pack it as an internal text") from None


def photometric(ld, lamp_name) -> IESLight | None:
    """The IES light of the Light ``ld`` when its tree is the one this module reads (its docstring),
    else None; SceneError when its file is missing or is not a photometric file Relight reads."""
    kind = measured_kind(ld.type)
    if kind is None or not has_ies(ld):
        return None
    nodes = list(ld.node_tree.nodes)
    if sorted(n.type for n in nodes) != sorted([IES, EMISSION, OUTPUT]):
        return None
    ies = next(n for n in nodes if n.type == IES)
    em = next(n for n in nodes if n.type == EMISSION)
    out = next(n for n in nodes if n.type == OUTPUT)
    links = {(lk.from_node.type, lk.from_socket.identifier, lk.to_node.type, lk.to_socket.identifier)
             for lk in ld.node_tree.links}
    fac_to_strength = any(f == IES and t == EMISSION and ts == em.inputs["Strength"].identifier
                          for f, _, t, ts in links)
    em_to_out = any(f == EMISSION and t == OUTPUT and ts == out.inputs["Surface"].identifier for f, _, t, ts in links)
    if not (fac_to_strength and em_to_out and len(links) == 2):
        return None
    text, source = _text(ies, lamp_name)
    try:
        ph = parse_lm63(text, source)
    except PhotometryError as e:
        raise SceneError(f"lamp {lamp_name!r}: {e}") from None
    colour = np.array(em.inputs["Color"].default_value, dtype=np.float64)[:3]
    strength = float(ies.inputs["Strength"].default_value)
    if not (np.all(np.isfinite(colour)) and np.isfinite(strength)):
        raise SceneError(f"lamp {lamp_name!r}: its Emission Color or IES Strength is NaN or infinite: give them "
                         "finite values")
    return IESLight(kind, CyclesProfile.of(ph), colour * strength, [f"its IES file {source!r}: {n}" for n in ph.notes],
                    source)


def write_ies(ld, name, text, owner=None):
    """Give the Light ``ld`` the node tree ``photometric`` reads: an IES Texture node (Internal: a new
    Text ``name`` holding the LM-63 ``text``, saved in the .blend) whose Fac feeds an Emission's Strength
    (Color white, the node's Strength 1: Cycles emits colour x Power x the profile), into the Light
    Output. ``owner``: the result id the Text is tagged with (results.tag_owned). Returns the Text."""
    from .visibility import tag_owned

    txt = bpy.data.texts.new(name)
    txt.write(text)
    txt.use_fake_user = False  # (a Text keeps itself by default: its lamp's node is its one user)
    ld.use_nodes = True
    tree = ld.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    out = tree.nodes.new("ShaderNodeOutputLight")
    em = tree.nodes.new("ShaderNodeEmission")
    ies = tree.nodes.new("ShaderNodeTexIES")
    ies.mode = "INTERNAL"
    ies.ies = txt
    ies.inputs["Strength"].default_value = 1.0
    em.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    em.inputs["Strength"].default_value = 1.0
    tree.links.new(ies.outputs["Fac"], em.inputs["Strength"])
    tree.links.new(em.outputs["Emission"], out.inputs["Surface"])
    ies.location, em.location, out.location = (-400, 0), (-150, 0), (100, 0)
    if owner is not None:
        tag_owned(txt, owner)
    return txt
