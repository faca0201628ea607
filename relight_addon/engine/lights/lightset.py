"""Lights over the candidate patches, of any registered kind (no bpy).

A *candidate* is a patch that may become a light: ``candidate_mask`` is the one definition.
A surface light is a set of candidate patches that share one exitance (W/m^2); lights may
overlap (the same cell in a cell light, a 2x2 group and its polygon: multi-scale candidates),
so the exitance a patch emits is ``basis @ e``. The patch model (engine/patch_models/) builds
the LightSet; the inverse problem, the reduction, the stored result and the add-on work per
light through it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..geometry import group_mean_basis, unit
from ..registry import LIGHT_KINDS

__all__ = ["LightSet", "candidate_mask", "kind_code", "lights_from_groups", "append_lamps"]


def kind_code(name: str) -> int:
    """The code of a light kind (its position in LIGHT_KINDS: the codes stored in a result)."""
    LIGHT_KINDS[name]  # ValueError naming the known kinds
    return LIGHT_KINDS.names().index(name)


def candidate_mask(patches, mode: str = "inverse") -> np.ndarray:
    """(P,) bool: the patches that may emit.

    inverse ("solve"): every patch that is not forbidden, not already emitting (the scene's own
    emitters stay fixed background light) and not painted: a painted face asks for light, it does
    not hold it (the paper lets a painted patch emit; on artists' files the answer was then the
    painted floor, lane or desk glowing). direct ("reduce"): the scene's emitters (patches with a
    positive exitance in any channel).
    """
    emitting = np.any(patches.exitance > 0, axis=1)
    if mode == "direct":
        return emitting
    if mode != "inverse":
        raise ValueError(f"unknown mode {mode!r}; use 'inverse' or 'direct'")
    return ~patches.forbidden & ~emitting & ~patches.target


@dataclass
class LightSet:
    """Lights over the candidate patches ``patches`` (|C|,) (ascending patch indices).

    basis: (|C|, n_lights) CSR 0/1, patch c is part of the exitance source of light l (a
    light of an irradiance kind has an empty column and its source in ``irradiance``).
    kind: (n_lights,) codes of LIGHT_KINDS (``kind_code``). area (m^2), center, normal: per
    light, area-weighted over its patches (a lamp: its position, and its direction; a point lamp
    none). irradiance: None, or (P, n_lights) sparse direct irradiance (W/m^2) per unit strength,
    for the lights of irradiance kinds. lamps: None (no lamp), or per light the engine.lamps.Lamp
    a light of an irradiance kind is -- its whole geometry (position, direction, axes, cone,
    radius, size, shape), what the report and the Blender writers read -- and None for a surface
    light (``lamp``).
    """

    patches: np.ndarray
    basis: sp.csr_matrix
    kind: np.ndarray
    area: np.ndarray = field(default=None)
    center: np.ndarray = field(default=None)
    normal: np.ndarray = field(default=None)
    irradiance: object = None
    lamps: list = None

    @property
    def n_lights(self) -> int:
        return int(self.basis.shape[1])

    def lamp(self, light):
        """The engine.lamps.Lamp light ``light`` is (its geometry), None for a surface light."""
        return None if self.lamps is None else self.lamps[int(light)]

    def with_geometry(self, patch_set):
        a = patch_set.area[self.patches]
        self.area = np.asarray(self.basis.T @ a).reshape(-1)
        self.center = group_mean_basis(self.basis, patch_set.center[self.patches], a)
        self.normal = unit(group_mean_basis(self.basis, patch_set.normal[self.patches], a))
        return self

    # -- kinds -----------------------------------------------------------------------------
    def kind_of(self, light):
        """The LightKind of one light."""
        return LIGHT_KINDS[LIGHT_KINDS.names()[int(self.kind[light])]].impl

    @property
    def kind_names(self) -> list:
        names = LIGHT_KINDS.names()
        return [names[int(k)] for k in self.kind]

    def count_by_kind(self) -> dict:
        """{kind name: number of lights}, every registered kind listed."""
        counts = np.bincount(np.asarray(self.kind, dtype=np.int64), minlength=len(LIGHT_KINDS.names()))
        return {name: int(counts[i]) for i, name in enumerate(LIGHT_KINDS.names())}

    @property
    def watts(self) -> np.ndarray:
        """(n_lights,) power (W) of one unit of strength in one channel (LightKind.watts)."""
        out = np.empty(self.n_lights)
        for code in np.unique(self.kind):
            sel = self.kind == code
            out[sel] = self.kind_of(int(np.flatnonzero(sel)[0])).watts(self.area[sel])
        return out

    @property
    def upper(self) -> np.ndarray:
        """(n_lights,) each light's largest strength per channel (LightKind.strength_upper; inf: none)."""
        out = np.full(self.n_lights, np.inf)
        for j in range(self.n_lights if self.lamps is not None else 0):
            if self.lamps[j] is not None:
                out[j] = self.kind_of(j).strength_upper(self.lamps[j])
        return out

    def power(self, strength) -> np.ndarray:
        """(n_lights,) power (W) of the lights at ``strength`` (n_lights, 3), summed over the channels."""
        return np.asarray(strength, dtype=np.float64).reshape(-1, 3).sum(axis=1) * self.watts

    # -- sources ---------------------------------------------------------------------------
    def members(self, light) -> np.ndarray:
        """Patch indices of one light's exitance source."""
        kept = self.__dict__.get("_csc")
        if kept is None or kept[0] is not self.basis:  # (the basis in columns, kept while it is the same)
            kept = self.__dict__["_csc"] = (self.basis, self.basis.tocsc())
        B = kept[1]
        return self.patches[B.indices[B.indptr[light]:B.indptr[light + 1]]]

    def patch_exitance(self, exitance, n_patches) -> np.ndarray:
        """(n_patches, 3) exitance the lights' ``exitance`` (n_lights, 3) put on the patches."""
        out = np.zeros((n_patches, 3))
        out[self.patches] = self.basis @ np.asarray(exitance, dtype=np.float64).reshape(-1, 3)
        return out

    def patch_irradiance(self, strength, n_patches) -> np.ndarray:
        """(n_patches, 3) direct irradiance the lights of irradiance kinds put on the patches."""
        out = np.zeros((n_patches, 3))
        if self.irradiance is not None:
            out += np.asarray(self.irradiance @ np.asarray(strength, dtype=np.float64).reshape(-1, 3))
        return out


def lights_from_groups(patch_set, mask, groups, kind="cell") -> LightSet:
    """One light of ``kind`` per distinct value of ``groups`` (P,) over the patches in ``mask`` (P,) bool."""
    C = np.flatnonzero(mask)
    _, light_of = np.unique(np.asarray(groups)[C], return_inverse=True)
    light_of = light_of.reshape(-1)
    n = int(light_of.max()) + 1 if len(C) else 0
    basis = sp.csr_matrix((np.ones(len(C)), (np.arange(len(C)), light_of)), shape=(len(C), n))
    return LightSet(C, basis, np.full(n, kind_code(kind), dtype=np.int8)).with_geometry(patch_set)


def append_lamps(lights: LightSet | None, candidates, n_patches: int, lamps, kinds, irradiance, area) -> LightSet:
    """``lights`` (None: there are none; ``candidates`` are then their (empty) patches) followed
    by one light of an irradiance kind per engine.lamps.Lamp of ``lamps``: its kind name in
    ``kinds``, its column of ``irradiance`` (P, n) its direct irradiance (W/m^2) per unit of its
    strength, its ``area`` (m^2; LightKind.watts reads it), its centre the lamp's position and its
    normal the lamp's direction (none for a point lamp: it shines every way)."""
    n = len(lamps)
    H = sp.csc_matrix(irradiance, dtype=np.float64) if sp.issparse(irradiance) else \
        sp.csc_matrix(np.asarray(irradiance, dtype=np.float64).reshape(n_patches, n))
    if lights is None:
        C = np.asarray(candidates, dtype=np.int64)
        lights = LightSet(C, sp.csr_matrix((len(C), 0)), np.zeros(0, dtype=np.int8), np.zeros(0),
                          np.zeros((0, 3)), np.zeros((0, 3)))
    n0 = lights.n_lights
    codes = np.array([kind_code(k) for k in kinds], dtype=np.int8).reshape(n)
    center = np.array([lamp.position for lamp in lamps], dtype=np.float64).reshape(-1, 3)
    normal = np.array([lamp.kind.normal(lamp) for lamp in lamps], dtype=np.float64).reshape(-1, 3)
    old = lights.irradiance if lights.irradiance is not None else sp.csc_matrix((n_patches, n0))
    basis = sp.hstack([lights.basis, sp.csr_matrix((lights.basis.shape[0], n))]).tocsr()
    own = list(lights.lamps) if lights.lamps is not None else [None] * n0
    return LightSet(lights.patches, basis, np.concatenate([np.asarray(lights.kind, dtype=np.int8), codes]),
                    np.concatenate([np.asarray(lights.area, dtype=np.float64).reshape(-1),
                                    np.asarray(area, dtype=np.float64).reshape(n)]),
                    np.concatenate([np.asarray(lights.center, dtype=np.float64).reshape(-1, 3), center]),
                    np.concatenate([np.asarray(lights.normal, dtype=np.float64).reshape(-1, 3), normal]),
                    irradiance=sp.hstack([sp.csc_matrix(old), H]).tocsc(), lamps=own + list(lamps))
