"""Prepare once, re-solve per stroke (issue 20, item 1; no bpy).

A solve's answer depends on the scene (geometry, materials, forbidden faces, lamps, World, the
options) and on the paint. ``PreparedScene`` keeps what depends only on the scene, keyed by a
fingerprint of it (``scene_key``), and re-solves when only the paint changed:

- the patches, when the patch model meshes without looking at the paint (a model registered with
  ``paint_independent=True``: the polygon model); the paint is mapped onto them (a patch asks for
  the target of the face it lies on, as engine.scene.build_patches does);
- the ray-cast form factors (every patch's hemisphere rays: the bulk of the rays a solve casts);
- the kernel's rows (engine.kernel_transfer: the transport from the candidate lights to a
  target patch), per patch, for every patch painted so far: a stroke computes only its new rows.

The rest (the lights offered for the targets, the inverse problem, the selection, the
certificate and the curve) is the cold solve's own code (pipeline.jobs.run_solve), given the
prepared patches and form factors. A change the fingerprint sees (an object moved, a material, a
forbidden face, an option) rebuilds it, and ``stale_reason`` says why.

Not yet kept (issue 20 stays open on them): the adaptive model's patches follow the paint (its
clusters never mix painted and unpainted faces, and its refinement follows the targets), so it
is prepared from scratch each time and says so; the factorisation of the radiosity system and
the transfer to every paintable patch (each re-solve factorises again).
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..engine.formfactors import auto_rays_per_patch, compute_form_factors
from ..engine.kernel_transfer import apply_kernel_pairs, kernel_form_factors
from ..engine.options import JobOptions
from ..engine.registry import ESTIMATORS, PATCH_MODELS
from ..engine.scene import FaceSet, PatchSet
from . import jobs

__all__ = ["PreparedScene", "scene_key", "paint_independent"]

#: the FaceSet arrays a solve depends on apart from the paint
_SCENE_ARRAYS = ("vertices", "triangles", "triangle_face", "loop_vertices", "loop_start", "loop_total",
                 "face_object", "face_index", "reflectance", "exitance", "forbidden", "face_material")


def scene_key(faces: FaceSet, options: JobOptions, default_max_patch_size=None) -> dict:
    """What the prepared state depends on, part by part: {part: digest}. Two keys differ in the
    parts that changed (``stale_reason`` names them)."""
    def digest(*items):
        h = hashlib.sha1()
        for x in items:
            h.update(np.ascontiguousarray(x).tobytes() if isinstance(x, np.ndarray) else repr(x).encode())
        return h.hexdigest()

    arrays = {a: getattr(faces, a) for a in _SCENE_ARRAYS if getattr(faces, a) is not None}
    return {
        "geometry": digest(*(arrays[a] for a in ("vertices", "triangles", "triangle_face", "loop_vertices",
                                                 "loop_start", "loop_total", "face_object", "face_index")
                             if a in arrays), list(faces.object_names)),
        "materials": digest(arrays["reflectance"], arrays["exitance"], arrays.get("face_material", 0),
                            repr(faces.material_lobes)),
        "forbidden faces": digest(arrays.get("forbidden", 0)),
        "lamps and World": digest(repr(faces.lamps), repr(faces.world_radiance)),
        "options": digest(sorted(options.to_dict().items()), default_max_patch_size),
    }


def paint_independent(options: JobOptions) -> bool:
    """Whether the options' patch model meshes the faces without looking at the paint."""
    return bool(PATCH_MODELS[options.patch_model].get("paint_independent", False))


@dataclass
class PreparedScene:
    """The paint-independent part of a solve (see the module docstring)."""

    key: dict
    options: JobOptions
    default_max_patch_size: float | None
    patches: PatchSet  # as meshed (their targets are replaced per solve)
    form_factors: object  # formfactors.FormFactors, ray-cast only (no kernel pairs)
    kernel_sources: np.ndarray = None  # the candidate patches the kernel rows are for
    kernel_rows: dict = field(default_factory=dict)  # target patch -> (n_sources,) kernel form factors
    seconds: dict = field(default_factory=dict)  # "prepare": s, "kernel rows": s of the last solve
    solves: int = 0  # solves made from this state

    @classmethod
    def prepare(cls, faces: FaceSet, options: JobOptions, default_max_patch_size=None, progress=None, cancel=None):
        """Mesh the faces and cast the form factors' rays once. Raises ValueError when the
        options' patch model follows the paint (nothing could be kept)."""
        options = options.validate()
        if not paint_independent(options):
            raise ValueError(f"the {PATCH_MODELS[options.patch_model].label} patch model follows the paint "
                             "(a stroke changes its patches): nothing can be prepared once for it; use Polygons")
        t0 = time.perf_counter()
        jobs.check_before_meshing(faces, options, default_max_patch_size)
        patches = jobs.patch_model(options, default_max_patch_size).mesh(faces)
        kernel = jobs.uses_kernel_pairs(options)
        rays = (int(options.rays_per_patch) if options.rays_per_patch is not None
                else auto_rays_per_patch(patches.n_patches, kernel=kernel))
        F = compute_form_factors(patches, rays_per_patch=rays, seed=options.seed, threads=options.threads,
                                 progress=progress, cancel=cancel)
        return cls(scene_key(faces, options, default_max_patch_size), options, default_max_patch_size, patches, F,
                   seconds={"prepare": time.perf_counter() - t0})

    def stale_reason(self, faces: FaceSet, options: JobOptions, default_max_patch_size=None) -> str | None:
        """None when this state serves ``faces`` and ``options``; else what changed."""
        key = scene_key(faces, options.validate(), default_max_patch_size)
        changed = [part for part in key if key[part] != self.key.get(part)]
        return f"the {', '.join(changed)} changed since it was prepared" if changed else None

    def painted(self, faces: FaceSet) -> PatchSet:
        """The prepared patches with the paint of ``faces`` (each patch its face's target)."""
        return replace(self.patches, target=faces.target[self.patches.face].copy(),
                       target_radiosity=faces.target_radiosity[self.patches.face].copy())

    def estimate(self, patches, options, progress=None, cancel=None, pairs=None):
        """build_model's estimator: the prepared ray-cast form factors and, for the estimators
        with kernel pairs, the kernel's rows of the targets (the new ones computed, the others
        kept), applied as compute_form_factors applies them."""
        F = self.form_factors
        if pairs is None or not ESTIMATORS[options.estimator].get("kernel_pairs", False):
            return replace(F, matrix=F.matrix.copy())
        t0 = time.perf_counter()
        rec, src = (np.asarray(p, dtype=np.int64) for p in pairs)
        if self.kernel_sources is None or not np.array_equal(src, self.kernel_sources):
            self.kernel_sources, self.kernel_rows = src, {}
        new = np.array([r for r in rec if int(r) not in self.kernel_rows], dtype=np.int64)
        if len(new):
            K = kernel_form_factors(patches, new, src, seed=options.seed, threads=options.threads, cancel=cancel,
                                    sampler=F.sampler)
            self.kernel_rows.update({int(r): K[i] for i, r in enumerate(new)})
        K = np.stack([self.kernel_rows[int(r)] for r in rec]) if len(rec) else np.zeros((0, len(src)))
        # the pairs replace F's entries before the sending scale of partly buried patches (as in
        # compute_form_factors): taken out of F's columns, put back after
        send = np.ones(patches.n_patches) if F.send is None else np.asarray(F.send, dtype=np.float64)
        scale = np.where(send > 0, send, 1.0)
        M = F.matrix.astype(np.float64) / scale[None, :] if isinstance(F.matrix, np.ndarray) \
            else F.matrix.multiply(1.0 / scale[None, :]).tocsr()
        M = apply_kernel_pairs(M, patches.area, rec, src, K)
        M = (M * scale[None, :]).astype(np.float32) if isinstance(M, np.ndarray) \
            else M.multiply(scale[None, :]).tocsr().astype(np.float32)
        self.seconds["kernel rows"] = time.perf_counter() - t0
        return replace(F, matrix=M, kernel_pairs=int(K.size), seconds=self.seconds["kernel rows"])

    def solve(self, faces: FaceSet, polygon_counts=None, progress=None, cancel=None, notes=None):
        """The inverse solve of ``faces`` (this scene with its current paint) from the prepared
        state: pipeline.jobs.run_solve with the prepared patches and form factors."""
        reason = self.stale_reason(faces, self.options, self.default_max_patch_size)
        if reason is not None:
            raise ValueError(f"the prepared scene is stale: {reason}")
        self.solves += 1
        return jobs.run_solve(faces, self.options, polygon_counts, self.default_max_patch_size, progress, cancel,
                              patches=self.painted(faces), notes=notes, estimate=self.estimate)
