"""No caller switches on a lamp kind's name (issue 38, item 1): a lamp kind is a class in its own
file of engine/lights/ (point.py, spot.py, area.py, sun.py), and callers ask the kind object
(``Lamp.kind``, LIGHT_KINDS), never compare its name.

Every string literal of relight_addon/ that is a lamp kind's name (Blender's Light type, "SPOT",
or the light kind's, "spot") is found where it switches: an operand of ``==`` / ``!=`` / ``in`` /
``not in`` (alone or inside the tuple, list or set compared with), a key of a dict keyed on two
or more kind names (a kind table: a single "area" key is a record's field, m^2), or a ``case``
pattern. It may appear so only in its own kind's file, and in the few places ALLOWED lists (each
with the line it must still match, so that a stale entry fails too). The one table that turns a
bpy Light's ``type`` into a kind is ``KIND_OF_TYPE`` in blender/lamps.py.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "relight_addon"
#: lamp kind names -> the file of engine/lights/ that may switch on them
NAMES = {"POINT": "point", "SPOT": "spot", "AREA": "area", "SUN": "sun",
         "point": "point", "spot": "spot", "area": "area", "sun": "sun"}
#: (file relative to relight_addon/, text of the line, why it may name kinds)
ALLOWED = [
    ("blender/lamps.py", 'KIND_OF_TYPE = {"POINT": "point", "SPOT": "spot", "AREA": "area", "SUN": "sun"}',
     "the one table from a bpy Light's type to its lamp kind"),
    ("blender/layers.py", 'DOMAIN_NAMES = {"POINT": "Vertex"',
     "Blender's attribute domain POINT (a vertex), not a lamp"),
]


def _switch_literals(tree):
    """(line, value) of the string constants of ``tree`` in a comparison, a dict key or a case pattern."""
    found = []

    def strings(node):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return [node]
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return [e for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
        return []

    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for operand in [node.left, *node.comparators]:
                found.extend(strings(operand))
        elif isinstance(node, ast.Dict):
            keys = [k for k in node.keys if k is not None and strings(k)]
            if len({k.value for k in keys} & set(NAMES)) >= 2:
                found.extend(keys)
        elif isinstance(node, ast.MatchValue):
            found.extend(strings(node.value))
    return [(n.lineno, n.value) for n in found]


def kind_switches(root=ROOT) -> list:
    """["file:line: name: the line"] of every switch on a lamp kind's name outside its own file and ALLOWED."""
    out = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        lines = path.read_text().splitlines()
        for line, value in _switch_literals(ast.parse(path.read_text(), str(path))):
            if value not in NAMES or rel == f"engine/lights/{NAMES[value]}.py":
                continue
            text = lines[line - 1].strip()
            if any(rel == f and text.startswith(start) for f, start, _ in ALLOWED):
                continue
            out.append(f"{rel}:{line}: {value!r}: {text}")
    return out


def test_no_caller_switches_on_a_lamp_kinds_name():
    found = kind_switches()
    assert not found, "switches on a lamp kind's name outside its own file (ask the kind object):\n" + "\n".join(found)


def test_every_allowed_place_is_still_there():
    """An ALLOWED entry that no longer matches a line is stale: remove it."""
    for rel, start, why in ALLOWED:
        lines = [x.strip() for x in (ROOT / rel).read_text().splitlines()]
        assert any(x.startswith(start) for x in lines), f"{rel}: no line starts with {start!r} ({why})"


def test_the_check_finds_a_switch(tmp_path):
    """The test can fail: a comparison, a dict key and an ``in`` on kind names outside their files."""
    (tmp_path / "engine" / "lights").mkdir(parents=True)
    (tmp_path / "caller.py").write_text('def f(lamp):\n    if lamp.kind == "SPOT":\n        return 1\n'
                                        '    t = {"area": 2, "spot": 1}\n    r = {"area": 0.5}\n'
                                        '    return lamp.kind in ("POINT", "SUN")\n')
    (tmp_path / "engine" / "lights" / "spot.py").write_text('def g(k):\n    return k == "SPOT"\n')
    found = kind_switches(tmp_path)
    assert [f.split(": ")[1] for f in found] == ["'SPOT'", "'area'", "'spot'", "'POINT'", "'SUN'"], found
