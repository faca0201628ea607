"""What the sidebar says of a solve's warnings (no bpy): at most three lines, the most consequential
first, each a plain sentence short enough for the default sidebar, with its number and the fix.

A solve's report holds every warning in full (ten or more on an artist's file: facts, model notes,
advice). An artist reads three lines. Each warning is matched against ``RULES`` (first match):

- its **rank**: how much it changes what the artist gets. A light that makes no sense (sends almost
  none of its light to the targets, or is brighter than any luminaire), targets no light reaches,
  Cycles rendering darker than the prediction, too few lights: first. What Relight modelled as
  Cycles renders it (faces seen from behind, shared meshes): last. Plain facts of the solve (its
  error, the light colour chosen, the certificate) rank 0: in the Details popup and the report only;
- its **line**: a sentence of at most LINE_CHARS characters holding the warning's number;
- its **fix**: the name of what fixes it in the sidebar (``FIXES``), or None.

A warning no rule knows keeps its first clause, cut to LINE_CHARS at a word, with its first number
kept. Command-line flags and their parenthesised asides are not add-on text (``for_addon``).

The warnings' texts themselves are made here too (the second half of this module): the stages
(pipeline.jobs, pipeline.stages, pipeline.model) say what they found, these functions say it in
words, beside the rules that rank them.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..engine.bounds import POSITIVE_GAP
from ..engine.plausibility import MIN_UTILISATION

__all__ = ["LINE_CHARS", "MAX_LINES", "FIXES", "Line", "sidebar_lines", "for_addon", "NO_EMITTER_WARNING",
           "BEST_SELECTION", "background_note", "direct_fixed_note", "live_note", "taken_note", "certificate_notes",
           "positivity_notes", "unmet_notes", "colour_text"]

#: characters of a line: what fits the 3D Viewport's sidebar at its default width (Blender's
#: UI_SIDEBAR_PANEL_WIDTH, 220 px at UI scale 1, less the margins and the icon: about 175 px, at
#: panels._wrap's 6.3 px a character); the fix is a button on the row under it
LINE_CHARS = 28
#: lines the sidebar shows
MAX_LINES = 3
#: what fixes a warning, by name: the Blender layer draws it (an operator or a property)
FIXES = ("light_paths", "more_lights")

_NUM = r"([-+]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?)"


@dataclass(frozen=True)
class Line:
    """One sidebar line: ``text`` (at most LINE_CHARS), ``index`` (the warning's position in the
    solve's list: its full text), ``fix`` (a FIXES name or None), ``rank``."""

    text: str
    index: int
    fix: str | None
    rank: int


# (pattern, rank, line: a format of the match's groups, fix)
RULES = (
    (rf"\(\w+, {_NUM} W\) sends {_NUM}% of its light to the painted targets", 100,
     "Light: {1} % on targets", None),
    (rf"is {_NUM} cd/m\^2 bright, more than any luminaire", 95, "Light of {0} cd/m\u00b2", None),
    (rf": its targets are already {_NUM} % brighter than painted", 92, "{0} % too bright already", None),
    (rf"^{_NUM} target patch\(es\) cannot be met", 90, "{0} targets get no light", None),
    (rf"^Cycles would render the (?:targets|faces|lit faces) about {_NUM} % (darker|brighter)", 85,
     "Cycles renders {0} % {1}", "light_paths"),
    (rf"misses the targets by {_NUM} \(relative error\) with {_NUM} light", 80,
     "{1} lights miss by {0}", "more_lights"),
    (r"the scene has no emitter", 80, "The scene has no light", None),
    (rf"^indirect clamping at {_NUM}", 75, "Clamping at {0} darkens", "light_paths"),
    (rf"^Filter Glossy is {_NUM}", 70, "Filter Glossy {0} darkens", "light_paths"),
    (rf"the back side of its emitting faces lies {_NUM} (\w+) from", 65, "Emitter {0} {1} from surface", None),
    (r"^the scene renders with (?:BLENDER_)?([A-Z]+)", 60, "{0} is not Cycles", None),
    (rf"^{_NUM} candidate light\(s\) left out", 40, "{0} far lights left out", None),
    (r"^.+?: its mesh is linked from .* radiosity layer is not written", 35, "Linked mesh: no radiosity", None),
    (rf"^{_NUM} zero-area or degenerate face", 30, "{0} zero-area faces ignored", None),
    (rf"reflectance of {_NUM} face\(s\) clamped", 30, "{0} reflectances clamped", None),
    (rf"^{_NUM} face\(s\) .* face away from the scene", 20, "{0} faces read from behind", None),
    (rf"^{_NUM} face\(s\) .* are seen from both sides", 20, "{0} two-sided faces", None),
    (r" shares its mesh with ", 10, "Shared meshes: one's values", None),
    # the solve's plain facts: Details and the report only
    (r"^\d+ light\(s\): relative error", 0, "", None),
    (r"^light colour: .*chosen automatically", 0, "", None),
    (r"^no positive lighting meets these targets", 0, "", None),
    (r"^the scene's own light .* is kept", 0, "", None),
    (r"^every target within", 0, "", None),
    (r"^Solved from scratch", 0, "", None),
)
_RULES = tuple((re.compile(p), rank, line, fix) for p, rank, line, fix in RULES)
#: the rank of a warning no rule knows
UNKNOWN_RANK = 50


def for_addon(text: str) -> str:
    """A warning as the add-on shows it: without command-line flags (a parenthesised aside that
    names one, or the flag and its value)."""
    text = re.sub(r"\s*\([^()]*--[a-z][^()]*\)", "", text)
    text = re.sub(r"\s*--[a-z][a-z-]*(?:\s+[^\s;:,)]+)?", "", text)
    return re.sub(r"\s{2,}", " ", text).strip()


def _short(text: str, limit: int) -> str:
    """A warning no rule knows: its first clause (two when the first is only a count), without
    asides, cut at a word to ``limit`` characters, its first number kept."""
    plain = re.sub(r"\s+\([^()]*\)", "", for_addon(text))
    parts = re.split(r": |; ", plain)
    head = parts[0] if len(parts[0]) >= 16 or len(parts) == 1 else f"{parts[0]}: {parts[1]}"
    head = head.strip().rstrip(",.")
    head = head[:1].upper() + head[1:]
    if len(head) <= limit:
        return head
    number = re.search(_NUM, head)
    tail = f" {number.group(1)}" if number and number.start() > limit // 2 else ""
    cut = head[:limit - 1 - len(tail)].rsplit(" ", 1)[0].rstrip(",.;:")
    return cut + "\u2026" + tail


def _line(text: str, limit: int) -> tuple:
    """(rank, line, fix) of one warning."""
    for pattern, rank, line, fix in _RULES:
        m = pattern.search(text)
        if m:
            if rank == 0:
                return 0, "", None
            out = line.format(*(g.rstrip(".") for g in m.groups()))
            return rank, out if len(out) <= limit else _short(out, limit), fix
    return UNKNOWN_RANK, _short(text, limit), None


def sidebar_lines(warnings, limit: int = LINE_CHARS, n: int = MAX_LINES) -> list:
    """The sidebar's lines for a solve's ``warnings``: at most ``n``, highest rank first (ties in
    the solve's order), none for a warning of rank 0 (a plain fact)."""
    lines = []
    for i, w in enumerate(warnings):
        rank, text, fix = _line(w, limit)
        if rank > 0:
            lines.append(Line(text, i, fix, rank))
    lines.sort(key=lambda ln: -ln.rank)
    return lines[:n]


# ---------------------------------------------------------------------------- the warnings' texts

NO_EMITTER_WARNING = "the scene has no emitter (no lamp, no material with emission): every radiosity is 0"
BACKGROUND_NOTE = ("the scene's own light ({lamps} lamp(s){world}, {n} emissive face(s)) is kept as fixed background light; "
                   "the solve lights what they leave to the targets")
DIRECT_FIXED_NOTE = ("kept as fixed light, which a reduction cannot switch off: {}; its light is part of the scene's "
                     "radiosity and of every configuration's")
LIVE_NOTE = ("live answer from the prepared transport ({why}): Solve & Reduce gives the full solve")
#: the selection the positivity note advises (the best configurations the project finds)
BEST_SELECTION = "greedy-swap"


def not_converged_note(message: str) -> str:
    """The forward radiosity solve stopped before converging."""
    return f"the radiosity solve did not converge: {message}".strip()


def background_note(n_emissive: int, n_lamps: int, world: bool) -> str:
    """A solve keeps the scene's own light (lamps, World, emissive faces) as fixed light."""
    return BACKGROUND_NOTE.format(n=n_emissive, lamps=n_lamps, world=", the World" if world else "")


def direct_fixed_note(names) -> str:
    """The direct mode's fixed light in words: the World, the lamps of negative power (``names``:
    [(name, kind, power)] of engine.scene_light.direct_lights)."""
    return DIRECT_FIXED_NOTE.format(", ".join(f"the World ({n})" if kind == "world" else
                                              f"lamp {n!r} (negative power)" for n, kind, _ in names))


def dark_lamps_note(dark) -> str:
    """The lamps a reduction leaves out because they light no face."""
    return (f"{len(dark)} lamp(s) light no face ({', '.join(dark[:5])}{' ...' if len(dark) > 5 else ''}): "
            "left out of the reduction, and left as they are in the written copy")


def kernel_unfit_note(n: int, names) -> str:
    """Light-to-target pairs the kernel could not compute (``names``: their objects)."""
    return (f"{n} light-to-target form factor(s) could not be computed by the kernel (a point on a "
            f"face's edge: coincident or degenerate faces of {', '.join(repr(x) for x in names[:6])}"
            f"{' ...' if len(names) > 6 else ''}): taken from the rays' estimate")


def already_brighter_note(name: str, ratio: float) -> str:
    """A target object the fixed light alone makes ``ratio`` times as bright as painted."""
    return (f"{name}: its targets are already {100 * (ratio - 1):.0f} % brighter "
            "than painted without any new light (the scene's own lamps, World and emitters)")


def taken_note(by: str, when: str, seconds) -> str:
    """A solve that took the answer the prepared state already made for the same paint, scene and
    options (pipeline.prepared.PreparedScene.answer): ``by`` made it at ``when`` in ``seconds``."""
    took = "" if seconds is None else f" in {seconds:.1f} s"
    return (f"the answer {by} made for this paint at {when}{took}, taken whole: the same paint, scene "
            "and options (nothing computed again)")


def live_note(n_targets: int) -> str:
    """What a Live stroke's answer is (pipeline.jobs.solve_stroke)."""
    return LIVE_NOTE.format(why=f"the lights offered and refined for the last solve's targets, {n_targets} target "
                                "patches; the new targets' direct light by the ray-cast form factors")


def unmet_notes(problem, patches, faces) -> list:
    """The painted targets no candidate light reaches (InverseProblem.unmet), by object, and the
    candidate lights left out as implausible (InverseProblem.implausible)."""
    out = []
    left = getattr(problem, "implausible", None)
    if left is not None and left.any():
        out.append(f"{int(left.sum())} candidate light(s) left out: each would reach the painted targets with "
                   f"less than {MIN_UTILISATION:.1%} of its light (others reach them with more than ten times that), "
                   "so lighting them would take a power far beyond what they receive")
    bad = getattr(problem, "unmet", None)
    if bad is None or not len(bad):
        return out
    obj, count = np.unique(patches.object[bad], return_counts=True)
    order = np.argsort(-count, kind="stable")
    names = ", ".join(f"{count[i]} of {faces.object_names[obj[i]]!r}" for i in order[:5])
    return out + [f"{len(bad)} target patch(es) cannot be met, no candidate light reaches them ({names}"
            f"{', ...' if len(obj) > 5 else ''}): no allowed surface or candidate lamp sends them light"]


def certificate_notes(problem, bounds, final, refined=None) -> list:
    """How good the final configuration is against the certificate (of the candidate lights;
    ``refined``: refine_stage's account, whose lamps may take the error below it)."""
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    k = final.n_lights
    exact = 1 <= k <= len(bounds.exact) and bool(bounds.exact[k - 1])
    lb = bounds.at(k) / norm
    if final.n_negative or final.relative_error <= 1e-9:
        return []
    if refined and refined["lamps_refined"] and final.relative_error < lb * (1 - 1e-6):
        return [f"{k} light(s): relative error {final.relative_error:.3g}, below the {lb:.3g} that no {k} of the "
                f"candidate lights can go below{' (exact optimum)' if exact else ''}: the chosen lamps' aim, cone, "
                "size and position were refined"]
    if exact and final.relative_error <= lb * (1 + 1e-6) + 1e-12:
        return [f"{k} light(s): the best possible with {k} non-negative lights (exhaustive search), "
                f"relative error {final.relative_error:.3g}"]
    return [f"{k} light(s): relative error {final.relative_error:.3g}; no {k} non-negative lights can go below "
            f"{lb:.3g}{' (exact optimum)' if exact else ''}, and no number of them below {bounds.nnls / norm:.3g}"]


def colour_text(colour) -> str:
    """A light colour mode in words ("white", "blackbody 2700-6500 K")."""
    rec = colour.summary()
    return rec["mode"] + (f" {rec['range_K'][0]:.0f}-{rec['range_K'][1]:.0f} K" if "range_K" in rec else "")


def positivity_notes(bound, final, colour=None, selection=None) -> list:
    """Say so when the final configuration misses the targets by much: whether no positive
    lighting can do better (targets brighter or darker than light can make them) or whether
    more lights / another selection would (never the selection already used). ``bound``:
    engine.bounds.positive_bound's."""
    if bound is None or not final.relative_error > POSITIVE_GAP:
        return []
    n_pos = int((bound.exitance.max(axis=1) > 0).sum())
    if bound.relative_error > POSITIVE_GAP:
        best = ("the best any non-negative set of the candidate lights can do is" if colour is None else
                f"no non-negative set of the candidate lights, {colour_text(colour)}, goes below")
        return [f"no positive lighting meets these targets: {best} a relative error of {bound.relative_error:.3g} "
                f"(NNLS, {n_pos} lights); the final configuration's is {final.relative_error:.3g}"]
    other = "" if selection == BEST_SELECTION else f", or use the {BEST_SELECTION} selection (Best k Lights)"
    return [f"the final configuration misses the targets by {final.relative_error:.3g} (relative error) with "
            f"{final.n_lights} light(s); positive lights can reach {bound.relative_error:.3g} with {n_pos}: allow "
            f"more lights{other}"]
