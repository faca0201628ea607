"""Options of a Relight job, with the engine's defaults (shared by the CLI and the add-on).

One table: ``JOB_PARAMS`` declares the job-wide options (rays, patch size, seed, the method
choices, the stop criteria), and every registered method declares its own parameters with it
(``engine/registry.py``'s :class:`Param`; e.g. the least-power selection's ``tolerance``, the
adaptive patch model's ``light_size``, ``refine_passes``, ``refine_tolerance``). From them:

- :class:`JobOptions`, a dataclass with one field per declared option (generated: existing
  callers keep ``JobOptions(selection="least-power", tolerance=0.1)``);
- ``JobOptions.validate``: every value's type and range from its declaration, and a
  ValueError for an option that the chosen methods do not use (refused, never ignored);
- the CLI's flags (``cli.py``), the add-on's scene properties and panel rows
  (``blender/ui/properties.py``, ``panels.py``, ``operators.job_options``).
"""
from __future__ import annotations

import dataclasses
import os

from . import colours, distributions, estimators, patch_models, selections, solvers, targets  # noqa: F401  (register the methods and kinds)
from .photometry.library import BUILTIN, load_library
from .registry import DISTRIBUTIONS, ESTIMATORS, LIGHT_COLOURS, PATCH_MODELS, SELECTIONS, SOLVERS, Param

DEFAULT_RAYS_PER_PATCH = 0  # 0 / None = automatic: engine.formfactors.auto_rays_per_patch
DEFAULT_SOLVER = "reduced"
DEFAULT_SELECTION = "greedy-swap"  # measured: docs/benchmarks.md "Best k lights"; the paper's is exitance-elimination
DEFAULT_DISTRIBUTION = "distance"  # the paper's choice (section 5)
DEFAULT_MAX_LIGHTS = 3
DEFAULT_PATCH_MODEL = "adaptive"  # the polygon model is the paper's (a patch per face)
DEFAULT_ESTIMATOR = "kernel"
DEFAULT_LIGHT_COLOUR = "auto"  # measured: docs/benchmarks.md "Light colour"

#: threads at most: more than the machine's CPU threads only costs memory (the ray buffers)
MAX_THREADS = 4 * (os.cpu_count() or 1)

#: configurations kept re-appliable in the .blend: every one up to this many lights, and
#: about STORE_LOG_POINTS log-spaced ones above (plus e_x and the final one); the chart and
#: the report keep the whole curve (the cost model counts their forward solves)
STORE_ALL_UP_TO = 32
STORE_LOG_POINTS = 40
#: intermediate (to-be-refined) models get this fraction of the rays
REFINE_RAY_FRACTION = 4

#: the option holding each user-chosen method, and its registry (the order the panel shows them)
METHOD_CHOICES = (("solver", SOLVERS), ("selection", SELECTIONS), ("distribution", DISTRIBUTIONS),
                  ("patch_model", PATCH_MODELS), ("estimator", ESTIMATORS), ("light_colour", LIGHT_COLOURS))


def _unused_without_distribution(o):
    if not SELECTIONS[o.selection].traits.distributes:
        users = ", ".join(m.name for m in SELECTIONS if m.traits.distributes)
        return f"the {o.selection} selection distributes no power (the selections that do: {users})"
    return ""


def _unused_by_least_power(o):
    if SELECTIONS[o.selection].traits.needs_tolerance:
        return f"the {o.selection} selection stops at its tolerance, not at the stop criteria"
    return ""


def _unused_by_single_scale(o):
    if not SELECTIONS[o.selection].traits.multiscale:
        users = ", ".join(m.name for m in SELECTIONS if m.traits.multiscale)
        return (f"the {o.selection} selection runs on single-scale light cells, without candidate lamps "
                f"(the selections that choose among cells and lamps: {users})")
    return ""


def _unused_without_lamps(o):
    why = _unused_by_single_scale(o)
    if why:
        return why
    if not any(getattr(o, name) for name in LAMP_OPTIONS) and not o.fixtures:
        return "no candidate lamp is offered (spot, area and point lamps all off, no --fixtures)"
    return ""


#: the options offering each kind of candidate lamp (engine/candidate_lamps.py)
LAMP_OPTIONS = ("spot_lamps", "area_lamps", "point_lamps")
#: the kinds offered by default: spots (measured: docs/benchmarks.md, "Candidate lamps": with area and
#: point lamps too the answers were no better on the gallery, the staircase and the living room)
DEFAULT_LAMPS = {"spot_lamps": True, "area_lamps": False, "point_lamps": False}
PARAM_FLAGS = {n: ("--no-" if DEFAULT_LAMPS[n] else "--") + n.replace("_", "-") for n in LAMP_OPTIONS}
#: the options of a job offering no candidate lamp (the surface cells alone, as before issue 17)
NO_LAMPS = {name: False for name in LAMP_OPTIONS}
#: candidate lamps at most (measured: docs/benchmarks.md, "Candidate lamps")
DEFAULT_MAX_LAMPS = 96

class OptionError(ValueError):
    """A refusal about the options, worded for where it is shown: ``str()`` names them by the
    CLI's flags, ``panel`` by the names the add-on's sidebar shows."""

    def __init__(self, cli: str, panel: str):
        super().__init__(cli)
        self.panel = panel


def check_light_kinds(options) -> None:
    """Refuse, before any work, an inverse solve that offers no kind of candidate light: the cells
    off and no lamp kind on (OptionError naming the flags, or the sidebar's Offer buttons)."""
    if not options.uses("surface_lights") or options.surface_lights or any(getattr(options, n) for n in LAMP_OPTIONS) \
            or options.fixtures:
        return
    given = [PARAM_FLAGS[n] for n in LAMP_OPTIONS if DEFAULT_LAMPS[n]]  # the flags that turned them off
    not_given = [PARAM_FLAGS[n] for n in LAMP_OPTIONS if not DEFAULT_LAMPS[n]]  # those that would turn them on
    titles = [PARAMS[n].title for n in ("surface_lights",) + LAMP_OPTIONS]
    raise OptionError(
        f"no candidate light: every kind is off: the cells (--no-surface-lights) and every lamp kind "
        f"({', '.join(given)} given; {' and '.join(not_given)} not given); leave the cells on or offer a lamp kind",
        f"no candidate light: every kind under Offer is off ({', '.join(titles)}): turn one on")


JOB_PARAMS = (
    Param("rays_per_patch", int, None, min=1, label="Rays per Patch", ui="zero", soft_max=65536, none="automatic",
          description="Form-factor quality: rays cast from every patch (automatic: about 4 million rays in "
                      "all, 1024 to 16384 per patch)"),
    Param("max_patch_size", float, None, min=0.0, min_exclusive=True, unit="LENGTH", label="Max Patch Size",
          ui="zero", none="the scene's relight_max_patch_size, else the diagonal of the region that decides the "
          "answer / 20",
          description="Largest patch edge in metres: larger faces are split into patches"),
    Param("seed", int, 0, min=0, max=2 ** 63 - 1, label="Seed", error="must be a non-negative integer "
          "(0 to 2^63 - 1), got {}", description="Random seed: results are reproducible"),
    Param("threads", int, None, min=1, max=MAX_THREADS, label="Threads", ui="hidden", none="every core",
          error=f"must be a whole number from 1 to {MAX_THREADS} (4 x this machine's {os.cpu_count() or 1} CPU "
                "threads: more only costs memory), got {}",
          description="Worker threads"),
    Param("solver", str, DEFAULT_SOLVER, registry=SOLVERS, label="Solver", inverse_only=True,
          description="Inverse solver"),
    Param("selection", str, DEFAULT_SELECTION, registry=SELECTIONS, label="Selection",
          description="How the lights are selected"),
    Param("distribution", str, DEFAULT_DISTRIBUTION, registry=DISTRIBUTIONS, label="Distribution",
          unused=_unused_without_distribution,
          description="Where a removed light's power goes (selections that distribute power)"),
    Param("light_colour", str, DEFAULT_LIGHT_COLOUR, registry=LIGHT_COLOURS, label="Light Colour", inverse_only=True,
          description="What colour a light may have: auto (blackbody unless the targets ask for coloured light), "
                      "free (each channel fitted on its own), white, blackbody (a colour temperature in a range), or "
                      "one-colour (any one colour per light, chosen with the light)"),
    Param("max_lights", int, DEFAULT_MAX_LIGHTS, min=1, label="Max Lights", ui="toggle", soft_max=64,
          unused=_unused_by_least_power, description="Stop criterion: at most this many lights"),
    Param("error_threshold", float, None, min=0.0, label="Relative Error", ui="toggle", ui_default=0.1,
          soft_max=1.0, unit="FACTOR", unused=_unused_by_least_power,
          description="Stop criterion: relative error (Eq. 1 / ||b_P||) at most this"),
    Param("require_positive", bool, True, label="No Negatives", flag="--allow-negative", invert=True,
          description="The final configuration must have no negative exitance"),
    Param("patch_model", str, DEFAULT_PATCH_MODEL, registry=PATCH_MODELS, label="Patch Model",
          description="How the scene becomes patches and candidate lights"),
    Param("estimator", str, DEFAULT_ESTIMATOR, registry=ESTIMATORS, label="Estimator",
          description="Form-factor estimator"),
    # the candidate lights beside the cells (engine/candidate_lamps.py)
    Param("surface_lights", bool, True, label="Cells", flag="--no-surface-lights", invert=True, inverse_only=True,
          unused=_unused_by_single_scale,
          description="Candidate lights: the candidate surfaces' own light cells, 2 x 2 groups and whole polygons"),
    Param("spot_lamps", bool, DEFAULT_LAMPS["spot_lamps"], label="Spots",
          flag=PARAM_FLAGS["spot_lamps"], invert=DEFAULT_LAMPS["spot_lamps"],
          inverse_only=True, unused=_unused_by_single_scale,
          description="Candidate lights: spot lamps mounted in front of the candidate surfaces, each cone just "
                      "covering a target region"),
    Param("area_lamps", bool, DEFAULT_LAMPS["area_lamps"], label="Area Lamps",
          flag=PARAM_FLAGS["area_lamps"], invert=DEFAULT_LAMPS["area_lamps"],
          inverse_only=True, unused=_unused_by_single_scale,
          description="Candidate lights: area lamps mounted in front of the candidate surfaces, facing a target "
                      "region"),
    Param("point_lamps", bool, DEFAULT_LAMPS["point_lamps"], label="Points",
          flag=PARAM_FLAGS["point_lamps"], invert=DEFAULT_LAMPS["point_lamps"],
          inverse_only=True, unused=_unused_by_single_scale,
          description="Candidate lights: point lamps mounted in front of the candidate surfaces"),
    Param("fixtures", str, None, label="Fixtures", inverse_only=True, unused=_unused_by_single_scale,
          none="no fixtures",
          description="Candidate lights: the catalogue fixtures of a fixture library, a folder of .ies / .ldt "
                      f"files or {BUILTIN!r} (the library Relight ships), each hung at the mounting positions and "
                      "dimmed between 0 and 100 % of its rated lumens; empty: none (engine/photometry/library.py)"),
    Param("lamp_drop", float, None, min=0.0, min_exclusive=True, unit="LENGTH", label="Lamp Drop", ui="zero",
          inverse_only=True, unused=_unused_without_lamps,
          none="2 % of the diagonal of the region that decides the answer",
          description="Distance in metres in front of the candidate surfaces at which the candidate lamps hang"),
    Param("refine_lamps", bool, True, label="Refine Lamps", flag="--no-lamp-refinement", invert=True,
          inverse_only=True, unused=_unused_without_lamps,
          description="Refine the chosen lamps' aim, cone, size and position on their surface to lower the error"),
    Param("max_lamps", int, DEFAULT_MAX_LAMPS, min=1, label="Max Lamps", soft_max=512, inverse_only=True,
          unused=_unused_without_lamps,
          description="Candidate lamps at most (the mounting positions are as many as this allows)"),
)


def _method_params():
    """{name: (Param, [(choice option, Method), ...])}: every method's declared parameters; a
    name two methods declare must be declared alike (then it is used when either is chosen)."""
    table = {}
    job = {p.name for p in JOB_PARAMS}
    for kind, registry in METHOD_CHOICES:
        for method in registry:
            for p in method.params:
                if p.name in job:
                    raise ValueError(f"{registry.kind} {method.name!r}: parameter {p.name!r} is a job option")
                if p.name in table and table[p.name][0] != p:
                    raise ValueError(f"parameter {p.name!r} is declared differently by two methods")
                table.setdefault(p.name, (p, []))[1].append((kind, method))
    return table


METHOD_PARAMS = _method_params()
#: every declared option, job-wide first
PARAMS = {**{p.name: p for p in JOB_PARAMS}, **{n: v[0] for n, v in METHOD_PARAMS.items()}}


def method_params(kind, name) -> tuple:
    """The Params of method ``name`` of the choice option ``kind`` ("selection", ...)."""
    return dict(METHOD_CHOICES)[kind][name].params


def _users(name):
    return METHOD_PARAMS[name][1]


class _JobOptionsBase:
    def uses(self, name) -> bool:
        """Does this job use option ``name``? (A method's parameter: its method is chosen; a
        job option: no chosen method makes it moot.)"""
        if name in METHOD_PARAMS:
            return any(getattr(self, kind) == m.name and self.uses(kind) for kind, m in _users(name))
        p = PARAMS[name]
        return not (p.unused and p.unused(self))

    def param(self, name, fallback=None):
        """The value of option ``name`` when this job uses it, else ``fallback``."""
        return getattr(self, name) if self.uses(name) else fallback

    def unused_reason(self, name) -> str:
        """Why option ``name`` is not used by this job's methods ("" when it is)."""
        if name in METHOD_PARAMS:
            if self.uses(name):
                return ""
            for kind, m in _users(name):
                if getattr(self, kind) == m.name:  # its method is chosen, but the choice is moot
                    why = PARAMS[kind].unused(self)
                    return f"is used only by the {m.name} {dict(METHOD_CHOICES)[kind].kind}, and {why}"
            users = " or ".join(f"the {m.name} {dict(METHOD_CHOICES)[kind].kind}" for kind, m in _users(name))
            chosen = ", ".join(f"the {kind.replace('_', ' ')} is {getattr(self, kind)}" for kind in
                               dict.fromkeys(k for k, _ in _users(name)))
            return f"is used only by {users} ({chosen})"
        p = PARAMS[name]
        reason = p.unused(self) if p.unused else ""
        return f"is not used: {reason}" if reason else ""

    def validate(self, given=()):
        """Check every option against its declaration (type, range; the method choices against
        their registries), then refuse an option that the chosen methods do not use: one set to
        a value other than its default (or None), or named in ``given`` (the CLI passes the
        flags on its command line). ValueError with one line naming the option."""
        if self.rays_per_patch == 0:
            self.rays_per_patch = None
        for name in METHOD_PARAMS:  # a method's parameter set to None: not set, its declared default
            if getattr(self, name) is None:
                setattr(self, name, PARAMS[name].default)
        for name, p in PARAMS.items():
            try:
                setattr(self, name, p.check(getattr(self, name)))
            except ValueError as exc:
                if p.registry is not None:
                    raise
                raise ValueError(f"{name.replace('_', ' ')} {exc}") from None
        for name, p in PARAMS.items():
            value = getattr(self, name)
            if name in given or (value is not None and value != p.default):
                reason = self.unused_reason(name)
                if reason:
                    raise ValueError(f"{p.cli_flag} {reason}")
        if self.param("fixtures"):  # (the library read, a bad file refused naming its line, before any work)
            load_library(self.fixtures)
        LIGHT_COLOURS[self.light_colour].bind(self)()  # (its own checks: a blackbody range, before any work)
        return self

    def to_dict(self):
        """Every option; the parameters of methods not chosen as None (the job does not use them;
        ``JobOptions(**d)`` gives the same options back)."""
        d = dataclasses.asdict(self)
        for name in METHOD_PARAMS:
            if not self.uses(name):
                d[name] = None
        return d


JobOptions = dataclasses.make_dataclass(
    "JobOptions", [(p.name, object, dataclasses.field(default=p.default)) for p in PARAMS.values()],
    bases=(_JobOptionsBase,), namespace={"__module__": __name__})
JobOptions.__doc__ = ("The options of a job: one field per declared option (JOB_PARAMS, then the methods' "
                      "parameters), defaults from the declarations; see the module's docstring.")
