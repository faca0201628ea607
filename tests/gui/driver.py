"""Drives the Relight add-on in a real Blender window, as an artist would (not a pytest module).

Run by tools/gui_test.py inside the Debian trixie chroot (Blender 4.3.2 under Xvfb):

    blender -p 0 0 1600 1000 staircase_targets.blend --python driver.py -- OUT_DIR

The extension is already installed in that Blender's user directory (tests/gui/prep.py, with
Preferences > Install from Disk's operator). Every step is a ``bpy.app.timers`` tick of one
generator; buttons are found by hovering them and pressing Ctrl+C (Blender copies an operator
button's Python command), then pressed with real xdotool clicks. Screenshots come from outside
Blender (ImageMagick ``import``). A heartbeat timer measures whether the UI stays responsive.

Checks are printed as ``GUI-CHECK <status> <name>: <detail>`` and written to OUT_DIR/result.json;
Blender exits with os._exit(0) when every check passed (xfail allowed), 1 otherwise.
"""
import json
import math
import os
import subprocess
import sys
import time
import traceback

import bmesh
import bpy
import numpy as np

ARGS = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
OUT = ARGS[0] if ARGS else "/tmp/relight-gui"
PKG = "bl_ext.user_default.relight"
SENTINEL = "<relight-gui-probe>"
PAUSE_LIMIT = 2.5  # s: the longest main-thread pause allowed while a solve runs or cancels

RESULT = {"checks": [], "shots": [], "timings": {}, "blender": bpy.app.version_string}
BEAT = []
T0 = time.monotonic()


def log(*a):
    print("GUI-LOG", *a, flush=True)


def check(name, ok, detail="", xfail=None):
    ok = bool(ok)
    status = ("XPASS" if xfail else "pass") if ok else ("xfail" if xfail else "FAIL")
    RESULT["checks"].append({"name": name, "status": status, "detail": str(detail)[:800], "xfail": xfail})
    print(f"GUI-CHECK {status} {name}: {detail}", flush=True)
    return ok


# --- windows, regions, coordinates -------------------------------------------------------

def window():
    return bpy.context.window_manager.windows[0]


def area3d():
    return next(a for a in window().screen.areas if a.type == "VIEW_3D")


def region(kind, area=None):
    return next(r for r in (area or area3d()).regions if r.type == kind)


def screen_h():
    return window().height


def to_screen(reg, rx, ry):
    """Region pixel (from its bottom-left) -> X screen pixel (from the top-left)."""
    win = window()
    return int(win.x + reg.x + rx), int(screen_h() - (win.y + reg.y + ry))


def to_region(reg, sx, sy):
    win = window()
    return sx - win.x - reg.x, (screen_h() - sy) - win.y - reg.y


def override():
    a = area3d()
    return bpy.context.temp_override(window=window(), area=a, region=region("WINDOW", a))


def mods():
    return {k: sys.modules[f"{PKG}.{k}"] for k in ("blender.results", "blender.ui.panels", "blender.ui.operators",
                                                   "blender.ui.viewport", "blender.layers", "blender.live",
                                                   "blender.preparation", "pipeline.notes")}


# --- input ----------------------------------------------------------------------------------

def xdo(*args):
    subprocess.run(["xdotool", *map(str, args)], check=True, timeout=30)


def move(x, y):
    xdo("mousemove", int(x), int(y))


def shot(name, wait=True):
    path = os.path.join(OUT, name + ".png")
    proc = subprocess.Popen(["import", "-window", "root", path])
    if wait:
        proc.wait(timeout=60)
    RESULT["shots"].append(name)
    return path


def viewport_center():
    a = area3d()
    r = region("WINDOW", a)
    ui = region("UI", a)
    return to_screen(r, (ui.x - r.x) // 2, r.height // 2)


def edit_faces(ob, faces):
    """Tab (in the viewport) into Edit Mode on the active ``ob`` (mode_set when the key did not
    take), face select mode, exactly ``faces`` selected. Returns whether Tab entered Edit Mode."""
    yield from key_in_viewport("Tab")
    tabbed = bpy.context.mode == "EDIT_MESH"
    if not tabbed:
        with override():
            bpy.ops.object.mode_set(mode="EDIT")
        yield 1.0
    with override():
        bpy.ops.mesh.select_mode(type="FACE")
    edit_select(ob, faces)
    return tabbed


def key_in_viewport(key):
    move(*viewport_center())
    yield 0.4
    xdo("key", key)
    yield 1.0


def click(x, y, settle=1.0):
    move(x, y)
    yield 0.5
    xdo("click", "1")
    yield settle


# --- finding buttons: hover + Ctrl+C, positions kept in the sidebar's view coordinates ----------

def ui_region():
    return region("UI")


def hover_copy(sx, sy, wait=0.15):
    wm = bpy.context.window_manager
    wm.clipboard = SENTINEL
    move(sx, sy)
    xdo("key", "ctrl+c")
    yield wait
    got = wm.clipboard
    return None if got == SENTINEL else got


def scroll_sidebar(notches):
    """Scroll the sidebar (positive = down) by what its mouse wheel runs, View2D's scroll
    operators (one step a notch), called on the region itself: a wheel turned over a list (the
    Results' rows, wherever the layout puts them under the mouse) scrolls the list instead."""
    a = area3d()
    if notches:
        step = bpy.ops.view2d.scroll_down if notches > 0 else bpy.ops.view2d.scroll_up
        with bpy.context.temp_override(window=window(), area=a, region=region("UI", a)):
            for _ in range(abs(notches)):
                step()
    # Blender redraws the sidebar (software OpenGL) for each notch: wait until it has settled
    last, still = None, 0
    for _ in range(40):
        yield 0.25
        top = ui_region().view2d.region_to_view(0, 0)[1]
        still = still + 1 if last is not None and abs(top - last) < 0.5 else 0
        last = top
        if still >= 2:
            break


def probe_page(hits):
    """Probe the visible sidebar every 10 px: a column at 30 % of the width, and at 75 % on rows
    where the first column found a button (rows of two buttons), 4 px off when it misses."""
    r = ui_region()
    v2d = r.view2d
    inner = r.width - 40
    rows = []
    for ry in range(r.height - 6, 6, -10):
        sx, sy = to_screen(r, 10 + 0.30 * inner, ry)
        got = yield from hover_copy(sx, sy)
        if got:
            rows.append(ry)
            hits.setdefault(got, set()).add(tuple(round(v, 1) for v in v2d.region_to_view(10 + 0.30 * inner, ry)))
    for ry in rows:
        for dy in (0, -4, 4):  # a hover on a button's edge may not answer: 4 px above and below
            sx, sy = to_screen(r, 10 + 0.75 * inner, ry + dy)
            got = yield from hover_copy(sx, sy)
            if got:
                hits.setdefault(got, set()).add(
                    tuple(round(v, 1) for v in v2d.region_to_view(10 + 0.75 * inner, ry + dy)))
                break


#: every place where the last probe_sidebar found each button: {command: {(view x, view y)}}
LAST_HITS = {}

#: a page of the probe overlaps the previous one: it scrolls at most this fraction of the region
PAGE_OVERLAP = 0.8

#: where each button answered last, in view coordinates, of every probe: a probe for buttons known
#: starts at their page
PLACES = {}


def scroll_to(vy, lo, hi):
    """Scroll the sidebar until view y ``vy`` is at region y ``lo`` to ``hi``, or until the sidebar
    scrolls no further that way (at its top or bottom); the region y it ends at."""
    for _ in range(40):
        r = ui_region()
        ry = r.view2d.view_to_region(0, vy, clip=False)[1]
        if lo <= ry <= hi:
            break
        top = r.view2d.region_to_view(0, r.height)[1]
        far = abs(ry - r.height / 2) > r.height  # more than a region away: a page at a time
        yield from scroll_sidebar((3 if ry < lo else -3) * (4 if far else 1))
        for _ in range(24):  # a busy main thread (Live's worker) redraws the sidebar late: wait for it
            if abs(ui_region().view2d.region_to_view(0, r.height)[1] - top) >= 1:
                break
            yield 0.25
        else:
            log(f"the sidebar does not scroll towards view y {vy:.0f} (region y {ry:.0f} of {r.height})")
            break
    return ry


def probe_sidebar(max_pages=6, want=()):
    """Every copyable button of the sidebar: {python command or value: (view x, view y)} (the
    middle of the places where it answered), scrolling down page by page (each page scrolled by
    at most PAGE_OVERLAP of the region, so that no row falls between two pages). ``want``: the
    commands the caller presses next; the probe stops at the first page by which every one of
    them has answered (a page is 15-35 s of hovers: the probes were 1,088 s of the 1,394 s
    run when every probe read every page). When every one has a known place (PLACES) within half a region of the others, their
    page is probed first, from the topmost one in the region's upper half: the probe ends there if
    they all answer (a layout that moved them less than that), else it goes on from the top. A
    caller that checks what the sidebar shows, or that it does not show something, probes every
    page (no ``want``)."""
    t = time.monotonic()
    hits = {}
    known = [PLACES[w][1] for w in want if w in PLACES]
    if want and len(known) == len(want) and max(known) - min(known) < 0.45 * ui_region().height:
        h = ui_region().height
        yield from scroll_to(max(known), 0.5 * h, h - 60)
        yield from probe_page(hits)
    if not (want and all(w in hits for w in want)):
        yield from scroll_sidebar(-60)
        for page in range(max_pages):
            yield from probe_page(hits)
            if want and all(w in hits for w in want):
                break
            top = ui_region().view2d.region_to_view(0, 0)[1]
            yield from scroll_sidebar(30)
            moved = abs(ui_region().view2d.region_to_view(0, 0)[1] - top)
            if moved < 2:
                break  # the bottom of the sidebar is visible
            limit = PAGE_OVERLAP * ui_region().height
            if moved > limit:  # 30 notches scrolled past rows never probed: scroll back over them
                yield from scroll_sidebar(-int(math.ceil(30 * (moved - limit) / moved)))
    LAST_HITS.clear()
    LAST_HITS.update(hits)
    found = {}
    for k, pts in hits.items():
        x = min(p[0] for p in pts)  # the first column that answered
        ys = sorted((p[1] for p in pts if p[0] == x), reverse=True)
        # a button drawn twice (Match Cycles Light Paths: atop the Results and under a warning):
        # the topmost one's hits (10 px apart a probe), never the mean of both
        first = [ys[0]]
        for y in ys[1:]:
            if first[-1] - y > 14:
                break
            first.append(y)
        found[k] = (x, sum(first) / len(first))
    PLACES.update(found)
    RESULT["timings"].setdefault("probe_s", []).append(round(time.monotonic() - t, 1))
    log("probe found", json.dumps({k: [round(v[0]), round(v[1])] for k, v in found.items()}))
    return found


def press(found, command, settle=1.2, retries=2):
    """Scroll the button into view, check by hover that it is the one, click it. A button the
    probe missed (a hover whose copy came too late under load) is probed for again, twice."""
    if command not in found:
        if retries > 0:
            log(f"{command} not among the probed buttons: probing again")
            found.update((yield from probe_sidebar(want={command})))
            return (yield from press(found, command, settle, retries - 1))
        raise AssertionError(f"button {command} not found in the sidebar (probe saw {sorted(found)})")
    vx, vy = found[command]
    # (the probe may leave the sidebar at its bottom: the top buttons are ~2,000 px away; not under the
    # sticky panel header drawn atop a scrolled sidebar; at its top already, the hover below checks it)
    yield from scroll_to(vy, 20, ui_region().height - 60)
    r = ui_region()
    rx, ry = r.view2d.view_to_region(vx, vy, clip=False)
    if not 0 <= ry <= r.height:
        raise AssertionError(f"button {command} could not be scrolled into the sidebar (region y {ry:.0f})")
    sx, sy = to_screen(r, rx, ry)
    got = None
    for wait in (0.3, 0.6, 1.0, 2.0):  # (under load the copy may come late: nothing copied yet)
        got = yield from hover_copy(sx, sy, wait)
        if got == command:
            break
    if got != command:
        RESULT.setdefault("layout_moved", []).append(command)
        log(f"at the place of {command} (region {rx}, {ry}) the sidebar has {got!r}: probing again")
        if retries <= -3:  # (a few more probes than for a button not found at all, never forever)
            raise AssertionError(f"button {command} not where the probe found it (at its place: {got!r})")
        found.update((yield from probe_sidebar(want={command})))
        return (yield from press(found, command, settle, retries - 1))
    yield from click(sx, sy, settle)
    return sx, sy


PAUSES = []  # (seconds since start, pause, solve stage before -> after)
_STAGE = [None]


def heartbeat():
    now = time.monotonic()
    try:
        state = sys.modules[PKG + ".blender.ui.operators"].solve_state(bpy.context.scene)
        stage = None if state is None else f"{state['stage']} {state['fraction']:.2f}"
    except Exception:  # noqa: BLE001  (not loaded yet, or an older add-on)
        stage = None
    if BEAT and now - BEAT[-1] > 0.5:
        PAUSES.append((round(BEAT[-1] - T0, 2), round(now - BEAT[-1], 2), f"{_STAGE[0]} -> {stage}"))
    _STAGE[0] = stage
    BEAT.append(now)
    if len(BEAT) > 50000:
        del BEAT[:25000]
    return 0.05


def max_gap(t0, t1):
    ts = [t0] + [t for t in BEAT if t0 <= t <= t1] + [t1]
    return max(b - a for a, b in zip(ts[:-1], ts[1:]))


# --- scene state ---------------------------------------------------------------------------

def counts():
    return mods()["blender.ui.panels"]._counts(bpy.context)


def mesh_objects():
    return [o for o in bpy.context.scene.objects if o.type == "MESH"]


def set_active(obj):
    vl = bpy.context.view_layer
    for o in bpy.context.scene.objects:
        o.select_set(o == obj)
    vl.objects.active = obj


def edit_select(obj, faces):
    bm = bmesh.from_edit_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    for f in bm.faces:
        f.select_set(False)
    for k in faces:
        bm.faces[k].select_set(True)
    bm.select_flush_mode()
    bmesh.update_edit_mesh(obj.data)


def shading():
    s = area3d().spaces.active.shading
    return s.type, s.color_type


def relight_traces():
    """Relight's results left in the scene (what Clear must remove): the stored curve, anything
    carrying ``relight_owner`` (the emitters object, its mesh and material), radiosity layers."""
    out = []
    scene = bpy.context.scene
    if "relight_result" in scene.keys():
        out.append("scene relight_result")
    for kind in ("objects", "meshes", "materials", "collections", "images"):
        out += [f"{kind}:{b.name}" for b in getattr(bpy.data, kind) if b.get("relight_owner")]
    for o in mesh_objects():
        if "relight_radiosity" in o.data.attributes:
            out.append(f"{o.name}.relight_radiosity")
    return out


def reports():
    """The session's reports, oldest first, read through an Info editor (the timeline area
    turned into one for a moment): select all, Copy, read the clipboard."""
    area = next(a for a in window().screen.areas if a.type in ("DOPESHEET_EDITOR", "TIMELINE", "INFO")
                and a != area3d())
    old = area.ui_type
    area.ui_type = "INFO"
    yield 0.5
    wm = bpy.context.window_manager
    wm.clipboard = SENTINEL
    with bpy.context.temp_override(window=window(), area=area, region=region("WINDOW", area)):
        bpy.ops.info.select_all(action="SELECT")
        bpy.ops.info.report_copy()
    text = wm.clipboard
    area.ui_type = old
    yield 0.3
    return [] if text == SENTINEL else [ln for ln in text.splitlines() if ln.strip()]


# --- the chart as seen on screen ---------------------------------------------------------

def load_shot(path):
    img = bpy.data.images.load(path, check_existing=False)
    w, h = img.size
    px = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3]  # top-down rows, like X screen coordinates


def chart_on_screen(path):
    """(x0, y0, x1, y1) of the chart in the screenshot (its distinctive background colour
    inside the sidebar), and the x of its marker line, or None."""
    chart = sys.modules[PKG + ".pipeline.chart"]
    a = load_shot(path)
    r = ui_region()
    x_lo, x_hi = r.x, r.x + r.width
    bg = np.array(chart.COLORS["background"][:3], dtype=np.float32)
    mask = np.all(np.abs(a[:, x_lo:x_hi] - bg) < 1.5 / 255, axis=-1)
    if mask.sum() < 500:
        return None
    ys, xs = np.nonzero(mask)
    box = [int(xs.min()) + x_lo, int(ys.min()), int(xs.max()) + x_lo, int(ys.max())]
    sub = a[box[1]:box[3] + 1, box[0]:box[2] + 1]
    mk = np.array(chart.COLORS["marker"][:3], dtype=np.float32)
    mmask = np.all(np.abs(sub - mk) < 0.08, axis=-1)
    if not mmask.any():
        return box, None
    col_counts = mmask.sum(axis=0)
    return box, float(box[0] + np.argmax(col_counts))


def check_marker(name, path):
    panels = mods()["blender.ui.panels"]
    geo = panels.last_chart_geometry()
    seen = chart_on_screen(path)
    if seen is None or geo is None or geo.get("marker") is None:
        return check(name, False, f"chart on screen {seen}, geometry {geo}")
    box, mx = seen
    w_img = geo["size"][0]
    scale = (box[2] - box[0] + 1) / w_img
    want = box[0] + geo["marker"][0] * scale
    current = mods()["blender.results"].chart_data(bpy.context.scene)["current"]
    ok = mx is not None and abs(mx - want) <= 3 and geo["current"] == current
    return check(name, ok, f"marker at x={mx}, expected {want:.1f} (chart {box}, drawn at {scale:.3f} x), "
                           f"curve point {geo['current']} (shown {current})")


# --- the scenario ---------------------------------------------------------------------------

def floor_strokes(floor, n_strokes=4, per_stroke=12):
    """Groups of unpainted polygons of ``floor`` (a mesh object) next to its painted ones (as a
    brush extends the paint)."""
    painted = mods()["blender.layers"].face_flags(floor, "target")
    M = floor.matrix_world
    centres = [M @ p.center for p in floor.data.polygons]
    hub = sum((centres[k] for k in np.flatnonzero(painted)), centres[0] * 0) / max(int(painted.sum()), 1)
    free = sorted(np.flatnonzero(~painted), key=lambda k: (centres[k] - hub).length)
    return [[int(k) for k in free[i * per_stroke:(i + 1) * per_stroke]] for i in range(n_strokes)]


def attr_stroke(ob, faces, rgb):
    """What a Vertex Paint stroke writes (Debian's Blender has no brush to paint with: shared/
    gui-blender.md): the faces' corners of the active target layer at colour ``rgb``, alpha 1, and
    the mesh updated, in Vertex Paint mode in the window."""
    me = ob.data
    layer = me.color_attributes["relight_target"]
    col = np.zeros((len(me.loops), 4), dtype=np.float32)
    layer.data.foreach_get("color", col.ravel())
    for k in faces:
        p = me.polygons[k]
        col[p.loop_start:p.loop_start + p.loop_total] = (*rgb, 1.0)
    layer.data.foreach_set("color", col.ravel())
    me.update()


def live_mode(scene, settings, floor):
    live = mods()["blender.live"]
    results = mods()["blender.results"]
    set_active(floor)
    with override():
        if bpy.context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
    yield 1.0
    found = yield from probe_sidebar(want={"bpy.ops.relight.live()"})
    if not check("the Live toggle is in the sidebar", "bpy.ops.relight.live()" in found, sorted(found)):
        return
    yield from press(found, "bpy.ops.relight.live()", settle=1.0)
    s = live.session(scene)
    t0 = time.monotonic()
    while s is not None and s.updates < 1 and time.monotonic() - t0 < 300:
        yield 0.2
    check("Live turns on and answers from the prepared scene", s is not None and s.updates >= 1,
          None if s is None else live.status_text(s))
    if s is None:
        return
    shot("11e_live_on")
    # Live reads the paint at the first tick after a stroke, unless a brush's modal operator runs
    # (live.stroke_running): the window lists its modal operators, Live's own among them
    running = [op.bl_idname for win in bpy.context.window_manager.windows for op in win.modal_operators]
    check("the window lists its modal operators (Live's own: not a stroke)",
          "RELIGHT_OT_live" in running and not live.stroke_running(bpy.context, time.monotonic()), running)
    found = yield from probe_sidebar(want={"bpy.ops.relight.paint_targets()"})
    yield from press(found, "bpy.ops.relight.paint_targets()", settle=1.5)
    changed, waits, pauses, how = [], [], [], []
    stairs = scene.objects["flight_1"]
    groups = floor_strokes(floor)
    steps = floor_strokes(stairs, 2, 6)
    rgb = tuple(settings.paint_color)
    state = mods()["blender.preparation"].PREPARED
    # on the stairs (faces the adaptive model keeps whole: the live re-solve), on the floor (faces it
    # clustered), then Fill Selected on the stairs and, last, Unpaint of the same faces (an erase)
    strokes = [(stairs, steps[0], "paint"), (floor, groups[0], "paint"), (stairs, steps[1], "fill"),
               (stairs, steps[1], "unpaint")]
    for i, (ob, faces, action) in enumerate(strokes):
        n0, rid0, targets0 = s.updates, results.result_id(scene), counts()[0]
        t_stroke = time.monotonic()
        if action == "paint":  # in Vertex Paint: what a brush stroke writes
            attr_stroke(ob, faces, rgb)
            kind = "vertex paint layer"
        else:  # Fill Selected / Unpaint in Edit Mode, its button clicked
            if bpy.context.mode != "EDIT_MESH" or bpy.context.object is not ob:
                with override():
                    bpy.ops.object.mode_set(mode="OBJECT")
                set_active(ob)
                yield from edit_faces(ob, faces)
            unpaint = action == "unpaint"
            command = f"bpy.ops.relight.fill_targets(unpaint={unpaint})"
            found = yield from probe_sidebar(want={command})
            t_stroke = time.monotonic()  # (the pauses from the click on: the probe is the driver's own)
            yield from press(found, command, settle=0.5)
            kind = "Unpaint" if unpaint else "Fill Selected"
        t_up = time.monotonic()
        while s.updates == n0 and not s.paused and time.monotonic() - t_up < 120:
            yield 0.1
        t_done = time.monotonic()
        waits.append(round(t_done - t_up, 2))
        pauses.append(round(max_gap(t_stroke, t_done), 2))
        changed.append(s.updates > n0 and results.result_id(scene) != rid0
                       and (counts()[0] < targets0 if action == "unpaint" else counts()[0] > targets0))
        st = state.get(scene.name)
        how.append(f"{ob.name}, {kind}: {'live re-solve' if st is not None and st.reason is None else 'full'}")
        log("live stroke", i, live.status_text(s), "targets", targets0, "->", counts()[0])
        shot(f"11f_live_stroke_{i}")
    RESULT["timings"]["live"] = {"answer_after_stroke_s": waits, "longest_pause_s": pauses, "strokes": how,
                                 "last": live.status_text(s)}
    check("the lights change after each stroke in Live mode", changed and all(changed),
          f"{changed}; strokes {how}; {live.status_text(s)}")
    check("the brush stays responsive in Live mode", pauses and max(pauses) < PAUSE_LIMIT,
          f"longest main-thread pauses per stroke {pauses} s; answers {waits} s after the stroke")
    yield from button_after_live(scene, settings, s, state)
    # ESC right after a stroke: the re-solve running (if any) is dropped; the scene keeps the last answer
    if bpy.context.mode == "EDIT_MESH":
        yield from key_in_viewport("Tab")
    with override():
        bpy.ops.object.mode_set(mode="OBJECT")
    set_active(floor)
    attr_stroke(floor, groups[1], rgb)
    yield 0.15
    move(*viewport_center())
    n_esc, rid_esc, solving = s.updates, results.result_id(scene), s.worker is not None
    xdo("key", "Escape")
    yield 3.0
    data_ok = True
    try:
        results.check_stored(scene, results.load_result(scene))
    except Exception as exc:  # noqa: BLE001
        data_ok = f"{exc}"
    check("ESC turns Live off and leaves the scene consistent (nothing written after it)",
          live.session(scene) is None and (s.worker is None or not s.worker.is_alive()) and s.updates == n_esc
          and results.result_id(scene) == rid_esc and data_ok is True,
          f"session {live.session(scene)}, status {s.status!r}, re-solve running at ESC: {solving}, "
          f"updates {n_esc} -> {s.updates}, stored result {data_ok}")
    shot("11g_live_off")
    with override():
        bpy.ops.object.mode_set(mode="OBJECT")
    yield 1.0


def button_after_live(scene, settings, s, state):
    """Solve & Reduce once Live's later answers to the last stroke are in: it takes the answer of
    Live's warm solve of this paint (PreparedScene.answer) instead of solving it again (issue 37)."""
    m = mods()
    live, operators, results = m["blender.live"], m["blender.ui.operators"], m["blender.results"]
    ready = yield from wait_for(lambda: s.worker is None and s.to_refine is None and s.status == "up to date", 240)
    st = state.get(scene.name)
    made = None if st is None or st.answer is None else st.answer[2]
    found = yield from probe_sidebar(want={"bpy.ops.relight.solve()"})
    rid = results.result_id(scene)
    t_click = time.monotonic()
    yield from press(found, "bpy.ops.relight.solve()", settle=0.1)
    yield from wait_for(lambda: results.result_id(scene) != rid and operators.solve_state(scene) is None, 300)
    took = round(time.monotonic() - t_click, 2)
    RESULT["timings"]["live"]["button_after_warm_solve_s"] = took
    check("Solve & Reduce after Live's later answers takes the answer of Live's warm solve of that paint",
          ready and made == "Live's warm solve" and "taken whole" in settings.last_warnings,
          f"{took} s from the click to the answer shown; the state's last answer made by {made!r}; "
          f"{live.status_text(s)}; warnings {settings.last_warnings[-300:]!r}")
    yield 1.0  # (the sidebar redrawn with the answer before the screenshot)
    shot("11f_live_button_after_warm_solve")


def wait_for(cond, timeout):
    t0 = time.monotonic()
    while not cond() and time.monotonic() - t0 < timeout:
        yield 0.2
    return cond()


def live_on(scene, found, name):
    """Live's button pressed (``found``: the sidebar's buttons): its session once its first answer is
    in and it is up to date, else None (checked as ``name``)."""
    live = mods()["blender.live"]
    yield from press(found, "bpy.ops.relight.live()", settle=1.0)
    s = live.session(scene)
    ok = check(name, s is not None and (
        yield from wait_for(lambda: s.base is not None and s.worker is None and s.status == "up to date", 300)),
        None if s is None else live.status_text(s))
    return s if ok else None


def live_watch(scene):
    """Issue 35 (cases 13, 14): with Live on, a candidate hidden from renders and an object deleted
    with the Delete key pause Live, the object named in the sidebar's line and the status bar, the
    scene as last written; Ctrl+Z leaves Live running or paused with a reason, never an exception."""
    m = mods()
    live, operators, results = m["blender.live"], m["blender.ui.operators"], m["blender.results"]
    set_active(scene.objects["floor_0"])
    found = yield from probe_sidebar(want={"bpy.ops.relight.live()"})
    s = yield from live_on(scene, found, "Live turns on again (after Clear: a full solve first)")
    if s is None:
        return

    def said(text, name):
        return any("Live paused" in t and name in t for t in text)

    # the ceiling (a candidate) hidden from renders (the Outliner's camera icon: hide_render)
    rid = results.result_id(scene)
    scene.objects["ceiling"].hide_render = True
    yield from wait_for(lambda: s.paused, 30)
    yield 1.0
    shot("11h_live_paused_hidden")
    text = yield from reports()
    check("a candidate hidden from renders pauses Live, named in the sidebar and the status bar",
          s.paused == "object 'ceiling' hidden from renders: Solve & Reduce prepares again"
          and results.result_id(scene) == rid and said(text, "'ceiling' hidden from renders"),
          f"{live.status_text(s)}; reports {text[-2:]}")
    scene.objects["ceiling"].hide_render = False
    yield 0.5
    found = yield from probe_sidebar(want={"bpy.ops.relight.solve()"})
    yield from press(found, "bpy.ops.relight.solve()", settle=1.0)
    yield from wait_for(lambda: operators.solve_state(scene) is None, 300)
    check("Solve & Reduce prepares again and Live goes on", (
        yield from wait_for(lambda: s.paused is None and s.worker is None and s.status == "up to date", 120)),
        live.status_text(s))

    # a wall deleted with the Delete key in the viewport
    set_active(scene.objects["wall_west"])
    rid = results.result_id(scene)
    yield from key_in_viewport("Delete")
    yield from wait_for(lambda: s.paused, 30)
    yield 1.0
    shot("11i_live_paused_deleted")
    text = yield from reports()
    check("an object deleted with Live on pauses it, named, without an exception",
          "wall_west" not in scene.objects
          and s.paused == "object 'wall_west' deleted: Solve & Reduce prepares again"
          and results.result_id(scene) == rid and said(text, "'wall_west' deleted")
          and not any("Relight Live:" in t for t in text), f"{live.status_text(s)}; reports {text[-2:]}")

    # Ctrl+Z: the wall back; Live runs on (the objects found again by name) or pauses with a reason
    name = s.scene
    yield from key_in_viewport("ctrl+z")
    yield 3.0
    sc = bpy.data.scenes[name]
    running = [op.bl_idname for win in bpy.context.window_manager.windows for op in win.modal_operators]
    yield from wait_for(lambda: s.worker is None and (s.paused or s.status == "up to date"), 120)
    shot("11j_live_after_undo")
    text = yield from reports()
    check("Ctrl+Z with Live on: the wall back, Live running or paused with a reason, no exception",
          "wall_west" in sc.objects and live.session(sc) is s and "RELIGHT_OT_live" in running
          and (s.paused is None or "Solve & Reduce" in s.paused) and not any("Relight Live:" in t for t in text),
          f"{live.status_text(s)}; modal operators {running}; reports {text[-2:]}")
    move(*viewport_center())
    xdo("key", "Escape")
    yield 2.0
    check("ESC turns Live off after the undo", live.session(sc) is None, live.status_text(s))


def view_target(scene):
    """Issue 40 in the window: New View Target opens an image of the camera's view in an Image Editor
    in Paint mode; a brush stroke there paints targets (alpha); Solve & Reduce shows the predicted
    camera image beside it, with its error; Clear Results removes the prediction, not the painting."""
    m = mods()
    operators = m["blender.ui.operators"]
    vt = sys.modules[f"{PKG}.blender.ui.view_target_ops"]
    set_active(scene.objects["floor_0"])
    found = yield from probe_sidebar(want={"bpy.ops.relight.new_view_target()", "bpy.ops.relight.solve()"})
    yield from press(found, "bpy.ops.relight.new_view_target()", settle=2.0)
    img = scene.relight_camera_target.image
    areas = [a for a in window().screen.areas if a.type == "IMAGE_EDITOR" and img is not None
             and a.spaces.active.image == img]
    said = [ln for ln in (yield from reports()) if "New view target" in ln]
    yield 1.0  # (the brush Relight adds is made active from a timer)
    brush = bpy.context.scene.tool_settings.image_paint.brush
    check("New View Target: an image of the camera's view, free everywhere, in an Image Editor in Paint mode, "
          "with a brush (Debian's Blender has none of its own: Relight adds one, and says so)",
          img is not None and areas and areas[0].spaces.active.ui_mode == "PAINT" and brush is not None
          and (brush.name != vt.PAINT_BRUSH_NAME or any("brush" in ln for ln in said))
          and max(np.asarray(img.pixels[:], dtype=np.float32)[3::4]) == 0.0,
          None if img is None else f"{img.name} {tuple(img.size)}, editors {[a.spaces.active.ui_mode for a in areas]}, "
          f"brush {None if brush is None else brush.name}; {said[-1:]}")
    if img is None or not areas:
        return
    shot("18_view_target_new")
    # a brush stroke across the middle of the image (the Image Editor's window region)
    reg = region("WINDOW", areas[0])
    cx, cy = to_screen(reg, reg.width // 2, reg.height // 2)
    move(cx - 80, cy)
    yield 0.5
    xdo("mousedown", "1")
    for dx in range(-80, 81, 10):
        move(cx + dx, cy)
        yield 0.05
    xdo("mouseup", "1")
    yield 1.5
    alpha = np.asarray(img.pixels[:], dtype=np.float32)[3::4]
    painted = int((alpha > 0.5).sum())
    check("a brush stroke in the Image Editor paints view targets (alpha)", painted > 100,
          f"{painted} of {alpha.size} pixels painted")
    if painted <= 100:  # (so that the solve below still has targets to read)
        px = np.asarray(img.pixels[:], dtype=np.float32).reshape(img.size[1], img.size[0], 4)
        px[img.size[1] // 3: img.size[1] // 2, img.size[0] // 3: img.size[0] // 2] = (0.5, 0.5, 0.5, 1.0)
        img.pixels.foreach_set(px.ravel())
        log("the stroke painted nothing: pixels set from Python for the solve")
    shot("19_view_target_painted")
    yield from press(found, "bpy.ops.relight.solve()", settle=2.0)
    yield from wait_for(lambda: operators.solve_state(scene) is None, 400)
    yield 2.0
    pred = vt.prediction_image(scene)
    block = json.loads(pred.get(vt.ERROR_PROP) or "{}") if pred is not None else {}
    beside = [a for a in window().screen.areas if a.type == "IMAGE_EDITOR" and a.spaces.active.image == pred]
    check("Solve & Reduce with the view target: the predicted camera image beside the painted one, its error",
          pred is not None and beside and block.get("painted", 0) > 0
          and block.get("mean_relative_error") is not None and np.isfinite(block["mean_relative_error"]),
          f"prediction {None if pred is None else tuple(pred.size)}, shown in {len(beside)} editor(s), {block}")
    shot("20_view_prediction")
    # (the 3D View is narrower since the prediction's editor split it)
    found = yield from probe_sidebar(want={"bpy.ops.relight.live()"})
    yield from live_on_view_target(scene, found, img)
    found = yield from probe_sidebar(want={"bpy.ops.relight.clear_results()"})
    yield from press(found, "bpy.ops.relight.clear_results()", settle=2.0)
    check("Clear Results removes the prediction, the painted view target stays",
          vt.prediction_image(scene) is None and not [i for i in bpy.data.images if i.name.startswith("Relight Prediction")]
          and scene.relight_camera_target.image == img, [i.name for i in bpy.data.images])


def live_on_view_target(scene, found, img):
    """Live on, the view target painted again in the Image Editor: Live follows it as a stroke (its
    answer's rows are of the new pixels), never says "up to date" of paint it did not read, and the
    brush does not stall; ESC turns it off."""
    live = mods()["blender.live"]
    s = yield from live_on(scene, found, "Live turns on with a view target used")
    if s is None:
        return
    areas = [a for a in window().screen.areas if a.type == "IMAGE_EDITOR" and a.spaces.active.image == img]
    if not check("the painted view target is still in an Image Editor", areas, [a.type for a in window().screen.areas]):
        return
    before = np.asarray(img.pixels[:], dtype=np.float32)[3::4].copy()
    spec, updates = (s._faces or s.base.exp.faces).view_target, s.updates
    reg = region("WINDOW", areas[0])
    cx, cy = to_screen(reg, reg.width // 2, reg.height // 3)
    move(cx - 60, cy)
    yield 0.5
    t0 = time.monotonic()
    xdo("mousedown", "1")
    for dx in range(-60, 61, 10):
        move(cx + dx, cy)
        yield 0.05
    xdo("mouseup", "1")
    yield from wait_for(lambda: s.updates > updates and s.worker is None or s.paused, 120)
    took = time.monotonic() - t0
    yield 1.0
    changed = int((np.asarray(img.pixels[:], dtype=np.float32)[3::4] != before).sum())
    now = s._faces.view_target if s._faces is not None else None
    shot("20b_live_view_target_painted")
    text = yield from reports()
    check("a stroke on the view target in the Image Editor with Live on is answered as a stroke",
          changed > 0 and s.paused is None and s.updates > updates and now is not None and now is not spec
          and int(now.painted.sum()) > int(spec.painted.sum()) and not any("Relight Live:" in t for t in text),
          f"{changed} pixels changed, painted {int(spec.painted.sum())} -> "
          f"{None if now is None else int(now.painted.sum())}; answered {took:.1f} s after the stroke began; "
          f"{live.status_text(s)}; reports {text[-2:]}")
    move(*viewport_center())
    xdo("key", "Escape")
    yield 2.0
    check("ESC turns Live off", live.session(scene) is None, live.status_text(s))


def scenario():
    yield 3.0
    prefs = bpy.context.preferences
    check("the extension is installed and enabled", PKG in prefs.addons, sorted(prefs.addons.keys()))
    m = mods()
    panels, operators, results = m["blender.ui.panels"], m["blender.ui.operators"], m["blender.results"]
    scene = bpy.context.scene
    settings = scene.relight
    initial_shading = shading()
    RESULT["initial_shading"] = initial_shading

    # the camera view and the sidebar, with keys an artist uses
    yield from key_in_viewport("KP_0")
    r3d = area3d().spaces.active.region_3d
    if r3d.view_perspective != "CAMERA":
        r3d.view_perspective = "CAMERA"
        log("KP_0 did not switch to the camera; set from Python")
    yield from key_in_viewport("n")
    check("N opens the sidebar", area3d().spaces.active.show_region_ui)
    if not area3d().spaces.active.show_region_ui:
        area3d().spaces.active.show_region_ui = True
        yield 1.0

    # 1. the Relight tab, opened by clicking down the tab strip
    r = ui_region()
    tab_y = 6
    while r.active_panel_category != "Relight" and tab_y < r.height:
        tab_y += 14
        yield from click(*to_screen(r, r.width - 10, r.height - tab_y), settle=0.6)
        r = ui_region()
    check("the Relight tab opens with a click", r.active_panel_category == "Relight", r.active_panel_category)

    # 2. no active object: hints instead of unexplained greyed-out buttons
    with override():
        if bpy.context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
    for o in scene.objects:
        o.select_set(False)
    bpy.context.view_layer.objects.active = None
    yield 1.5
    shot("01_no_active_object")
    hints = panels.hints(bpy.context)
    check("without an active mesh the panel says why buttons are greyed", "Select a mesh object" in hints, hints)
    size = panels.effective_max_patch_size(scene)
    check("Max Patch Size 0 stands for the scene's relight_max_patch_size (shown as Auto)",
          settings.max_patch_size == 0 and size[0] == scene.get("relight_max_patch_size") and size[1] == "scene", size)
    found0 = yield from probe_sidebar()
    for cmd in ("bpy.ops.relight.paint_targets()", "bpy.ops.relight.fill_targets(unpaint=False)",
                "bpy.ops.relight.fill_targets(unpaint=True)", "bpy.ops.relight.forbid_faces(allow=False)",
                "bpy.ops.relight.forbid_faces(allow=True)", "bpy.ops.relight.solve()"):
        check(f"button {cmd} is in the sidebar", cmd in found0)

    # 3. a mesh becomes active: the rows stay where they were
    floor = scene.objects["floor_0"]
    set_active(floor)
    yield 1.5
    found = yield from probe_sidebar()
    moved = {k: (found0[k][1], found[k][1]) for k in found0 if k.startswith("bpy.ops") and k in found
             and abs(found0[k][1] - found[k][1]) > 8}
    check("the panel does not jump when a mesh becomes active", not moved, moved)
    shot("02_tab")

    # 4. Paint Targets
    yield from press(found, "bpy.ops.relight.paint_targets()", settle=2.0)
    active = floor.data.color_attributes.active_color
    check("Paint Targets enters Vertex Paint on the target layer",
          bpy.context.mode == "PAINT_VERTEX" and active is not None and active.name == "relight_target",
          (bpy.context.mode, active.name if active else None))
    shot("03_paint_targets")

    # 5. Edit Mode: the panel keeps working (defect 1); Fill Selected then Unpaint
    t0, c0, f0, _ = counts()
    targets0 = m["blender.layers"].face_flags(floor, "target")
    fill = [int(k) for k in np.flatnonzero(~targets0)[:4]]
    tabbed = yield from edit_faces(floor, fill)
    check("Tab enters Edit Mode", tabbed, bpy.context.mode)
    yield 1.5
    t1, c1, f1, notes = counts()
    check("counts in Edit Mode (from the edit mesh)", (t1, f1) == (t0, f0), f"{(t1, c1, f1)} vs {(t0, c0, f0)} {notes}")
    yield from scroll_sidebar(-40)
    shot("04_edit_mode")
    yield from press(found, "bpy.ops.relight.fill_targets(unpaint=False)", settle=1.5)
    t2 = counts()[0]
    check("Fill Selected paints the 4 selected faces", t2 == t0 + 4, f"{t0} -> {t2}")
    shot("05_fill_selected")
    yield from press(found, "bpy.ops.relight.fill_targets(unpaint=True)", settle=1.5)
    t3 = counts()[0]
    check("Unpaint makes them non-targets again", t3 == t0, f"{t2} -> {t3}")
    # Fill Selected (lx): the same faces become illuminance targets (issue 21), Unpaint removes them
    yield from press(found, "bpy.ops.relight.fill_targets(illuminance=True)", settle=1.5)
    t4 = counts()[0]
    check("Fill Selected (lx) makes the 4 selected faces illuminance targets", t4 == t0 + 4, f"{t0} -> {t4}")
    yield from press(found, "bpy.ops.relight.fill_targets(unpaint=True)", settle=1.5)
    check("Unpaint removes the illuminance targets", counts()[0] == t0, f"{t4} -> {counts()[0]}")

    # 6. Forbid / Allow Selected in Edit Mode on a wall
    yield from key_in_viewport("Tab")
    wall = scene.objects["wall_east"] if "wall_east" in scene.objects else \
        next(o for o in mesh_objects() if o.name.startswith("wall"))
    with override():
        if bpy.context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
    set_active(wall)
    cand = np.flatnonzero(m["blender.layers"].face_flags(wall, "candidate"))[:6]
    c_before = counts()[1]
    yield from edit_faces(wall, [int(k) for k in cand])
    yield 1.0
    yield from press(found, "bpy.ops.relight.forbid_faces(allow=False)", settle=1.5)
    shot("06_forbid_selected")
    in_edit = bpy.context.mode == "EDIT_MESH"
    yield from key_in_viewport("Tab")
    c_after = counts()[1]
    check("Forbid Selected removes the 6 faces from the candidates", in_edit and c_after == c_before - 6,
          f"{c_before} -> {c_after}, still in Edit Mode: {in_edit}")
    yield from key_in_viewport("Tab")
    yield from press(found, "bpy.ops.relight.forbid_faces(allow=True)", settle=1.5)
    yield from key_in_viewport("Tab")
    check("Allow Selected gives them back", counts()[1] == c_before, f"{c_after} -> {counts()[1]}")
    check("back in Object Mode", bpy.context.mode == "OBJECT", bpy.context.mode)

    # 7. Solve & Reduce, modal, with progress
    t_click = time.monotonic()
    yield from press(found, "bpy.ops.relight.solve()", settle=0.3)
    running_seen, k, t_first, t_last = False, 0, None, None
    deadline = time.monotonic() + 900
    while time.monotonic() < deadline:
        state = operators.solve_state(scene)
        if state is not None:
            running_seen = True
            t_last = time.monotonic()
            t_first = t_first or t_last
            if k < 3 and state["fraction"] >= 0.25 * k:
                shot(f"07_solving_{k}", wait=False)
                k += 1
        elif running_seen or len(settings.curve):
            break
        yield 0.5
    t_done = time.monotonic()
    RESULT["timings"]["solve_s"] = round(t_done - t_click, 1)
    check("the solve runs in the background with progress", running_seen and k >= 1, f"progress shots: {k}")
    if running_seen:
        gap = max_gap(t_first, t_last)
        RESULT["timings"]["solve_pauses_s"] = {"start (export, meshing)": round(max_gap(t_click, t_first), 2),
                                               "while solving": round(gap, 2),
                                               "finish (apply the result)": round(max_gap(t_last, t_done), 2)}
        # the worker shares the GIL and 2 busy cores with Blender's software OpenGL: pauses of
        # a second happen; a solve run on the main thread would pause it for the whole solve
        check("the UI stays responsive while solving", gap < PAUSE_LIMIT,
              f"longest main-thread pause {gap:.2f} s over {t_last - t_first:.0f} s of solving; "
              f"{RESULT['timings']['solve_pauses_s']}")
    yield from scroll_sidebar(40)
    shot("08_solved")  # while the status bar still shows the last report
    n_rows = len(settings.curve)
    final = settings.curve[settings.curve_index] if n_rows else None
    check("the solve fills the curve and ends at <= 3 positive lights",
          n_rows >= 2 and final is not None and final.n_negative == 0 and 1 <= final.n_lights <= 3,
          f"{n_rows} rows, final {final.n_lights if final else None} lights")
    check("the summary is kept for the panel", settings.last_summary.startswith(f"{final.n_lights} lights"),
          settings.last_summary)
    RESULT["warnings"] = settings.last_warnings
    check("after the solve the viewport shows the predicted radiosity",
          shading() == ("SOLID", "VERTEX") and floor.data.color_attributes.active_color.name == "relight_radiosity",
          (shading(), floor.data.color_attributes.active_color.name))
    text = yield from reports()
    last = text[-1] if text else ""
    warnings = [w for w in settings.last_warnings.split("\n") if w]
    top = mods()["pipeline.notes"].sidebar_lines(warnings)
    want = (mods()["pipeline.notes"].for_addon(warnings[top[0].index]) if top else settings.last_summary)[:60]
    check("the solve's most consequential message is the last report (the status bar shows it)", want in last,
          last[:300])
    result_before = scene.get("relight_result")

    # 8. rows of the list: the chart marker follows the row picked
    apply_cmd = "bpy.ops.relight.clear_results()"  # (the row under the list: a click on a row shows it)
    # (every page: the rows below are scrolled to from the sidebar's bottom, where a whole probe ends)
    found = yield from probe_sidebar()
    if check("the Results panel has its buttons", apply_cmd in found, sorted(found)):
        # the button under the list a quarter of the region up from its bottom: the list's six rows
        # above it on screen, however tall the panel above (the lights' list, the warnings)
        for _ in range(30):
            r = ui_region()
            ry = r.view2d.view_to_region(*found[apply_cmd], clip=False)[1]
            if 0.15 * r.height <= ry <= 0.35 * r.height:
                break
            yield from scroll_sidebar(2 if ry > 0.35 * r.height else -2)
        r = ui_region()
        ax, ay = r.view2d.view_to_region(*found[apply_cmd], clip=False)
        path = shot("09_chart_final")
        check_marker("the chart marks the final configuration", path)
        picked = set()
        ui = bpy.context.preferences.system.ui_scale
        for j in (1, 3, 5):
            sx, sy = to_screen(r, r.width * 0.35, ay + (30 + 20.8 * j) * ui / 1.0417)
            before = settings.curve_index
            yield from click(sx, sy, settle=2.0)
            picked.add(settings.curve_index)
            path = shot(f"10_row_{j}")
            check_marker(f"after picking row {settings.curve_index} the chart marker follows", path)
            panel = (mods()["blender.results"].load_result(scene).meta.get("rows") or [None] * (settings.curve_index + 1))[
                settings.curve_index]
            check(f"after picking row {settings.curve_index} the Results list its lights and light on the targets",
                  panel is not None and settings.last_lights == panel["lights"]
                  and settings.last_photometric == panel["photometric"]
                  and len([ln for ln in settings.last_lights.split("\n") if ln]) == settings.curve[
                      settings.curve_index].n_lights,
                  f"{settings.last_lights!r} vs {panel and panel['lights']!r}")
            log("row click", j, before, "->", settings.curve_index)
        check("clicking rows picks different configurations", len(picked) >= 3, sorted(picked))
        shot("11_results")

        # 8a. the View (issue 36 item 2): the illuminance in false colour with its legend, the
        # view transform Standard meanwhile and the artist's given back after
        view = scene.relight_view
        transform = scene.view_settings.view_transform
        view.mode = "ILLUMINANCE"
        yield 1.5
        floor_layer = scene.objects["floor_0"].data.color_attributes.get("relight_display")
        check("the false-colour illuminance view is shown, with Standard colours",
              floor_layer is not None and scene.view_settings.view_transform == "Standard"
              and shading() == ("SOLID", "VERTEX"), (floor_layer, scene.view_settings.view_transform, shading()))
        shot("11a_false_colour")
        check("the View sub-panel is registered under Results",
              getattr(bpy.types, "RELIGHT_PT_view", None) is not None
              and bpy.types.RELIGHT_PT_view.bl_parent_id == "RELIGHT_PT_results", None)
        view.mode = "PREDICTED"
        yield 1.0
        check("back to the predicted view, the artist's view transform is given back",
              scene.view_settings.view_transform == transform, (transform, scene.view_settings.view_transform))

        # 8b. a row clicked after the scene changed (issue 19, case 13): not applied; the list
        # goes back to the row the scene shows, and the panel says why
        shown = settings.curve_index
        mover = scene.objects["floor_0"]
        z0 = mover.location.z
        mover.location.z = z0 + 0.05  # as G Z would
        yield 1.0
        sx, sy = to_screen(r, r.width * 0.35, ay + (30 + 20.8 * 2) * ui / 1.0417)
        yield from click(sx, sy, settle=2.0)
        shot("11b_row_after_change")
        check("a row clicked after a scene change is not applied: the list shows the scene's row",
              settings.curve_index == shown and int(scene.get("relight_shown", -1)) == shown
              and "not applied" in settings.apply_error and "floor_0" in settings.apply_error,
              f"index {settings.curve_index} (shown {shown}), {settings.apply_error!r}")
        xdo("key", "Escape")  # the popup that says it
        mover.location.z = z0
        yield 1.0
        # the scene is as solved again: a row applies, and the panel's line goes
        settings.curve_index = (shown + 1) % len(settings.curve)
        yield 1.0
        settings.curve_index = shown
        yield 1.0
        check("once the scene is back, the row applies and the panel's line goes",
              settings.apply_error == "" and settings.curve_index == shown, repr(settings.apply_error))

    # 8c. the warnings (issue 36 item 4): at most three short lines, the most consequential first,
    # none cut at the sidebar's default width; each with its fix under it; Details lists all; a
    # click on a line gives its whole text (no command-line flag) in the status bar
    notes = mods()["pipeline.notes"]
    warnings = [w for w in settings.last_warnings.split("\n") if w]
    found = yield from probe_sidebar()
    top = notes.sidebar_lines(warnings)
    drawn = sorted(k for k in range(len(warnings)) if f"bpy.ops.relight.warning_details(index={k})" in found)
    check("at most three warnings show, the most consequential ones",
          len(drawn) <= notes.MAX_LINES and drawn == sorted(ln.index for ln in top),
          f"{len(warnings)} warnings, drawn {drawn}, ranked {[(ln.index, ln.rank, ln.text) for ln in top]}")
    check("Details lists every warning", not warnings or "bpy.ops.relight.warnings_popup()" in found,
          sorted(k for k in found if "warnings_popup" in k))
    import blf

    ui = bpy.context.preferences.system.ui_scale
    r = ui_region()
    blf.size(0, 11 * ui)
    # measured against the sidebar's default width (Blender's UI_SIDEBAR_PANEL_WIDTH, 220 px x UI
    # scale; this window's may be wider), less the panel's and the box's margins and the line's icon
    room = min(r.width, 220 * ui) - 60 * ui
    widths = [(ln.text, round(blf.dimensions(0, ln.text)[0])) for ln in top]
    check(f"no warning line is cut at the sidebar's default width (220 x UI scale {ui:g}; this one {r.width} px)",
          all(w <= room for _, w in widths), f"room {room:.0f} px: {widths}")
    for ln in [ln for ln in top if ln.fix == "light_paths"][:1]:  # (one Match, under the first it fixes)
        line_y = [y for _, y in LAST_HITS.get(f"bpy.ops.relight.warning_details(index={ln.index})", ())]
        under = [p for p in LAST_HITS.get("bpy.ops.relight.match_light_paths()", ())
                 if line_y and 0 < min(line_y) - p[1] <= 40 * ui]
        check(f"warning {ln.text!r} has its fix under it", under,
              f"line at {sorted(line_y)}, Match at {sorted(LAST_HITS.get('bpy.ops.relight.match_light_paths()', ()))}")
    if top:
        cmd = f"bpy.ops.relight.warning_details(index={top[0].index})"
        yield from press(found, cmd, settle=1.5)
        text = yield from reports()
        whole = notes.for_addon(warnings[top[0].index])
        check("a click on a warning's line gives its whole text in the status bar, without flags",
              text and whole[:80] in text[-1] and "--" not in text[-1], (text[-1][:200] if text else None))
        shot("11c_warnings")
    fix = next((ln for ln in top if ln.fix == "light_paths"), None)
    if fix is not None:
        before = (scene.cycles.diffuse_bounces, scene.cycles.max_bounces)
        yield from press(found, "bpy.ops.relight.match_light_paths()", settle=1.5)
        after = (scene.cycles.diffuse_bounces, scene.cycles.max_bounces)
        check("the warning's Match button sets Cycles' light paths", after != before and after[0] > before[0],
              f"{before} -> {after}")

    # 8d. a refused Solve started in Edit Mode (issue 19, case 15): the message, the scene and
    # the user's mode as they were
    scale_before = settings.target_scale
    settings.target_scale = 0.0  # every target asks for no light: refused
    set_active(floor)
    yield from key_in_viewport("Tab")
    in_edit = bpy.context.mode == "EDIT_MESH"
    result_before = scene.get("relight_result")
    # (the presses below, after Live mode and a large solve, take this probe's places: each is checked
    # by a hover first, and probed for again when the sidebar has moved)
    found = yield from probe_sidebar(want={"bpy.ops.relight.solve()", "bpy.ops.relight.show_radiosity()",
                                           "bpy.ops.relight.make_area_lights()", "bpy.ops.relight.clear_results()"})
    yield from press(found, "bpy.ops.relight.solve()", settle=2.5)
    text = yield from reports()
    check("a refused Solve in Edit Mode says why and leaves the user in Edit Mode",
          in_edit and bpy.context.mode == "EDIT_MESH" and operators.solve_state(scene) is None
          and scene.get("relight_result") == result_before and text and "nothing to light" in text[-1],
          f"mode {bpy.context.mode}, last report {(text[-1][:160] if text else None)!r}")
    shot("11d_refused_in_edit_mode")
    yield from key_in_viewport("Tab")
    settings.target_scale = scale_before
    yield 1.0

    # 8e. Live mode (issue 20): strokes in Vertex Paint re-solved off the main thread; the lights
    # change after each; the brush never waits (the main thread's pauses recorded); ESC turns it
    # off with the scene as last written
    yield from live_mode(scene, settings, floor)
    result_before, n_rows = scene.get("relight_result"), len(settings.curve)  # (Live wrote its answers)

    # 9. a large solve: the cost question, then ESC; the UI keeps running while it cancels
    settings.rays_per_patch = 262144
    yield 1.0
    yield from press(found, "bpy.ops.relight.solve()", settle=2.0)
    shot("12_cost_question")
    asked = operators.solve_state(scene) is None
    xdo("key", "Down")
    yield 0.5
    xdo("key", "Return")
    yield 5.0
    state = operators.solve_state(scene)
    check("a large solve asks first, then still runs modally", asked and state is not None, state)
    shot("13_large_solve_running")
    t_esc = time.monotonic()
    move(*viewport_center())
    xdo("key", "Escape")
    while operators.solve_state(scene) is not None and time.monotonic() - t_esc < 120:
        yield 0.1
    t_end = time.monotonic()
    gap = max_gap(t_esc, t_end)
    beats = len([t for t in BEAT if t_esc < t < t_end])
    RESULT["timings"]["cancel_s"] = round(t_end - t_esc, 2)
    # waiting for the worker on the main thread (the old modal's join) gives no heartbeat at
    # all between ESC and the end of the cancel
    check("ESC cancels without freezing the UI", operators.solve_state(scene) is None and gap < PAUSE_LIMIT
          and (beats >= 2 or t_end - t_esc < 0.3),
          f"cancelled in {t_end - t_esc:.2f} s, {beats} heartbeats meanwhile, longest main-thread pause {gap:.2f} s")
    check("the cancelled solve leaves the previous result", scene.get("relight_result") == result_before
          and len(settings.curve) == n_rows)
    shot("14_cancelled")
    settings.rays_per_patch = 0
    yield 1.0

    # 10. Show / Hide Radiosity, Make Area Lights, Clear
    yield from press(found, "bpy.ops.relight.show_radiosity()", settle=1.5)
    check("Hide Radiosity gives the viewport its shading back", shading() == initial_shading,
          f"{shading()} vs {initial_shading}")
    shot("15_radiosity_hidden")
    yield from press(found, "bpy.ops.relight.show_radiosity()", settle=1.5)
    check("Show Radiosity shows it again", shading() == ("SOLID", "VERTEX"), shading())
    row = settings.curve[settings.curve_index]
    data = results.load_result(scene)
    power = float(data.curve_power[int(data.point_index[settings.curve_index])])
    # the lamps the solve placed (issue 17): Light objects of Relight's, as the stored configuration has them
    rid = scene.get("relight_result_id")
    placed = sorted(o.name for o in scene.objects if o.type == "LIGHT" and o.get("relight_owner") == rid)
    e_shown = data.exitance[settings.curve_index]
    want = sorted(data.lamps[int(data.light_lamp[j])]["name"] for j in range(len(e_shown))
                  if data.light_lamp[j] >= 0 and max(e_shown[j]) > 0)
    check("the configuration's lamps are Light objects in the viewport", placed == want, f"{placed} vs {want}")
    yield from press(found, "bpy.ops.relight.make_area_lights()", settle=2.0)
    made = next((c for c in bpy.data.collections if c.get("relight_area_lights") is not None), None)
    lights = [o.name for o in made.objects if o.type == "LIGHT"] if made is not None else []
    # summed over the channels, as the configuration's power: Cycles emits colour x Power in each
    energy = sum(sum(scene.objects[n].data.color) * scene.objects[n].data.energy for n in lights)
    check("Make Area Lights: area lights carrying the configuration's power",
          lights and (power is None or row.n_negative or abs(energy - power) <= 1e-3 * power),
          f"{len(lights)} lights for {row.n_lights} light(s), {energy:.4g} W (configuration: {power} W)")
    shot("16_area_lights")
    yield from press(found, "bpy.ops.relight.clear_results()", settle=2.0)
    traces = relight_traces()
    check("Clear removes Relight's results", not traces and len(settings.curve) == 0, traces)
    check("Clear gives the viewport its shading back", shading() == initial_shading, shading())
    left = [n for n in lights if n in scene.objects]
    check("Clear removes the placed lamps", not [n for n in placed if n in scene.objects], placed)
    check("the area lights Make Area Lights made survive Clear (as its tooltip says)", left == lights,
          f"{len(left)} of {len(lights)} left")
    yield from scroll_sidebar(-40)
    shot("17_cleared")

    # 11. a textured World, rendered by Cycles from this window session (blender/world.py): a Sky
    # Texture with its sun; the map comes back with the sun found, and nothing temporary is left
    import importlib

    bworld = importlib.import_module(PKG + ".blender.world")
    sky_world = bpy.data.worlds.new("relight gui sky")
    sky_world.use_nodes = True  # Blender 4.x: a new World has no node tree until then
    sky = sky_world.node_tree.nodes.new("ShaderNodeTexSky")
    bg = next(n for n in sky_world.node_tree.nodes if n.type == "BACKGROUND")
    sky_world.node_tree.links.new(sky.outputs["Color"], bg.inputs["Color"])
    before = (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras), len(bpy.data.worlds))
    t0 = time.monotonic()
    env = bworld.render_world_map(sky_world, sun_hints=bworld.sky_suns(sky_world.node_tree))
    dt = time.monotonic() - t0
    after = (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras), len(bpy.data.worlds))
    suns = env.split_suns()[0]
    check("a Sky Texture World is rendered to its map in the window session",
          env.shape == (128, 256) and len(suns) == 1 and after == before and bpy.context.scene == scene,
          f"{env.shape}, {len(suns)} sun(s), {dt:.1f} s, data {before} -> {after}")
    bpy.data.worlds.remove(sky_world)
    yield 0.5

    # 12. Live's watch (issue 35): a candidate hidden from renders, an object deleted, Ctrl+Z
    yield from live_watch(scene)

    # 13. the camera-view target (issue 40): painted in the Image Editor, the prediction beside it
    # (the scene found again: live_watch's Ctrl+Z replaced the data-blocks)
    yield from view_target(bpy.context.scene)


def finish(code=None):
    RESULT["timings"]["total_s"] = round(time.monotonic() - T0, 1)
    RESULT["pauses"] = PAUSES
    failed = [c for c in RESULT["checks"] if c["status"] == "FAIL"]
    RESULT["passed"] = not failed and code is None
    with open(os.path.join(OUT, "result.json"), "w") as fh:
        json.dump(RESULT, fh, indent=1)
    print(f"GUI-DONE {len(RESULT['checks'])} checks, {len(failed)} failed", flush=True)
    os._exit(0 if RESULT["passed"] else 1)


GEN = scenario()


def tick():
    try:
        return max(0.01, float(next(GEN)))
    except StopIteration:
        finish()
    except Exception:
        traceback.print_exc()
        check("the scenario ran to its end", False, traceback.format_exc().strip().splitlines()[-1])
        try:
            shot("zz_failure")
        finally:
            finish(1)
    return None


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(heartbeat, first_interval=0.05, persistent=True)
bpy.app.timers.register(tick, first_interval=2.0, persistent=True)
