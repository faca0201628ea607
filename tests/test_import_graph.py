"""The package's import graph: no import cycle, and an engine that never needs bpy.

The graph is built from the modules' ASTs: every ``import`` / ``from ... import`` of the
package's own modules, at module level or inside a function (a lazy import is still a
dependency); the registries import nothing (their methods' packages register themselves).
Every module that imports without bpy is also imported for real, alone (the package's modules
cleared from sys.modules before each), in a subprocess where bpy and Blender's other modules
cannot be imported.
"""
from __future__ import annotations

import ast
import json
import os
import pkgutil
import subprocess
import sys
from pathlib import Path


ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "relight_addon"
ENGINE = PACKAGE + ".engine"
#: the layers that never import bpy
BPY_FREE = (ENGINE, PACKAGE + ".pipeline")
#: Blender's own modules: the engine must import none of them
BLENDER_MODULES = ("bpy", "bmesh", "mathutils", "gpu", "gpu_extras", "bpy_extras", "bl_math", "blf", "aud", "idprop")

def package_modules() -> dict:
    """Dotted name -> (path, is_package) of every module of the package (pkgutil, directory by
    directory: nothing is imported, so bpy modules are listed too)."""
    mods = {}

    def walk(name, directory):
        mods[name] = (directory / "__init__.py", True)
        for info in pkgutil.iter_modules([str(directory)]):
            if info.ispkg:
                walk(f"{name}.{info.name}", directory / info.name)
            else:
                mods[f"{name}.{info.name}"] = (directory / f"{info.name}.py", False)

    walk(PACKAGE, ROOT / PACKAGE)
    return mods


MODULES = package_modules()


def _resolve(module: str | None, level: int, current: str, is_package: bool) -> str:
    if not level:
        return module or ""
    parts = current.split(".") if is_package else current.split(".")[:-1]
    parts = parts[:len(parts) - (level - 1)]
    return ".".join(parts + ([module] if module else []))


def module_imports(name: str) -> tuple[set, set]:
    """(the package's own modules that ``name`` imports anywhere in its code, the top-level
    names of every absolute import it makes anywhere)."""
    path, is_package = MODULES[name]
    own, external = set(), set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                external.add(alias.name.split(".")[0])
                if alias.name.split(".")[0] == PACKAGE:
                    own.add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(node.module, node.level, name, is_package)
            if node.level == 0:
                external.add(target.split(".")[0])
            if not target.split(".")[0] == PACKAGE:
                continue
            subs = {f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in MODULES}
            own |= subs
            if len(subs) < len(node.names):  # names from the module itself, not only its submodules
                own.add(target)
    return {m for m in own if m in MODULES and m != name}, external


def import_graph() -> dict:
    return {m: module_imports(m)[0] for m in MODULES}


def cycles(graph: dict) -> list:
    """The graph's strongly connected components of more than one module (Tarjan), each as one
    cycle through it (a readable path a -> b -> ... -> a)."""
    index, low, stack, on, comps = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [(comp, _one_cycle(graph, comp)) for comp in comps]


def _one_cycle(graph, comp, start=None):
    """A shortest cycle through ``start`` (default: the component's first module), by a
    breadth-first search in the component, as a path."""
    start = min(comp) if start is None else start
    prev = {start: None}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v] & comp):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return list(reversed(path)) + [start]
            if w not in prev:
                prev[w] = v
                queue.append(w)
    return [start]


def _names(path):
    return " -> ".join(p.removeprefix(PACKAGE + ".") for p in path)


def test_no_import_cycle():
    """Every import the modules make (module level or inside functions): no cycle."""
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(
        f"{_names(path)} (among {len(comp)} modules)" for comp, path in found)


def test_registries_import_nothing_of_the_package():
    """The registries never import their methods (no cycle through a lazy package import): each
    kind's package registers itself when the module that dispatches to it imports it."""
    assert module_imports(ENGINE + ".registry")[0] == set()
    from relight_addon.engine import options, registry  # noqa: F401  (options imports every kind)

    for r in (v for v in vars(registry).values() if isinstance(v, registry.Registry)):
        assert r.names(), f"the {r.kind} registry is empty after importing engine.options"


def bpy_free_layer(m) -> bool:
    return any(m == p or m.startswith(p + ".") for p in BPY_FREE)


def test_engine_imports_no_blender_module():
    """No engine or pipeline module imports bpy (or bmesh, mathutils ...), directly or through any of the
    package's modules it imports, at module level or inside a function."""
    graph = import_graph()
    direct = {m: module_imports(m)[1] & set(BLENDER_MODULES) for m in MODULES}
    bad = {}  # the module that imports Blender -> a shortest path to it from an engine module
    for m in sorted(x for x in MODULES if bpy_free_layer(x)):
        prev, queue = {m: None}, [m]
        while queue:
            v = queue.pop(0)
            if direct[v]:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                if v not in bad or len(path) < len(bad[v][0]):
                    bad[v] = (path[::-1], sorted(direct[v]))
                break
            for w in sorted(graph[v] - prev.keys()):
                prev[w] = v
                queue.append(w)
    assert not bad, "; ".join(f"{_names(path)} imports {mods}" for path, mods in bad.values())


_IMPORT_EACH = r"""
import importlib, importlib.abc, json, sys
blender, attempts = set(json.loads(sys.argv[1])), []

class NoBlender(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in blender:
            attempts.append(name)
            raise ModuleNotFoundError(f"No module named {name!r} (blocked: no Blender)", name=name)
        return None

sys.meta_path.insert(0, NoBlender())
out = {}
for name in json.loads(sys.argv[2]):
    for m in [m for m in sys.modules if m == "relight_addon" or m.startswith("relight_addon.")]:
        del sys.modules[m]
    del attempts[:]
    try:
        importlib.import_module(name)
        out[name] = ["ok", list(attempts)]
    except ModuleNotFoundError as exc:
        out[name] = ["blender" if (exc.name or "").split(".")[0] in blender else "error", repr(exc)]
    except Exception as exc:
        out[name] = ["error", repr(exc)]
print(json.dumps(out))
"""


def test_every_module_imports_alone_without_blender():
    """Each module imported alone (the package cleared from sys.modules first) with Blender's
    modules blocked: the engine's all import and try no Blender module; any other module either
    imports or fails only for a Blender module its own code imports at module level."""
    names = sorted(MODULES)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = subprocess.run([sys.executable, "-c", _IMPORT_EACH, json.dumps(BLENDER_MODULES), json.dumps(names)],
                         capture_output=True, text=True, cwd=str(ROOT), env=env, timeout=300)
    assert run.returncode == 0, run.stderr
    res = json.loads(run.stdout.strip().splitlines()[-1])
    errors = {m: r[1] for m, r in res.items() if r[0] == "error"}
    assert not errors, errors
    engine = [m for m in names if bpy_free_layer(m)]
    assert all(res[m] == ["ok", []] for m in engine), {m: res[m] for m in engine if res[m] != ["ok", []]}
    bpy_free = {m for m in names if res[m][0] == "ok"}
    assert bpy_free >= set(engine) | {PACKAGE, PACKAGE + ".pipeline.jobs", PACKAGE + ".cli"}, sorted(set(names) - bpy_free)
