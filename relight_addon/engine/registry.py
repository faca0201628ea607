"""Registries of the engine's interchangeable methods (no bpy).

A new method is one file that registers itself here, plus its import in its package's
``__init__`` (``solvers/``, ``selections/``, ``distributions/``, ``patch_models/``,
``estimators/``, ``lights/``). The CLI choices, the job options, the add-on's enum properties and the
cost model all read these registries, so nothing else changes when a method is added.

    from ..registry import SOLVERS

    @SOLVERS.register("my-solver", "My Solver", "What it does, for the tooltip", paper=False)
    def solve(problem, **kw): ...

``Registry[name]`` returns the :class:`Method`; an unknown name raises ValueError with the
list of known ones (the CLI and the operators show that line to the user).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["Method", "Registry", "PATCH_MODELS", "ESTIMATORS", "SOLVERS", "SELECTIONS", "DISTRIBUTIONS", "LIGHT_KINDS"]


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    description: str
    impl: Callable
    extra: dict = field(default_factory=dict)

    def __call__(self, *args, **kwargs):
        return self.impl(*args, **kwargs)

    def get(self, key, default=None):
        return self.extra.get(key, default)


class Registry:
    """Named methods of one kind, in registration order (the order the UI lists them)."""

    def __init__(self, kind: str, package: str):
        self.kind = kind
        self._package = package  # imported on first use: its modules register themselves
        self._methods: dict[str, Method] = {}
        self._loaded = False

    def register(self, name: str, label: str, description: str, **extra):
        def deco(impl):
            if name in self._methods:
                raise ValueError(f"{self.kind} {name!r} is registered twice")
            self._methods[name] = Method(name, label, description, impl, dict(extra))
            return impl
        return deco

    def _load(self):
        if not self._loaded:
            self._loaded = True
            importlib.import_module(self._package, __package__)

    def __getitem__(self, name) -> Method:
        self._load()
        try:
            return self._methods[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown {self.kind} {name!r}; choose one of {', '.join(self.names())}") from None

    def __contains__(self, name) -> bool:
        self._load()
        return name in self._methods

    def __iter__(self):
        self._load()
        return iter(self._methods.values())

    def names(self) -> tuple:
        self._load()
        return tuple(self._methods)

    def enum_items(self) -> list:
        """(identifier, label, description) triples for a Blender EnumProperty."""
        return [(m.name, m.label, m.description) for m in self]


PATCH_MODELS = Registry("patch model", ".patch_models")
ESTIMATORS = Registry("form-factor estimator", ".estimators")
SOLVERS = Registry("inverse solver", ".solvers")
SELECTIONS = Registry("selection", ".selections")
DISTRIBUTIONS = Registry("distribution", ".distributions")
LIGHT_KINDS = Registry("light kind", ".lights")
