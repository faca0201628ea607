"""Registry traits and method parameters (issue 38, item 4): a method receives exactly its declared
parameters (``Method.bind``), and a registry's traits are typed, checked when a method registers."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from relight_addon.engine.options import JobOptions
from relight_addon.engine.reduction import Distributor
from relight_addon.engine.registry import (DISTRIBUTIONS, ESTIMATORS, LIGHT_COLOURS, PATCH_MODELS, SELECTIONS, SOLVERS,
                                           Param, Registry, SelectionTraits, SolverTraits)


def toy_registry():
    reg = Registry("selection", ".selections", SelectionTraits)  # (its package is imported: reads work)
    return reg


def test_an_unknown_trait_is_refused_at_registration():
    reg = toy_registry()
    with pytest.raises(ValueError, match=r"selection 'toy': unknown trait nonnegative= .*distributes"):
        reg.register("toy", "Toy", "A toy", nonnegative=True)
    with pytest.raises(ValueError, match="unknown trait"):
        Registry("distribution", ".distributions").register("toy", "Toy", "A toy", paper=True)
    assert "toy" not in reg


def test_a_trait_of_the_wrong_type_is_refused():
    reg = toy_registry()
    with pytest.raises(ValueError, match="distributes= must be bool"):
        reg.register("toy", "Toy", "A toy", distributes="no")
    with pytest.raises(ValueError, match="refit= must be callable"):
        reg.register("toy", "Toy", "A toy", refit=3)
    with pytest.raises(ValueError, match="cost must be one of"):
        Registry("inverse solver", ".solvers", SolverTraits).register("toy", "Toy", "A toy", cost="cheap")


def test_traits_have_their_defaults_in_one_place():
    reg = toy_registry()
    reg.register("toy", "Toy", "A toy", multiscale=True)(lambda s: None)
    assert reg["toy"].traits == SelectionTraits(multiscale=True)
    assert reg["toy"].traits.distributes  # the default
    assert {m.name for m in SELECTIONS if not m.traits.distributes} == {"greedy-swap", "least-power", "nnls-greedy"}
    assert [m.name for m in SOLVERS if m.traits.nonnegative] == ["nnls"]
    assert [m.name for m in ESTIMATORS if m.traits.kernel_pairs] == ["kernel"]
    assert [m.name for m in PATCH_MODELS if m.traits.paint_independent] == ["polygon"]
    assert {m.name for m in LIGHT_COLOURS if m.traits.relaxation} == {"auto", "blackbody"}


def test_a_method_receives_its_declared_parameters():
    reg = toy_registry()
    got = []

    @reg.register("toy", "Toy", "A toy", params=(Param("gain", float, 1.0, min=0.0), Param("rounds", int, None, min=1)))
    def toy(s, gain, rounds):
        got.append((s, gain, rounds))

    reg["toy"].bind(SimpleNamespace(gain=2, rounds=None, unrelated=5))("curve")
    reg["toy"].bind()("defaults")
    reg["toy"].bind(SimpleNamespace(gain=2.0), rounds=3)("given")
    assert got == [("curve", 2.0, None), ("defaults", 1.0, None), ("given", 2.0, 3)]
    assert type(got[0][1]) is float  # (checked by its declaration: an int given for a float)
    with pytest.raises(ValueError, match="'toy' has no parameter tolerance"):
        reg["toy"].bind(tolerance=0.1)
    with pytest.raises(ValueError, match="gain must be"):
        reg["toy"].bind(gain=-1.0)
    with pytest.raises(ValueError, match="not a selection"):
        SELECTIONS.bound(reg["toy"].bind())


def test_the_job_options_reach_the_selection_and_the_distribution():
    o = JobOptions(selection="least-power", tolerance=0.3, uniformity=0.5).validate()
    assert dict(SELECTIONS["least-power"].bind(o).params) == {"tolerance": 0.3, "uniformity": 0.5}
    assert dict(SELECTIONS["greedy-swap"].bind(o).params) == {}
    o = JobOptions(selection="exitance-elimination", distribution="coplanar", coplanar_tolerance=0.01).validate()
    assert dict(DISTRIBUTIONS["coplanar"].bind(o).params) == {"coplanar_tolerance": 0.01}
    prob = SimpleNamespace(light_normal=np.array([[0.0, 0, 1], [0, 0, 1], [0, 1, 0]]),
                           light_center=np.array([[0.0, 0, 0], [1, 0, 0.005], [0, 0, 0]]), light_watts=np.ones(3))
    loose = Distributor(prob, DISTRIBUTIONS["coplanar"].bind(o))  # 0.005 off the plane: within 1 % of the extent
    tight = Distributor(prob, "coplanar")  # the declared default, 1e-3
    assert loose.kind == tight.kind == "coplanar"
    assert loose.pair[0, 1] and not tight.pair[0, 1]


def test_the_light_colour_receives_its_range():
    o = JobOptions(light_colour="blackbody", temperature_min=3000.0).validate()
    assert LIGHT_COLOURS["blackbody"].bind(o)().range == (3000.0, 6500.0)
    assert LIGHT_COLOURS["auto"].bind(o)().blackbody.range == (3000.0, 6500.0)
    assert LIGHT_COLOURS["white"].bind(o)().name == "white"  # (declares no parameter: receives none)
