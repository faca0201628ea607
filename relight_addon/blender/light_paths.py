"""Cycles light paths that render what Relight predicts, and what the scene's own would cost (bpy).

Relight predicts the converged radiosity: every bounce of light, nothing clamped. Cycles'
defaults render less: 4 diffuse bounces (Blender's default) cut the tail of the interreflections
(about 10 % of the light in a furnished room, issue 9), and the indirect clamp (default 10)
cuts the samples brighter than it, which small bright lights produce.

- ``matched_settings(rho_max)``: no direct or indirect clamping, reflective caustics on (a
  Principled BSDF's specular layer is otherwise dropped after a diffuse bounce), Filter Glossy
  off (it widens glossy lobes after a diffuse bounce without their energy compensation, so
  they lose light: measured ~4 % on floor targets of default Principled materials), and Diffuse,
  Glossy and Total bounces at least ``engine.bounces.required_bounces(rho_max)``, the limit
  after which less than 0.5 % of the light is left (rho_max^(limit + 2), Cycles keeping
  limit + 1 reflections; rho_max: the scene's largest effective reflectance, its white-furnace
  albedo). Bounce limits already higher are kept.
- ``match_light_paths(scene, rho_max)`` writes them (``--out`` and the "Match Cycles Light
  Paths" operator) and returns what it changed.
- ``assess(scene, F, reflectance, B, mask, area)``: the ``render_settings`` block of a report
  and its warnings: the scene's current settings, the estimated difference on the targets of
  rendering with its bounce limit (the engine's radiosity truncated after that many bounces,
  ``engine.bounces.bounce_deficit``), and a warning when clamping is on and the light is bright
  enough to reach it (its effect is not estimated).
"""
from __future__ import annotations

import numpy as np

from ..engine.bounces import TAIL, bounce_deficit, exitance_of, kept_terms, required_bounces
from ..engine.units import MAX_REFLECTANCE, radiance_from_exitance

__all__ = ["NOTICEABLE", "current_settings", "matched_settings", "match_light_paths", "scene_materials",
           "scene_max_reflectance",
           "assess", "assess_solve", "assess_radiosity", "snapshot"]

#: a difference on the targets above this (relative) is worth a warning
NOTICEABLE = 0.01
_KEYS = ("max_bounces", "diffuse_bounces", "glossy_bounces", "sample_clamp_direct", "sample_clamp_indirect",
         "caustics_reflective", "blur_glossy")


def current_settings(scene) -> dict:
    """The scene's Cycles light-path settings that change how much light is rendered."""
    c = scene.cycles
    out = {k: getattr(c, k) for k in _KEYS}
    out = {k: (bool(v) if isinstance(v, bool) else (int(v) if k.endswith("bounces") else float(v)))
           for k, v in out.items()}
    out["render_engine"] = scene.render.engine
    return out


def effective_bounces(settings: dict) -> int:
    """The bounce limit a diffuse-only path meets: min(Diffuse, Total)."""
    return int(min(settings["diffuse_bounces"], settings["max_bounces"]))


def checked_terms(settings: dict, rho_max: float) -> int:
    """The reflections ``assess`` truncates the radiosity after (``settings``: current_settings'):
    what the bounce limit keeps when it is short of required_bounces(rho_max), else 0 (the
    exitance alone is needed)."""
    n_eff = effective_bounces(settings)
    return kept_terms(n_eff) if n_eff < required_bounces(rho_max) else 0


def prepare_stroke_checks(products, settings: dict, reflectance, B0) -> None:
    """The products a Live stroke's ``assess`` reads (bounces.ColumnProducts: every light's and
    those of the fixed light's radiosity ``B0``), made before the first stroke (any thread;
    ``settings``: a ``snapshot``)."""
    rho = np.asarray(reflectance)
    n = checked_terms(settings["scene"], float(rho.max()) if rho.size else 0.0)
    products.of(B0, np.zeros((products.T[0].shape[1], 3)), n)


def matched_settings(rho_max: float, settings: dict | None = None) -> dict:
    """The light-path settings that render the converged, unclamped radiosity (see the module
    docstring); ``settings``: the current ones (higher bounce limits are kept)."""
    n = required_bounces(rho_max)
    cur = settings or {}
    return {"sample_clamp_direct": 0.0, "sample_clamp_indirect": 0.0, "caustics_reflective": True, "blur_glossy": 0.0,
            "diffuse_bounces": max(n, int(cur.get("diffuse_bounces", 0))),
            "glossy_bounces": max(n, int(cur.get("glossy_bounces", 0))),
            "max_bounces": max(n, int(cur.get("max_bounces", 0)))}


def match_light_paths(scene, rho_max: float) -> dict:
    """Write ``matched_settings`` into the scene's Cycles settings, and turn the work planes' Ray
    Visibility off (WORK_PLANE_VISIBILITY: light passes through them, as Relight models them);
    returns {setting: (old, new)} of what changed (the render engine is left alone)."""
    cur = current_settings(scene)
    want = matched_settings(rho_max, cur)
    changed = {}
    for k, v in want.items():
        if cur[k] != v:
            setattr(scene.cycles, k, v)
            changed[k] = (cur[k], v)
    from .layers import work_plane

    for ob in scene.objects:  # work planes: light passes through them, as Relight models them
        if ob.type == "MESH" and work_plane(ob):
            for k in WORK_PLANE_VISIBILITY:
                if getattr(ob, k, False):
                    setattr(ob, k, False)
                    changed[f"{ob.name}.{k}"] = (True, False)
    return changed


#: the Ray Visibility a work plane is given (the camera still sees it)
WORK_PLANE_VISIBILITY = ("visible_diffuse", "visible_glossy", "visible_transmission", "visible_volume_scatter",
                         "visible_shadow")


def describe(changed: dict) -> str:
    names = {"max_bounces": "Total bounces", "diffuse_bounces": "Diffuse bounces", "glossy_bounces": "Glossy bounces",
             "sample_clamp_direct": "Clamp Direct", "sample_clamp_indirect": "Clamp Indirect",
             "caustics_reflective": "Reflective Caustics", "blur_glossy": "Filter Glossy"}
    if not changed:
        return "the light paths already match"
    return ", ".join(f"{names.get(k, k)} {old:g} -> {new:g}" if not isinstance(new, bool) else
                     f"{names.get(k, k)} {'on' if new else 'off'}" for k, (old, new) in changed.items())


def scene_materials(context=None) -> dict:
    """{"max_reflectance", "max_glossy"}: the largest effective reflectance (white-furnace
    albedo, any channel) and the largest glossy share of it among the materials of the objects
    Relight exports (no material: the default grey)."""
    import bpy

    from .exported_materials import DEFAULT_REFLECTANCE
    from .visibility import exported_objects
    from .materials import surface_closure

    context = context or bpy.context
    seen, rho, glossy = set(), 0.0, 0.0
    for ob in exported_objects(context):
        for mat in [s.material for s in ob.material_slots] or [None]:
            key = None if mat is None else mat.name
            if key in seen:
                continue
            seen.add(key)
            if mat is None or mat.get("relight_generated"):
                r = DEFAULT_REFLECTANCE if mat is None else 0.0
            else:
                c = surface_closure(mat)
                r = float(np.max(c.reflectance))
                glossy = max(glossy, float(np.max(c.specular)))
            rho = max(rho, min(r, MAX_REFLECTANCE))
    return {"max_reflectance": rho, "max_glossy": glossy}


def scene_max_reflectance(context=None) -> float:
    """The largest effective reflectance among the exported objects' materials (``scene_materials``)."""
    return scene_materials(context)["max_reflectance"]


def snapshot(scene) -> dict:
    """What ``assess`` reads of the scene (its light-path settings and the largest glossy share of
    its materials), read once on the main thread: ``assess(None, ..., settings=snapshot(scene))``
    then runs in any thread (Live mode's worker)."""
    return {"scene": current_settings(scene), "max_glossy": scene_materials()["max_glossy"]}


def assess(scene, F, reflectance, B, mask=None, area=None, what="targets", glossy_share=None,
           settings=None, stroke=None) -> tuple:
    """(render_settings block, warnings) for radiosity ``B`` (P, 3) W/m^2 on patches of
    ``reflectance`` with form factors ``F``, if the scene is rendered with its current settings.
    ``mask``: the patches the difference is reported on (``what`` names them);
    ``glossy_share``: the largest glossy part of the materials' reflectance (whether Filter
    Glossy matters; default: read from the scene's materials). ``settings``: ``snapshot``'s,
    instead of reading the scene (no bpy). ``stroke``: (bounces.ColumnProducts, B0, e) when B is
    B0 + T e (a Live stroke's): its products with F from theirs, cached per light."""
    cur = current_settings(scene) if settings is None else dict(settings["scene"])
    if settings is not None and glossy_share is None:
        glossy_share = settings["max_glossy"]
    rho = np.asarray(reflectance, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    rho_max = float(rho.max()) if rho.size else 0.0
    n_req = required_bounces(rho_max)
    n_eff = effective_bounces(cur)
    block = {"scene": cur, "max_reflectance": rho_max, "tail": TAIL, "required_bounces": n_req,
             "matched": all(cur[k] == v for k, v in matched_settings(rho_max, cur).items()),
             "estimated_difference": None, "clamping": None, "filter_glossy": None, "written": None}
    warnings = []
    if cur["render_engine"] != "CYCLES":
        warnings.append(f"the scene renders with {cur['render_engine']}: the prediction is for Cycles (EEVEE "
                        "shows the emitters but not their multi-bounce indirect light; see docs/validation.md)")
    if F is None or not np.any(B > 0):
        return block, warnings
    truncated = None
    if stroke is not None:  # B = B0 + T e: rho F B and (rho F)^(n+1) B from the lights' columns'
        products, B0, strengths = stroke
        first, tail = products.of(B0, strengths, checked_terms(cur, rho_max))
        e, truncated = B - first, B - tail
    else:
        e = exitance_of(F, rho, B)  # the exitance that gives B (the lights' radiance; the truncation's start)
    if n_eff < n_req:
        d = bounce_deficit(F, rho, B, kept_terms(n_eff), mask, area, exitance=e, truncated=truncated)
        block["estimated_difference"] = {**d, "bounce_limit": n_eff, "of": what,
                                         "method": "engine radiosity truncated after the reflections the scene's "
                                                   "bounce limit keeps (Neumann series) against the converged one"}
        if d["mean"] < -NOTICEABLE:
            warnings.append(
                f"Cycles would render the {what} about {-100 * d['mean']:.1f} % darker than predicted with the "
                f"scene's light paths (Diffuse bounces {cur['diffuse_bounces']}, Total {cur['max_bounces']}; "
                f"up to {-100 * d['min']:.1f} % on a patch; estimated from the engine's radiosity "
                f"truncated after {kept_terms(n_eff)} reflections); {n_req} bounces are needed for reflectance "
                f"{rho_max:.2f}: "
                "use Match Cycles Light Paths (--out writes them)")
    _filter_glossy(cur, glossy_share, block, warnings)
    _clamping(cur, e, rho_max, block, warnings)
    return block, warnings


def _filter_glossy(cur, glossy_share, block, warnings) -> None:
    """``assess``'s Filter Glossy check: noted in ``block`` and named in ``warnings`` when the scene
    blurs glossy reflections and its materials have a glossy part."""
    if glossy_share is None:
        glossy_share = scene_materials()["max_glossy"]
    if cur["blur_glossy"] > 0 and glossy_share > 0.005:
        block["filter_glossy"] = {"setting": cur["blur_glossy"], "estimated": False}
        warnings.append(f"Filter Glossy is {cur['blur_glossy']:g}: Cycles widens glossy reflections after a diffuse "
                        "bounce without keeping their energy, so the specular layers render darker in indirect light "
                        "(measured ~4 % on targets of default Principled materials; not estimated here); use Match "
                        "Cycles Light Paths (--out turns it off)")


def _clamping(cur, e, rho_max, block, warnings) -> None:
    """``assess``'s clamping check: noted in ``block`` and named in ``warnings`` when the lights'
    radiance (from their exitance ``e``) reaches the scene's sample clamps."""
    radiance_max = float(radiance_from_exitance(max(e.max(), 0.0)))
    clamps = {k: cur[k] for k in ("sample_clamp_direct", "sample_clamp_indirect") if cur[k] > 0}
    if clamps:
        block["clamping"] = {"settings": clamps, "light_radiance_max": radiance_max, "estimated": False}
        hit = {k: v for k, v in clamps.items() if radiance_max * (rho_max if k.endswith("indirect") else 1.0) > v}
        if hit:
            what_c = " and ".join(f"{'indirect' if k.endswith('indirect') else 'direct'} clamping at {v:g}"
                                  for k, v in hit.items())
            warnings.append(f"{what_c}: the lights' radiance reaches {radiance_max:.3g} W/m^2/sr, so Cycles may "
                            "render darker than predicted (clamping effects are not estimated); use Match Cycles "
                            "Light Paths (--out turns clamping off)")


def assess_solve(scene, outcome, settings=None, products=None) -> tuple:
    """``assess`` for a solve's final configuration, on its target patches (``settings``: a
    ``snapshot``, no bpy). ``products``: the prepared state's bounces.ColumnProducts (a Live
    stroke's outcome: its radiosity the fixed light's plus its lights' columns of the transfer)."""
    problem, patches = outcome.problem, outcome.patches
    B = np.asarray(outcome.stored.radiosity[outcome.final_index], dtype=np.float64)
    mask = problem.target_mask
    what = "targets" if outcome.report.get("command") == "solve" else "lit faces"
    stroke = None
    if products is not None and problem.prepared_rows_transfer() is products.T:
        stroke = (products, problem.background_radiosity, outcome.stored.exitance[outcome.final_index])
    return assess(scene, problem.F, patches.reflectance, B, mask, patches.area, what, settings=settings,
                  stroke=stroke)


def assess_radiosity(scene, result) -> tuple:
    """``assess`` for a forward radiosity result, over every patch."""
    p = result.patches
    return assess(scene, result.form_factors, p.reflectance, result.patch_radiosity, None, p.area, "faces")
