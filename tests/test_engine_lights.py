"""The light model (engine/lights/): kinds from the registry, and a light as a source.

References: the inverse of A formed explicitly (numpy), so a light's column of T must equal
A^-1 applied to its source -- an exitance on its patches, or rho times a direct irradiance.
"""
import numpy as np
import pytest
import scipy.sparse as sp

import flatland
from relight_addon.engine.inverse import InverseError, InverseProblem
from relight_addon.engine.targets import PaintedRadiance
from relight_addon.engine.lights import LightSet, kind_code
from relight_addon.engine.registry import LIGHT_KINDS

RHO = np.array([0.5, 0.6, 0.7])


@pytest.fixture(scope="module")
def room():
    return flatland.room(4.0, 3.0, n_per_wall=(8, 6, 8, 6), reflectance=RHO)


def test_surface_kinds_registered_in_stored_code_order():
    # the codes are stored in results (.blend): their order must not change
    assert LIGHT_KINDS.names()[:3] == ("cell", "group", "polygon")
    for name in ("cell", "group", "polygon"):
        kind = LIGHT_KINDS[name].impl
        assert kind.source == "exitance" and kind.strength_unit == "W/m^2" and kind.writer == "surface"
        assert kind.watts(np.array([2.5]))[0] == 2.5  # power of 1 W/m^2 on 2.5 m^2
    with pytest.raises(ValueError, match="cell, group, polygon"):
        kind_code("spotlight")


def _two_lights(r, H_column):
    """A cell light on the first ceiling patch and a light whose source is the irradiance H_column."""
    P = len(r["area"])
    ceiling = np.flatnonzero(r["wall"] == "ceiling")
    cand = np.zeros(P, bool)
    cand[ceiling[0]] = True
    basis = sp.csr_matrix(np.array([[1.0, 0.0]]))
    H = sp.csr_matrix(H_column.reshape(P, 1) * np.array([[0.0, 1.0]]))
    code = kind_code("cell")
    lights = LightSet(np.flatnonzero(cand), basis, np.array([code, code], dtype=np.int8),
                      np.array([r["area"][ceiling[0]], 1.0]), r["center"][[ceiling[0], ceiling[0]]],
                      r["normal"][[ceiling[0], ceiling[0]]], irradiance=H)
    return cand, lights


def test_a_light_column_is_A_inverse_of_its_source(room):
    r = room
    P = len(r["area"])
    floor = r["wall"] == "floor"
    rng = np.random.default_rng(3)
    H_col = np.where(r["wall"] == "left", rng.uniform(1, 5, P), 0.0)  # a lamp lighting the left wall
    cand, lights = _two_lights(r, H_col)
    prob = InverseProblem(r["F"], r["area"], r["reflectance"], [PaintedRadiance.masked(floor, np.ones((P, 3)))], cand,
                          r["center"], r["normal"], lights=lights)
    for c in range(3):
        Ainv = np.linalg.inv(np.eye(P) - RHO[c] * r["F"])
        exitance_col = Ainv[prob.targets][:, np.flatnonzero(cand)[0]]
        irradiance_col = Ainv[prob.targets] @ (RHO[c] * H_col)
        np.testing.assert_allclose(prob.transfer[c][:, 0], exitance_col, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(prob.transfer[c][:, 1], irradiance_col, rtol=1e-10, atol=1e-14)
    # the forward route gives the same radiosity for any configuration of both lights
    strength = np.array([[3.0, 2.0, 1.0], [0.5, 1.5, 2.5]])
    B = prob.configuration_radiosity(strength)
    np.testing.assert_allclose(B[prob.targets], prob.target_radiosity_of(strength), rtol=1e-10, atol=1e-12)


def test_a_light_without_source_is_refused(room):
    r = room
    P = len(r["area"])
    cand, lights = _two_lights(r, np.zeros(P))  # the second light lights nothing
    with pytest.raises(InverseError, match="every light must have a source"):
        InverseProblem(r["F"], r["area"], r["reflectance"],
                       [PaintedRadiance.masked(r["wall"] == "floor", np.ones((P, 3)))],
                       cand,
                       r["center"], r["normal"], lights=lights)
