"""Target kinds: what a solve is asked to meet, as rows of a linear system on the radiosity.

A target is an object of a registered kind (``engine.registry.TARGET_KINDS``, one file per
kind here) that gives

- ``rows(n_patches)``: its rows, a sparse (k, P) linear map on the patches' radiosity B (the same
  map in every channel): a painted face selects its patches, a mean would average several;
- ``values``: (k, 3) W/m^2, what each row of B is asked to be (in the radiosity's units);
- ``region``: (k,) int, per row the object of a uniformity region (the least-power selection's
  uniformity goal: illuminance targets), -1 for none;
- ``shown()``: (k, 3) the values in the kind's own unit (``unit``), as the report says them.

``TargetRows.stack`` puts the targets of a problem into one system (``InverseProblem``): rows
ordered by the first patch they read (stable), so a scene's painted and illuminance targets keep
the patches' order. A kind's ``from_scene(faces, patches, F)`` (F: the form factors) makes its target of a scene (None
when the scene has none); ``scene_targets`` asks every registered kind.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..registry import TARGET_KINDS
from .kind import Target, TargetAims, selection_rows
from .radiance import PaintedRadiance  # (the kinds register themselves, in this order)
from .illuminance import Illuminance
from .view import ViewTarget

__all__ = ["Target", "TargetRows", "scene_targets", "target_aims", "TargetAims", "selection_rows", "PaintedRadiance", "Illuminance", "ViewTarget"]


@dataclass
class TargetRows:
    """The targets of a problem stacked into one system: ``matrix`` (m, P) CSR on B, ``values``
    (m, 3) W/m^2, ``region`` (m,), ``target`` (m,) the index in ``targets`` of each row's target.
    ``patch`` (m,): the patch of each row when every row selects one patch, each patch once
    (``selects``: the paper's formulation substitutes them), else the first patch each row reads."""

    targets: list
    matrix: sp.csr_matrix
    values: np.ndarray
    region: np.ndarray
    target: np.ndarray
    patch: np.ndarray
    selects: bool
    #: (m,) row r of the system is row order[r] of the targets' rows stacked in turn (None: the same order)
    order: np.ndarray = None

    @classmethod
    def stack(cls, targets, n_patches) -> "TargetRows":
        """The rows of ``targets`` (their kinds' ``rows`` and ``values``) in one system of
        ``n_patches`` columns, ordered by the first patch each row reads (stable: a kind's own order
        among rows that start on one patch); ValueError on rows of another width or reading nothing."""
        targets = list(targets)
        mats = [sp.csr_matrix(t.rows(n_patches), dtype=np.float64) for t in targets]
        if any(M.shape[1] != n_patches for M in mats):
            raise ValueError(f"a target's rows do not have {n_patches} columns")
        M = sp.vstack(mats, format="csr") if mats else sp.csr_matrix((0, n_patches))
        M.sort_indices()
        if np.any(np.diff(M.indptr) == 0):
            raise ValueError("a target row reads no patch")
        values = np.concatenate([np.asarray(t.values, dtype=np.float64).reshape(-1, 3) for t in targets]) \
            if targets else np.zeros((0, 3))
        region = np.concatenate([t.region for t in targets]) if targets else np.zeros(0, np.int64)
        which = np.repeat(np.arange(len(targets)), [X.shape[0] for X in mats])
        first = M.indices[M.indptr[:-1]]
        order = np.argsort(first, kind="stable")
        M = M[order]
        selects = bool(np.all(np.diff(M.indptr) == 1) and np.all(M.data == 1.0)
                       and len(np.unique(first)) == len(first))  # (one patch per row, each patch once)
        return cls(targets, M, values[order], region[order].astype(np.int64), which[order], first[order], selects,
                   order)

    @property
    def m(self) -> int:
        return self.matrix.shape[0]

    def kind_of(self, row) -> str:
        """The kind of target row ``row``."""
        return self.targets[self.target[row]].kind

    def of(self, X) -> np.ndarray:
        """The rows applied to X (P, ...): a selection's rows of X, else the sparse product."""
        if self.selects:
            return X[self.patch]
        return np.asarray(self.matrix @ X)

    def _stacked(self, blocks) -> np.ndarray | None:
        """The targets' ``blocks`` (one per target: None, or an array of its rows first) in the
        system's rows; None when every block is."""
        shape = next((np.shape(b)[1:] for b in blocks if b is not None), None)
        if shape is None:
            return None
        counts = np.bincount(self.target, minlength=len(self.targets))
        full = np.concatenate([np.zeros((k,) + shape) if b is None else np.asarray(b, dtype=np.float64)
                               for b, k in zip(blocks, counts)])
        return full if self.order is None else full[self.order]

    def lamp_terms(self, lamps, irradiance=None, samples=None) -> np.ndarray | None:
        """(m, len(lamps), 3): what the lamps (engine.lamps.Lamp) add to the rows beyond B per unit
        strength (each kind's ``lamp_terms``; ``samples``: theirs), None when no kind adds anything."""
        if not len(lamps):
            return None
        return self._stacked([t.lamp_terms(lamps, irradiance, samples) for t in self.targets])

    def bsdf_rows(self):
        """(m, P) sparse, or None: the rows' shares that see their patch's first reflection through
        its BSDF (each kind's ``bsdf_rows``), in the system's order."""
        P = self.matrix.shape[1]
        blocks = [t.bsdf_rows(P) for t in self.targets]
        if all(b is None for b in blocks):
            return None
        counts = np.bincount(self.target, minlength=len(self.targets))
        M = sp.vstack([sp.csr_matrix((k, P)) if b is None else sp.csr_matrix(b, dtype=np.float64)
                       for b, k in zip(blocks, counts)], format="csr")
        return M if self.order is None else M[self.order]

    def fixed_light(self) -> np.ndarray | None:
        """(m, 3): what the scene's own lamps add to the rows beyond B (each kind's ``fixed_light``)."""
        return self._stacked([t.fixed_light() for t in self.targets])

    def columns(self) -> np.ndarray:
        """(P, m) dense: the rows' transpose, right-hand sides of A^T Y = R^T."""
        if self.selects:
            Y = np.zeros((self.matrix.shape[1], self.m))
            Y[self.patch, np.arange(self.m)] = 1.0
            return Y
        return self.matrix.T.toarray()


def scene_targets(faces, patches, F=None, kept=()) -> list:
    """The targets of a scene (FaceSet ``faces`` meshed into ``patches``, form factors ``F``): every
    registered kind's (``from_scene``), in registration order. ``kept``: the targets of an earlier
    paint on the same model, each taken again where it ``serves`` (a Live stroke's retarget: a
    camera-view target's rows took 1.3 s to make on the living room), else given to the kind's
    ``from_scene`` (what of it is the same: a repainted view target's unchanged patches' rows)."""
    found = (next((t for t in kept if type(t) is kind.impl and t.serves(faces, F)), None)
             or kind.impl.from_scene(faces, patches, F, kept) for kind in TARGET_KINDS)
    return [t for t in found if t is not None]


def target_aims(faces, patches, sampler) -> TargetAims:
    """Every registered kind's ``Target.aims`` together (radiosities summed, mounts joined)."""
    found = [a for a in (kind.impl.aims(faces, patches, sampler) for kind in TARGET_KINDS) if a is not None]
    radiosity = [a.radiosity for a in found if a.radiosity is not None]
    return TargetAims(np.sum(radiosity, axis=0) if radiosity else None,
                      np.concatenate([a.mounts for a in found] + [np.zeros((0, 3))]),
                      np.concatenate([a.mount_patches for a in found] + [np.zeros(0, dtype=np.int64)]))
