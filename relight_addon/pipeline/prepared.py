"""Prepare once, re-solve per stroke (issue 20, item 1; no bpy).

A solve's answer depends on the scene (geometry, materials, forbidden faces, lamps, World, the
options) and on the paint. ``PreparedScene`` keeps, from a solve, what depends only on the scene,
keyed by a fingerprint of it (``scene_key``), and the next solve starts from it when only the
paint changed:

- the patches. The polygon model meshes without looking at the paint (registered
  ``paint_independent=True``). The adaptive model's do depend on it: a painted face is meshed at
  the patch size, clusters never mix painted and unpainted faces, and the refinement follows the
  targets. Its patches are kept as the solve made them and the new paint is *mapped* onto them:
  a patch asks for the target of the face it lies on (as engine.scene.build_patches does), which
  is exact for every face that is a patch of its own or split into several (no patch spans it and
  another face). Paint on faces clustered with others maps onto the kept cluster (``painted``: a
  touched cluster is a target at its painted faces' area-weighted mean radiosity, and at their
  mean illuminance when they are asked for one (``PatchSet.target_lux``); painted-face error 1.03 x
  a cold solve's for 12 clustered faces, 1.11 x for 24); only a cluster painted with both kinds
  (lx on some faces, a radiosity on others) cannot be mapped (one patch is one target): that solve
  starts from scratch, and says so (``unmappable``). The kept patches are not refined again for
  the new targets (refinement passes 0 from the prepared state);
- the ray-cast form factors (every patch's hemisphere rays: the bulk of a solve's rays, and all of
  the refinement passes' ones);
- the kernel's entries (engine.kernel_transfer: the transport from a candidate light's patch to a
  target patch), per (target, source) pair: a stroke draws only the pairs it has not (the new
  target patches' rows, the kept rows' new sources: an erased patch is a candidate again). Every
  pair samples on a stream of its own, keyed by the seed and the two patches' geometry, so these
  are the entries the cold solve's one draw of every pair gives, bit for bit (before, rows drawn
  apart were other samples: 14 % apart in error on the adaptive staircase, so every row was drawn
  again);
- the candidate lamps' direct irradiance (``KeptLamps``), keyed by the lamp's kind and geometry
  (candidate_lamps.lamp_key), each lamp drawn on its own seed (lamp_seed): a solve plans its lamps
  for its targets (the spots aimed at the painted regions, the mounting positions among the
  unpainted candidates) and computes those not kept; a kept lamp is the number offer_lamps
  computes for it in a cold solve, bit for bit.

What still parts the warm solve from the cold one on the polygon model (its mesh is the cold
solve's): the kept hemisphere rays were cast with the first paint's decisive region's offset
(engine.extent; a warm solve's lamps hang at the new paint's drop, as the cold solve's), so the cold
solve casts slightly other rays (the staircase's extend: the ray-cast F 0.0024 apart at most;
tests/test_prepared.py: every kind of stroke within 1 %). On the adaptive model
the kept mesh is not the one the cold solve makes for the new paint either.

Every solve says in its report (``prepared``, ``account``) what it kept and what it computed.
The rest (the lamps' plan, the inverse problem and its factorisation, the selection, the
certificate, the direct light, the lamp refinement and the curve) is the cold solve's own code
(pipeline.jobs.run_solve), given the kept patches, form factors, kernel entries and lamps' irradiance. A change
the fingerprint sees (an object moved, a material, a forbidden face, an option) is not followed:
``stale_reason`` names it, and the caller prepares again.

The last solve's model (pipeline.model.Model: its lights, the lamps offered and refined for its targets
among them, its factorised radiosity system) is kept too, for Live mode's strokes (``live``): the
problem retargeted on the transfer from every light to every patch (InverseProblem.retarget,
all_rows_transfer), then the selection's quick search from the last solve's configurations, the
certificate and the curve (jobs.solve_stroke); and for a lamp of the scene moved or set
anew (``move_lamps``: the model's fixed light cast again). A stroke's live answer is of the paint
alone (it starts from the last *solve*, never from an earlier stroke). Its later answers
(``refine_live``, REFINE_STEPS, in Live's worker once the quick one is shown) close what the
quick answer loses against a cold solve (up to 17 % in error on the staircase, issue 37): the
selection's full search and the lamps refined for the stroke's targets on the retargeted model,
then the warm solve (``solve``'s, not kept).

The last full answer made from the state (a solve's, or Live's warm solve of a stroke) is kept
with a digest of its inputs (``answer``, ``answer_inputs``: the state's key, the paint, the lux,
the view target, the polygon counts). Solve & Reduce asked for the same inputs takes it whole (a
copy of its report, the warnings saying whose answer it is): the same solve computed again gives
it to the bit (every sampling keyed by the seed and the geometry). So the button after a stroke,
once Live's later answers are in, is the write alone (issue 37: "the button uses what Live
prepared"); while Live's warm solve runs, the button waits for it (the scene's lock) and takes it.

Meshing every face as a painted one is (clustered only below 1/16 of its size) would let every
stroke on a floor or a wall map onto the adaptive model's patches; tried on the staircase, it took
977 patches to 1,451 and moved the predicted error from 0.063 / 0.051 (seeds 3 / 4) to 0.073 / 0.074,
so it is not done until Cycles says which prediction is right: paint on clustered faces maps onto
the kept clusters instead (above).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from ..engine.blas_threads import controller as blas_controller, one_blas_thread
from ..engine.by_content import digest
from ..engine.bounces import ColumnProducts
from ..engine.candidate_lamps import lamp_key, lamps_irradiance, plan_lamps
from ..engine.extent import decisive_region
from ..engine.geometry import triangle_areas
from ..engine.formfactors import auto_rays_per_patch, compute_form_factors, pairs_then_sending_scale
from ..engine.kernel_transfer import kernel_form_factors
from ..engine.lights import append_lamps
from ..engine.options import JobOptions
from ..engine.registry import ESTIMATORS, PATCH_MODELS
from ..engine.scene import FaceSet, PatchSet
from ..engine.units import TINY
from . import jobs
from . import notes as texts
from .checks import check_solvable, face_areas
from .model import move_scene_light, retarget_model

__all__ = ["PreparedScene", "scene_key", "paint_independent", "REFINE_STEPS"]

#: a Live stroke's answers after its quick one (PreparedScene.refine_live), in order
REFINE_STEPS = ("full search", "warm solve")

#: the FaceSet arrays a solve depends on apart from the paint
_SCENE_ARRAYS = ("vertices", "triangles", "triangle_face", "loop_vertices", "loop_start", "loop_total",
                 "face_object", "face_index", "reflectance", "exitance", "forbidden", "face_material", "passes")


def scene_key(faces: FaceSet, options: JobOptions, default_max_patch_size=None) -> dict:
    """What the prepared state depends on, part by part: {part: digest}. Two keys differ in the
    parts that changed (``stale_reason`` names them)."""
    arrays = {a: getattr(faces, a) for a in _SCENE_ARRAYS if getattr(faces, a) is not None}
    return {
        "geometry": digest(*(arrays[a] for a in ("vertices", "triangles", "triangle_face", "loop_vertices",
                                                 "loop_start", "loop_total", "face_object", "face_index", "passes")
                             if a in arrays), list(faces.object_names)),
        "materials": digest(arrays["reflectance"], arrays["exitance"], arrays.get("face_material", 0),
                            faces.material_lobes),
        "forbidden faces": digest(arrays.get("forbidden", 0)),
        "lamps and World": digest(faces.lamps, faces.world_radiance),
        "options": digest(sorted(options.to_dict().items()), default_max_patch_size),
    }


#: KeptLamps keeps the irradiance of at most this many x max_lamps lamps (the latest plans'); also
#: the kernel rows of this many x the targets of a solve
KEPT_PLANS = 4


class KeptLamps:
    """The candidate lamps' direct irradiance per W on one mesh, kept between solves, keyed by the
    lamp's kind and geometry (engine.candidate_lamps.lamp_key: not its name, its place in the
    plan): a solve's ``offer`` (engine.candidate_lamps.offer_lamps' signature, build_inverse_model's
    ``offer``) plans the lamps for its targets as offer_lamps does and computes only the lamps not
    kept. Each lamp's numbers are drawn on its own seed (lamp_seed: the job's seed and its key), so
    a kept lamp's irradiance is the one offer_lamps computes for it in a cold solve, bit for bit.
    Their irradiance does not depend on the paint: only the plan does (the spots aimed at the
    painted regions, the mounting positions among the unpainted candidates)."""

    def __init__(self):
        self.columns = {}  # lamp_key(lamp) -> (patch indices, irradiance per W there): its column of H
        self.reused = self.computed = 0  # of the last offer

    def offer(self, lights, patches, candidates, options, sampler, seed=0, progress=None, notes=None, aims=None):
        lamps, kinds = plan_lamps(patches, candidates, options, sampler, notes=notes, aims=aims)
        self.reused = self.computed = 0
        if not lamps:
            return lights, 0
        keys = [lamp_key(lamp) for lamp in lamps]
        H = np.zeros((patches.n_patches, len(lamps)))
        todo = np.array([k not in self.columns for k in keys])
        new = np.flatnonzero(todo)
        H[:, new] = lamps_irradiance(patches, [lamps[i] for i in new], sampler, seed, progress)
        for j, k in enumerate(keys):
            if todo[j]:
                at = np.flatnonzero(H[:, j])
                self.columns[k] = (at, H[at, j])
            else:
                at, value = self.columns.pop(k)  # (re-inserted: the latest plans' are kept)
                H[at, j] = value
                self.columns[k] = (at, value)
        self.reused, self.computed = int((~todo).sum()), int(todo.sum())
        for k in list(self.columns)[:max(0, len(self.columns) - KEPT_PLANS * max(len(lamps), 1))]:
            del self.columns[k]
        lit = np.flatnonzero(H.max(axis=0) > 0)
        area = np.array([lamps[i].kind.area(lamps[i]) for i in lit])
        return append_lamps(lights, np.flatnonzero(candidates), patches.n_patches, [lamps[i] for i in lit],
                            [kinds[i] for i in lit], H[:, lit], area), len(lamps)


def paint_independent(options: JobOptions) -> bool:
    """Whether the options' patch model meshes the faces without looking at the paint."""
    return PATCH_MODELS[options.patch_model].traits.paint_independent


def clustered_faces(patches: PatchSet) -> np.ndarray:
    """(n_faces,) bool: the faces that share a patch with another face (clusters)."""
    pairs = np.unique(np.stack([patches.tri_patch, patches.tri_face], axis=1), axis=0)
    per_patch = np.bincount(pairs[:, 0], minlength=patches.n_patches)
    out = np.zeros(patches.n_faces, dtype=bool)
    out[pairs[per_patch[pairs[:, 0]] > 1, 1]] = True
    return out


class _Clusters(NamedTuple):
    """The patches over several faces (clusters) of a mesh: its faces in them, their triangles'
    patch, face and area (m^2), and the clusters' patch indices."""

    patches: PatchSet
    faces: np.ndarray  # (n_faces,) bool: clustered_faces
    tri_patch: np.ndarray
    tri_face: np.ndarray
    tri_area: np.ndarray
    ids: np.ndarray


@dataclass
class PreparedScene:
    """The paint-independent part of a scene's last solve (see the module docstring)."""

    key: dict
    options: JobOptions
    default_max_patch_size: float | None
    patches: PatchSet = None  # the last solve's patches (None: no solve yet)
    paint: tuple = None  # (target, target_radiosity) of the faces at the last solve
    form_factors: object = None  # formfactors.FormFactors of ``_cast_for``, ray-cast only (no kernel pairs)
    _cast_for: object = None  # the PatchSet the form factors were cast for
    kernel_rows: dict = field(default_factory=dict)  # target patch -> (P,) kernel form factors (NaN: not drawn)
    seconds: dict = field(default_factory=dict)  # "rays": s of the last cast, "kernel rows": of the last solve
    solves: int = 0  # solves made
    warm: int = 0  # ... of which from the kept state
    reason: str = None  # why the last solve started from scratch (None: from the kept state)
    model: object = None  # pipeline.model.Model of the last solve (``live`` retargets it)
    live_solves: int = 0  # live re-solves made
    refined_solves: int = 0  # live strokes' second answers made (refine_live)
    starts: dict = field(default_factory=dict)  # {n_lights: lights} the last answer's curve (live starts there)
    _clustered: "_Clusters" = None  # _clusters(): paint-independent, computed once per mesh
    _face_area: np.ndarray = None  # checks.face_areas of the prepared scene's faces (geometry only)
    _nnls_start: np.ndarray = None  # the last solve's or stroke's all-lights NNLS (the next certificate's start)
    _stroke_targets: list = field(default_factory=list)  # the last stroke's targets kept_by_retarget (the next's)
    _products: object = None  # bounces.ColumnProducts of the model's transfer to every patch (column_products)
    lamps: KeptLamps = field(default_factory=KeptLamps)  # the candidate lamps' irradiance on the kept mesh
    drawn: dict = field(default_factory=dict)  # the last estimate's work: {"rays cast", "kernel rows drawn", ...}
    #: the last full answer made from this state: (digest of its inputs, ``answer_inputs``; the outcome as it
    #: was returned; what made it; when): ``solve`` and Live's warm solve take it for the same inputs
    answer: tuple = None

    @classmethod
    def prepare(cls, faces: FaceSet, options: JobOptions, default_max_patch_size=None):
        """An empty state for this scene and options: the first solve fills it."""
        options = options.validate()
        return cls(scene_key(faces, options, default_max_patch_size), options, default_max_patch_size)

    def stale_reason(self, faces: FaceSet, options: JobOptions, default_max_patch_size=None,
                     key: dict | None = None) -> str | None:
        """None when this state serves ``faces`` and ``options``; else what changed. ``key``: their
        scene_key, when the caller has it (it hashes every array of the scene)."""
        key = key or scene_key(faces, options.validate(), default_max_patch_size)
        changed = [part for part in key if key[part] != self.key.get(part)]
        return f"the {', '.join(changed)} changed since it was prepared" if changed else None

    def unmappable(self, faces: FaceSet) -> str | None:
        """None when the paint of ``faces`` maps onto the kept patches (``painted``); else why not:
        a kept cluster (a patch over several faces) painted with an illuminance target (lx) on some
        of its faces and a radiosity on others (one patch is one target of one kind)."""
        if self.patches is None:
            return "nothing is kept yet"
        if paint_independent(self.options) or faces.target_lux is None \
                or not np.any(self._clustered_faces() & faces.target & (faces.target_lux > 0)):
            return None  # (no lux asked on a clustered face: nothing to mix)
        mixed = np.flatnonzero(self._cluster_paint(faces)[3])
        if len(mixed):
            ps = self.patches
            hit = np.unique(ps.tri_face[np.isin(ps.tri_patch, mixed)])
            hit = hit[faces.target[hit]]
            names = sorted({faces.object_names[o] for o in faces.face_object[hit]})
            return (f"an illuminance target (lx) and a painted radiosity on {int(len(hit))} face(s) the patch model "
                    f"had clustered together ({len(mixed)} patch(es); objects: {', '.join(names[:5])}"
                    f"{' ...' if len(names) > 5 else ''})")
        return None

    def _clustered_faces(self) -> np.ndarray:
        """clustered_faces of the kept patches (paint-independent: computed once per mesh)."""
        return self._clusters().faces

    def _clusters(self) -> "_Clusters":
        """The kept patches' clusters (_Clusters), paint-independent: computed once per mesh (a
        stroke on the million-triangle room took their triangles' areas again: 0.17 s of its 0.39 s)."""
        if self._clustered is None or self._clustered.patches is not self.patches:
            patches = self.patches
            faces = clustered_faces(patches)
            tris = np.flatnonzero(faces[patches.tri_face])
            tp = patches.tri_patch[tris]
            self._clustered = _Clusters(patches, faces, tp, patches.tri_face[tris],
                                        triangle_areas(patches.tri_vertices[tris]), np.unique(tp))
        return self._clustered

    def _cluster_paint(self, faces: FaceSet) -> tuple:
        """What the paint of ``faces`` asks of the kept clusters (patches over several faces): per
        patch (P,), the painted area of its clustered faces, their area-weighted radiosity (P, 3) and
        lux (0 where none), and whether it mixes faces asked for lux with faces painted a radiosity;
        all zero on patches of one face."""
        cl = self._clusters()
        P = cl.patches.n_patches
        share, radiosity, lux = np.zeros(P), np.zeros((P, 3)), np.zeros(P)
        mixed = np.zeros(P, dtype=bool)
        # (the painted ones only: the others' terms are 0, which leave every sum as it is, bit for bit)
        on = np.flatnonzero(faces.target[cl.tri_face])
        if not len(on):
            return share, radiosity, lux, mixed
        tp, tf, a = cl.tri_patch[on], cl.tri_face[on], cl.tri_area[on]
        share = np.bincount(tp, weights=a, minlength=P)
        on = share > 0
        for c in range(3):
            radiosity[:, c] = np.bincount(tp, weights=a * faces.target_radiosity[tf, c], minlength=P)
        radiosity[on] /= share[on, None]
        if faces.target_lux is not None:
            asked = faces.target_lux[tf] > 0
            lux_area = np.bincount(tp, weights=a * asked, minlength=P)
            lux = np.bincount(tp, weights=a * asked * faces.target_lux[tf], minlength=P)
            lux[on] /= np.maximum(lux_area[on], TINY)
            mixed = (lux_area > 0) & (lux_area < share)
        return share, radiosity, lux, mixed

    def painted(self, faces: FaceSet) -> PatchSet:
        """The kept patches with the paint of ``faces``: each patch its face's target; a cluster
        (a patch over several faces, which the adaptive model made of unpainted faces) a target
        when any of its faces is painted, at the area-weighted mean radiosity of its painted faces
        (their least-squares target on one uniform patch), and when they are asked for an
        illuminance, at their area-weighted mean lux (``PatchSet.target_lux``; a cluster that
        mixes the two kinds is ``unmappable``). Measured on the staircase against a cold
        solve, which meshes the new paint at the patch size (977 patches -> 988 and 1,001): the
        painted-face error 1.03 x the cold solve's for 12 clustered faces painted, 1.11 x for 24; a
        cluster a target only when painted over half its area, 1.06 x and 1.30 x
        (docs/benchmarks.md, "The button after a stroke")."""
        patches = self.patches
        target = faces.target[patches.face].copy()
        radiosity = faces.target_radiosity[patches.face].copy()
        lux = None
        if not paint_independent(self.options):
            share, mean, lux_mean, _ = self._cluster_paint(faces)
            cl = self._clusters().ids
            target[cl] = share[cl] > 0
            radiosity[cl] = mean[cl]
            if faces.target_lux is not None:
                lux = faces.target_lux[patches.face].copy()
                lux[cl] = lux_mean[cl]
        return replace(patches, target=target, target_radiosity=radiosity, target_lux=lux)

    def estimate(self, patches, options, progress=None, cancel=None, pairs=None):
        """build_inverse_model's estimator: the prepared ray-cast form factors and, for the estimators
        with kernel pairs, the kernel's rows of the targets (the new ones computed, the others
        kept), applied as compute_form_factors applies them."""
        cast = 0.0
        self.drawn = {"rays cast": 0}
        if patches is not self._cast_for:  # a new mesh (a first solve, a refinement pass): cast its rays
            rays = (int(options.rays_per_patch) if options.rays_per_patch is not None
                    else auto_rays_per_patch(patches.n_patches, kernel=pairs is not None))
            t0 = time.perf_counter()
            self.form_factors = compute_form_factors(patches, rays_per_patch=rays, seed=options.seed,
                                                     threads=options.threads, progress=progress, cancel=cancel)
            self._cast_for, self.kernel_rows = patches, {}
            self.lamps = KeptLamps()  # (another mesh: another irradiance)
            self.seconds["rays"] = cast = time.perf_counter() - t0
            self.drawn["rays cast"] = int(rays) * patches.n_patches
        F = self.form_factors
        if pairs is None or not ESTIMATORS[options.estimator].traits.kernel_pairs:
            return replace(F, matrix=F.matrix.copy(), seconds=cast)
        t0 = time.perf_counter()
        rec, src = (np.asarray(p, dtype=np.int64) for p in pairs)
        self._draw_pairs(patches, rec, src, options, F.sampler, cancel)
        K = np.stack([self.kernel_rows[int(r)][src] for r in rec]) if len(rec) else np.zeros((0, len(src)))
        # the pairs replace F's entries before the sending scale of partly buried patches, as
        # compute_form_factors applies them
        M = pairs_then_sending_scale(F.matrix, patches.area, F.send, rec, src, K, unscale=True)
        self.seconds["kernel rows"] = time.perf_counter() - t0
        return replace(F, matrix=M, kernel_pairs=int(K.size), seconds=cast + self.seconds["kernel rows"])

    def _draw_pairs(self, patches, rec, src, options, sampler, cancel):
        """Fill ``kernel_rows`` for every (target ``rec``, source ``src``) pair not drawn yet: the new
        targets' rows over every source, the kept rows' new sources (an erased patch is a candidate
        again). Each pair samples on a stream of its own (kernel_transfer: keyed by the seed and the
        two patches), so these are the entries the cold solve's one draw of every pair gives."""
        P = patches.n_patches
        have = np.array([int(r) in self.kernel_rows for r in rec], dtype=bool)
        new, old = rec[~have], rec[have]
        draw = dict(seed=options.seed, threads=options.threads, cancel=cancel, sampler=sampler)
        pairs = 0
        if len(new) and len(src):
            K = kernel_form_factors(patches, new, src, **draw)
            for i, r in enumerate(new):
                row = np.full(P, np.nan)
                row[src] = K[i]
                self.kernel_rows[int(r)] = row
            pairs += K.size
        elif len(new):
            for r in new:
                self.kernel_rows[int(r)] = np.full(P, np.nan)
        if len(old) and len(src):
            missing = np.isnan(np.stack([self.kernel_rows[int(r)][src] for r in old])).any(axis=0)
            if missing.any():
                K = kernel_form_factors(patches, old, src[missing], **draw)
                for i, r in enumerate(old):
                    self.kernel_rows[int(r)][src[missing]] = K[i]
                pairs += K.size
        self.drawn.update({"kernel rows drawn": len(new), "kernel rows kept": len(old), "kernel pairs drawn": pairs,
                           "kernel pairs kept": len(rec) * len(src) - pairs})
        for r in rec.tolist():  # (re-inserted: the rows of the latest KEPT_PLANS solves' targets are kept)
            self.kernel_rows[r] = self.kernel_rows.pop(r)
        for r in list(self.kernel_rows)[:max(0, len(self.kernel_rows) - KEPT_PLANS * max(len(rec), 1))]:
            del self.kernel_rows[r]

    def offer(self, *args, **kw):
        """build_inverse_model's ``offer``: the candidate lamps, their irradiance kept (KeptLamps)."""
        return self.lamps.offer(*args, **kw)

    def account(self) -> dict:
        """What the last solve took from the prepared state and what it made anew (its report's
        ``prepared``): the rays kept or cast, the kernel's target rows and (target, source) pairs kept
        or drawn, the candidate lamps' irradiance kept or computed; the rest is computed anew on
        every solve."""
        return {"from_prepared_state": self.reason is None, "reason": self.reason,
                "kept": {"form factors (hemisphere rays)": self.reason is None and not self.drawn.get("rays cast"),
                         "kernel rows": self.drawn.get("kernel rows kept", 0),
                         "kernel pairs": self.drawn.get("kernel pairs kept", 0),
                         "candidate lamps' irradiance": self.lamps.reused},
                "computed": {"rays cast": self.drawn.get("rays cast", 0),
                             "kernel rows": self.drawn.get("kernel rows drawn", 0),
                             "kernel pairs": self.drawn.get("kernel pairs drawn", 0),
                             "candidate lamps' irradiance": self.lamps.computed},
                "computed anew": ["the candidate lamps' plan (aimed at the targets)", "the inverse problem and its "
                                  "factorisation", "the reduction", "the direct light", "the lamp refinement"]}

    def _warm(self, faces: FaceSet) -> tuple:
        """(the kept patches with ``faces``' paint, the options a solve on them runs with): the same
        mesh, so its rays and kernel rows serve (``_cast_for``), and no refinement pass re-meshes it;
        the decisive region the new paint's (engine.extent: the lamps' drop follows it, as in a cold
        solve of the same paint; the rays' offset the kept rays' own, ``PatchSet.ray_scale``)."""
        kept = self.painted(faces)
        ray_scale = kept.ray_scale if kept.ray_scale is not None else \
            kept.region.diagonal if kept.region is not None else None
        patches = replace(kept, region=decisive_region(faces), ray_scale=ray_scale)
        self._cast_for = patches
        options = self.options
        if options.param("refine_passes", 0):
            options = replace(options, refine_passes=0)
        return patches, options

    def solve(self, faces: FaceSet, polygon_counts=None, progress=None, cancel=None, notes=None, meshed=None,
              key=None):
        """The inverse solve of ``faces`` (this scene with its current paint): from the kept state
        when the paint maps onto it, else from scratch (``meshed``: its patches when the caller
        has them; the reason in ``self.reason``), keeping what this solve makes.
        pipeline.jobs.run_solve either way. ``key``: stale_reason's."""
        stale = self.stale_reason(faces, self.options, self.default_max_patch_size, key)
        if stale is not None:
            raise ValueError(f"the prepared scene is stale: {stale}")
        self.reason = self.unmappable(faces)
        self.solves += 1
        inputs = self.answer_inputs(faces, polygon_counts)
        outcome = self._taken(inputs) if self.reason is None else None
        if outcome is None:
            outcome = self._solved(faces, polygon_counts, progress, cancel, notes, meshed)
            self._keep_answer(inputs, outcome, "the last solve")
        if self._cast_for is not outcome.patches:  # not the mesh the rays were cast for: keep nothing
            self.patches = self._cast_for = self.form_factors = self.model = None
        else:
            self.patches, self.model = outcome.patches, outcome.model
            # (the first stroke's certificate starts from this solve's all-lights NNLS: its lights)
            bounds = outcome.reduction.certificate
            self._nnls_start = None if bounds is None else bounds.nnls_exitance
            self.paint = (faces.target.copy(), faces.target_radiosity.copy())
            self.starts = _starts(outcome)
        return outcome

    def _solved(self, faces, polygon_counts, progress, cancel, notes, meshed):
        """``solve``'s computation: from the kept patches (``reason`` None) or from scratch."""
        options, patches = self.options, meshed
        if self.reason is None:  # the kept patches, their rays, with the new paint
            patches, options = self._warm(faces)
            self.warm += 1
        self.answer = None  # (what this solve casts and keeps is no longer that answer's)
        try:
            outcome = jobs.run_solve(faces, options, polygon_counts, self.default_max_patch_size, progress, cancel,
                                     patches=patches, notes=notes, estimate=self.estimate,
                                     offer=self.offer)
        except BaseException:  # cancelled or refused part-way: what was cast may be another mesh's
            self.patches = self._cast_for = self.form_factors = self.model = None
            raise
        outcome.report["prepared"] = self.account()
        return outcome

    def answer_inputs(self, faces: FaceSet, polygon_counts=None) -> str:
        """A digest of what a solve of ``faces`` reads beyond the scene this state serves (its
        ``key``, checked first): the paint (the painted radiosity, the lux, the view target) and
        the polygon counts; the key itself (a lamp moved since: ``move_lamps``)."""
        return digest(self.key, faces.target, faces.target_radiosity, faces.target_lux, faces.view_target,
                      polygon_counts)

    def _keep_answer(self, inputs: str, outcome, by: str) -> None:
        """``outcome``, a full answer just made for ``inputs``, kept as it was returned (its
        report and warnings copied: the caller finishes them)."""
        self.answer = (inputs, _copied(outcome), by, time.strftime("%H:%M:%S"))

    def _taken(self, inputs: str):
        """The kept answer (a copy) when it was made for these ``inputs``, its report saying so
        (``prepared.taken``, a warning); else None. The same paint, scene and options: the same
        solve, computed again, would give it (Live's warm solve is ``solve``'s)."""
        if self.answer is None or self.answer[0] != inputs:
            return None
        _, kept, by, when = self.answer
        outcome = _copied(kept)
        note = texts.taken_note(by, when, outcome.report.get("timings_s", {}).get("total"))
        outcome.report["prepared"] = {**outcome.report.get("prepared", {}), "taken": note}
        outcome.warnings.append(note)
        outcome.report["warnings"].append(note)
        return outcome

    def move_lamps(self, faces: FaceSet) -> None:
        """The scene's lamps changed and nothing else (a kept lamp moved, turned, resized or set to
        another power: ``faces``' lamps): the last solve's model takes their light as its fixed
        light anew (pipeline.model.move_scene_light: their direct light cast on the kept scene, its
        radiosity through the kept factorisation) and this state its key, so that ``live``
        re-solves the rest around them. Its lights, form factors and transfer stay. ValueError
        when anything else changed, or nothing is solved yet."""
        if self.model is None:
            raise ValueError("nothing is solved yet")
        key = scene_key(faces, self.options, self.default_max_patch_size)
        changed = [part for part in key if key[part] != self.key.get(part)]
        if any(part != "lamps and World" for part in changed):
            raise ValueError(f"the {', '.join(changed)} changed since it was prepared")
        self.model = move_scene_light(self.model, faces, self.options.seed)
        self.key = key

    def prepare_live(self, faces: FaceSet) -> None:
        """What every live stroke reads, made once before the first (Live's worker): the transfer
        from every light to every patch, the rows of it of the targets a stroke keeps (a camera-view
        target's: InverseProblem._rows_of, 1.1 s on the living room), the faces the patch model
        clustered, the face areas, the BLAS controller a stroke's one_blas_thread sets (17 ms)."""
        problem = self.model.problem
        problem.all_rows_transfer()
        blas_controller()
        if any(t.kept_by_retarget for t in problem.target_rows.targets):
            problem.retarget(list(problem.target_rows.targets))
        self._clustered_faces()
        self._face_area = face_areas(faces)

    def column_products(self):
        """The products with F of the model's transfer to every patch, per light, kept across
        strokes (bounces.ColumnProducts: a stroke's light-paths check, light_paths.assess_solve);
        None before prepare_live."""
        T_all = None if self.model is None else self.model.problem.prepared_rows_transfer()
        if T_all is None:
            return None
        if self._products is None or self._products.T is not T_all:
            self._products = ColumnProducts(self.model.problem.F, self.model.patches.reflectance, T_all)
        return self._products

    def live(self, faces: FaceSet, polygon_counts=None, progress=None, cancel=None, notes=None, key=None):
        """A stroke's live re-solve (Live mode) from the last solve's model: its patches with the
        paint of ``faces`` (mapped as ``solve`` maps it), its lights, form factors and solvers,
        the problem retargeted on the transfer to every patch (pipeline.model.retarget_model,
        jobs.solve_stroke). Changes nothing kept: each stroke starts from the last
        solve. None when it cannot follow (``self.reason`` says why): the caller solves in full."""
        self.reason = (self.stale_reason(faces, self.options, self.default_max_patch_size, key)
                       or ("nothing is solved yet" if self.model is None else self.unmappable(faces)))
        if self.reason is not None:
            return None
        if self._face_area is None:  # (the geometry is the prepared one: the key says so)
            self._face_area = face_areas(faces)
        check_solvable(faces, notes, area=self._face_area)
        t0 = time.perf_counter()
        model = retarget_model(self.model, faces, self.painted(faces), kept=self._stroke_targets)
        self._stroke_targets = [t for t in model.problem.target_rows.targets if t.kept_by_retarget]
        with one_blas_thread():  # (small products: a second thread costs more than it gives)
            outcome = jobs.solve_stroke(model, self.options, polygon_counts, progress, cancel, t0=t0,
                                        initial=dict(self.starts),  # (the last solve's: of the paint alone)
                                        nnls_start=self._nnls_start)
        self.live_solves += 1
        bounds = outcome.reduction.certificate
        self._nnls_start = None if bounds is None else bounds.nnls_exitance
        outcome.warnings.append(texts.live_note(self.model.problem.m))
        return outcome

    def refine_live(self, best, step=0, polygon_counts=None, progress=None, cancel=None):
        """A stroke's better answers (Live, in its worker, once the quick one, ``live``'s, is
        shown), step by step (REFINE_STEPS), each kept when its final error is lower than
        ``best``'s (the answer shown: the quick one, or an earlier step's): the outcome, else None.

        - step 0, "full search": what a solve does after building its model, on the stroke's
          retargeted model (``best.model``; jobs.solve_model: the inverse solve, the selection's
          full search instead of the quick one, the kernel's direct light of the curve's lights not
          corrected yet, the certificate, the placed lamps refined for the stroke's targets; the
          last solve's lamps, refined for its paint, stay candidates);
        - step 1, "warm solve": the solve of the stroke's paint from the prepared state as
          ``solve`` makes it (the kept patches, rays and kernel rows; the lamps offered for the new
          targets, the new target patches' kernel rows, the problem factorised again), not kept:
          the strokes after it still start from the last solve.

        Neither step re-meshes the adaptive model for the new paint. Nothing kept changes but the
        kernel's rows of the new target patches and the irradiance of the lamps it planned (step 1;
        the next solve's)."""
        faces = best.faces
        if step == 0:
            outcome = jobs.solve_model(best.model, self.options, polygon_counts, progress, cancel)
        else:
            inputs = self.answer_inputs(faces, polygon_counts)
            outcome = self._taken(inputs)
            if outcome is None:
                patches, options = self._warm(faces)
                self.answer = None
                outcome = jobs.run_solve(faces, options, polygon_counts, self.default_max_patch_size, progress,
                                         cancel, patches=patches, estimate=self.estimate, offer=self.offer)
                outcome.report["prepared"] = self.account()
                self._keep_answer(inputs, outcome, "Live's warm solve")  # (Solve & Reduce takes it: the same paint)
        self.refined_solves += 1
        if not outcome.reduction.final.relative_error < best.reduction.final.relative_error:
            return None
        outcome.warnings.append(texts.LIVE_NOTE.format(why=f"its {REFINE_STEPS[step]} for these {outcome.problem.m} "
                                                           "target patches, after the quick answer"))
        return outcome


def _copied(outcome):
    """A solve's outcome with its own report, warnings and curve rows, down to what a caller sets
    in them (report.finish: the warnings, timings, render settings and each object's radiance
    along the normal; camera_view.predict_view: the view target's block); the rest shared, read
    only (a deep copy of a large scene's report, a row per polygon, would take seconds)."""
    report = dict(outcome.report)
    report["warnings"] = list(report.get("warnings") or [])
    report["timings_s"] = dict(report.get("timings_s") or {})
    if report.get("objects"):
        report["objects"] = {name: dict(rows) for name, rows in report["objects"].items()}
    return replace(outcome, report=report, warnings=list(outcome.warnings), curve=[dict(r) for r in outcome.curve])


def _starts(outcome) -> dict:
    """{n_lights: lights} of an answer's non-negative configurations (a live re-solve's starts)."""
    return {int(pt.n_lights): np.asarray(pt.lights, dtype=np.int64).copy() for pt in outcome.reduction.curve
            if pt.n_negative == 0 and pt.n_lights > 0}


def scene_lamps_differ(a: FaceSet, b: FaceSet) -> bool:
    """Whether two exports of a scene differ in their lamps (scene_key's "lamps and World" part)."""
    return digest(a.lamps) != digest(b.lamps)
