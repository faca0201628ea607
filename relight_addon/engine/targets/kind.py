"""The target-kind interface (engine/targets/__init__.py's docstring): ``Target``, the base of
every kind, and ``selection_rows``, the rows of a kind that selects patches."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

__all__ = ["Target", "TargetAims", "selection_rows"]


def selection_rows(patches, n_patches) -> sp.csr_matrix:
    """(k, P) CSR: row i selects patch ``patches[i]`` (weight 1)."""
    patches = np.asarray(patches, dtype=np.int64).reshape(-1)
    k = len(patches)
    return sp.csr_matrix((np.ones(k), patches, np.arange(k + 1)), shape=(k, n_patches))


@dataclass
class TargetAims:
    """What the candidate lamps aim at beyond the painted patches (engine.candidate_lamps):
    ``radiosity`` (P,) W/m^2 or None, the radiosity asked on patches no paint covers (a camera-view
    target's: the patches its painted pixels see; target_clusters); ``mounts`` (m, 3) points on
    surfaces where a lamp must hang to give what is asked (a painted highlight: where the camera's
    ray reflected by the glossy surface meets a surface), ``mount_patches`` (m,) their patches."""

    radiosity: np.ndarray | None = None
    mounts: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mount_patches: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


class Target:
    """A target of some kind (engine/targets' docstring): subclasses set ``kind`` and ``unit`` and give
    ``rows``, ``values`` and, when they differ from the defaults, ``region`` and ``shown``."""

    kind = ""
    unit = "W/m^2"
    values: np.ndarray
    #: whether a retargeted model keeps this kind's target between paints (``serves``) and its rows'
    #: products (InverseProblem._rows_of)
    kept_by_retarget = False

    def rows(self, n_patches) -> sp.csr_matrix:
        raise NotImplementedError

    @property
    def region(self) -> np.ndarray:
        return np.full(len(self.values), -1, dtype=np.int64)

    def shown(self) -> np.ndarray:
        return np.asarray(self.values, dtype=np.float64)

    @classmethod
    def aims(cls, faces, patches, sampler):
        """What the candidate lamps should aim at for this kind's targets of ``faces`` beyond the
        painted patches (``patches.target``): a TargetAims (engine/targets/__init__.py), or None."""
        return None

    def lamp_terms(self, lamps, irradiance=None, samples=None):
        """None when this kind's rows see the lamps' light through B alone; else (k, len(lamps), 3)
        W/m^2 per unit strength: what each lamp (engine.lamps.Lamp) adds to the rows beyond B
        (a glossy surface's reflection of its direct light, engine/targets/view.py).
        ``irradiance`` (P, len(lamps)) optional: the lamps' direct irradiance on the patches (a
        lamp that lights none of the rows' patches adds nothing). ``samples``: the samples of a
        lamp with an extent per point (None: the kind's own; fewer for a search's estimate)."""
        return None

    def fixed_light(self):
        """None, or (k, 3) W/m^2: what the scene's own lamps add to the rows beyond B (lamp_terms
        of the fixed light)."""
        return None

    def bsdf_rows(self, n_patches):
        """None, or (k, n_patches) sparse: the share of each row that reads a patch's radiosity
        where the row sees the patch's first reflection through the patch's own BSDF (a camera-view
        target's glossy rows: their patch, at the row's weight). B holds that reflection with the
        albedo of its incidence (engine.incidence: InverseProblem's first_bounce and lamp_excess);
        such a row must not count the albedo's excess over rho twice."""
        return None

    #: None, or (an earlier target, rows of this one (r,), its rows (r,)): rows of this target that
    #: are that target's, bit for bit (a repainted camera-view target's unchanged patches': its
    #: from_scene with ``kept``); the inverse problem takes their products with the transfer from it
    rows_taken = None

    @classmethod
    def from_scene(cls, faces, patches, F=None, kept=()):
        """This kind's target of a scene (FaceSet ``faces`` meshed into ``patches``), or None.
        ``kept``: the targets an earlier paint made on the same model (a Live stroke's), whose work
        a kind may take again where it is the same."""
        return None

    def serves(self, faces, F) -> bool:
        """Whether this target, made for another paint of the same scene on the same model (its
        form factors ``F``), is the one ``from_scene(faces, ...)`` would make: a retargeted model
        (a Live stroke's) keeps it instead of making it again. False by default: the painted kinds'
        rows are read again (cheap)."""
        return False
