"""The job's report: made here, and finished here, for the CLI and the add-on alike (no bpy).

``solve_report`` (the solve / reduce commands) and ``radiosity_report`` (the forward command)
make the JSON report from the stages' results (README.md, "Headless usage", lists its fields);
``finish`` adds what only the Blender layer can measure -- the render settings the scene's
Cycles light paths give (light_paths.py) and the radiance along the faces' normals
(viewing.py) -- and merges their warnings, once, into the report and the outcome. ``json_safe``
turns the result into plain JSON (no NaN or inf: they become null).
"""
from __future__ import annotations

import json
import math

import numpy as np

from ..engine.best_lights import total_power
from ..engine.candidate_lamps import default_drop, offered_kinds
from ..engine.light_colour import blackbody_rec709
from ..engine.plausibility import implausible_mark, implausible_notes
from ..engine.scene import patch_lux
from ..engine.units import MIN_REFLECTANCE_LUX, illuminance_lux, luminous_flux_lm

__all__ = ["json_safe", "fixture_schedule", "schedule_notes", "schedule_lines", "solve_report", "radiosity_report", "finish", "light_records", "lamp_records", "placed_record",
           "kinds_text"]


def json_safe(x):
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        if x.dtype.kind == "f":  # in C: the non-finite values become None
            return np.where(np.isfinite(x), x, None).tolist() if not np.all(np.isfinite(x)) else x.tolist()
        return json_safe(x.tolist())
    if isinstance(x, (np.bool_, bool)):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def lamp_records(model, strength) -> list:
    """Direct mode: each of the scene's lamps in the reduction at ``strength`` (n_lights, 3), as
    the written copy sets it: name, type (point, spot, area, sun), kind, kept, the unit of its
    power per channel (W; a sun's W/m^2), power_before / power_after [r, g, b] (what Cycles emits:
    colour x Power x gain), gain [r, g, b] (what Cycles multiplies colour x Power by: the Light's
    Exposure, Temperature and Normalize, engine.lamps.Lamp.gain), and Blender's values before and
    after: energy (Power, W; a sun's Strength, W/m^2) and colour (engine.lights.lamp.blender_values;
    a lamp not kept is disabled, its values unchanged). A kept lamp that no Power and colour can
    give its power (a channel its Temperature lacks) has energy_after and color_after None and the
    reason in ``problem``."""
    from ..engine.lights.lamp import blender_values

    if model.lamp_lights is None:
        return []
    out = []
    for j, i in zip(*model.lamp_lights):
        lamp = model.faces.lamps[i]
        s = np.asarray(strength[j], dtype=np.float64)
        kept = bool(np.any(s > 0))
        problem = None
        try:
            energy, color = blender_values(s, lamp.energy, lamp.color, lamp.gain) if kept else (0.0, lamp.color)
        except ValueError as e:
            energy, color, problem = None, None, str(e)
        out.append({"name": lamp.name, "type": lamp.kind.blender_type.lower(), "kind": model.lights.kind_names[j], "kept": kept,
                    "unit": model.lights.kind_of(j).strength_unit,
                    "power_before": lamp.power, "power_after": s if kept else np.zeros(3), "gain": lamp.gain,
                    "energy_before": float(lamp.energy), "energy_after": None if energy is None else float(energy),
                    "color_before": lamp.color, "color_after": color, **({"problem": problem} if problem else {})})
    return out


def placed_record(lamp, kind, strength, temperature=None) -> dict:
    """A lamp the solve placed (engine/lights/spot.py, area.py, point.py) at ``strength`` (3,)
    (its power per channel, W), as the report lists it and the written copy makes it: object (the
    Light object's name), kind (spot, area, point), type (Blender's), location and direction (its
    -Z; a point lamp's is only its orientation), power (W, the channels' sum), strength [r, g, b],
    energy (Blender's Power, W) and color (Power x colour = the strength), radius (m), a spot's
    spot_size and spot_blend (Blender's, rad) and cone_angle_deg (its full angle), an area lamp's
    shape, size [u, v] (m), spread (Blender's Spread, rad: the full angle) and spread_deg.
    ``temperature`` (K, a blackbody light's): the Light's Temperature (Use Temperature on: Cycles
    multiplies colour x Power by its blackbody colour), and energy and color with it. The kind's own
    fields are its ``report_fields`` (engine/lights/)."""
    from ..engine.lights.lamp import blender_values

    s = np.asarray(strength, dtype=np.float64).reshape(3)
    gain = lamp.gain if temperature is None else blackbody_rec709(temperature) * lamp.gain  # (x a fixture's IES gain)
    energy, color = blender_values(s, lamp.energy, lamp.color, gain)
    rec = {"object": lamp.name, "polygons": [], "kind": kind, "type": lamp.kind.blender_type.lower(),
           "location": lamp.position, "direction": lamp.direction, "axis_u": lamp.axis_u, "center": lamp.position,
           "normal": lamp.kind.normal(lamp), "area": lamp.kind.area(lamp), "exitance": None, "strength": s,
           "power": float(s.sum()), "energy": float(energy), "color": color}
    if temperature is not None:
        rec["temperature_K"] = float(temperature)
    rec.update(lamp.kind.report_fields(lamp))
    return rec


def light_records(model, curve, row: int) -> list:
    """The lights of kept configuration ``row`` with a non-zero exitance, as the report lists
    them: object, polygons (base-mesh indices), kind, center and normal (world), area (m^2),
    exitance [r, g, b] (W/m^2), power (W), luminous_flux_lm (lm: engine.units) and, for blackbody
    lights, temperature_K. A lamp (direct mode): object = the lamp's name, no
    polygons, its position and direction (none for a point lamp), area (an Area lamp's; a sun's:
    the area it lights), exitance None, ``strength`` [r, g, b] (its power per channel) and
    power, with the values ``lamp_records`` gives it."""
    lights = model.lights
    e = curve.exitance[row]
    watts, kinds = lights.watts, lights.kind_names
    lamps = {r["name"]: r for r in lamp_records(model, e)}
    lamp_of = dict(zip(*model.lamp_lights)) if model.lamp_lights is not None else {}
    out = []
    on = np.flatnonzero(np.any(e != 0, axis=1))
    colour = getattr(model.problem, "colour", None)
    info = dict(zip(on.tolist(), colour.describe(e[on]))) if colour is not None else {}
    for j in on:
        rec = _one_light(model, curve, lights, (watts, kinds), lamps, lamp_of, e, j, info.get(int(j), {}))
        power = rec["strength"] if rec.get("exitance") is None else np.asarray(e[j]) * watts[j]  # W per channel
        rec["luminous_flux_lm"] = float(luminous_flux_lm(power))
        rec.update(info.get(int(j), {}))
        out.append(rec)
    return out


def _one_light(model, curve, lights, watts_kinds, lamps, lamp_of, e, j, info) -> dict:
    """light_records' record of light ``j`` (``watts_kinds``: the lights' watts and kind names, taken
    once for all; ``info``: its colour's, e.g. a blackbody's temperature)."""
    watts, kinds = watts_kinds
    if lights.kind_of(j).writer == "placed":
        return placed_record(lights.lamp(j), kinds[j], e[j], info.get("temperature_K"))
    if j in lamp_of:
        rec = lamps[model.faces.lamps[lamp_of[j]].name]
        return {"object": rec["name"], "polygons": [], "kind": kinds[j], "center": lights.center[j],
                "normal": lights.normal[j], "area": float(lights.area[j]), "exitance": None,
                "strength": e[j], "power": float(e[j].sum() * watts[j]),
                **{k: v for k, v in rec.items() if k not in ("name", "kind")}}
    pids = curve.light_polygons[j].indices
    obj = model.patches.object[lights.members(j)[0]]
    return {"object": model.faces.object_names[obj], "polygons": np.sort(pids - curve.polygons.offset[obj]).tolist(),
            "kind": kinds[j], "center": lights.center[j], "normal": lights.normal[j],
            "area": float(lights.area[j]), "exitance": e[j], "power": float(e[j].sum() * watts[j])}


def _lamp_drop(options, patches, model):
    """The distance (m) the candidate lamps hung at (the option, else its automatic value), None
    when none were offered."""
    if model.mode != "inverse" or not offered_kinds(options):
        return None
    return float(options.lamp_drop if options.lamp_drop is not None else default_drop(patches))


def solve_report(model, options, inv, red, curve, warnings: list, timings: dict, bounds=None, point_bounds=None,
                 fixed_light=None, per_face=True) -> dict:
    """Stage 5: the JSON report of a solve or a reduce (see README.md), from jobs.Model, the job's
    JobOptions, the InverseResult (None in direct mode), the ReductionResult, jobs.Curve and the
    certificate's bounds. ``per_face`` False (a Live stroke's): ``objects`` is null, the per-face
    values being in the scene (the radiosity layer, the stored result), not written as JSON."""
    faces, patches, problem = model.faces, model.patches, model.problem
    fi = curve.final_row
    final = red.curve[red.final_index]
    pmap = curve.polygons
    E_patch = model.lights.patch_exitance(curve.exitance[fi], patches.n_patches) + model.background
    objects = _per_face(pmap, patches, curve, E_patch) if per_face else None
    photometric = target_photometry(model, curve.radiosity[fi], E_patch) if model.mode == "inverse" else None
    norm = problem.target_norm if problem.target_norm > 0 else 1.0
    lamps = lamp_records(model, curve.exitance[fi]) if model.mode != "inverse" else None
    warnings = list(warnings) + [f"lamp {r['name']!r}: {r['problem']}: the written copy cannot show this configuration "
                                 "(turn its Temperature off, or raise it, and reduce again)"
                                 for r in lamps or [] if "problem" in r]
    final_lights = light_records(model, curve, fi)
    schedule = fixture_schedule(final_lights) if options.param("fixtures") else None
    if schedule:
        more = [pt for pt in red.curve if pt.n_negative == 0 and pt.n_lights > final.n_lights]
        best = min(more, key=lambda pt: (pt.relative_error, pt.n_lights), default=None)
        warnings += schedule_notes(schedule, None if best is None or not best.relative_error < final.relative_error
                                   else (best.n_lights, best.relative_error, final.relative_error))
    if model.mode == "inverse":  # (each record gets its utilisation; the implausible ones named)
        warnings += implausible_notes(problem, final_lights, np.flatnonzero(np.any(curve.exitance[fi] != 0, axis=1)))
    return {
        "command": "solve" if model.mode == "inverse" else "reduce",
        "units": {"radiosity": "W/m^2", "exitance": "W/m^2", "power": "W", "length": "m"},
        "scene": {"objects": len(faces.object_names), "faces": int(faces.n_faces),
                  "triangles": int(len(faces.triangles)), "patches": int(patches.n_patches)},
        "timings_s": timings,
        "estimate": {"memory_bytes": model.cost["memory_bytes"], "seconds": model.cost["seconds"]},
        "options": {**options.to_dict(), "rays_per_patch": int(model.form_factors.rays_per_patch),
                    "max_patch_size": float(patches.max_patch_size),
                    "light_size": None if patches.light_size is None else float(patches.light_size),
                    "lamp_drop": _lamp_drop(options, patches, model)},
        "model": {"patch_model": options.patch_model, "estimator": options.estimator,
                  "lights_by_kind": (model.lamp_refinement or {}).get("offered") or model.lights.count_by_kind(),
                  "refinement": model.refinement, "lamp_refinement": model.lamp_refinement,
                  "direct_light": model.direct},
        "inverse": _inverse_record(model, options, inv),
        "reduction": {"selection": red.selection, "distribution": red.distribution, "seconds": red.seconds,
                      "final_index": red.final_index},
        "light_colour": light_colour_record(problem, options),
        "curve": [{"n_lights": p.n_lights, "error": p.error, "relative_error": p.relative_error,
                   "n_negative": p.n_negative, "power": total_power(p.exitance, problem.light_watts, p.lights),
                   "bound_relative_error": None if point_bounds is None else float(point_bounds[i] / norm)}
                  for i, p in enumerate(red.curve)],
        "certificate": None if bounds is None else {
            # relative to the painted targets' norm, as every relative error of the report (the bounds'
            # own are of what the lights must add to the scene's fixed light)
            "nnls_relative_error": bounds.nnls / norm, "seconds": bounds.seconds,
            "by_lights": [{"n_lights": int(k), "bound_relative_error": float(r), "exact": bool(x)}
                          for k, r, x in zip(bounds.k, bounds.bound / norm, bounds.exact)]},
        "final": {"n_lights": final.n_lights, "error": final.error, "relative_error": final.relative_error,
                  "n_negative": final.n_negative, "power": total_power(final.exitance, problem.light_watts, final.lights),
                  "bound_relative_error": None if point_bounds is None else float(point_bounds[red.final_index] / norm),
                  "lights": final_lights},
        "fixed_light": fixed_light,
        **({"fixture_schedule": schedule} if options.param("fixtures") else {}),
        "targets_photometric": photometric,
        "lamps": lamps,
        "objects": objects,
        "warnings": warnings,
    }


#: a fixture dimmed to at least this share of its rated lumens is at full output (the selection's bound,
#: LightKind.strength_upper, up to the bounded least squares' rounding)
FULL_OUTPUT = 1.0 - 1e-6


def fixture_schedule(lights) -> list:
    """The fixture schedule of a configuration's lights (``light_records``: the records of catalogue
    fixtures, engine/lights/fixture.py, those with a ``fixture``), per fixture type in order of its
    first light: fixture (its catalogue name), description, count, rated_lumens and rated_watts (one
    fixture's), lumens and watts in all (lm at the dimming solved; W its rated input watts x the
    dimming: dimming taken as linear in the input power), and per light its object, location,
    direction and dimming (1 = 100 % of its rated lumens: every selection keeps it within 0-1,
    FixtureKind.strength_upper). ``at_full`` lists the objects at full output (FULL_OUTPUT), which
    schedule_notes names: the targets ask for more light than those fixtures give."""
    out = {}
    for rec in lights:
        if rec.get("fixture") is None:
            continue
        row = out.setdefault(rec["fixture"], {"fixture": rec["fixture"], "description": rec.get("fixture_description"),
                                              "count": 0, "rated_lumens": float(rec["rated_lumens"]),
                                              "rated_watts": float(rec["rated_watts"]), "lumens": 0.0, "watts": 0.0,
                                              "lights": [], "at_full": []})
        dim = float(rec["luminous_flux_lm"]) / row["rated_lumens"]
        row["count"] += 1
        row["lumens"] += float(rec["luminous_flux_lm"])
        row["watts"] += dim * row["rated_watts"]
        row["lights"].append({"object": rec["object"], "location": rec["location"], "direction": rec["direction"],
                              "dimming": dim, "lumens": float(rec["luminous_flux_lm"])})
        if dim >= FULL_OUTPUT:
            row["at_full"].append(rec["object"])
    return list(out.values())


def schedule_notes(schedule, more=None) -> list:
    """The warning of a fixture schedule with fixtures at full output: the targets ask for more light than
    the answer's fixtures give within their ratings; more of them (Max Lights) give more. ``more``: (n, the
    relative error with n lights, the answer's), the curve's best with more lights, or None."""
    full = [f"{len(row['at_full'])} x {row['fixture']}" for row in schedule if row["at_full"]]
    if not full:
        return []
    n = sum(row["count"] for row in schedule)
    curve = ("the curve shows the error with each number of them" if more is None else
             f"the curve: relative error {more[2]:.3g} with {n}, {more[1]:.3g} with {more[0]}")
    return [f"{', '.join(full)} of the answer's {n} fixtures at 100 % of their rated lumens: the targets ask for "
            f"more light than {n} fixtures give within their ratings; raise Max Lights for more fixtures ({curve})"]


def schedule_lines(schedule) -> list:
    """The fixture schedule as the sidebar shows it: a line per fixture type (how many, their dimming,
    lumens and watts in all) and a total."""
    lines = []
    for row in schedule:
        dims = [li["dimming"] for li in row["lights"]]
        lines.append(f"{row['count']} x {row['fixture']} at {100 * min(dims):.0f}-{100 * max(dims):.0f} %: "
                     f"{row['lumens']:.0f} lm, {row['watts']:.1f} W" + (" (at full output)" if row["at_full"] else ""))
    if schedule:
        lines.append(f"in all {sum(r['count'] for r in schedule)} fixtures: {sum(r['lumens'] for r in schedule):.0f} lm, "
                     f"{sum(r['watts'] for r in schedule):.1f} W")
    return lines


def _per_face(pmap, patches, curve, E_patch) -> dict:
    """The report's ``objects``: per object, its faces' final radiosity, painted target and exitance."""
    radiosity = pmap.split(curve.final_polygon_radiosity())
    exitance = pmap.split(pmap.mean(E_patch))
    target = pmap.split(np.where(pmap.mean(patches.target.astype(float)[:, None]) > 0.5,
                                 pmap.mean(np.where(patches.target[:, None], patches.target_radiosity, 0.0)),
                                 np.nan))
    return {name: {"radiosity": radiosity[name], "target": _nan_to_none(target[name]),
                   "exitance": exitance[name]} for name in radiosity}


def _inverse_record(model, options, inv) -> dict:
    """The report's ``inverse``: the inverse problem and its solve (e_x; none in direct mode)."""
    problem, patches = model.problem, model.patches
    n_targets_faces = int(np.sum(model.faces.target)) if model.mode == "inverse" else None
    return {
        # (a Live stroke whose selection does not read e_x solves none: the solver, and no e_x)
        "solver": inv.solver if inv else options.solver if model.mode == "inverse" else "direct-lighting",
        "solved": inv is not None or model.mode != "inverse",
        "n_targets": int(problem.m), "n_target_faces": n_targets_faces,
        "error_over": target_rows_text(patches, problem.targets) if model.mode == "inverse" else
        "every patch that does not emit (the scene's radiosity)",
        "n_candidates": int(problem.n_lights),  # candidate lights, at all scales
        "n_candidate_patches": int(len(problem.candidates)),
        "rank": inv.rank if inv else None,
        "rcond": inv.rcond if inv else None,
        "error": inv.error if inv else None if model.mode == "inverse" else 0.0,
        "relative_error": inv.relative_error if inv else None if model.mode == "inverse" else 0.0,
        "n_negative": inv.n_negative if inv else None if model.mode == "inverse" else 0,
        "seconds": inv.seconds if inv else 0.0,
        "condition_estimate": float(problem.condition),
        "target_norm": problem.target_norm,
    }


def target_photometry(model, radiosity, exitance) -> dict:
    """The painted targets' predicted light, per target object (its target patches, area-weighted):
    radiosity (W/m^2, mean [r, g, b]) and the illuminance arriving there (lx: engine.units, from
    the irradiance E = (B - e) / reflectance of each channel, B = e + reflectance x E): mean, min,
    max and the uniformity U0 = min / mean (EN 12464-1); ``target_lx``: the mean of its
    illuminance targets (Fill Selected in lx), where it has some. A patch with a channel of reflectance
    below MIN_REFLECTANCE_LUX reflects too little to read its illuminance from its radiosity: left
    out, and counted (``unread_patches``). ``radiosity``, ``exitance``: (P, 3) of the configuration."""
    patches = model.patches
    asked_lux = patch_lux(model.faces, patches)
    tg = np.flatnonzero(patches.target)
    rho = patches.reflectance[tg]
    ok = np.all(rho >= MIN_REFLECTANCE_LUX, axis=1)
    irr = np.where(ok[:, None], (radiosity[tg] - exitance[tg]) / np.where(ok[:, None], rho, 1.0), 0.0)
    lux = illuminance_lux(np.maximum(irr, 0.0))
    out = {}
    obj = patches.object[tg]
    for o in np.unique(obj):
        sel = obj == o
        a = patches.area[tg][sel]
        rec = {"radiosity_mean": (radiosity[tg][sel] * a[:, None]).sum(axis=0) / a.sum(),
               "unread_patches": int(np.sum(~ok[sel])), "patches": int(np.sum(sel & ok))}
        lux_target = None if asked_lux is None else asked_lux[tg][sel]
        if lux_target is not None and np.any(lux_target > 0):  # its illuminance targets (lx), area-weighted
            w = a * (lux_target > 0)
            rec["target_lx"] = float((w * lux_target).sum() / w.sum())
        use = sel & ok
        if use.any():
            w, x = patches.area[tg][use], lux[use]
            mean = float((w * x).sum() / w.sum())
            rec["illuminance_lx"] = {"mean": mean, "min": float(x.min()), "max": float(x.max()),
                                     "u0": float(x.min() / mean) if mean > 0 else None}
        out[model.faces.object_names[int(o)]] = rec
    return out


def light_colour_record(problem, options) -> dict:
    """The report's light colour: the mode the lights have (``mode``: free, white, blackbody with
    its ``range_K``), and the option that chose it (``option``: e.g. auto)."""
    colour = getattr(problem, "colour", None)
    rec = colour.summary() if colour is not None else {"mode": "free"}
    return {**rec, "option": getattr(options, "light_colour", "free")}


def target_rows_text(patches, targets) -> str:
    """What the relative error (Eq. 1) and the certificate are computed over: the painted faces
    themselves, pieces of them, or (painted faces far below the patch size) clusters of them."""
    tri = np.isin(patches.tri_patch, targets)
    pairs = np.unique(np.column_stack([patches.tri_patch[tri], patches.tri_face[tri]]), axis=0)
    faces_per_patch = np.bincount(pairs[:, 0], minlength=patches.n_patches)[targets]
    patches_per_face = np.bincount(pairs[:, 1])
    n_faces = int(np.count_nonzero(patches_per_face))
    clustered = int(np.count_nonzero(faces_per_patch > 1))
    split = int(np.count_nonzero(patches_per_face > 1))
    if clustered:
        return (f"{len(targets)} rows for {n_faces} painted faces ({clustered} rows clusters of painted faces below "
                "1/16 of the patch size)")
    return f"the {n_faces} painted faces" + (f" ({split} in pieces: {len(targets)} rows)" if split else "")


def summary_line(report, n_rows=None) -> str:
    """The Results panel's summary of a solve: the final configuration, what its error is over,
    the kinds of light, the scene's own light kept (``n_rows``: the configurations listed)."""
    f = report["final"]
    neg = f"{f['n_negative']} negative" if f["n_negative"] else "no negatives"
    over = report["inverse"].get("error_over")
    n = len(report["curve"]) if n_rows is None else n_rows
    text = (f"{f['n_lights']} lights, relative error {f['relative_error']:.3g}{f' over {over}' if over else ''}, "
            f"{neg} ({n} configurations on the curve); {kinds_text(report)}")
    colour = report.get("light_colour") or {}
    if colour.get("mode") not in (None, "free"):
        text += f"; {colour['mode']} lights" + (f" {colour['range_K'][0]:.0f}-{colour['range_K'][1]:.0f} K"
                                                 if "range_K" in colour else "")
    fixed = [r for r in report.get("fixed_light") or [] if r.get("share") is not None]
    if fixed:  # the scene's own light the solve kept, and its share of the painted light
        text += "; the scene's own light: " + ", ".join(f"{r['name']} {100 * r['share']:.0f} %" for r in fixed)
    return text


def fixed_light_rows(report) -> str:
    """The Results panel's list of the scene's own light: one line per lamp, World and emissive
    object the solve kept, "kind<TAB>name<TAB>share" (share of the targets' painted light)."""
    return "\n".join(f"{r['kind']}\t{r['name']}\t{r['share']:.6g}" for r in report.get("fixed_light") or []
                     if r.get("share") is not None)


def photometric_rows(report) -> str:
    """The Results panel's predicted light on the targets: one line per target object whose
    illuminance is read, "object<TAB>mean lx<TAB>min lx<TAB>U0<TAB>target lx or empty<TAB>patches"
    (U0 over one patch says nothing: the panel says so)."""
    return _photometric_text(report.get("targets_photometric") or {})


def _photometric_text(photometric) -> str:
    rows = []
    for name, rec in photometric.items():
        lx = rec.get("illuminance_lx")
        if lx:
            target = "" if rec.get("target_lx") is None else f"{rec['target_lx']:.6g}"
            rows.append(f"{name}\t{lx['mean']:.6g}\t{lx['min']:.6g}\t{(lx['u0'] or 0.0):.6g}\t{target}\t"
                        f"{rec.get('patches', 0)}")
    return "\n".join(rows)


def light_rows(report) -> str:
    """The Results panel's lights of the final configuration: one line per light,
    "name<TAB>kind<TAB>power W<TAB>luminous flux lm<TAB>temperature K or empty<TAB>mark" (mark:
    why the light is implausible, engine.plausibility.implausible_mark, or empty)."""
    return _light_text(report["final"]["lights"])


def _light_text(records) -> str:
    """A line per light (5 tabs), then the fixture schedule's lines (SCHEDULE_LINE, tab, the line) if any."""
    return "\n".join([f"{li['object']}\t{li['kind']}\t{li['power']:.6g}\t{li.get('luminous_flux_lm', 0.0):.6g}\t"
                      f"{'' if li.get('temperature_K') is None else format(li['temperature_K'], '.0f')}\t"
                      f"{implausible_mark(li)}" for li in records]
                     + [f"{SCHEDULE_LINE}\t{line}" for line in schedule_lines(fixture_schedule(records))])


#: the first field of the sidebar's lines of a fixture schedule (blender/ui/panels.py draws them)
SCHEDULE_LINE = "schedule"


def row_panels(model, curve) -> list:
    """What the Results panel lists for each kept configuration (``curve``'s rows): {"lights": its
    lights (light_rows' lines, each marked when implausible), "photometric": its predicted light on
    the targets (photometric_rows' lines)}, so the panel follows the row shown."""
    out = []
    for k in range(len(curve.exitance)):
        records = light_records(model, curve, k)
        photometric = {}
        if model.mode == "inverse":
            implausible_notes(model.problem, records, np.flatnonzero(np.any(curve.exitance[k] != 0, axis=1)))
            e = model.lights.patch_exitance(curve.exitance[k], model.patches.n_patches) + model.background
            photometric = target_photometry(model, curve.radiosity[k], e)
        out.append({"lights": _light_text(records), "photometric": _photometric_text(photometric)})
    return out


def kinds_text(report) -> str:
    """What kinds of light the solve offered and chose, in words: "offered 180 cell, 42 group, 1
    polygon, 72 spot; chose 1 cell, 2 spot" (the report's model.lights_by_kind and final.lights)."""
    offered = [f"{n} {k}" for k, n in report["model"]["lights_by_kind"].items() if n]
    chosen = {}
    for li in report["final"]["lights"]:
        chosen[li["kind"]] = chosen.get(li["kind"], 0) + 1
    return f"offered {', '.join(offered) or 'none'}; chose {', '.join(f'{n} {k}' for k, n in chosen.items()) or 'none'}"


def _nan_to_none(rows):
    """Rows (polygons) with a NaN channel as None (unpainted), the others as lists."""
    rows = np.asarray(rows)
    bad = np.isnan(rows).any(axis=1)
    return [None if b else r for b, r in zip(bad.tolist(), rows.tolist())]


def radiosity_report(faces, patches, options, form_factors, info: dict, polygon_radiosity: dict, cost: dict,
                     warnings: list, timings: dict) -> dict:
    """The JSON report of the forward command (README.md, "The radiosity command")."""
    return json_safe({
        "command": "radiosity",
        "units": {"radiosity": "W/m^2", "length": "m"},
        "scene": {"objects": len(faces.object_names), "faces": int(faces.n_faces), "patches": int(patches.n_patches)},
        "timings_s": timings,
        "estimate": {"memory_bytes": cost["memory_bytes"], "seconds": cost["seconds"]},
        "options": {"rays_per_patch": None if form_factors is None else int(form_factors.rays_per_patch),
                    "max_patch_size": float(patches.max_patch_size), "seed": int(options.seed)},
        "solver": {k: v for k, v in info.items() if k != "warnings"},
        "objects": {name: {"radiosity": rows} for name, rows in polygon_radiosity.items()},
        "warnings": warnings,
    })


def finish(report: dict, warnings: list | None = None, render_settings=None, normal_radiance=None,
           export_seconds=None, input_path=None) -> dict:
    """Complete a report with what the Blender layer measured: ``render_settings`` (block, its
    warnings) from light_paths.assess_*; ``normal_radiance`` {object: rows} from viewing.py (the
    reported objects only: instance groups are not); the export time and the input file. Each
    warning is added once to the report and to ``warnings`` (the outcome's, shown by the add-on)."""
    if render_settings is not None:
        block, warns = render_settings
        report["render_settings"] = json.loads(json.dumps(block, default=float))
        for w in warns:
            if warnings is not None and w not in warnings:
                warnings.append(w)
            if w not in report["warnings"]:
                report["warnings"].append(w)
    for name, rows in (normal_radiance or {}).items():
        if name in (report["objects"] or {}):
            report["objects"][name]["radiance_normal"] = json_safe(rows)
    if export_seconds is not None:
        report["timings_s"]["export"] = export_seconds
    if input_path is not None:
        report["input"] = input_path
    return report
