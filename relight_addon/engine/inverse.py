"""The inverse radiosity system: the paper's "mathematical phase".

Per channel (R, G, B) the forward system is ``A b = e`` with
``A = I - diag(rho) F`` (b radiosity and e self-exitance, both W/m^2).
The user paints radiosities ``b_P`` on a set P of m patches (targets) and
allows lights on a set C of candidates (every patch that is not forbidden);
forbidden patches have e = 0. More generally the targets are m rows ``R B = b`` of any kinds
(engine/targets/: a painted patch's row selects it, other kinds' rows may mix patches); below, a
selection's "rows P of A^-1" are ``R A^-1``.

Two formulations of the same inverse problem, plus a physical one (each a registered
solver in ``engine/solvers/``; see engine.registry):

``solver="svd"`` (the paper, [Conte02])
    Substitute the knowns into ``A b - e = 0``: the unknowns are b on the
    unpainted patches U and e on the candidates C, so
    ``[A[:, U]  -I[:, C]] [b_U; e_C] = -A[:, P] b_P``, i.e. ``M x = r``
    (n rows, |U| + |C| columns). Its minimum-norm least-squares solution via
    the SVD pseudo-inverse, singular values below ``rcond * s_max`` cut off
    (default ``rcond = max(rows, cols) * eps``), gives e_x.
``solver="reduced"``
    The forward system is linear, so on the targets ``b_P = T e_C`` with T
    the rows P, columns C of ``A^-1`` (from an LU factorisation of A, never
    forming the inverse). The minimum-norm least-squares solution of
    ``T e_C = b_P`` (m x |C|). The two routes have different minimum-norm
    solutions; both reproduce feasible targets to solver precision.
``solver="nnls"`` (beyond the paper)
    Non-negative least squares on T per channel: a physical configuration
    (e >= 0) at the cost of a residual when the targets are not reachable
    with positive lights.

The error of any configuration is Eq. 1 through T:
``sqrt(sum over targets and the 3 channels of (b_P - T e_C)^2)``.
"""
from __future__ import annotations

import copy
import time
import warnings as _warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .geometry import group_mean_basis, unit
from .sampling import check_cancel, run_cancellable
from .lights import LightSet, candidate_mask, kind_code
from .plausibility import implausible_lights
from .radiosity import lossless_patches, radiosity_matrix
from . import solvers  # noqa: F401  (registers the solvers that solve_inverse dispatches to)
from .registry import SOLVERS
from .solvers.common import channel_groups
from .scene import SceneError
from .targets import PaintedRadiance, TargetRows, scene_targets
from .units import TINY

__all__ = [
    "InverseError",
    "InverseProblem",
    "InverseResult",
    "solve_inverse",
    "direct_lighting_problem",
]


#: above this many patches A is never factorised: its solves are iterative on the sparse F
#: (engine.radiosity's dense/sparse limits for F itself are separate)
DIRECT_SOLVE_LIMIT = 6000
#: relative residual of the iterative solves
ITERATIVE_TOL = 1e-10
#: condition-number estimate of A above which the problem warns (a closed scene of reflectance
#: 1 - 1e-6 is about 1e6; closer to 1 the float32 rows of F, within 1.2e-7 of their sums, set the limit)
ILL_CONDITIONED = 1e6
#: condition-number estimate treated as singular (about 1 / machine epsilon / 100)
SINGULAR = 1e14


class InverseError(SceneError):
    """The inverse problem cannot be set up or solved; the message is for the user."""


class DivergentTransport(InverseError):
    """The transport I - rho F would create light: a bound of its growth per bounce ``rate`` >= 1,
    from the patches ``rows`` ((P,) bool) where it grows."""

    def __init__(self, rate, rows, names=None):
        self.rate, self.rows, self.names = float(rate), rows, names
        where = f" ({names})" if names else ""
        super().__init__(f"the form factors of {int(np.sum(rows))} patch(es){where} send back more light than they "
                         f"receive ({self.rate:.3g} per bounce): their faces overlap, coincide or lie inside other "
                         "faces; remove the duplicate faces (Merge by Distance, Delete Loose) or hide those objects")


    def named(self, object_names, patch_object):
        """The same error naming the objects of its patches (``patch_object`` (P,) indices into
        ``object_names``), the most patches first."""
        obj, count = np.unique(np.asarray(patch_object)[self.rows], return_counts=True)
        order = np.argsort(-count, kind="stable")
        names = ", ".join(f"{count[i]} of '{object_names[obj[i]]}'" for i in order[:4])
        return DivergentTransport(self.rate, self.rows, names + (", ..." if len(obj) > 4 else ""))


#: power sweeps of growth_bound (each a product with F)
GROWTH_SWEEPS = 40


def growth_bound(F, rho, sweeps: int = GROWTH_SWEEPS):
    """(bound, rows): an upper bound of the spectral radius of M = diag(rho) F (non-negative), the
    rate at which the radiosity iteration converges, and the rows (P,) bool where it is >= 1 at the
    end. The Collatz-Wielandt bound max_i (M x)_i / x_i holds for every positive x: x = 1 gives
    the largest row sum (kept when it is below 1), power sweeps of x tighten it towards the
    spectral radius (a patch that sees half-buried patches has a row sum above 1, the whole scene
    still loses light at every bounce)."""
    rho = np.asarray(rho, dtype=np.float64)
    x = np.ones(F.shape[0])
    best, rows = np.inf, None
    for _ in range(max(int(sweeps), 1)):
        y = rho * np.asarray(F @ x, dtype=np.float64).reshape(-1)
        ratio = y / x
        if float(ratio.max()) < best:
            best, rows = float(ratio.max()), ratio >= 1.0
        if best < 1.0:
            break
        x = y / max(float(y.max()), TINY) + 1e-12  # (kept positive)
    return best, rows


class _Factor:
    """LU factorisation of A for one channel, with its 1-norm condition estimate."""

    def __init__(self, A):
        self.sparse = sp.issparse(A)
        if self.sparse:
            try:
                self.lu = spla.splu(A.tocsc())
            except RuntimeError as exc:  # exactly singular
                raise InverseError(
                    "the radiosity system I - rho F is singular (a closed scene with reflectance 1?)") from exc
            self.cond = float("nan")
            try:
                self.cond = float(spla.onenormest(A) * spla.onenormest(spla.LinearOperator(
                    A.shape, matvec=self.lu.solve, rmatvec=lambda x: self.lu.solve(x, trans="T"))))
            except Exception:  # the estimate is advisory only
                pass
        else:
            with _warnings.catch_warnings():
                _warnings.simplefilter("ignore", sla.LinAlgWarning)
                self.lu = sla.lu_factor(A, check_finite=False)
            diag = np.abs(np.diag(self.lu[0]))
            if diag.min() <= np.finfo(float).eps * max(diag.max(), 1.0):
                raise InverseError(
                    "the radiosity system I - rho F is singular (a closed scene with reflectance 1?)")
            anorm = np.abs(A).sum(axis=0).max()
            rc, _ = sla.lapack.dgecon(self.lu[0], anorm, norm="1")
            self.cond = float(1.0 / rc) if rc > 0 else float("inf")
        if self.cond > SINGULAR:
            raise InverseError(
                f"the radiosity system I - rho F is numerically singular (condition estimate {self.cond:.3g}); "
                "a closed scene with reflectance 1?")

    def solve(self, rhs, trans=False):
        if self.sparse:
            return self.lu.solve(np.asarray(rhs, dtype=np.float64), trans="T" if trans else "N")
        return sla.lu_solve(self.lu, rhs, trans=1 if trans else 0, check_finite=False)


class _Iterative:
    """Solves of A = I - diag(rho) F without factorising A (large models): block Jacobi / Neumann
    iteration X <- R + rho o (F X) (transposed: Y <- R + F^T (rho o Y)) on all right-hand sides at
    once, one sparse matrix product per sweep. It converges because rho < 1 and F's rows sum to
    at most 1 (rate <= max rho_i sum_j F_ij, reported as ``rate``)."""

    def __init__(self, F, rho):
        self.F = F.tocsr() if sp.issparse(F) else np.asarray(F)
        self.FT = self.F.T.tocsr() if sp.issparse(F) else self.F.T
        self.rho = np.asarray(rho, dtype=np.float64)
        self.rate, growing = growth_bound(self.F, self.rho)
        if not self.rate < 1.0:
            raise DivergentTransport(self.rate, growing)
        self.cond = float((1 + self.rate) / (1 - self.rate))  # (a bound on cond_inf(A) when rows sum to <= 1)
        self.sparse = True
        self.max_iter = int(np.ceil(np.log(ITERATIVE_TOL) / np.log(max(self.rate, 1e-3)))) + 10

    def solve(self, rhs, trans=False):
        R = np.asarray(rhs, dtype=np.float64)
        one = R.ndim == 1
        R = R.reshape(len(R), -1)
        if R.size == 0:  # (no right-hand side: a reduce whose lights are all lamps has no surface column)
            return R[:, 0] if one and R.shape[1] else R
        rho = self.rho[:, None]
        X = R.copy()
        scale = max(float(np.abs(R).max()), TINY)
        for _ in range(self.max_iter):
            Xn = R + (self.FT @ (rho * X) if trans else rho * (self.F @ X))
            done = float(np.abs(Xn - X).max()) <= ITERATIVE_TOL * scale
            X = Xn
            if done:
                break
        else:
            raise InverseError(f"the iterative radiosity solve did not converge in {self.max_iter} sweeps")
        return X[:, 0] if one else X


@dataclass
class InverseResult:
    """Solution of the inverse problem.

    exitance: (|C|, 3) W/m^2 on the candidates (``problem.candidates`` order).
    rank: numerical rank used by the pseudo-inverse (min over channels; for
    nnls the number of lights with a non-zero exitance).
    error: Eq. 1 through T; relative_error = error / ||b_P||.
    n_negative: number of candidates with at least one negative channel.
    seconds: wall time of the mathematical phase (building and solving the system,
    including the LU factorisation when T is needed and not yet cached).
    """

    solver: str
    exitance: np.ndarray
    rank: int
    error: float
    relative_error: float
    n_negative: int
    seconds: float
    rcond: float | None = None
    warnings: list = field(default_factory=list)

    def patch_exitance(self, problem):
        return problem.patch_exitance(self.exitance)


def _array(x, shape, name, dtype=np.float64):
    """``x`` as an array of ``shape``, finite when float (InverseError naming ``name`` if not)."""
    try:
        a = np.asarray(x, dtype=dtype).reshape(shape)
    except (ValueError, TypeError) as exc:
        raise InverseError(f"{name} must have shape {shape}") from exc
    if dtype is np.float64 and not np.all(np.isfinite(a)):
        raise InverseError(f"{name} contains NaN or infinite values")
    return a


def _form_factor_matrix(F):
    """(F, emission_share or None): the (P, P) matrix (CSR when sparse) of form factors or of a
    formfactors.FormFactors, checked square and finite."""
    share = None
    if hasattr(F, "matrix"):  # formfactors.FormFactors
        F, share = F.matrix, getattr(F, "emission_share", None)
    if sp.issparse(F):
        F = F.tocsr()
        n, data = F.shape[0], F.data
    else:
        F = np.asarray(F)
        n, data = (F.shape[0] if F.ndim == 2 else -1), F
    if F.ndim != 2 or F.shape != (n, n) or n == 0:
        raise InverseError(f"form factors must be a square (P, P) matrix, got shape {F.shape}")
    if not np.all(np.isfinite(data)):
        raise InverseError("the form factors contain NaN or infinite values")
    return F, share


def target_rows(targets, n_patches) -> TargetRows:
    """The targets (a list of engine.targets objects) stacked into the problem's rows, checked:
    at least one row, finite non-negative values."""
    try:
        rows = TargetRows.stack(targets, n_patches)
    except ValueError as exc:
        raise InverseError(str(exc)) from exc
    if rows.m == 0:
        raise InverseError("no target: paint a radiosity on at least one face")
    if not np.all(np.isfinite(rows.values)):
        raise InverseError("target radiosity contains NaN or infinite values")
    if np.any(rows.values < 0):
        raise InverseError("target radiosities must be non-negative")
    return rows


class InverseProblem:
    """Inverse lighting problem on patches.

    F: (P, P) form factors (dense ndarray or scipy.sparse), F[i, j] from i to j.
    area (P,) m^2, reflectance (P, 3), ``targets`` a list of targets (engine.targets: each kind
    gives its rows, a linear map on B, and their values; ``target_rows`` stacks them),
    candidate_mask (P,) bool (not forbidden), center (P, 3), normal (P, 3).
    Patch centres and normals are only used by the reduction's distributions;
    ``exitance`` (P, 3) optionally holds the scene's own emitters (for the
    Gauss-Seidel error route and direct-lighting mode).

    The system's rows are the targets' (``target_rows``, m of them): ``targets`` (m,) the patch of
    each row (the first it reads when a row mixes several), ``target_mask`` (P,) the patches the
    rows read, ``target_region`` (m,) their uniformity regions, ``b_target`` (m, 3) their values
    less the fixed light's radiosity there.

    ``lights``: the LightSet (engine.lights) over the candidates, of any kinds; each light's
    column of T is A^-1 applied to its source (``transfer``). Without it, ``light_basis``
    (|C|, n_lights) 0/1 or ``light_groups`` (P,) int (candidate patches with the same value
    form ONE light with one exitance, e.g. the patches of one Blender face) make surface
    lights; default: every candidate patch is a light cell. The unknowns, T's columns, e_x
    and the reduction are per light; radiosity stays per patch. ``n_lights``, ``light_area``,
    ``light_center``, ``light_normal``, ``light_watts`` (W per unit strength) and
    ``light_rows()`` describe the lights.
    """

    #: the light colour mode (a LIGHT_COLOURS instance, engine/colours/); None: free colours
    colour = None

    def __init__(self, F, area, reflectance, targets, candidate_mask,
                 center=None, normal=None, light_groups=None, light_basis=None, lights=None,
                 first_bounce=None, background=None, background_irradiance=None, lamp_excess=None,
                 background_excess=None, cancel=None):
        #: ``cancel()`` returning True stops the factorisation between channels (sampling.Cancelled)
        self.cancel = cancel
        self.F, share = _form_factor_matrix(F)
        n = self.n_patches = self.F.shape[0]
        #: (P,) or None: the share of a patch's emission that leaves it into the scene
        #: (formfactors.FormFactors.emission_share): F's columns carry its inverse for the radiosity,
        #: a whole-area mean, while an emitter sends the exitance of its visible part (Cycles emits
        #: from the whole face, the buried part into the occluder)
        self.emission_share = None if share is None else np.asarray(share, dtype=np.float64).reshape(n)
        self._init_patches(area, reflectance, candidate_mask, center, normal)
        self._set_targets(target_rows(targets, n))
        if len(self.candidates) == 0 and (lights is None or lights.irradiance is None):
            raise InverseError("no candidate light: every face is forbidden")  # (lamps have no candidate patch)
        self.exitance = np.zeros((n, 3))
        if lights is not None:
            if not np.array_equal(np.asarray(lights.patches), self.candidates):
                raise InverseError("the lights' candidate patches are not the problem's candidates")
            light_basis = lights.basis
        self._init_lights(light_groups, light_basis, lights)
        self._factors = None
        self._transfer = None
        self._all_rows = None  # all_rows_transfer's
        self._rows_solved = {}  # inverse_rows': id(factors) -> (factors, rows, Y)
        #: what a retarget keeps (_rows_of, lamp_view_terms, _first_bounce_of_lights): ("rows", id(target),
        #: id(T)), ("lamp terms", id(target)), ("first bounce", channel); ("of",): the T_all of the rows
        self._kept_rows = {}
        self.condition_warnings = []  # what factors() found (a retargeted problem keeps them)
        self.transfer_seconds = None
        self.warnings = []
        #: optional per channel: D (P, P) sparse, the first reflection of the lights' light with
        #: the albedo of its incidence (engine.incidence): B = A^-1 (e + D e); None: B = A^-1 e
        self.first_bounce = first_bounce
        #: optional per channel: X (P, n_lights) sparse, the first reflection of the lamps' direct light
        #: beyond rho H, with the albedo of its incidence (engine.incidence.lamp_excess): the lights
        #: of irradiance kinds' source is rho H s + X s; ``background_excess`` (P, 3) W/m^2 the same
        #: for the fixed lamps' light
        self.lamp_excess = lamp_excess
        #: None, or (P, n_lights) sparse: the surface lights' direct light computed anew (W/m^2 per
        #: unit exitance: a better gather minus F's, ``correct_direct``), in T and in the forward solves
        self.direct_correction = None
        self._init_fixed_light(background, background_irradiance, background_excess)

    def _init_patches(self, area, reflectance, candidate_mask, center, normal):
        n = self.n_patches
        self.area = _array(area, (n,), "area")
        if np.any(self.area <= 0):
            raise InverseError(f"patch areas must be positive; patches {np.flatnonzero(self.area <= 0)[:10].tolist()} are not")
        self.reflectance = _array(reflectance, (n, 3), "reflectance")
        if np.any(self.reflectance < 0) or np.any(self.reflectance > 1):
            raise InverseError("reflectance must lie in [0, 1]")
        self.candidate_mask = _array(candidate_mask, (n,), "candidate mask", dtype=bool)
        self.center = _array(center, (n, 3), "centre") if center is not None else np.zeros((n, 3))
        self.normal = _array(normal, (n, 3), "normal") if normal is not None else np.zeros((n, 3))
        self.candidates = np.flatnonzero(self.candidate_mask)

    def _set_targets(self, rows: TargetRows):
        """The system's rows (``target_rows``) and what is read of them; ``b_target`` their values
        (the fixed light's radiosity is subtracted by ``_init_fixed_light``), ``target_norm``
        their norm (relative errors are of what was asked)."""
        self.target_rows = rows
        self.targets = rows.patch
        #: (m,) per target row: the object of its uniformity region (illuminance targets), -1 for
        #: none (the least-power selection's uniformity goal)
        self.target_region = rows.region
        self.b_target = rows.values.copy()  # (m, 3)
        self.target_norm = float(np.linalg.norm(self.b_target))

    @property
    def target_mask(self) -> np.ndarray:
        """(P,) bool: the patches the targets' rows read."""
        mask = np.zeros(self.n_patches, dtype=bool)
        mask[self.target_rows.matrix.indices] = True
        return mask

    def _init_fixed_light(self, background, background_irradiance, background_excess):
        """(P, 3) W/m^2 ``background_radiosity``: the radiosity of the fixed light (``background``:
        the scene's own emitters' exitance; ``background_irradiance``: the lamps' direct
        irradiance, engine.lamps; ``background_excess`` its first reflection's), subtracted from
        the targets: the lights supply what it leaves. target_norm stays the asked targets' norm."""
        n = self.n_patches
        self.background_radiosity = np.zeros((n, 3))
        e_bg = None if background is None else _array(background, (n, 3), "background exitance")
        h_bg = None if background_irradiance is None else _array(background_irradiance, (n, 3), "background irradiance")
        x_bg = None if background_excess is None else _array(background_excess, (n, 3), "background excess")
        self.background_radiosity = self._fixed_light(e_bg, h_bg, x_bg)
        #: (P, 3) the scene's own emitters' exitance (None: none)
        self.background_exitance = e_bg
        self.b_target = self.b_target - self.target_rows.of(self.background_radiosity) - self._fixed_beyond(self.target_rows)
        self.b_target = self.b_target + self._seen_by_bsdf(self._bsdf_rows(self.target_rows), e_bg)

    def _bsdf_rows(self, rows):
        """TargetRows.bsdf_rows of ``rows`` (S) when B holds a first reflection's excess (``first_bounce``), else None."""
        return None if self.first_bounce is None else rows.bsdf_rows()

    def _seen_by_bsdf(self, S, e_bg):
        """(m, 3) or 0: S D e_bg, what target rows that see their patch's first reflection through its
        BSDF (``_bsdf_rows``: S) do not read of the fixed emitters' ``e_bg`` in B."""
        return 0.0 if S is None or e_bg is None else np.asarray(S @ self.first_reflection(e_bg))

    def _fixed_beyond(self, rows):
        """(m, 3) or 0: what the scene's own lamps add to target rows ``rows`` beyond the radiosity
        (TargetRows.fixed_light: a camera-view target's highlights of them)."""
        X = rows.fixed_light()
        return 0.0 if X is None else X

    def _fixed_light(self, background=None, irradiance=None, excess=None) -> np.ndarray:
        """(P, 3) W/m^2: the radiosity of the fixed light (the scene's own emitters' exitance
        ``background``, the lamps' direct irradiance ``irradiance`` and its first reflection's
        ``excess``), 0 without any."""
        n = self.n_patches
        if not ((background is not None and np.any(background > 0)) or
                (irradiance is not None and np.any(irradiance != 0))):  # (a lamp of negative power: negative)
            return np.zeros((n, 3))
        e = np.zeros((n, 3)) if background is None else background
        return self.forward_radiosity(e, irradiance, excess)

    def _init_lights(self, light_groups, light_basis, lights=None):
        C = self.candidates
        nC = len(C)
        if light_basis is not None:
            B = sp.csr_matrix(light_basis, dtype=np.float64)
            if B.shape[0] != nC:
                raise InverseError(f"the light basis has {B.shape[0]} rows for {nC} candidate patches")
            B.data[:] = 1.0
            empty = np.diff(B.tocsc().indptr) == 0
            H = None if lights is None else lights.irradiance
            if H is not None:  # a light of an irradiance kind has its source there
                Hc = sp.csc_matrix(H, copy=True)
                Hc.eliminate_zeros()
                empty &= np.diff(Hc.indptr) == 0
            if B.shape[1] == 0 or np.any(empty):
                raise InverseError("every light must have a source: cover at least one candidate patch, "
                                   "or light at least one patch")
        else:
            if light_groups is None:
                light_of = np.arange(nC)
            else:
                g = np.asarray(light_groups).reshape(self.n_patches)[C]
                _, light_of = np.unique(g, return_inverse=True)
                light_of = light_of.reshape(-1)
            B = sp.csr_matrix((np.ones(nC), (np.arange(nC), light_of)), shape=(nC, int(light_of.max()) + 1))
        self.light_basis = B  # (|C|, n_lights): patch c belongs to light l
        self.n_lights = int(B.shape[1])
        self.grouped = not (self.n_lights == nC and B.nnz == nC and np.array_equal(B.indices, np.arange(nC)))
        self.overlapping = bool(np.any(np.diff(B.indptr) > 1))  # a patch in several lights (multi-scale)
        aC = self.area[C]
        self.light_area = np.asarray(B.T @ aC).reshape(-1)
        self.light_center = group_mean_basis(B, self.center[C], aC)
        self.light_normal = unit(group_mean_basis(B, self.normal[C], aC))
        if lights is not None and lights.irradiance is not None:  # lights without patches (lamps): their own
            own = np.diff(B.tocsc().indptr) == 0
            self.light_area[own] = np.asarray(lights.area, dtype=np.float64)[own]
            self.light_center[own] = np.asarray(lights.center, dtype=np.float64)[own]
            self.light_normal[own] = np.asarray(lights.normal, dtype=np.float64)[own]
        if lights is None:
            code = kind_code("polygon" if light_groups is not None else "cell")
            lights = LightSet(C, B, np.full(self.n_lights, code, dtype=np.int8), self.light_area,
                              self.light_center, self.light_normal)
        elif lights.irradiance is not None and lights.irradiance.shape != (self.n_patches, self.n_lights):
            raise InverseError(f"the lights' irradiance has shape {lights.irradiance.shape}, "
                               f"not ({self.n_patches}, {self.n_lights})")
        self.lights = lights
        #: (n_lights,) power (W) of one unit of strength in one channel (area for surface lights)
        self.light_watts = lights.watts
        #: (n_lights,) each light's largest strength per channel (inf: none; a catalogue fixture's rated flux)
        self.light_upper = lights.upper

    @property
    def source_basis(self):
        """(|C|, n_lights) sparse: the exitance each light sends into the scene from its candidate
        patches per unit strength, ``light_basis`` times their ``emission_share``."""
        if self.emission_share is None:
            return self.light_basis
        return (sp.diags(self.emission_share[self.candidates]) @ self.light_basis).tocsc()

    @property
    def light_of(self):
        """Light of each candidate patch, when the lights partition the candidates (else ValueError)."""
        B = self.light_basis
        if self.overlapping or B.nnz != B.shape[0]:
            raise ValueError("the lights overlap (multi-scale candidates): a patch has no single light")
        return B.indices.astype(np.int64)

    def light_rows(self):
        """Form-factor rows of the lights (n_lights, P): area-weighted means of their patches'; for
        a light of an irradiance kind (a lamp), the share of its power that reaches each patch
        directly (its irradiance x the patch's area / its watts)."""
        FC = self.F[self.candidates]
        FC = FC.toarray() if sp.issparse(FC) else np.asarray(FC, dtype=np.float64)
        FC = FC.astype(np.float64)
        if not self.grouped:
            return FC
        W = (self.light_basis.multiply(self.area[self.candidates][:, None])).T.tocsr()
        sized = self.light_area > 0
        rows = np.asarray(W @ FC) / np.where(sized, self.light_area, 1.0)[:, None]
        H = self.lights.irradiance
        if H is not None:
            own = np.diff(self.light_basis.tocsc().indptr) == 0
            direct = np.asarray(sp.csc_matrix(H)[:, own].T.toarray()) * self.area[None, :]
            rows[own] = direct / self.light_watts[own][:, None]
        return rows

    # -- system ---------------------------------------------------------
    @property
    def m(self):
        return len(self.targets)

    def factors(self):
        """Solvers of A per channel (channels with identical reflectance share one): LU factors up
        to DIRECT_SOLVE_LIMIT patches, iterative sweeps on the sparse F above."""
        if self._factors is None:
            factors = [None] * 3
            for g in channel_groups(self.reflectance):
                check_cancel(self.cancel)  # (a channel's LU: 0.2-0.3 s on 2,305 patches)
                rho = self.reflectance[:, g[0]]
                closed = lossless_patches(self.F, rho)
                if closed.any():
                    raise InverseError(
                        f"the radiosity system I - rho F is singular: {int(closed.sum())} patch(es) with reflectance "
                        "1 form a closed scene that never loses light (lower the reflectance below 1)")
                # (a cancel does not wait for the LU: it ends in the background, dropped)
                fac = (_Iterative(self.F, rho) if self.n_patches > DIRECT_SOLVE_LIMIT
                       else run_cancellable(lambda: _Factor(radiosity_matrix(self.F, rho)), self.cancel,
                                            "solve cancelled"))  # may raise
                for c in g:
                    factors[c] = fac
            self._factors = factors  # only once every channel is factorised
            cond = max(f.cond for f in self._factors)
            if np.isfinite(cond) and cond > ILL_CONDITIONED or np.isinf(cond):
                self.condition_warnings.append(
                    f"the radiosity system is ill-conditioned (condition estimate {cond:.3g}); "
                    "reflectances close to 1 in a closed scene amplify every error")
                self.warnings.extend(self.condition_warnings)
        return self._factors

    @property
    def condition(self):
        """1-norm condition estimate of A, worst channel."""
        return max(f.cond for f in self.factors())

    @property
    def transfer(self):
        """T per channel: list of 3 arrays (m, |C|), rows P and columns C of A^-1.

        Computed with the smaller of ``A^T Y = I[:, P]`` (m right-hand sides) and
        ``A X = I[:, C]`` (|C| right-hand sides) from the LU factors.
        """
        if self._transfer is None:
            t0 = time.perf_counter()
            facs = self.factors()
            n, R, C = self.n_patches, self.target_rows, self.candidates
            T = [None] * 3
            done = {}
            D = self.first_bounce
            S = self._bsdf_rows(R)  # rows that see their patch's first reflection by its BSDF
            seen = self.lamp_view_terms(R)
            for c in range(3):
                key = (id(facs[c]), None if D is None else self._same_first_bounce(c))
                if key in done:
                    T[c] = done[key]
                    continue
                if R.m <= len(C):
                    Y = self.inverse_rows(facs[c])  # Y^T = R A^-1, the rows' rows of A^-1
                    if D is not None:  # rows P of A^-1 (I + D): Y + D^T Y
                        Y = Y + np.asarray(D[c].T @ Y)
                        if S is not None:  # less S D: those rows' BSDF gives the first reflection itself
                            Y = Y - (D[c].T @ S.T).toarray()
                    T[c] = np.ascontiguousarray(Y[C].T)
                else:
                    rhs = np.zeros((n, len(C)))
                    rhs[C, np.arange(len(C))] = 1.0
                    if D is not None:
                        rhs += D[c][:, C].toarray()
                    X = facs[c].solve(rhs)  # columns C of A^-1 (I + D)
                    T[c] = np.ascontiguousarray(R.of(X))
                    if S is not None:
                        T[c] = T[c] - (S @ D[c][:, C]).toarray()
                if self.emission_share is not None:  # what a candidate patch's exitance sends (``source``)
                    T[c] = T[c] * self.emission_share[C][None, :]
                if self.grouped:  # one column per light: the sum of its patches' columns
                    T[c] = np.ascontiguousarray(np.asarray(self.light_basis.T @ T[c].T).T)
                H = self.lights.irradiance
                if H is not None:  # lights of irradiance kinds: rows P of A^-1 diag(rho) H
                    T[c] = T[c] + self._irradiance_transfer(facs[c], c, H)
                if seen is not None:  # what the lamps add to the rows beyond B (a view target's highlights)
                    T[c][:, seen[0]] += seen[1][:, :, c]
                if not np.all(np.isfinite(T[c])):
                    raise InverseError("the radiosity system could not be solved (non-finite transfer matrix)")
                done[key] = T[c]
            self._transfer = T
            self._leave_out_implausible()
            self.transfer_seconds = time.perf_counter() - t0
            self._check_reachable()
        return self._transfer

    def lamp_view_terms(self, rows, kept=False):
        """(the lights that are lamps (n,), X (m, n, 3)): what each adds per unit strength to target
        rows ``rows`` (a TargetRows) beyond the radiosity (TargetRows.lamp_terms: a camera-view
        target's glossy pixels reflect a lamp's direct light through their BSDF), or None when no
        row's kind adds anything (channels that share T share the first's: one reflectance).
        ``kept``: a target ``kept_by_retarget`` has its block computed once for these lights
        (_kept_rows: a Live stroke's retarget asks again)."""
        lamps = self.lights.lamps
        idx = [] if lamps is None else [j for j, lamp in enumerate(lamps) if lamp is not None]
        if not idx:
            return None
        H = self.lights.irradiance
        ls, Hs = [lamps[j] for j in idx], None if H is None else sp.csc_matrix(H)[:, idx]
        if not kept:
            X = rows.lamp_terms(ls, Hs)
        else:
            blocks = []
            for target in rows.targets:
                block = self._kept_rows.get(("lamp terms", id(target)))
                if block is None or block[0] is not target or block[1] is not self.lights:
                    block = (target, self.lights, target.lamp_terms(ls, Hs))
                    if target.kept_by_retarget:
                        self._kept_rows[("lamp terms", id(target))] = block
                blocks.append(block[2])
            X = rows._stacked(blocks)
            self._prune_kept(rows)
        return None if X is None else (np.asarray(idx, dtype=np.int64), X)

    def _leave_out_implausible(self):
        """Candidate lights that send less than MIN_UTILISATION of their light to the targets, while
        others send at least 10 x that, are left out (their transfer columns 0: no selection takes
        them, the certificate bounds the others): to reach the targets they would need a power far
        beyond what the targets receive (engine.plausibility). ``implausible`` (n_lights,) bool."""
        self.implausible = implausible_lights(self)
        if self.implausible.any():
            for t in {id(t): t for t in self._transfer}.values():  # (channels may share one array)
                t[:, self.implausible] = 0.0

    def all_rows_transfer(self):
        """T with every patch as a target: 3 arrays (P, n_lights), each patch's radiosity per unit
        strength of each light (channels that share their solver and D share one array): columns of
        A^-1 applied to every light's source -- its exitance on its patches through (I + D) and
        ``emission_share``, rho H (+ its first reflection's excess, ``lamp_excess``) for the lights
        of irradiance kinds, rho times the kernel's ``direct_correction`` -- one solve with
        n_lights right-hand sides per channel. Its rows of the targets are ``transfer`` (the
        other route: rows of A^-1, for few targets). Computed once; ``retarget`` reads it."""
        if self._all_rows is None:
            self.transfer  # (its rows first: they decide which lights are left out, ``implausible``)
            facs = self.factors()
            n, C, D = self.n_patches, self.candidates, self.first_bounce
            H = self.lights.irradiance
            if self.direct_correction is not None:
                H = self.direct_correction if H is None else sp.csc_matrix(H) + self.direct_correction
            H = None if H is None else sp.csc_matrix(H)
            basis = sp.csc_matrix(self.source_basis)
            out, done = [None] * 3, {}
            for c in range(3):
                key = (id(facs[c]), None if D is None else self._same_first_bounce(c))
                if key not in done:
                    rhs = np.zeros((n, self.n_lights))
                    rhs[C] = basis.toarray()  # each light's exitance per unit strength, on its patches
                    if D is not None:
                        rhs += np.asarray(D[c][:, C] @ basis.toarray())
                    if H is not None:
                        rhs += self.reflectance[:, c:c + 1] * H.toarray()
                    if self.lamp_excess is not None:
                        rhs += self.lamp_excess[c].toarray()
                    X = np.ascontiguousarray(facs[c].solve(rhs))
                    if not np.all(np.isfinite(X)):
                        raise InverseError("the radiosity system could not be solved (non-finite transfer matrix)")
                    done[key] = X
                out[c] = done[key]
            left = getattr(self, "implausible", None)  # (the lights the transfer leaves out: the same here)
            if left is not None and left.any():
                cols = np.flatnonzero(left)
                for t in {id(t): t for t in out}.values():
                    t[:, cols] = 0.0
            self._all_rows = out
        return self._all_rows

    def prepared_rows_transfer(self):
        """``all_rows_transfer`` when it is made already, else None (it is never made here)."""
        return self._all_rows

    def with_background(self, background=None, background_irradiance=None, background_excess=None):
        """This problem with another fixed light (the arguments as the constructor's: the scene's
        own emitters' exitance, the lamps' direct irradiance, its first reflection's excess):
        its radiosity through the kept factorisation, the targets' b_P less it; the lights, the
        transfer and the solvers shared. A kept lamp moved (pipeline.prepared)."""
        n = self.n_patches
        new = copy.copy(self)
        shaped = [None if x is None else np.asarray(x, dtype=np.float64).reshape(n, 3)
                  for x in (background, background_irradiance, background_excess)]
        new.background_radiosity = self._fixed_light(*shaped)
        if not np.all(np.isfinite(new.background_radiosity)):
            raise InverseError("the scene's own light gives non-finite radiosity")
        R = self.target_rows
        new.b_target = self.b_target + R.of(self.background_radiosity) - R.of(new.background_radiosity)
        new.background_exitance = shaped[0]
        S = self._bsdf_rows(R)
        new.b_target = new.b_target - self._seen_by_bsdf(S, self.background_exitance) + \
            self._seen_by_bsdf(S, new.background_exitance)
        return new

    def retarget(self, targets) -> "InverseProblem":
        """This problem with other targets (a list of engine.targets objects; the same scene, lights,
        solvers and fixed light): its T is their rows of ``all_rows_transfer`` (no factorisation,
        no solve), its b_P their values less the fixed light's radiosity. A stroke's re-solve
        (pipeline.prepared)."""
        rows = target_rows(targets, self.n_patches)
        T_all = self.all_rows_transfer()
        new = copy.copy(self)
        new._set_targets(rows)
        new._rows_solved = {}
        S = self._bsdf_rows(rows)
        new.b_target = rows.values - rows.of(self.background_radiosity) - self._fixed_beyond(rows) + \
            self._seen_by_bsdf(S, self.background_exitance)
        new._transfer = self._rows_of(rows, T_all)
        if S is not None:  # (less S D: rows that see their patch's first reflection by its BSDF, as transfer's)
            left = getattr(self, "implausible", None)
            for c in sorted({id(t): c for c, t in reversed(list(enumerate(new._transfer)))}.values()):
                corr = (S @ self._first_bounce_of_lights(c)).toarray()
                if left is not None and left.any():
                    corr[:, left] = 0.0
                new._transfer[c] -= corr
        seen = self.lamp_view_terms(rows, kept=True)
        if seen is not None:
            for c in sorted({id(t): c for c, t in reversed(list(enumerate(new._transfer)))}.values()):
                new._transfer[c][:, seen[0]] += seen[1][:, :, c]
        new.transfer_seconds = 0.0
        new.warnings = list(self.condition_warnings)
        new._check_reachable()
        return new

    def _first_bounce_of_lights(self, c):
        """(P, n_lights) sparse: D_c's columns of the candidates, per light (``source_basis``):
        what retarget's rows seeing their patch through its BSDF take off, computed once per
        problem (_kept_rows)."""
        key = ("first bounce", c)
        kept = self._kept_rows.get(key)
        if kept is None or kept[0] is not self.lights:
            kept = (self.lights, self.first_bounce[c][:, self.candidates] @ sp.csc_matrix(self.source_basis))
            self._kept_rows[key] = kept
        return kept[1]

    def _rows_of(self, rows, T_all) -> list:
        """rows.of(t) for each channel's t of ``T_all`` (channels sharing one array share the
        answer). A target its kind keeps between paints (``kept_by_retarget``: a camera-view
        target's 941 rows read hundreds of patches each, 0.47 s a stroke on the living room) has its
        block computed once for this problem's T_all (``_kept_rows``, shared by the retargeted
        copies); the blocks stacked as TargetRows stacks the rows (the same bits)."""
        if not any(t.kept_by_retarget for t in rows.targets):
            shared = {}
            return [shared.setdefault(id(t), np.ascontiguousarray(rows.of(t))) for t in T_all]
        kept = self._kept_rows
        if kept.get(("of",)) is not T_all:
            kept.clear()
            kept[("of",)] = T_all
        shared = {}
        for t in T_all:
            if id(t) in shared:
                continue
            blocks = []
            for target in rows.targets:
                block = kept.get(("rows", id(target), id(t)))
                if block is None or block[0] is not target:
                    M = sp.csr_matrix(target.rows(self.n_patches), dtype=np.float64).sorted_indices()
                    block = (target, _product(M, t, target.rows_taken, kept))
                    if target.kept_by_retarget:
                        kept[("rows", id(target), id(t))] = block
                blocks.append(block[1])
            shared[id(t)] = np.ascontiguousarray(rows._stacked(blocks))
        self._prune_kept(rows)
        return [shared[id(t)] for t in T_all]

    def _prune_kept(self, rows) -> None:
        """_kept_rows keeps the blocks of this problem's own targets and of ``rows``' (the last
        stroke's: a view target painted anew is the next stroke's too), no others (each a few MB)."""
        live = {id(t) for t in list(rows.targets) + list(self.target_rows.targets)}
        for key in [k for k in self._kept_rows if k[0] in ("rows", "lamp terms") and k[1] not in live]:
            del self._kept_rows[key]

    def add_lights(self, lights, columns, excess=None):
        """Extend the problem to ``lights`` (a LightSet: the problem's lights followed by new ones,
        engine.lights.append_lamps) whose new lights' columns of T are ``columns`` (3 arrays (m, n_new),
        computed by the caller from their sources, e.g. engine.lamp_refinement.Transport); ``excess``
        their columns of ``lamp_excess`` (3 sparse (P, n_new)) when the problem has it."""
        n0 = self.n_lights
        self._all_rows, self._kept_rows = None, {}  # (a dict of its own: copies share the one before)
        if self.lamp_excess is not None:
            n_new = lights.n_lights - n0
            new = excess if excess is not None else [sp.csc_matrix((self.n_patches, n_new))] * 3
            self.lamp_excess = [sp.hstack([self.lamp_excess[c], new[c]]).tocsc() for c in range(3)]
        if self.direct_correction is not None:
            self.direct_correction = sp.hstack([self.direct_correction,
                                                sp.csc_matrix((self.n_patches, lights.n_lights - n0))]).tocsc()
        T = self.transfer
        self._init_lights(None, lights.basis, lights)
        if self.n_lights < n0 or any(np.shape(columns[c]) != (self.m, self.n_lights - n0) for c in range(3)):
            raise InverseError(f"{self.n_lights - n0} new light(s) need 3 transfer blocks of shape "
                               f"({self.m}, {self.n_lights - n0})")
        self._transfer = [np.ascontiguousarray(np.hstack([T[c], np.asarray(columns[c], dtype=np.float64)]))
                          for c in range(3)]

    def inverse_rows(self, fac):
        """Y (P, m): Y^T = R A^-1 (R the targets' rows; a selection's: rows P of A^-1), from the
        factors ``fac`` of one channel; solved once per factors and rows (the transfer, the
        lamps' columns, the direct light's correction and the lamp refinement read it)."""
        kept = self._rows_solved.get(id(fac))
        if kept is None or kept[0] is not fac or kept[1] is not self.target_rows:
            kept = (fac, self.target_rows, fac.solve(self.target_rows.columns(), trans=True))
            self._rows_solved[id(fac)] = kept
        return kept[2]

    def correct_direct(self, lights, dH):
        """The direct light of the surface lights ``lights`` (indices) computed anew, e.g. by the
        kernel estimator: ``dH`` (P, len(lights)) W/m^2 per unit of their exitance, the new gather
        minus F's. Their columns of T gain rows P of A^-1 diag(rho) dH, and every forward solve
        (``configuration_radiosity``) the reflection rho dH s of their light."""
        lights = np.asarray(lights, dtype=np.int64)
        self._all_rows, self._kept_rows = None, {}  # (a dict of its own: copies share the one before)
        dH = np.asarray(dH, dtype=np.float64).reshape(self.n_patches, len(lights))
        if not np.all(np.isfinite(dH)):
            raise InverseError("the lights' direct light is not finite")
        T = self.transfer
        facs = self.factors()
        done = set()
        for c in range(3):  # channels of one reflectance share their factors and their T (``transfer``)
            if id(T[c]) in done:
                continue
            done.add(id(T[c]))
            Y = self.inverse_rows(facs[c])
            T[c][:, lights] += (dH.T @ (self.reflectance[:, c:c + 1] * Y)).T
        new = sp.csc_matrix((dH.ravel(), (np.repeat(np.arange(self.n_patches), len(lights)),
                                          np.tile(lights, self.n_patches))), shape=(self.n_patches, self.n_lights))
        self.direct_correction = new if self.direct_correction is None else (self.direct_correction + new).tocsc()

    def emitter_direct_correction(self, strength):
        """(P, P) CSC or None: ``direct_correction`` per emitting patch, column k the direct
        irradiance (W/m^2) the kernel finds on every patch beyond F's gather, per unit of patch k's
        exitance, at the configuration ``strength`` (n_lights, 3). A light's correction is shared
        among its patches by the power they send (exact where a patch belongs to one light of the
        configuration; where lights overlap, a mix weighted by their strengths)."""
        if self.direct_correction is None:
            return None
        DC = self.direct_correction.tocsc()
        s = np.abs(np.asarray(strength, dtype=np.float64).reshape(-1, 3)).sum(axis=1)
        cols = np.flatnonzero((np.diff(DC.indptr) > 0) & (s > 0))
        if len(cols) == 0:
            return None
        basis = sp.csc_matrix(self.light_basis)
        power = basis[:, cols].multiply(self.area[self.candidates][:, None])  # per unit strength
        share = power @ sp.diags(s[cols] / self.light_area[cols])  # (|C|, cols): p_lm s_l
        exitance = np.asarray(basis @ s).reshape(-1)  # each candidate's exitance (channel sum)
        per_unit = share.T @ sp.diags(np.divide(1.0, exitance, out=np.zeros_like(exitance), where=exitance > 0))
        X = (DC[:, cols] @ per_unit).tocoo()  # (P, |C|)
        return sp.csc_matrix((X.data, (X.row, self.candidates[X.col])), shape=(self.n_patches, self.n_patches))

    def _irradiance_transfer(self, fac, c, H):
        """(m, n_lights): rows P of A^-1 diag(rho_c) H, the targets' radiosity per unit strength of
        lights whose source is a direct irradiance H (P, n_lights)."""
        Y = self.inverse_rows(fac)  # Y^T = rows P of A^-1
        T = H.T @ (self.reflectance[:, c:c + 1] * Y)
        if self.lamp_excess is not None:
            T = T + self.lamp_excess[c].T @ Y
        return np.asarray(T.T)

    def _same_first_bounce(self, c):
        """The first channel whose D equals channel c's (grey materials: one transfer for all)."""
        D = self.first_bounce
        return next(k for k in range(c + 1) if k == c or (D[k] != D[c]).nnz == 0)

    def first_reflection(self, e_full) -> np.ndarray:
        """(P, 3) D s: what the first reflection's albedo at incidence adds beyond rho to the light
        of the exitance ``e_full`` (P, 3) that leaves into the scene (``source`` less s); 0 without
        ``first_bounce``."""
        e = np.asarray(e_full, dtype=np.float64).reshape(self.n_patches, 3)
        if self.emission_share is not None:
            e = e * self.emission_share[:, None]
        if self.first_bounce is None:
            return np.zeros_like(e)
        return np.stack([np.asarray(self.first_bounce[c] @ e[:, c]).reshape(-1) for c in range(3)], axis=1)

    def source(self, e_full):
        """s + D s, s the exitance ``e_full`` (P, 3), or (P, K, 3) for K configurations, that leaves
        into the scene (``emission_share``): the source with the first reflection's correction
        (``first_bounce``)."""
        e_full = np.asarray(e_full, dtype=np.float64)
        e = e_full.reshape(self.n_patches, -1, 3)
        if self.emission_share is not None:
            e = e * self.emission_share[:, None, None]
        if self.first_bounce is not None:
            e = e + np.stack([self.first_bounce[c] @ e[:, :, c] for c in range(3)], axis=2)
        return e.reshape(e_full.shape if e_full.ndim == 3 else (self.n_patches, 3))

    def _check_reachable(self):
        T = self._transfer
        scale = max(float(np.abs(t).max()) for t in T)
        reach = np.zeros(self.m, dtype=bool)
        for t in T:
            reach |= np.abs(t).max(axis=1) > 1e-12 * max(scale, TINY)
        self.unreachable = self.targets[~reach]
        bad = self.targets[(~reach) & (self.b_target.max(axis=1) > 0)]
        if len(bad) == len(self.targets):
            raise InverseError(
                "no candidate light reaches any target (" + self._why_unreached() + "); "
                f"target patches {bad[:20].tolist()}")
        self.unmet = bad  # (the report names their objects: pipeline.jobs.unmet_note)

    def _why_unreached(self) -> str:
        """Why no light reaches a target, as far as the geometry tells: the candidates' or the
        targets' fronts turned away from each other (flipped normals), else occlusion."""
        def facing(a, na, b):  # per patch of a: some patch of b in front of it
            return np.array([np.any((b - x) @ n > 1e-9) for x, n in zip(a, na)], dtype=bool)

        C, P = self.candidates, self.targets
        if np.any(self.normal) and len(C) * len(P) <= 4e7:
            if not facing(self.center[C], self.normal[C], self.center[P]).any():
                return ("every candidate face turns its back to the targets: are their normals flipped? "
                        "(Edit Mode: Mesh > Normals > Recalculate Outside, or Flip)")
            if not facing(self.center[P], self.normal[P], self.center[C]).any():
                return ("every target turns its back to the candidate faces: are the painted faces' normals flipped? "
                        "(Edit Mode: Mesh > Normals > Recalculate Outside, or Flip)")
        return "occluded, or every face that reaches them is forbidden"

    # -- evaluation -----------------------------------------------------
    def target_radiosity_of(self, e_C):
        """Radiosity (m, 3) on the targets produced by light exitances e_C (n_lights, 3)."""
        e_C = np.asarray(e_C, dtype=np.float64).reshape(self.n_lights, 3)
        return np.stack([self.transfer[c] @ e_C[:, c] for c in range(3)], axis=1)

    def error(self, e_C):
        """Eq. 1: sqrt of the sum over targets and channels of squared differences (W/m^2)."""
        return float(np.linalg.norm(self.target_radiosity_of(e_C) - self.b_target))

    def relative_error(self, e_C):
        return self.error(e_C) / self.target_norm if self.target_norm > 0 else self.error(e_C)

    def patch_exitance(self, e_C):
        """Full (P, 3) exitance with the lights' e_C (n_lights, 3) on their patches, 0 elsewhere."""
        out = np.zeros((self.n_patches, 3))
        out[self.candidates] = self.light_basis @ np.asarray(e_C, dtype=np.float64).reshape(-1, 3)
        return out

    def forward_radiosity(self, e_full, irradiance=None, excess=None):
        """Exact forward solution B (P, 3) of A B = e (+ D e, ``first_bounce``) + rho H (+ X), H a
        direct irradiance (P, 3) W/m^2 (lamps), X its first reflection beyond rho H (``excess``,
        (P, 3) W/m^2: engine.incidence.lamp_excess), through the LU factors."""
        s = self.source(e_full)
        if irradiance is not None:
            s = s + self.reflectance * np.asarray(irradiance, dtype=np.float64).reshape(self.n_patches, 3)
        if excess is not None:
            s = s + np.asarray(excess, dtype=np.float64).reshape(self.n_patches, 3)
        return np.stack([self.factors()[c].solve(s[:, c]) for c in range(3)], axis=1)

    def configuration_radiosity(self, strength):
        """B (P, 3) of the lights at ``strength`` (n_lights, 3): every kind's source, transported."""
        H = self.lights.patch_irradiance(strength, self.n_patches) if self.lights.irradiance is not None else None
        if self.direct_correction is not None:
            dH = np.asarray(self.direct_correction @ np.asarray(strength, dtype=np.float64).reshape(-1, 3))
            H = dH if H is None else H + dH
        return self.forward_radiosity(self.patch_exitance(strength), H, self.excess_of(strength))

    def excess_of(self, strength):
        """(P, 3) W/m^2: the lamps' first reflection beyond rho H at ``strength`` (n_lights, 3)
        (``lamp_excess``), None without it."""
        if self.lamp_excess is None:
            return None
        s = np.asarray(strength, dtype=np.float64).reshape(-1, 3)
        return np.stack([np.asarray(self.lamp_excess[c] @ s[:, c]).reshape(-1) for c in range(3)], axis=1)

    @classmethod
    def from_patches(cls, patches, F, lights_per_face=True, faces=None):
        """Problem from a PatchSet (its targets: engine.targets.scene_targets, of the FaceSet
        ``faces`` it was meshed from when given; candidates as ``lights.candidate_mask``) and its
        form factors; with ``lights_per_face`` a light is a whole face (all its patches), as
        Blender shows it."""
        return cls(F, patches.area, patches.reflectance, scene_targets(faces, patches, F),
                   candidate_mask(patches), patches.center, patches.normal,
                   light_groups=patches.face if lights_per_face else None)


def direct_lighting_problem(F, area, reflectance, exitance, center=None, normal=None, light_groups=None,
                            light_basis=None, first_bounce=None, lights=None, strength=None,
                            background_irradiance=None, lamp_excess=None):
    """Direct-lighting mode: reduce the scene's own emitters.

    The candidates are the current lights (patches with a positive exitance in any
    channel); every other patch is a target at the radiosity the full
    configuration gives it. Returns ``(problem, e_x)`` with e_x the lights'
    strengths (n_lights, 3), the starting configuration of a reduction. ``first_bounce``: the
    problem's D (InverseProblem.first_bounce); ``lamp_excess``: its X (InverseProblem.lamp_excess).

    ``lights`` may end with lights of an irradiance kind (the scene's lamps, engine/lights/lamp.py:
    no candidate patch, a column of ``lights.irradiance``); ``strength`` (their number, 3) is their
    own strength (a lamp's power per channel), e_x's for them. ``background_irradiance`` (P, 3)
    W/m^2: fixed light that no reduction can switch off (the World), transported into every
    configuration's radiosity (``background_radiosity``). The targets' b_P is then the lights'
    share of the scene's radiosity, and ``target_norm`` the norm of the whole radiosity on the
    targets (relative errors are of the light the scene has, as in inverse mode of the painted).
    """
    exitance = np.asarray(exitance, dtype=np.float64)
    n = exitance.shape[0] if exitance.ndim == 2 else -1
    if exitance.ndim != 2 or exitance.shape[1] != 3 or not np.all(np.isfinite(exitance)):
        raise InverseError("exitance must be a finite (P, 3) array")
    if np.any(exitance < 0):
        raise InverseError("direct-lighting mode needs non-negative exitances")
    emitters = exitance.max(axis=1) > 0
    own = np.zeros(0, dtype=bool)  # the lights without patches (lamps)
    if lights is not None and lights.irradiance is not None:
        own = np.diff(sp.csc_matrix(lights.basis).indptr) == 0
    if not emitters.any() and not own.any():
        raise InverseError("the scene has no light (no patch with a positive exitance, no lamp)")
    if emitters.all():
        raise InverseError("every patch is a light: no patch is left to compare radiosities on")
    s_own = np.zeros((int(own.sum()), 3)) if strength is None else np.asarray(strength, dtype=np.float64)
    if s_own.shape != (int(own.sum()), 3) or not np.all(np.isfinite(s_own)) or np.any(s_own < 0):
        raise InverseError(f"the lamps' strength must be a finite non-negative ({int(own.sum())}, 3) array")
    prob = InverseProblem(F, area, reflectance, [PaintedRadiance.masked(~emitters, np.zeros((n, 3)))], emitters,
                          center, normal,
                          light_groups=light_groups, light_basis=light_basis, lights=lights,
                          first_bounce=first_bounce, background_irradiance=background_irradiance,
                          lamp_excess=lamp_excess)
    # power-conserving per light (the surface lights of direct-lighting mode partition the emitters)
    e_x = group_mean_basis(prob.light_basis, exitance[prob.candidates], prob.area[prob.candidates])
    H = None
    if own.any():
        e_x[own] = s_own
        H = prob.lights.patch_irradiance(np.where(own[:, None], e_x, 0.0), n)
    B = prob.forward_radiosity(exitance, H, None if H is None else prob.excess_of(np.where(own[:, None], e_x, 0.0)))
    R = prob.target_rows
    prob.b_target = R.of(B).copy()
    prob.target_norm = float(np.linalg.norm(R.of(B) + R.of(prob.background_radiosity)))
    prob.exitance = exitance.copy()
    return prob, e_x


def solve_inverse(problem: InverseProblem, solver="svd", rcond=None, svd_driver="auto", **kw):
    """Solve the inverse problem with a registered solver (``engine.solvers``: see the module
    docstring for the paper's, the reduced and the NNLS formulations).

    rcond: relative singular-value cut-off of the pseudo-inverse (default
    ``max(rows, cols) * machine eps``, as numpy's matrix_rank). svd_driver: 'auto' (the
    default: Cholesky of the Gram matrix when the system has full row rank with margin, which
    is the same pseudo-inverse solution, else 'gelsd'), 'gelsd' (LAPACK divide-and-conquer
    least squares) or 'svd' (explicit SVD pseudo-inverse); both give the same minimum-norm
    solution. Other keywords go to the solver.
    """
    method = SOLVERS[solver]
    if rcond is not None and not (np.isfinite(rcond) and 0 <= rcond < 1):
        raise ValueError(f"rcond must be in [0, 1), got {rcond}")
    t0 = time.perf_counter()
    out = method(problem, rcond=rcond, svd_driver=svd_driver, **kw)
    seconds = time.perf_counter() - t0
    e = out.exitance
    if not np.all(np.isfinite(e)):
        raise InverseError("the inverse solve produced non-finite exitances (ill-posed system)")
    err = problem.error(e)
    rel = err / problem.target_norm if problem.target_norm > 0 else err
    warns = list(problem.warnings)
    if method.traits.nonnegative and rel > 1e-3:
        warns.append(f"no non-negative configuration meets the targets: residual {err:.4g} W/m^2 "
                     f"({100 * rel:.3g}% of the targets' norm)")
    warns.extend(w for w in out.warnings if w not in warns)
    return InverseResult(solver=solver, exitance=e, rank=int(out.rank), error=err, relative_error=rel,
                         n_negative=int((e < 0).any(axis=1).sum()), seconds=seconds,
                         rcond=out.rcond, warnings=warns)


def _product(M, t, taken, kept) -> np.ndarray:
    """M @ t (M sparse (k, P), t (P, n)), the rows its target took from an earlier target
    (``taken``: Target.rows_taken, a repainted view target's unchanged patches') copied from that
    target's product when ``kept`` (InverseProblem._kept_rows) holds it for this t: row by row the
    same bits, the others' product only (a view target's 941 rows by 844 lights: 0.3 s a stroke)."""
    earlier = None if taken is None else kept.get(("rows", id(taken[0]), id(t)))
    if earlier is None or earlier[0] is not taken[0]:
        return np.asarray(M @ t)
    _, new, old = taken
    out = np.empty((M.shape[0], t.shape[1]))
    out[new] = earlier[1][old]
    rest = np.setdiff1d(np.arange(M.shape[0]), new)
    out[rest] = np.asarray(M[rest] @ t)
    return out
