"""Live mode (issue 20, item 2): while it is on, every stroke, Fill and Unpaint updates the lights,
the radiosity layer and the chart. bpy on the main thread; the re-solves in a worker thread
(pipeline.prepared.PreparedScene.live, no bpy).

A ``LiveSession`` per scene, driven by ``tick()`` on the main thread (the ``relight.live`` modal
operator's timer):

- its first answer is a solve of the scene as it is when Live is turned on (preparation.SolveJob
  in the worker: from the session's prepared state when that still serves); later Solve & Reduce
  solves replace the model it re-solves from;
- when Blender reported a change (``depsgraph_update_post``: ``dirty``) and no brush stroke runs
  (``stroke_running``: no paint or sculpt modal operator in a window; where Blender cannot say,
  none for QUIET seconds), the paint is read again (export.repaint: the target layers only, no
  export) and, when new, re-solved in the worker. While a re-solve runs,
  newer paint waits, and supersedes it: an answer whose paint is no longer the newest is dropped;
- an answer for the newest paint is written into the scene (operators.show_solve), and the
  time of the update and its cost are shown;
- once a stroke's quick answer is written and no newer paint waits for LATER_PAUSE seconds (the
  artist paused: a stroke soon after finds the worker idle), its later answers are computed in the
  worker, step by step (pipeline.prepared.REFINE_STEPS: the selection's full search and the lamps
  refined for its targets on the retargeted model, then the warm solve from the prepared state),
  each written when its error is lower than the answer shown (``refined``; not better:
  ``kept_quick``); a newer stroke, a pause or ``stop()`` cancels the one running. The quick
  answer lost up to 17 % against a cold solve's error; the later ones are within 1 % of it on the
  staircase and the living room (docs/benchmarks.md, issue 37);
- paint on faces the patch model clustered with others is mapped onto the kept clusters
  (PreparedScene.painted) and answered as any stroke; an illuminance target changed on such a
  face cannot be mapped and is solved in full (in the worker);
- a lamp of the scene moved, turned or set to another power (a kept one, say): its light is cast
  again on the kept scene and taken through the kept factorisation (PreparedScene.move_lamps),
  and the rest re-solved around it, without a full solve;
- a lamp added, deleted, hidden from or shown to renders (its object, a collection, the view
  layer) is followed the same way (``_watch``: the depsgraph's updates do not name what is gone);
- the camera-view target painted in the Image Editor, its image replaced, the camera moved, Use
  in Solve switched: read again (``_view_read``) and answered as a stroke on the prepared model
  (its rows made again for the new pixels; a stroke elsewhere keeps them: engine.targets.view);
- a change the prepared state cannot follow (a mesh moved or edited, its modifiers, a material,
  the World, options, the scene's patch size; faces
  forbidden or allowed, an object's "no lights" or "work plane" switch; an exported object
  deleted or hidden from renders, or a mesh shown to them)
  pauses Live with the reason naming the object, the scene as last written, until Solve & Reduce
  prepares again;
- Undo and Redo (Blender reads the scene back): the exported objects found again by name (Live
  follows the scene as reverted, its geometry checked), or Live pauses naming the one that is
  gone; what paused Live on an object is looked at again (an undone deletion resumes it);
- ``stop()`` (the toggle, ESC, another file): a re-solve running is asked to stop and its answer
  dropped; the scene keeps the last answer written, whole.
"""
from __future__ import annotations

import hashlib
import threading
import time
from dataclasses import replace

import bpy
import numpy as np

from . import camera_view, export, lamp_state, light_paths, meshes, preparation, results, visibility
from .lamps import export_lamps
from .layers import MAX_PATCH_SIZE_PROP, scene_settings, work_plane
from ..engine.blas_threads import one_blas_thread
from ..engine.by_content import digest
from ..pipeline import jobs
from ..pipeline.prepared import REFINE_STEPS, scene_lamps_differ

__all__ = ["LiveSession", "SESSIONS", "TICK", "session", "start", "stop", "status_parts", "status_text"]

#: scene name -> LiveSession (at most one per scene)
SESSIONS = {}
#: seconds between two ticks (the modal operator's timer): how soon a finished answer is written
#: (an idle tick holds the main thread 0.1 ms on the 22k-triangle living room)
TICK = 0.01
#: while a brush stroke runs (a modal operator of these prefixes: Vertex Paint's, Sculpt's Paint
#: brush, ...), nothing is read (each read holds the main thread, 19 ms on the 22k-triangle living
#: room); it is read at the first tick after the stroke
STROKE_OPERATORS = ("PAINT_OT_", "SCULPT_OT_")
#: seconds without a depsgraph update before the paint is read where Blender cannot list the modal
#: operators running (the brush at rest: a stroke ended, or paused)
QUIET = 0.04
#: seconds after a stroke's quick answer is written before its later answers start (the artist has
#: paused): a stroke that comes sooner finds the worker idle. Started at once, a later answer that
#: the next stroke cancelled held that stroke 35-50 ms and shared the two CPUs with its solve
#: (130-147 against 70-94 ms: its LAPACK calls end in the background), on the 22k living room
LATER_PAUSE = 0.3


class LiveSession:
    def __init__(self, context, options_fn, show_fn):
        self.scene = context.scene.name
        self.options_fn = options_fn  # settings (scene.relight) -> JobOptions: the sidebar's
        self.show_fn = show_fn  # (context, job, outcome, finished=, trusted=, show=, packed=): ui.operators.show_solve
        self.dirty = True
        self.last_change = 0.0  # time.monotonic() of the last depsgraph update
        self.paint = None  # _paint_of the faces last read
        self.shown = None  # the paint of the answer in the scene
        self.worker = None
        self.result = {}
        self.cancel = threading.Event()
        self.solving = None  # the paint the worker solves
        self.updates = 0
        self.superseded = 0
        self.last_update = None  # time.strftime of the last answer written
        self.last_seconds = None  # its solve (worker) and write (main thread) seconds
        self.status = "starting"
        self.paused = None  # why Live waits for Solve & Reduce
        self.base = None  # the preparation.PREPARED_JOBS job re-solved from
        self.geometry = None  # _geometry_digest of its objects
        self.changed = set()  # what changed that the prepared state cannot follow (the depsgraph's)
        self.touched = set()  # ("OBJECT" | "MESH", name): what the depsgraph updated since the last read
        self.touched_all = True  # (read every object: the first read, or updates that do not say what)
        self.lamps_moved = set()  # the lamps whose placement or settings changed (followed, not paused)
        self.lamps = None  # the scene's lamps as the next re-solve takes them (None: as prepared)
        self._faces = None
        self.view_setting = None  # _view_setting of the scene at the last read
        self.target_scale = None  # the scene's target scale the paint is read with (followed: a new one reads it all)
        self.exported = {}  # name -> as_pointer() of the base's exported objects (the deletion watch)
        self.watched = None  # (_watched: the meshes and lamps a render shows) when the base was taken
        self.reloaded = False  # Undo or Redo read the scene back since the last read
        self.prepared = None  # the job of Live's first answer (a solve of the scene as it was turned on)
        self.prewarm_seconds = None  # the transfer to every patch and the check's products: their time (before the first stroke)
        self.to_refine = None  # (job, the answer shown, its paint, the step): a stroke's next answer
        self.refine_at = 0.0  # time.monotonic() from which it may start (LATER_PAUSE after a quick answer)
        self.refined = 0  # a stroke's later answers written (better than the one shown: REFINE_STEPS)
        self.kept_quick = 0  # ... not written (not better: the one shown stands)

    # -- main thread ---------------------------------------------------------------------
    def tick(self, context) -> None:
        """Collect a finished answer, read the paint when Blender reported a change, start the
        next re-solve (main thread)."""
        if self.dirty and stroke_running(context, self.last_change):
            return  # (the brush is painting: nothing is read or written until the stroke ends)
        if self.worker is not None and not self.worker.is_alive():
            self._collect(context)
        job = preparation.PREPARED_JOBS.get(self.scene)
        state = preparation.PREPARED.get(self.scene)
        if self.prepared is None or job is None or state is None or state.model is None:
            # Live's first answer is a solve of the scene as it is now (from the session's prepared
            # state when it still serves: preparation.SolveJob.run), its model the one strokes follow
            if self.worker is None and (self.dirty or not self.paused):  # (paused: retried on a change)
                self.dirty = False
                self._start_full(context)
            return
        if job is not self.base:  # a new preparation: Live's first solve, or Solve & Reduce
            if self.worker is None:  # (a stroke's full solve: collected first)
                self._follow(context, job, state)
            return
        if self.reloaded and self.changed:  # Undo or Redo: what the watch and the digests tell anew is read again
            undone = {c for c in self.changed if not c.startswith("object ")}
            if undone != self.changed:
                self.changed, self.dirty = undone, True
                if not undone:
                    self.paused, self.status = None, "up to date"
        if not self.changed and self.options_fn(context.scene.relight).to_dict() != state.options.to_dict():
            self.changed.add("the options changed")
        if not self.changed:
            self._scene_settings(context.scene, job)
        if self.changed:
            self.paused = f"{', '.join(sorted(self.changed))}: Solve & Reduce prepares again"
            self.status = "paused"
            self.to_refine = None
            if self.worker is not None and self.result.get("refining"):
                self.cancel.set()  # (a stroke's later answer: of a scene that changed)
            return
        if self.dirty:
            self._read_paint(context, job)  # (and the watch: what was deleted, hidden, added)
            if self.changed:
                return
        if self.lamps_moved and self.worker is None:  # the scene's lamps read again: re-solved around them
            self.lamps_moved = set()
            lamps, _ = export_lamps(context, visibility.render_visible_objects(context), visibility.owner_of)
            self.lamps = lamps
            self.shown = None  # the answer shown is of the lamps before
            if self._faces is not None:
                self._faces = replace(self._faces, lamps=lamps)
        if self.worker is not None and self.result.get("refining") and not _same(self.paint, self.solving):
            self.cancel.set()  # (a newer stroke: its quick answer first)
        if self.worker is not None or self.paused or self.paint is None:
            return
        if self.shown is not None and _same(self.paint, self.shown):
            if self.to_refine is not None and self.to_refine[0] is job and _same(self.to_refine[2], self.paint):
                if time.monotonic() >= self.refine_at:
                    self._start_refine(state, *self.to_refine)  # (the stroke's next, better answer)
            elif self.status != "up to date":
                self.status = "up to date"
            return
        self._start_live(job, state, self._faces)

    def _follow(self, context, job, state) -> None:
        """A new preparation (Live's first solve, or Solve & Reduce): its objects watched, and what
        every stroke reads made in the worker before the first (PreparedScene.prepare_live)."""
        self.base, self.changed, self.paused, self.dirty = job, set(), None, True
        self._faces, self.touched_all = None, True
        names = job.exp.faces.object_names[:len(job.exp.objects)]
        gone = _gone(context, names, job.exp.objects)
        if gone:  # (deleted while the first solve ran)
            self.changed.update(gone)
            return
        self.exported = {n: ob.as_pointer() for n, ob in zip(names, job.exp.objects)}
        self.target_scale = job.exp.settings["target_scale"]
        self.watched = _watched(context)
        self.geometry = _geometry_digest(job.exp.objects)
        self.status = "preparing the transfer to every patch"
        faces = job.exp.faces
        settings = light_paths.snapshot(bpy.data.scenes[self.scene])  # (the strokes' light-paths check)

        def prewarm():  # what every stroke reads, made before the first (PreparedScene.prepare_live)
            t0 = time.perf_counter()
            state.prepare_live(faces)
            light_paths.prepare_stroke_checks(state.column_products(), settings, state.patches.reflectance,
                                              state.model.problem.background_radiosity)
            self.prewarm_seconds = time.perf_counter() - t0

        self._run(prewarm, job)
        self.result["prewarm"] = True

    def _scene_settings(self, scene, job) -> None:
        """The scene's Relight settings (each tick): a new target scale is followed (every object's
        paint read again with it), a new patch size (the model's) added to ``changed``, the view
        target's settings changed read at once (``_view_read``)."""
        settings = scene_settings(scene)
        if settings["max_patch_size"] != job.exp.settings["max_patch_size"]:
            self.changed.add(f"the patch size ({MAX_PATCH_SIZE_PROP}) changed")
        elif settings["target_scale"] != self.target_scale:
            self.target_scale, self.dirty, self.touched_all = settings["target_scale"], True, True
        elif _view_setting(scene) != self.view_setting:  # (a property set by a script: no depsgraph update)
            self.dirty = True

    def _view_read(self, context, job, touched, every):
        """The scene's view target (its image, the camera, the working resolution, Use in Solve, the
        render's size and view transform: camera_view.scene_view_target) for the next answer: the
        one read before unless an image, a camera or the scene camera's object was updated or its
        settings changed (Live's own writes update the scene at every answer: a large reference
        image read then would stall the brush), and the one read before when the same (its rows are
        kept by the prepared model's strokes: engine.targets.view, ``serves``). A view target that
        cannot be read (its image gone unreadable) adds to ``changed``, said."""
        scene = context.scene
        setting = _view_setting(scene)
        was = (self._faces or job.exp.faces).view_target
        camera = scene.camera
        look = every or setting != self.view_setting or any(kind in _VIEW_KINDS for kind, _ in touched) \
            or (camera is not None and ("OBJECT", camera.name) in touched)
        self.view_setting = setting
        if not look or (setting is None and was is None):
            return was
        try:
            now = camera_view.scene_view_target(scene)
        except ValueError as exc:  # (SceneError too: the user's image or camera, a message naming it)
            self.changed.add(f"the view target cannot be read ({exc})")
            return was
        if (now is None and was is None) or (now is not None and was is not None and digest(now) == digest(was)):
            return was
        return now

    def _read_paint(self, context, job) -> None:
        """The paint read again (Blender reported a change): ``paint`` and ``_faces``; a mesh that
        moved or was edited, deleted, hidden from or shown to renders is added to ``changed`` (the
        prepared state cannot follow it)."""
        self.dirty = False
        self._watch(context, job)
        if self.changed:
            return
        # only the objects the depsgraph updated are read again and digested (a stroke's: a
        # million-triangle scene's every mesh took 0.17 s of the main thread each tick)
        touched, every = self.touched, self.touched_all or self._faces is None
        self.touched, self.touched_all = set(), False
        view = self._view_read(context, job, touched, every)
        if self.changed:
            return
        objs = [ob for ob in job.exp.objects
                if every or ("OBJECT", ob.name) in touched or ("MESH", ob.data.name) in touched]
        faces = export.repaint(job.exp, None if every else {ob.name for ob in objs},
                               None if every else self._faces, self.target_scale)  # (in Edit Mode: its edit mesh first)
        if self.lamps is not None:
            faces = replace(faces, lamps=self.lamps)
        if faces.view_target is not view:  # (painted in the Image Editor, the camera moved: followed)
            faces = replace(faces, view_target=view)
        now = _geometry_digest(objs)
        moved = sorted(name for name in now if now[name] != self.geometry.get(name))
        if moved:
            self.changed.update(f"object {name!r} moved or edited" for name in moved)
            return
        forbid = np.unique(faces.face_object[faces.forbidden != job.exp.faces.forbidden])
        if len(forbid):  # (the lights the model offers change: Forbid or Allow, the no-lights switch)
            self.changed.update(f"object {faces.object_names[o]!r}: faces forbidden or allowed" for o in forbid)
            return
        planes = set() if faces.passes is None else {faces.object_names[o] for o in np.unique(
            faces.face_object[faces.passes])}
        switched = sorted(ob.name for ob in objs if work_plane(ob) != (ob.name in planes))
        if switched:  # (its faces pass light or reflect it: the model's)
            self.changed.update(f"object {name!r}: its work plane switch changed" for name in switched)
            return
        self._faces = faces
        if self.paint is None or not _same(_paint_of(faces), self.paint):
            self.paint = _paint_of(faces)

    def _watch(self, context, job) -> None:
        """What the depsgraph's updates do not say object by object: an exported object deleted
        (or, after Undo or Redo, not the same object any more), hidden from renders (its own
        ``hide_render``, a collection's, the view layer's), a mesh shown to them (added, or shown
        again): into ``changed``; the lamps a render shows, added, deleted, hidden or shown: into
        ``lamps_moved`` (re-read and followed). After Undo or Redo, the exported objects that are
        still the same are found again by name (the scene read back: Blender's Python objects of
        the ones before may be stale; one deleted and brought back by Undo is another data-block)."""
        names = list(self.exported)
        if self.reloaded:
            self.reloaded, self.shown, self.touched_all = False, None, True  # (the answer shown may be undone)
            self.lamps_moved.add("(Undo)")
            found = [bpy.data.objects.get(n) for n in names]
            gone = [f"object {n!r} deleted" if ob is None else f"object {n!r} replaced"
                    for n, ob in zip(names, found) if ob is None or ob.type != "MESH"]
            if gone:
                self.changed.update(gone)
                return
            # the objects of those names (Undo reads back at another address what it deleted or
            # changed): followed, the geometry digest (every object, at this read) says whether
            # they are still the ones prepared
            job.exp.objects[:] = found
            self.exported = {n: ob.as_pointer() for n, ob in zip(names, found)}
        gone = _gone(context, names, job.exp.objects, self.exported)
        if gone:
            self.changed.update(gone)
            return
        meshes, lamps = _watched(context)
        was_meshes, was_lamps = self.watched
        self.changed.update(f"object {n!r} hidden from renders" for n in was_meshes - meshes if n in names)
        self.changed.update(f"object {n!r} deleted or hidden from renders" for n in was_meshes - meshes
                            if n not in names)
        self.changed.update(f"object {n!r} added or shown in renders" for n in meshes - was_meshes)
        if lamps != was_lamps:  # (their placement and settings: the depsgraph's updates, _on_depsgraph)
            self.lamps_moved.update(n for n, _ in lamps ^ was_lamps)
            self.watched = (was_meshes, lamps)

    def _start_live(self, job, state, faces):
        self.solving = self.paint
        self.status = "solving"
        settings = light_paths.snapshot(bpy.data.scenes[self.scene])  # the worker finishes the report

        def work():
            t0 = time.perf_counter()
            # only the paint (and the lamps, read again) differs from the export the state was
            # prepared from (export.repaint; the rest is watched on the main thread)
            if faces.lamps is not state.model.faces.lamps and scene_lamps_differ(faces, state.model.faces):
                state.move_lamps(faces)  # the kept model's fixed light anew: their light, on the kept scene
            out = state.live(faces, job.inputs["polygon_counts"], cancel=self.cancel.is_set,
                             notes=job.inputs["notes"], key=state.key)
            self.result["quick"] = out  # (its second answer, refine_live, comes after it is shown)
            if out is None:  # lx on clustered faces: the full solve, from the state (meshed for the paint)
                full = preparation.SolveJob(replace(job.exp, faces=faces), job.options, job.mode, job.inputs,
                                            session=job.session)
                out = full.run(cancel=self.cancel.is_set)
                self.result["job"] = full
            with one_blas_thread():  # (the light paths' check: small products too)
                self.result["job"].finish(None, out, view_radiance=False, settings=settings,
                                          products=state.column_products())
            self.result["finished"] = True
            # (packed here: the main thread's write is the scene's alone; ValueError is said as any error)
            self.result["packed"] = results.packed_result(out, self.result["job"].exp.fingerprints)
            self.result["seconds"] = time.perf_counter() - t0
            return out

        self._run(work, job)

    def _start_refine(self, state, job, best, paint, step):
        """A stroke's next answer (prepared.REFINE_STEPS), once the one before is shown and no newer
        paint waits (PreparedScene.refine_live: the selection's full search and the lamps refined
        for the stroke's targets, then the warm solve); written when better than the answer shown,
        dropped when a newer stroke comes."""
        self.to_refine = None
        self.solving = paint
        self.status = f"improving the answer ({REFINE_STEPS[step]})"
        settings = light_paths.snapshot(bpy.data.scenes[self.scene])

        def work():
            t0 = time.perf_counter()
            out = state.refine_live(best, step, job.inputs["polygon_counts"], cancel=self.cancel.is_set)
            if out is None:
                return None
            with one_blas_thread():
                job.finish(None, out, view_radiance=False, settings=settings, products=state.column_products())
            self.result["finished"] = True
            self.result["packed"] = results.packed_result(out, job.exp.fingerprints)
            self.result["seconds"] = time.perf_counter() - t0
            return out

        self._run(work, job)
        self.result["refining"] = (best, step)

    def _start_full(self, context):
        """The first solve of the session (no prepared model): export and solve in full."""
        try:
            job = preparation.SolveJob.export(context, self.options_fn(context.scene.relight), session=True,
                                              view_target=camera_view.scene_view_target(context.scene))
        except Exception as exc:  # noqa: BLE001  (SceneError, ValueError: the user's message)
            self.paused = f"{exc}"
            self.status = "paused"
            return
        self.paint = _paint_of(job.exp.faces)
        self.solving = self.paint
        self.status = "preparing (a full solve)"
        self._run(lambda: self._predicted(job.run(cancel=self.cancel.is_set)), job)
        self.result["first"] = True

    def _predicted(self, outcome):
        """A full solve's outcome with its view target's report block and camera image (in the worker)."""
        camera_view.predict_view(outcome, cancel=self.cancel.is_set)
        return outcome

    def _run(self, fn, job):
        self.result = {"job": job}
        self.cancel = threading.Event()

        def work():
            try:
                with preparation.LOCKS[self.scene]:  # (one solve at a time on the scene's state)
                    self.result["outcome"] = fn()
            except BaseException as exc:  # noqa: BLE001  (reported on the main thread)
                self.result["error"] = exc

        self.worker = threading.Thread(target=work, daemon=True)
        self.worker.start()

    def _collect(self, context):
        """The worker's answer into the scene, when its paint is still the newest (main thread)."""
        self.worker, result, solving = None, self.result, self.solving
        if result.get("refining") and (isinstance(result.get("error"), jobs.Cancelled) or self.changed
                                       or ("error" not in result and result.get("outcome") is None)):
            self.status = "paused" if self.changed else "up to date"
            if "error" not in result and not self.changed:  # not better: the answer shown stands, the next step follows
                self.kept_quick += 1
                self._next_step(result["refining"][0], result["refining"][1], solving)
            return  # (or cancelled: a newer stroke)
        if "error" in result:
            exc = result["error"]
            self.status = "paused"
            self.paused = None if isinstance(exc, jobs.Cancelled) else f"{exc}"
            return
        if result.get("prewarm"):
            self.status = "ready"
            return
        outcome = result.get("outcome")
        if outcome is None:  # the state could not follow: say why, wait for Solve & Reduce
            state = preparation.PREPARED.get(self.scene)
            self.paused = f"{state.reason if state else 'nothing prepared'}: Solve & Reduce prepares again"
            self.status = "paused"
            return
        if result.get("first"):
            self.prepared = result["job"]
        if self.dirty and self.base is not None and self.base is preparation.PREPARED_JOBS.get(self.scene):
            self._read_paint(context, self.base)  # (a change since the last read: is this answer's paint still the newest?)
            if self.changed:
                return  # (the scene moved on: the next tick pauses and says why)
        if (self.paint is not None and not _same(solving, self.paint)) or self.lamps_moved:
            self.superseded += 1  # a newer stroke, or the lamps changed: its re-solve comes next
            return
        t0 = time.perf_counter()
        mode = None
        painting = context.mode == "PAINT_VERTEX"
        # while painting, the brush keeps its layer (the radiosity layer is written, not made active)
        layers = {ob.name: ob.data.color_attributes.active_color_name for ob in context.scene.objects
                  if painting and ob.type == "MESH" and ob.data is not None}
        if context.mode == "EDIT_MESH":  # the meshes are written in Object Mode (Fill Selected)
            mode = context.object.mode
            bpy.ops.object.mode_set(mode="OBJECT")
        try:
            # the meshes are the exported ones (the geometry digest, checked at every change)
            self.show_fn(context, result["job"], outcome, finished=result.get("finished", False),
                         trusted=self.base is not None, show=not painting, packed=result.get("packed"))
            for name, layer in layers.items():
                colors = bpy.data.objects[name].data.color_attributes
                if layer and layer in colors and colors.active_color_name != layer:
                    colors.active_color = colors[layer]
        except Exception as exc:  # noqa: BLE001  (SceneError, ValueError: the scene is unchanged)
            self.paused, self.status = f"{exc}", "paused"
            return
        finally:
            if mode is not None:
                bpy.ops.object.mode_set(mode=mode)
        # the depsgraph takes the write now, and what it updated is forgotten: it is Relight's own
        # (the radiosity layer on every mesh; digesting them all again took 0.24 s of the main
        # thread at the next tick on the 1M-triangle room), nothing else ran meanwhile
        touched, every = set(self.touched), self.touched_all
        context.view_layer.update()
        self.touched, self.touched_all = touched, every
        self.shown = solving
        if result.get("refining"):
            self.refined += 1
            self._next_step(outcome, result["refining"][1], solving)
        else:
            self.updates += 1
            quick = result.get("quick")
            self.to_refine = None if quick is None else (self.base, quick, solving, 0)
            self.refine_at = time.monotonic() + LATER_PAUSE
        self.last_update = time.strftime("%H:%M:%S")
        self.last_seconds = (result.get("seconds", outcome.report["timings_s"]["total"]), time.perf_counter() - t0)
        self.status = "up to date"

    def _next_step(self, best, step, paint) -> None:
        """The stroke's answer after step ``step`` (``best``: the answer shown), if any."""
        self.to_refine = (self.base, best, paint, step + 1) if step + 1 < len(REFINE_STEPS) else None

    def stop(self):
        """Ask a running re-solve to stop; its answer is never written (the scene keeps the last)."""
        self.cancel.set()
        self.status = "off"


def _geometry_digest(objects) -> dict:
    """{object name: digest} of the exported objects' evaluated meshes (vertex positions and
    polygon loops, after their modifiers and shape keys: the export's) and placement: what a
    stroke never changes."""
    out = {}
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for ob in objects:
        h = hashlib.sha256()  # (in memory only: best_lights._digest's choice)
        ob_eval = ob.evaluated_get(depsgraph)
        editing = ob.mode == "EDIT"  # (its evaluated mesh wraps the edit mesh: converted to read it)
        me = ob_eval.to_mesh() if editing else ob_eval.data
        try:
            co = meshes.foreach_array(me.vertices, "co", len(me.vertices), np.float32, 3)
            loops = meshes.foreach_array(me.loops, "vertex_index", len(me.loops), np.int32)
        finally:
            if editing:
                ob_eval.to_mesh_clear()
        h.update(co.tobytes())
        h.update(loops.tobytes())
        h.update(np.array(ob.matrix_world, dtype=np.float32).tobytes())
        out[ob.name] = h.hexdigest()
    return out


def _gone(context, names, objects, pointers=None) -> list:
    """The exported objects (``names``, their bpy ``objects``) deleted since: no longer in
    bpy.data, not the same data-block (``pointers``: name -> as_pointer()), or no longer linked to
    the scene, each as the pause names it. Never touches a removed object's Python object."""
    out = []
    scene_objects = context.scene.objects
    for name, ob in zip(names, objects):
        now = bpy.data.objects.get(name)
        try:
            same = now is not None and now.as_pointer() == (ob.as_pointer() if pointers is None else pointers[name])
        except ReferenceError:  # (its Python object: removed with it)
            same = False
        if not same or scene_objects.get(name) is None:
            out.append(f"object {name!r} deleted")
    return out


def _watched(context) -> tuple:
    """(meshes, lamps) a render of the view layer shows, the user's (not Relight's results):
    the meshes' names (visibility.exported_objects); the lamps' (name, data-block address) pairs,
    hidden from renders as lamps.export_lamps reads it (a lamp a shown reduction turned off: as
    the user set it)."""
    renderable = visibility.render_visible_objects(context)
    meshes = {ob.name for ob in visibility.exported_objects(context)}
    lamps = set()
    for ob in context.scene.objects:
        if ob.type == "LIGHT" and ob.name in renderable and visibility.owner_of(ob) is None:
            was = lamp_state.before(ob)
            if not (ob.hide_render if was is None else was["hide_render"]):
                lamps.add((ob.name, ob.as_pointer()))
    return meshes, lamps


def stroke_running(context, last_change: float) -> bool:
    """Whether a brush stroke may still be painting: a modal operator of STROKE_OPERATORS runs in
    a window; where Blender cannot say (no ``Window.modal_operators``), a depsgraph update less
    than QUIET seconds ago (``last_change``: time.monotonic()). Headless, no stroke runs."""
    wm = getattr(context, "window_manager", None)
    for win in getattr(wm, "windows", ()):
        ops = getattr(win, "modal_operators", None)
        if ops is None:
            return time.monotonic() - last_change < QUIET
        if any(op.bl_idname.startswith(STROKE_OPERATORS) for op in ops):
            return True
    return False


def _paint_of(faces) -> tuple:
    """What Live answers for: (target, radiosity, the view target (its spec, read anew only when it
    changed: compared as the same object))."""
    return faces.target, faces.target_radiosity, faces.view_target


def _same(a, b) -> bool:
    return a is not None and b is not None and np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) \
        and a[2] is b[2]


def session(scene) -> LiveSession | None:
    return SESSIONS.get(scene.name)


def start(context, options_fn, show_fn) -> LiveSession:
    """Live on for the context's scene: its session (a new one, or the one running)."""
    s = SESSIONS.get(context.scene.name)
    if s is None:
        s = SESSIONS[context.scene.name] = LiveSession(context, options_fn, show_fn)
    for handlers, fn in _handlers():
        if fn not in handlers:
            handlers.append(fn)
    return s


def stop(scene_name=None) -> None:
    """Live off for a scene (every scene: None)."""
    for name in [scene_name] if scene_name else list(SESSIONS):
        s = SESSIONS.pop(name, None)
        if s is not None:
            s.stop()
    for handlers, fn in _handlers() if not SESSIONS else ():
        if fn in handlers:
            handlers.remove(fn)


def _handlers():
    h = bpy.app.handlers
    return [(h.depsgraph_update_post, _on_depsgraph), (h.undo_post, _on_undo), (h.redo_post, _on_undo)]


def _on_undo(scene, _arg=None):
    """Undo or Redo read the scene back: every session's exported objects are found again by name
    at its next tick (LiveSession._watch)."""
    for s in SESSIONS.values():
        s.reloaded, s.dirty, s.touched_all = True, True, True


#: the data-blocks a view target is read from besides the scene camera's object and the scene's
#: settings (an update of one reads it again: LiveSession._view_read)
_VIEW_KINDS = ("Image", "Camera")


def _view_setting(scene):
    """What a view target reads from the scene besides its image's pixels and the camera's placement
    and lens (None: no view target used): the image, the working resolution, the scene camera,
    the render's size and the view transform (a PNG's pixels are read through it)."""
    props = getattr(scene, "relight_camera_target", None)
    if props is None or props.image is None or not props.use:
        return None
    r, v = scene.render, scene.view_settings
    return (props.image.as_pointer(), props.resolution, None if scene.camera is None else scene.camera.as_pointer(),
            r.resolution_x, r.resolution_y, r.resolution_percentage, r.pixel_aspect_x, r.pixel_aspect_y,
            v.view_transform, v.look, v.exposure, v.gamma)


#: what the prepared state depends on besides the meshes, by data-block type, as the pause names it
_WATCHED = {"Material": "material", "World": "the World"}  # (lamps and objects: by their bpy type)


def _on_depsgraph(scene, depsgraph=None):
    """Blender changed something: read the paint again at the next tick; a material or the World
    the user changed (not Relight's own results) is named, a lamp moved or set anew followed."""
    s = SESSIONS.get(scene.name)
    if s is None:
        return
    s.dirty, s.last_change = True, time.monotonic()
    if depsgraph is None:
        s.touched_all = True
    for u in getattr(depsgraph, "updates", ()):
        idb = getattr(u.id, "original", u.id)
        if isinstance(idb, bpy.types.Mesh):
            s.touched.add(("MESH", idb.name))
        elif isinstance(idb, bpy.types.Object):
            s.touched.add(("OBJECT", idb.name))
        elif type(idb).__name__ in _VIEW_KINDS:  # (what the view target is read from)
            s.touched.add((type(idb).__name__, idb.name))
        kind = ("object" if isinstance(idb, bpy.types.Object) else "lamp" if isinstance(idb, bpy.types.Light)
                else _WATCHED.get(type(idb).__name__))
        if kind is None or visibility.owner_of(idb) is not None:
            continue
        # (a mesh's placement is in the geometry digest: a mode switch also flags its transform)
        if kind == "object" and not (u.is_updated_transform and idb.type == "LIGHT"):
            continue
        if kind == "material" and not u.is_updated_shading:
            continue
        if kind == "lamp" or (kind == "object" and idb.type == "LIGHT"):
            s.lamps_moved.add(idb.name)  # (a kept lamp moved or resized: Live follows it)
            continue
        s.changed.add(f"{kind} {idb.name!r} changed" if kind != "the World" else "the World changed")


def status_parts(s: LiveSession) -> list[str]:
    """What Live is doing, then the time and cost of the last update: the sidebar's lines, each
    wrapped on its own (panels.draw_live), and, joined, the status bar's and the report's line."""
    if s.paused:
        return [f"Live paused: {s.paused}"]
    parts = [f"Live: {s.status}"]
    if s.last_update:
        solve, write = s.last_seconds
        better = f", {s.refined} improved later" if s.refined else ""
        parts.append(f"updated {s.last_update} ({solve:.2f} s solve, {write:.2f} s write, "
                     f"{s.updates} update(s){better})")
    return parts


def status_text(s: LiveSession) -> str:
    """The status in one line (the status bar's, an operator's report, the tests')."""
    return "; ".join(status_parts(s))
