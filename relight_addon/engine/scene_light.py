"""The light a scene already has besides its emissive materials: its lamps and its World (no bpy).

``scene_light`` casts their direct irradiance on the patches (engine.lamps, engine.world), one
column per lamp and then the World's; ``scene_light_excess`` is the lamps' first reflection beyond
rho H (engine.first_reflection). A solve keeps this light fixed (``fixed_light_shares``: each
one's share of the targets; ``brighter_than_painted``: the target objects it alone already makes
brighter than painted). The direct-lighting mode ("reduce") reduces the scene's lamps instead:
``direct_lights`` makes them lights (engine/lights/lamp.py), and ``scene_light_at`` gives their
light in a configuration; ``placed_light_at`` is the direct light of a solve's placed lamps.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .first_reflection import incidence_of
from .incidence import lamp_albedo_excess
from .lamps import lamp_irradiance
from .lights import candidate_mask
from .lights.lamp import add_lamps
from .scene import FaceSet, PatchSet, SceneError
from .world import world_irradiance

__all__ = ["ALREADY_BRIGHTER", "has_scene_light", "scene_light", "scene_light_excess", "direct_lights",
           "scene_light_at", "placed_light_at", "fixed_light_shares", "brighter_than_painted"]

#: a target object whose fixed light alone exceeds the painted radiosity by more than this is named
ALREADY_BRIGHTER = 0.05


def has_scene_light(faces: FaceSet) -> bool:
    """Whether the scene has lamps or a World that lights it (engine.lamps)."""
    return bool(faces.lamps) or faces.world_radiance is not None


def scene_light(faces: FaceSet, patches: PatchSet, F, seed=0) -> tuple:
    """The light the scene already has, besides its emissive materials: (H (P, n, 3) W/m^2, the
    direct irradiance of each lamp and of the World (engine.lamps); [(name, kind, power)] per
    column). Shadow and sky rays are cast on the form factors' sampler (one Embree scene)."""
    sampler = getattr(F, "sampler", None)
    cols = [lamp_irradiance(patches, faces.lamps, sampler=sampler, seed=seed)]
    names = [(lamp.name, lamp.kind.blender_type.lower(), lamp.power) for lamp in faces.lamps]
    if faces.world_radiance is not None:
        M = getattr(F, "matrix", F)
        rows = np.asarray(M.sum(axis=1), dtype=np.float64).reshape(-1)
        cols.append(world_irradiance(patches, faces.world_radiance, sampler=sampler, seed=seed,
                                     sky_share=1.0 - rows)[:, None, :])
        names.append((faces.world_name or "World", "world", None))
    return np.concatenate(cols, axis=1), names


def scene_light_excess(faces: FaceSet, patches: PatchSet, H, only=None):
    """(P, 3) W/m^2: the scene's lamps' first reflection beyond rho H (``H`` scene_light's, the
    lamps' columns first; the World's light, from every direction, has none), of lamp ``only``
    alone when given; None without it."""
    inc = incidence_of(faces, patches)
    which = range(len(faces.lamps)) if only is None else [only] if only < len(faces.lamps) else []
    if inc is None or not which:
        return None
    return sum(lamp_albedo_excess(faces.lamps[i], patches.center, patches.normal, *inc) * H[:, i] for i in which)


def direct_lights(faces: FaceSet, patches: PatchSet, F, surface, seed=0) -> tuple:
    """Direct-lighting mode: the lights to reduce -- the emitter polygons (``surface``, a LightSet,
    or None without any) followed by the scene's lamps (engine/lights/lamp.py: each a light whose
    source is its direct irradiance per unit of its power) -- and the fixed light (the World).
    Returns (lights, (light indices, faces.lamps indices) of the lamps, H (P, n, 3) W/m^2 and
    [(name, kind, power)] of the fixed light, the names of the lamps that light no face). A lamp
    that lights no face is left out of the reduction (the written copy leaves it as it is); a lamp
    of negative power (Cycles renders it as negative light: blender/lamps.py) is fixed light, as
    the World is."""
    P = patches.n_patches
    H, names = scene_light(faces, patches, F, seed) if has_scene_light(faces) else (np.zeros((P, 0, 3)), [])
    n = len(faces.lamps)
    negative = [i for i, lamp in enumerate(faces.lamps) if np.any(lamp.power < 0)]
    unit = np.zeros((P, n))
    for i, lamp in enumerate(faces.lamps):  # H is the lamp's irradiance per W times its power per channel
        if i not in negative:
            c = int(np.argmax(lamp.power))
            unit[:, i] = H[:, i, c] / lamp.power[c]
    lit = np.flatnonzero(unit.max(axis=0) > 0) if n else np.zeros(0, dtype=np.int64)
    dark = [faces.lamps[i].name for i in range(n) if i not in set(lit.tolist()) and i not in negative]
    if surface is None and not len(lit):
        neg = [repr(faces.lamps[i].name) for i in negative]
        raise SceneError("nothing to reduce: no material emits and no lamp lights any face"
                         + (f" ({', '.join(dark[:5])}{' ...' if len(dark) > 5 else ''})" if dark else "")
                         + (f"; lamp(s) of negative power are not reduced: {', '.join(neg[:5])}" if neg else ""))
    C = np.flatnonzero(candidate_mask(patches, "direct"))
    n0 = 0 if surface is None else surface.n_lights
    lights = add_lamps(surface, C, P, [faces.lamps[i] for i in lit], unit[:, lit], patches.area)
    fixed = negative + list(range(n, H.shape[1]))
    return lights, (n0 + np.arange(len(lit)), lit), H[:, fixed], [names[k] for k in fixed], dark


def scene_light_at(faces: FaceSet, lights, lamp_lights, fixed_H, fixed_names, strength) -> np.ndarray:
    """(P, n, 3) W/m^2: the direct light of ``faces.lamps`` and then of the World (scene_light's
    columns) in the configuration ``strength`` (n_lights, 3) of the direct-lighting mode: each
    lamp at its strength in that configuration (0 when reduced away; a lamp outside the reduction
    as it is). ``lamp_lights``, ``fixed_H``, ``fixed_names``: direct_lights'."""
    if lamp_lights is None:
        return fixed_H
    P = fixed_H.shape[0]
    cols = np.zeros((P, len(faces.lamps), 3))
    H = sp.csc_matrix(lights.irradiance)
    for j, i in zip(*lamp_lights):
        cols[:, i] = H[:, j].toarray() * np.asarray(strength, dtype=np.float64)[j][None, :]
    index = {lamp.name: i for i, lamp in enumerate(faces.lamps)}
    fixed = [(k, index[name]) for k, (name, kind, _) in enumerate(fixed_names or []) if kind != "world"]
    for k, i in fixed:  # a lamp of negative power: fixed light, in its own column
        cols[:, i] = fixed_H[:, k]
    rest = [k for k in range(fixed_H.shape[1]) if k not in {k for k, _ in fixed}]
    return np.concatenate([cols, fixed_H[:, rest]], axis=1)


def placed_light_at(lights, strength) -> list:
    """[(engine.lamps.Lamp, (P, 3) W/m^2)]: the direct light of each placed lamp (engine/lights/
    spot.py, area.py, point.py) of ``lights`` (a LightSet) that is on in the configuration
    ``strength`` (n_lights, 3)."""
    if lights.irradiance is None:
        return []
    H = sp.csc_matrix(lights.irradiance)
    out = []
    for j in np.flatnonzero(np.any(np.asarray(strength) > 0, axis=1)):
        if lights.kind_of(j).writer == "placed":
            out.append((lights.lamp(j), H[:, j].toarray() * np.asarray(strength, dtype=np.float64)[j][None, :]))
    return out


def fixed_light_shares(faces: FaceSet, patches: PatchSet, problem, H, names, background, excess=True) -> list:
    """The scene's own light that a solve keeps, per lamp and the World (``H``, ``names``:
    scene_light's columns) and per emissive object (``background``, (P, 3) W/m^2): [{"name",
    "kind", "power", "share"}], its share of the targets' radiosity (painted; direct mode: the
    scene's), area-weighted, channels summed (None when the targets ask for none). ``excess``:
    the lamps' first reflection at its incidence counted (as the inverse problem counts it)."""
    tg = problem.targets
    w = problem.area[tg]
    painted = float(np.sum(w[:, None] * (problem.b_target + problem.background_radiosity[tg])))
    zero = np.zeros((patches.n_patches, 3))

    def share(B):
        return float(np.sum(w[:, None] * B[tg]) / painted) if painted > 0 else None

    rows = []
    for i, (name, kind, power) in enumerate(names or []):
        ex = scene_light_excess(faces, patches, H, i) if excess else None
        B = problem.forward_radiosity(zero, H[:, i], ex)
        rows.append({"name": name, "kind": kind, "power": power, "share": share(B)})
    emitting = np.any(background > 0, axis=1)
    for oi in np.unique(patches.object[emitting]):
        e = np.where((patches.object == oi)[:, None], background, 0.0)
        rows.append({"name": faces.object_names[oi], "kind": "emission", "power": None,
                     "share": share(problem.forward_radiosity(e))})
    return rows


def brighter_than_painted(faces: FaceSet, patches: PatchSet, problem, margin=ALREADY_BRIGHTER) -> list:
    """[(object name, got / want)]: the target objects whose fixed light alone (the problem's
    background radiosity) exceeds their painted radiosity by more than ``margin``."""
    tg = problem.targets
    out = []
    B_bg = problem.background_radiosity
    for oi in np.unique(patches.object[tg]):
        sel = tg[patches.object[tg] == oi]
        want = float(np.sum(problem.area[sel, None] * patches.target_radiosity[sel]))
        got = float(np.sum(problem.area[sel, None] * B_bg[sel]))
        if want > 0 and got > want * (1 + margin):
            out.append((faces.object_names[oi], got / want))
    return out
