"""Registries of the engine's interchangeable methods (no bpy).

A new method is one file that registers itself here, plus its import in its package's
``__init__`` (``solvers/``, ``selections/``, ``distributions/``, ``patch_models/``,
``estimators/``, ``lights/``, ``colours/``). The CLI choices, the job options, the add-on's enum properties and the
cost model all read these registries, so nothing else changes when a method is added.

A method's own parameters are declared with it, once, as :class:`Param` s; the CLI's flags,
``JobOptions``' fields and ``validate``, the add-on's scene properties and panel rows derive
from the declarations (``engine/options.py``):

    from ..registry import SOLVERS, Param

    @SOLVERS.register("my-solver", "My Solver", "What it does, for the tooltip", paper=False,
                      params=(Param("damping", float, 0.1, min=0, description="..."),))
    def solve(problem, **kw): ...

``Registry[name]`` returns the :class:`Method`; an unknown name raises ValueError with the
list of known ones (the CLI and the operators show that line to the user).
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["Param", "Method", "Registry", "PATCH_MODELS", "ESTIMATORS", "SOLVERS", "SELECTIONS", "DISTRIBUTIONS",
           "LIGHT_KINDS", "LIGHT_COLOURS"]


@dataclass(frozen=True)
class Param:
    """One option of a job or of a method: its one declaration.

    ``type`` is int, float, bool or str (a choice: ``registry`` names the choices). ``default``
    None means "not set" (``none`` says what the engine does then, e.g. "automatic"); a value
    outside [``min``, ``max``] (``min_exclusive``: strictly above ``min``) is refused, and so is
    a non-finite float. ``flag`` is the CLI's (default ``--name-with-dashes``; ``invert``: a
    store-false switch such as ``--allow-negative`` for ``require_positive``). For the add-on:
    ``ui`` is "field" (a property of that name), "zero" (0 in the property stands for None),
    "toggle" (a ``use_<name>`` checkbox beside the field; off = None) or "hidden" (not a
    scene property); ``ui_default`` is the property's default where ``default`` is None;
    ``soft_max`` and ``unit`` ("LENGTH") shape the field. ``error`` replaces the range message
    ({} = the value given). ``inverse_only``: used by inverse solves, not by ``reduce``.
    ``unused`` (job options): why the chosen methods ignore it, from the options ("" = used).
    """

    name: str
    type: type
    default: object = None
    min: float | None = None
    max: float | None = None
    description: str = ""
    label: str = ""
    min_exclusive: bool = False
    none: str = ""
    flag: str = ""
    invert: bool = False
    registry: "Registry | None" = None
    ui: str = "field"
    ui_default: object = None
    soft_max: float | None = None
    unit: str = ""
    error: str = ""
    inverse_only: bool = False
    unused: "Callable | None" = None  # a job option: options -> why the chosen methods ignore it ("" = used)

    @property
    def cli_flag(self) -> str:
        return self.flag or "--" + self.name.replace("_", "-")

    @property
    def title(self) -> str:
        return self.label or self.name.replace("_", " ").title()

    def choices(self) -> tuple:
        return self.registry.names() if self.registry is not None else ()

    def range_text(self) -> str:
        """The allowed values in words ("> 0", ">= 0", "1 to 64"), "" when any."""
        if self.type not in (int, float):
            return ""
        f = (lambda v: f"{int(v)}") if self.type is int else (lambda v: f"{v:g}")
        lo = None if self.min is None else (f"> {f(self.min)}" if self.min_exclusive else f">= {f(self.min)}")
        if self.max is not None:
            return f"{f(self.min)} to {f(self.max)}" if lo and not self.min_exclusive else \
                ", ".join(filter(None, (lo, f"<= {f(self.max)}")))
        return lo or ""

    def _range_error(self, given):
        if self.error:
            return self.error.format(given)
        if self.type is int:
            if self.max is None and self.min is not None:
                return f"must be 0 or more, got {given}" if self.min == 0 else f"must be at least {self.min:g}, got {given}"
            return f"must be {self.range_text()}, got {given}"
        what = " length in metres" if self.unit == "LENGTH" else " number"
        if self.min == 0 and self.max is None:
            return f"must be a {'positive' if self.min_exclusive else 'non-negative'}{what}, got {given}"
        return f"must be a finite{what} {self.range_text()}, got {given}".replace("  ", " ")

    def check(self, value, given=None):
        """The value, converted (an int for an int param, a float for a float one); ValueError
        (the text without the option's name) when it has the wrong type or is out of range."""
        given = value if given is None else given
        if value is None:
            if self.default is None:
                return None
            raise ValueError(f"needs a value (default {self.default!r})")
        if self.type is bool:
            if not isinstance(value, bool):
                raise ValueError(f"must be true or false, got {given!r}")
            return value
        if self.type is str:
            if self.registry is not None:
                self.registry[value]  # ValueError naming the known methods
            elif not isinstance(value, str):
                raise ValueError(f"must be a string, got {given!r}")
            return value
        if isinstance(value, bool):
            raise ValueError(f"must be a number, got {given!r}")
        if self.type is int:
            try:
                v = int(value)
            except (TypeError, ValueError, OverflowError):
                raise ValueError(f"not an integer: {given!r}") from None
            if v != value:
                raise ValueError(f"not an integer: {given!r}")
        else:
            try:
                v = float(value)
            except (TypeError, ValueError, OverflowError):
                raise ValueError(f"not a number: {given!r}") from None
            if not math.isfinite(v):
                raise ValueError(self._range_error(given))
        if self.min is not None and (v <= self.min if self.min_exclusive else v < self.min):
            raise ValueError(self._range_error(given))
        if self.max is not None and v > self.max:
            raise ValueError(self._range_error(given))
        return v

    def parse(self, text):
        """``check`` of a command-line string (for argparse's ``type``)."""
        if self.type is int:
            try:
                value = int(text)
            except ValueError:
                raise ValueError(f"not an integer: {text!r}") from None
        elif self.type is float:
            try:
                value = float(text)
            except ValueError:
                raise ValueError(f"not a number: {text!r}") from None
        else:
            value = text
        return self.check(value, given=text)

    def help(self, prefix="") -> str:
        """The CLI's help text: the description, the default and the range."""
        text = self.description.rstrip(".")
        if self.type is bool and self.invert:
            text = f"turns off {self.title!r}: {text[:1].lower()}{text[1:]}"
        parts = [prefix + (text[:1].lower() + text[1:] if prefix else text)]
        if self.type is not bool:
            d = (self.none or "none") if self.default is None else self.default
            parts.append(f"default: {d}")
            if self.range_text():
                parts.append(f"range {self.range_text()}")
        return "; ".join(p for p in parts if p).replace("%", "%%")


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    description: str
    impl: Callable
    extra: dict = field(default_factory=dict)
    params: tuple = ()  # its Params (engine/options.py builds the job options from them)

    def __call__(self, *args, **kwargs):
        return self.impl(*args, **kwargs)

    def get(self, key, default=None):
        return self.extra.get(key, default)


class Registry:
    """Named methods of one kind, in registration order (the order the UI lists them).

    The registry imports nothing: its methods' package registers them when imported (the package
    of a kind of method is imported by the module that dispatches to it -- inverse.py for the
    solvers, reduction.py for the selections and distributions, options.py for every user-chosen
    kind -- so no import cycle runs through here). Reading a registry whose package was never
    imported is a programming error, said as such."""

    def __init__(self, kind: str, package: str):
        self.kind = kind
        self.package = __name__.rsplit(".", 1)[0] + package  # e.g. relight_addon.engine.solvers
        self._methods: dict[str, Method] = {}

    def register(self, name: str, label: str, description: str, params=(), **extra):
        def deco(impl):
            if name in self._methods:
                raise ValueError(f"{self.kind} {name!r} is registered twice")
            self._methods[name] = Method(name, label, description, impl, dict(extra), tuple(params))
            return impl
        return deco

    def _loaded(self) -> dict:
        if self.package not in sys.modules:
            raise RuntimeError(f"the {self.kind} registry is read before {self.package} was imported "
                               "(import the package that registers them, e.g. engine.options)")
        return self._methods

    def __getitem__(self, name) -> Method:
        try:
            return self._loaded()[name]
        except (KeyError, TypeError):
            raise ValueError(f"unknown {self.kind} {name!r}; choose one of {', '.join(self.names())}") from None

    def __contains__(self, name) -> bool:
        return name in self._loaded()

    def __iter__(self):
        return iter(self._loaded().values())

    def names(self) -> tuple:
        return tuple(self._loaded())

    def enum_items(self) -> list:
        """(identifier, label, description) triples for a Blender EnumProperty."""
        return [(m.name, m.label, m.description) for m in self]


PATCH_MODELS = Registry("patch model", ".patch_models")
ESTIMATORS = Registry("form-factor estimator", ".estimators")
SOLVERS = Registry("inverse solver", ".solvers")
SELECTIONS = Registry("selection", ".selections")
DISTRIBUTIONS = Registry("distribution", ".distributions")
LIGHT_KINDS = Registry("light kind", ".lights")
LIGHT_COLOURS = Registry("light colour", ".colours")
#: what a solve is asked to meet: kinds of targets (engine/targets/), each giving rows on the radiosity
TARGET_KINDS = Registry("target kind", ".targets")
