"""One preparation step for every solve, shared by the CLI and the solve operator (bpy).

    job = SolveJob.export(context, options, mode)   # main thread: the scene -> FaceSet, checked
    job.mesh(progress, cancel)                      # any thread: patches and the cost estimate
    outcome = job.run(progress, cancel)             # any thread, no bpy: jobs.run_solve / run_reduce
    job.finish(scene, outcome, view_radiance=True)  # main thread: the report finished (report.finish)

then ``results.show_outcome`` writes it into the scene. The operator asks before a costly job
(``job.cost["warnings"]``); the CLI prints the estimate.

In a session (the add-on: ``SolveJob.export(..., session=True)``), a solve keeps its scene's
paint-independent part (pipeline.prepared.PreparedScene, one per scene), and the next solve starts
from it while only the paint changed (and maps onto the kept patches); otherwise it starts from
scratch and the solve's warnings say why.
"""
from __future__ import annotations

import collections
import threading
from dataclasses import dataclass

import bpy
import numpy as np

from . import export, light_paths
from ..engine.options import check_light_kinds
from ..pipeline import checks, jobs, meshing, prepared, report, viewing

__all__ = ["SolveJob", "PREPARED", "PREPARED_JOBS", "LOCKS"]

#: the session's prepared scenes: scene name -> pipeline.prepared.PreparedScene
PREPARED = {}
#: the job whose solve last filled PREPARED[scene name] (Live mode re-reads its objects' paint)
PREPARED_JOBS = {}
#: scene name -> the lock of its prepared state: one solve at a time works on it (Solve & Reduce's
#: worker, Live's): the engine's factorisations and its BLAS calls are not shared between threads
LOCKS = collections.defaultdict(threading.RLock)


@dataclass
class SolveJob:
    exp: object  # export.ExportedScene
    options: object  # JobOptions, validated
    mode: str  # "inverse" (solve) or "direct" (reduce)
    inputs: dict  # export.job_inputs
    patches: object = None
    cost: dict = None
    session: str = None  # the scene's name when the job keeps a prepared scene (the add-on)
    _key: dict = None  # prepared.scene_key of these faces and options, once hashed (``mesh``)

    @classmethod
    def export(cls, context, options, mode="inverse", target_scale=None, session=False, view_target=None) -> "SolveJob":
        """Export the scene and check, from the faces alone, that the job can be solved.
        ``session``: keep and re-use the scene's prepared state (see the module docstring).
        ``view_target``: an engine.targets.view.ViewSpec (blender/camera_view.py), the camera's pixels."""
        if mode == "inverse":
            check_light_kinds(options)  # (the options alone: before the export's work)
        exp = export.export_scene(context, target_scale=target_scale)
        exp.faces.view_target = view_target
        if mode == "inverse":
            checks.check_solvable(exp.faces, exp.notes)
        else:
            checks.check_reducible(exp.faces, exp.notes)
        name = (context or bpy.context).scene.name if session else None
        return cls(exp, options, mode, export.job_inputs(exp), session=name)

    def mesh(self, progress=None, cancel=None):
        """Mesh the faces (refused first when they cannot fit in memory) and estimate the solve.
        In a session whose prepared state serves these faces (the same scene and options, the
        paint mapped onto its patches), nothing is meshed: the solve starts from the kept
        patches, and the estimate is theirs with this paint (3.8 s of meshing on a million
        triangles, which the solve would not read)."""
        kept = self._kept_patches()
        if kept is not None:
            self.patches = None
            self.cost = meshing.solve_cost(kept, self.options, mode=self.mode)
            return kept, self.cost
        self.patches = meshing.mesh_for_job(self.exp.faces, self.options, self.inputs["default_max_patch_size"],
                                         mode=self.mode)
        self.cost = meshing.solve_cost(self.patches, self.options, mode=self.mode)
        return self.patches, self.cost

    def _kept_patches(self):
        """The session's prepared patches with these faces' paint (PreparedScene.painted) when its
        solve of them starts from them (stale_reason and unmappable: None), else None."""
        state = None if self.session is None or self.mode != "inverse" else PREPARED.get(self.session)
        if state is None or state.patches is None:
            return None
        lock = LOCKS[self.session]
        if not lock.acquire(blocking=False):  # (a solve runs on it, Live's: meshed as before, not waited for)
            return None
        try:
            faces = self.exp.faces
            self._key = prepared.scene_key(faces, self.options, self.inputs["default_max_patch_size"])
            serves = state.patches is not None and state.stale_reason(faces, self.options, key=self._key) is None \
                and state.unmappable(faces) is None
            return state.painted(faces) if serves else None
        finally:
            lock.release()

    def run(self, progress=None, cancel=None):
        """The solve (no bpy; any thread): a jobs.SolveOutcome."""
        if self.mode != "inverse":
            return jobs.run_reduce(self.exp.faces, self.options, progress=progress, cancel=cancel,
                                   patches=self.patches, **self.inputs)
        if self.session is None:
            return jobs.run_solve(self.exp.faces, self.options, progress=progress, cancel=cancel,
                                  patches=self.patches, **self.inputs)
        with LOCKS[self.session]:
            return self._run_session(progress, cancel)

    def _run_session(self, progress, cancel):
        faces, size = self.exp.faces, self.inputs["default_max_patch_size"]
        key = self._key or prepared.scene_key(faces, self.options, size)  # hashed once for the check and the solve
        state = PREPARED.get(self.session)
        why = None if state is None else state.stale_reason(faces, self.options, size, key)
        if state is None or why is not None:
            state = PREPARED[self.session] = prepared.PreparedScene(key, self.options, size)
        outcome = state.solve(faces, self.inputs["polygon_counts"], progress, cancel, self.inputs["notes"],
                              meshed=self.patches, key=key)
        PREPARED_JOBS[self.session] = self
        why = why or (state.reason if state.solves > 1 else None)
        if why is not None:
            outcome.warnings.append(f"solved from scratch: {why}")
        return outcome

    def finish(self, scene, outcome, view_radiance=True, input_path=None, settings=None, products=None):
        """The report finished with what only Blender can tell: the render settings of the scene's
        Cycles light paths, and (``view_radiance``) the radiance along the target faces' normals.
        ``settings``: light_paths.snapshot(scene), read before (then any thread: ``scene`` unused).
        ``products``: light_paths.assess_solve's (a Live stroke's)."""
        rows = self.normal_radiance(outcome) if view_radiance else None
        report.finish(outcome.report, outcome.warnings, light_paths.assess_solve(scene, outcome, settings, products),
                      rows, export_seconds=self.exp.seconds, input_path=input_path)
        return outcome

    def normal_radiance(self, outcome):
        """{object: rows}: what a bake shows on the target faces (viewing.py), or None when the
        targets are too many to compute it."""
        prob = outcome.problem
        mask = prob.target_mask
        if not np.any(mask) or np.sum(mask) > viewing.MAX_PATCHES:
            return None
        stored = outcome.stored
        B = np.asarray(stored.radiosity[outcome.final_index], dtype=np.float64)
        e = prob.patch_exitance(stored.exitance[outcome.final_index])
        if self.mode == "inverse":
            e = e + outcome.patches.exitance  # the scene's own emitters (fixed background)
        return viewing.normal_radiance(outcome.faces, outcome.patches, prob.F, B, self.exp.face_material,
                                       self.exp.material_lobes, self.inputs["polygon_counts"], mask, exitance=e,
                                       scene_light=outcome.scene_light, placed=outcome.placed_light,
                                       emission_share=prob.emission_share,
                                       direct_correction=prob.emitter_direct_correction(
                                           stored.exitance[outcome.final_index]))
