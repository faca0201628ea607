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
"""
from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["LINE_CHARS", "MAX_LINES", "FIXES", "Line", "sidebar_lines", "for_addon"]

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
