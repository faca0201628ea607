"""Registries of the engine's interchangeable methods (no bpy).

A new method is one file that registers itself here, plus its import in its package's
``__init__`` (``solvers/``, ``selections/``, ``distributions/``, ``patch_models/``,
``estimators/``, ``lights/``, ``colours/``). The CLI choices, the job options, the add-on's enum properties and the
cost model all read these registries, so nothing else changes when a method is added.

A method's own parameters are declared with it, once, as :class:`Param` s; the CLI's flags,
``JobOptions``' fields and ``validate``, the add-on's scene properties and panel rows derive
from the declarations (``engine/options.py``):

    from ..registry import SOLVERS, Param

    @SOLVERS.register("my-solver", "My Solver", "What it does, for the tooltip", nonnegative=True,
                      params=(Param("damping", float, 0.1, min=0, description="..."),))
    def solve(problem, damping): ...

A method receives exactly its declared parameters: ``method.bind(options)`` takes them from the
job options (or from keywords: ``bind(damping=0.2)``), and the :class:`Bound` method passes them
to the implementation as keywords. What a registry's callers need to know about a method (does a
selection distribute power? which cost model does a solver follow?) is a typed trait, declared
once per registry with its default (:class:`SelectionTraits`, ...): a keyword of ``register``
that is not a trait of that registry, or of the wrong type, is refused when the method registers.

``Registry[name]`` returns the :class:`Method`; an unknown name raises ValueError with the
list of known ones (the CLI and the operators show that line to the user).
"""
from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from types import MappingProxyType
from typing import Callable

__all__ = ["Param", "Method", "Bound", "Registry", "PATCH_MODELS", "ESTIMATORS", "SOLVERS", "SELECTIONS",
           "DISTRIBUTIONS", "LIGHT_KINDS", "LIGHT_COLOURS", "TARGET_KINDS", "PatchModelTraits", "EstimatorTraits", "SolverTraits",
           "SelectionTraits", "ColourTraits", "NoTraits"]


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


# The traits of each registry's methods: what its callers ask of a method, with the defaults.
@dataclass(frozen=True)
class NoTraits:
    """A registry whose methods declare no traits (distributions, light kinds)."""


@dataclass(frozen=True)
class PatchModelTraits:
    #: its patches do not depend on the paint (pipeline.prepared keeps them across paint changes)
    paint_independent: bool = False


@dataclass(frozen=True)
class EstimatorTraits:
    #: it takes the candidate-light-to-target pairs (the kernel's transport; pipeline.prepared, jobs)
    kernel_pairs: bool = False


#: the cost models of engine/cost.py
SOLVER_COSTS = ("transfer", "paper")


@dataclass(frozen=True)
class SolverTraits:
    #: its cost model (engine/cost.py): "transfer" (T from an LU of A) or "paper" (the SVD formulation)
    cost: str = "transfer"
    #: its exitances are never negative (engine.inverse warns when the targets are then not met)
    nonnegative: bool = False

    def __post_init__(self):
        if self.cost not in SOLVER_COSTS:
            raise ValueError(f"cost must be one of {', '.join(SOLVER_COSTS)}, got {self.cost!r}")


@dataclass(frozen=True)
class SelectionTraits:
    #: it gives a removed light's power to the others: it reads e_x and a distribution
    distributes: bool = True
    #: it chooses among the multi-scale candidates (cells, groups, polygons) and the candidate lamps
    multiscale: bool = False
    #: it stops at its own tolerance (a programme), not at the stop criteria
    needs_tolerance: bool = False
    #: the paper's Gauss-Seidel error route is offered for it
    gauss_seidel: bool = False
    #: one of the paper's four heuristics (benchmarks draw them apart)
    paper: bool = False
    #: (problem, lights, tolerance, uniformity) -> (exitance, message): its programme again on the chosen
    #: lights after their columns of T changed (pipeline.jobs), None when it has none
    refit: Callable | None = None


@dataclass(frozen=True)
class ColourTraits:
    #: its certificate relaxes the colour constraint (light_colour.relaxed_bound; engine/cost.py)
    relaxation: bool = False


def _traits(registry_kind, name, traits_type, extra):
    """The traits of a method being registered: ValueError for a keyword that is not one of
    ``traits_type``'s fields, or a value of the wrong type."""
    fields = {f.name: f for f in dataclasses.fields(traits_type)}
    for key, value in extra.items():
        if key not in fields:
            known = ", ".join(fields) or "none"
            raise ValueError(f"{registry_kind} {name!r}: unknown trait {key}= (the traits of a {registry_kind}: "
                             f"{known})")
        default = fields[key].default
        ok = callable(value) if default is None else isinstance(value, type(default))
        if not ok:
            raise ValueError(f"{registry_kind} {name!r}: trait {key}= must be "
                             f"{'callable' if default is None else type(default).__name__}, got {value!r}")
    try:
        return traits_type(**extra)
    except ValueError as exc:
        raise ValueError(f"{registry_kind} {name!r}: {exc}") from None


@dataclass(frozen=True)
class Method:
    name: str
    label: str
    description: str
    impl: Callable
    traits: object = NoTraits()  # its registry's traits dataclass (SelectionTraits, ...)
    params: tuple = ()  # its Params (engine/options.py builds the job options from them)

    def __call__(self, *args, **kwargs):
        return self.impl(*args, **kwargs)

    def bind(self, options=None, **values) -> "Bound":
        """This method with its declared parameters: each from ``values`` if given there, else
        from ``options`` (the job options: the field of that name), else its declared default (a
        value None is "not set": the default too). ValueError for a value that is not one of its
        parameters or fails its declaration's check."""
        declared = {p.name: p for p in self.params}
        unknown = [n for n in values if n not in declared]
        if unknown:
            raise ValueError(f"{self.name!r} has no parameter {', '.join(unknown)} "
                             f"(its parameters: {', '.join(declared) or 'none'})")
        bound = {}
        for name, p in declared.items():
            value = values[name] if name in values else getattr(options, name, None)
            try:
                bound[name] = p.check(p.default if value is None else value)
            except ValueError as exc:
                raise ValueError(f"{name.replace('_', ' ')} {exc}") from None
        return Bound(self, MappingProxyType(bound))


@dataclass(frozen=True)
class Bound:
    """A method with its parameters (``Method.bind``): calling it calls the implementation with
    the arguments given and the parameters as keywords."""

    method: Method
    params: MappingProxyType

    @property
    def name(self) -> str:
        return self.method.name

    @property
    def traits(self):
        return self.method.traits

    def __call__(self, *args):
        return self.method.impl(*args, **self.params)


class Registry:
    """Named methods of one kind, in registration order (the order the UI lists them).

    The registry imports nothing: its methods' package registers them when imported (the package
    of a kind of method is imported by the module that dispatches to it -- inverse.py for the
    solvers, reduction.py for the selections and distributions, options.py for every user-chosen
    kind -- so no import cycle runs through here). Reading a registry whose package was never
    imported is a programming error, said as such."""

    def __init__(self, kind: str, package: str, traits: type = NoTraits):
        self.kind = kind
        self.package = __name__.rsplit(".", 1)[0] + package  # e.g. relight_addon.engine.solvers
        self.traits = traits
        self._methods: dict[str, Method] = {}

    def register(self, name: str, label: str, description: str, params=(), **traits):
        """Register ``impl`` (the decorated function or class) as method ``name``; ``traits``:
        the registry's traits (ValueError now for one it does not have, or of the wrong type)."""
        checked = _traits(self.kind, name, self.traits, traits)

        def deco(impl):
            if name in self._methods:
                raise ValueError(f"{self.kind} {name!r} is registered twice")
            self._methods[name] = Method(name, label, description, impl, checked, tuple(params))
            return impl
        return deco

    def bound(self, choice) -> Bound:
        """``choice`` as a bound method: a name, with its declared defaults, or a Bound of this
        registry as it is (ValueError for an unknown name)."""
        if isinstance(choice, Bound):
            if self._loaded().get(choice.name) is not choice.method:
                raise ValueError(f"{choice.name!r} is not a {self.kind}")
            return choice
        return self[choice].bind()

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


PATCH_MODELS = Registry("patch model", ".patch_models", PatchModelTraits)
ESTIMATORS = Registry("form-factor estimator", ".estimators", EstimatorTraits)
SOLVERS = Registry("inverse solver", ".solvers", SolverTraits)
SELECTIONS = Registry("selection", ".selections", SelectionTraits)
DISTRIBUTIONS = Registry("distribution", ".distributions")
LIGHT_KINDS = Registry("light kind", ".lights")
LIGHT_COLOURS = Registry("light colour", ".colours", ColourTraits)
#: what a solve is asked to meet: kinds of targets (engine/targets/), each giving rows on the radiosity
TARGET_KINDS = Registry("target kind", ".targets")
