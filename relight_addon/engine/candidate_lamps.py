"""Candidate lamps: Spot, Area and Point lamps offered beside the surface cells (no bpy).

From the patches that may hold lights (the candidate surfaces) and the painted targets, a solve
offers lamps as a lighting designer would mount them, each one light of the candidate set that
Best k Lights chooses from (engine/lights/spot.py, area.py, point.py; the cells stay):

- **Mounting positions.** The candidate patches are grouped into at most ``positions`` groups by
  k-means on their centres (with their normals, so that a ceiling and a wall are not mixed); each
  group's position is the candidate patch nearest its centroid, moved ``drop`` (m) in front of it
  along its normal. ``drop`` defaults to DROP_FRACTION of the scene's bounding-box diagonal (17 cm
  in issue 17's 6 x 5 x 3.2 m gallery), and a patch whose drop is blocked (something closer in
  front of it) mounts nothing.
- **Target regions.** The painted targets that ask for light are grouped by object, orientation
  (normal_bucket) and painted value; each group and its halves and quarters (split across its
  principal axis, down to about the patch size) is a *cluster*, ranked by the power it asks for
  (area x painted radiosity); the first MAX_CLUSTERS are aimed at.
- **Spots**: from every position that sees a cluster (VISIBLE_SHARE of its area), one spot whose
  cone just covers it: its axis the centre of the smallest cone holding every vertex of the
  cluster's patches (Badoiu-Clarkson iterations), its Spot Size twice that cone's half-angle and
  CONE_MARGIN more, blend SPOT_BLEND, radius 0. So each position has several cones, one per
  cluster it sees: the whole painting, its halves, the band around it, ...
- **Area lamps**: from every position, for each of the first AREA_CLUSTERS clusters it sees, a
  square of the light size s per beam of AREA_BEAMS: "wide", facing the cluster's centre at
  Spread 180 degrees (Lambertian, one-sided), and "cover", along the spot's axis (the smallest
  cone holding the cluster), at the Spread whose footprint just holds the cluster: with Cycles'
  Spread (engine.lamps) a point of the lamp lights only the directions within half the spread of
  its axis, so a point at depth t along the axis and rho from it is lit when the lamp's square
  comes within t tan(spread / 2) of its projection: tan(spread / 2) = the largest
  (rho - s / 2) / t of the cluster's vertices (at least MIN_PENUMBRA s / (2 t): where the square
  alone is wider than the cluster, a projector of it).
  Measured on issue 17's gallery with area lamps alone (``--area-lamps --no-spot-lamps``, 3
  lights): "wide" only 0.864 (no better than the cells), with "cover" 0.350 (docs/benchmarks.md).
- **Point lamps**: one per position (radius 0).

Each lamp kind offers its own lamps (engine/lights/: LampKind.offer_at at a position, offer_for per
cluster it sees; the spots' CONES and CONE_MARGIN in spot.py, the area lamps' AREA_BEAMS,
AREA_CLUSTERS and MIN_PENUMBRA in area.py); a kind is offered when its ``option`` is on.

The count is bounded by ``max_lamps`` (the positions are as many as it allows:
``positions_for``), so the cost estimate holds (engine.cost: ``lamp_bound``). Each lamp's source is
its direct irradiance per W on the patches its light can reach (engine.lamps.lamp_irradiance,
LAMP_POINTS receiver points per patch, shadow rays on the form factors' sampler); a lamp that
lights no patch is left out. Deterministic for a seed.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .geometry import unit
from .lamps import lamp_irradiance
from .lights import append_lamps, lamp_kinds
from .patch_models.adaptive import normal_bucket
from .scene import key_lengths, key_scale
from .units import TINY

__all__ = ["DROP_FRACTION", "offered_kinds", "default_drop", "lamp_bound", "plan_lamps",
           "offer_lamps", "lamps_irradiance", "lamp_key", "lamp_seed", "target_clusters", "mount_positions", "Cluster", "Mounting"]

#: the default drop in front of the candidate surfaces, x the scene's bounding-box diagonal
DROP_FRACTION = 0.02
#: target clusters aimed at (a kind aims at the first few it sees: engine/lights/spot.py, area.py)
MAX_CLUSTERS = 6
#: a cluster is split across its principal axis while its extent along it is above this many
#: patch sizes, at most SPLIT_DEPTH times (halves, quarters)
SPLIT_EXTENT = 2.0
SPLIT_DEPTH = 2
#: a position aims at a cluster when at least this share of the cluster's area sees it
VISIBLE_SHARE = 0.5
#: receiver points per patch of a candidate lamp's irradiance (engine.lamps)
LAMP_POINTS = 16
#: k-means iterations of the mounting positions
KMEANS_ITERATIONS = 12


@dataclass
class Cluster:
    """A target region aimed at: its patches, its area-weighted centre, the vertices of its
    patches' triangles and the power it asks for (W: area x painted radiosity, channels summed)."""

    patches: np.ndarray
    center: np.ndarray
    points: np.ndarray
    power: float


@dataclass
class Mounting:
    """A mounting position while the lamps are planned: the kinds offer their lamps there
    (LampKind.offer_at, offer_for: ``add``; ``count``: the lamps planned so far)."""

    patches: object
    position: np.ndarray
    normal: np.ndarray
    size: float  # the light size (m): an area lamp's side
    lamps: list
    kinds: list

    @property
    def count(self) -> int:
        return len(self.lamps)

    def add(self, kind, lamp) -> None:
        self.lamps.append(lamp)
        self.kinds.append(kind.name)


def offered_kinds(options) -> tuple:
    """The names of the kinds of candidate lamps the job offers (the lamp kinds whose ``option``
    is on, in registration order: "spot", "area", "point"), from its options (none when the
    chosen selection runs on single-scale cells: engine/options.py)."""
    return tuple(k.name for k in lamp_kinds() if k.option and options.param(k.option, False))


def _offered(options) -> list:
    """The LampKinds the job offers (``offered_kinds``), each as it offers for the job (``LampKind.offered``)."""
    return [k.offered(options) for k in lamp_kinds() if k.option and options.param(k.option, False)]


def default_drop(patches) -> float:
    """DROP_FRACTION x the diagonal of the region that decides the answer (engine.extent), else
    of the patches' bounding box (m)."""
    if patches.region is not None:
        return DROP_FRACTION * patches.region.diagonal
    v = patches.tri_vertices.reshape(-1, 3)
    return DROP_FRACTION * float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))


def _per_position(kinds, n_clusters, work=False) -> int:
    """The lamps a position holds for ``n_clusters`` clusters (LampKind.per_position of the
    ``kinds`` offered); ``work``: their receiver-point work instead, in a spot's."""
    return sum(k.per_position(min(n_clusters, MAX_CLUSTERS), work) for k in kinds)


def positions_for(max_lamps, kinds, n_clusters, n_candidates) -> int:
    """How many mounting positions ``max_lamps`` lamps allow (at least one when any kind is offered)."""
    per = _per_position(kinds, n_clusters)
    if per == 0 or n_candidates == 0:
        return 0
    return int(min(n_candidates, max(1, max_lamps // per)))


def lamp_bound(patches, candidates, options, work=False) -> int:
    """An upper bound of the number of candidate lamps ``plan_lamps`` makes (engine.cost): the
    most that its positions x lamps per position can be for any number of target clusters (more
    clusters, more lamps per position but fewer positions), and at most ``max_lamps``. ``work``:
    the bound of their receiver-point work instead, in spots (``_per_position``)."""
    kinds = _offered(options)
    if not kinds:
        return 0
    n_cand = int(np.count_nonzero(candidates))
    most = max(positions_for(options.max_lamps, kinds, n, n_cand) * _per_position(kinds, n, work)
               for n in range(1, MAX_CLUSTERS + 1))
    return int(most if work else min(options.max_lamps, most))


# -- target regions ---------------------------------------------------------------------------

def _patch_vertices(patches, idx):
    sel = np.isin(patches.tri_patch, idx)
    return np.unique(patches.tri_vertices[sel].reshape(-1, 3), axis=0)


def _splits(patches, idx, size, depth):
    """``idx`` and its halves across its principal axis (recursively, ``depth`` times) while its
    extent along the axis exceeds SPLIT_EXTENT x ``size``."""
    out = [idx]
    if depth == 0 or len(idx) < 2:
        return out
    c, w = patches.center[idx], patches.area[idx]
    mean = (c * w[:, None]).sum(axis=0) / w.sum()
    _, _, vt = np.linalg.svd((c - mean) * np.sqrt(w)[:, None], full_matrices=False)
    t = (c - mean) @ vt[0]
    if np.ptp(t) <= SPLIT_EXTENT * size:
        return out
    order = np.argsort(t, kind="stable")
    ts = t[order]
    cuts = np.flatnonzero(np.diff(ts) > 1e-6 * max(np.ptp(ts), TINY)) + 1  # between distinct positions
    if not len(cuts):
        return out
    cum = np.concatenate([[0.0], np.cumsum(w[order])])
    half = int(cuts[np.argmin(np.abs(cum[cuts] - 0.5 * w.sum()))])  # the cut nearest the area's median
    for part in (np.sort(idx[order[:half]]), np.sort(idx[order[half:]])):
        out.extend(_splits(patches, part, size, depth - 1))
    return out


def target_clusters(patches, max_clusters=MAX_CLUSTERS, aims=None) -> list:
    """The target regions aimed at (see the module docstring), most power first: the painted
    patches at their painted radiosity, and where none is painted the radiosity ``aims`` (P,)
    asks (engine.targets.target_aims' radiosity: a camera-view target's patches; grey)."""
    wanted = np.where(patches.target[:, None], patches.target_radiosity, 0.0)
    if aims is not None:
        more = (wanted.sum(axis=1) <= 0) & (np.asarray(aims) > 0)
        wanted[more] = np.asarray(aims)[more, None] / 3.0
    want = wanted.sum(axis=1)
    tg = np.flatnonzero(want > 0)
    if not len(tg):
        return []
    key = np.column_stack([patches.object[tg], normal_bucket(patches.normal[tg]), wanted[tg]])
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.reshape(-1)
    size = float(patches.max_patch_size)
    found = []
    for g in range(int(group.max()) + 1):
        for idx in _splits(patches, tg[group == g], size, SPLIT_DEPTH):
            w = patches.area[idx]
            found.append((float((w * want[idx]).sum()), idx))
    found.sort(key=lambda x: (-x[0], int(x[1][0]), len(x[1])))
    out = []
    for power, idx in found[:max_clusters]:
        w = patches.area[idx]
        out.append(Cluster(idx, (patches.center[idx] * w[:, None]).sum(axis=0) / w.sum(), _patch_vertices(patches, idx),
                           power))
    return out


# -- mounting positions -----------------------------------------------------------------------

def mount_positions(patches, candidates, count, drop, sampler) -> tuple:
    """(positions (M, 3), normals (M, 3), patches (M,)) of at most ``count`` mounting positions: the
    candidate patches nearest the centroids of k-means groups of the candidates (centres with
    their normals), moved ``drop`` along their normal; a patch whose drop is blocked is not used."""
    C = np.flatnonzero(candidates)
    if count <= 0 or not len(C):
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    n = patches.normal[C]
    o = (patches.center[C] + n * sampler.offset).astype(np.float32)
    free = sampler.visible(o, n.astype(np.float32), np.full(len(C), 1.5 * drop, dtype=np.float32))
    C, n = C[free], n[free]
    if not len(C):
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    v = patches.tri_vertices.reshape(-1, 3)
    scale = max(float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))), TINY)
    # in units of the scene's diagonal, ties (a symmetric room) broken alike at every scale
    X = np.column_stack([patches.center[C] / scale, 0.5 * n])
    w = patches.area[C]
    k = min(int(count), len(C))
    # farthest-point start (from the candidate nearest the candidates' centroid), then Lloyd
    first = _first_least(np.linalg.norm(X - (X * w[:, None]).sum(axis=0) / w.sum(), axis=1))
    centers = [X[first]]
    d = np.linalg.norm(X - centers[0], axis=1)
    for _ in range(1, k):
        j = _first_least(-d)
        centers.append(X[j])
        d = np.minimum(d, np.linalg.norm(X - X[j], axis=1))
    centers = np.array(centers)
    for _ in range(KMEANS_ITERATIONS):
        label = _first_least(((X[:, None, :] - centers[None, :, :]) ** 2).sum(axis=2))
        for j in range(k):
            m = label == j
            if m.any():
                centers[j] = (X[m] * w[m, None]).sum(axis=0) / w[m].sum()
    pick = np.unique([_first_least(np.linalg.norm(X - c, axis=1)) for c in centers])
    P = C[pick]
    return patches.center[P] + drop * patches.normal[P], patches.normal[P].copy(), P


def _first_least(v, tie=1e-9):
    """np.argmin along the last axis, a value within ``tie`` of the least taken as tied (the first
    of them wins): rounding does not decide between places a symmetric scene makes equal."""
    v = np.asarray(v)
    pick = np.argmax(v <= v.min(axis=-1, keepdims=True) + tie, axis=-1)
    return int(pick) if pick.ndim == 0 else pick


def _visible_share(sampler, position, cluster, patches):
    """The share of the cluster's area whose centre sees ``position`` (shadow rays)."""
    c = patches.center[cluster.patches]
    d = position[None, :] - c
    t = np.linalg.norm(d, axis=1)
    d = d / np.maximum(t, TINY)[:, None]
    o = (c + patches.normal[cluster.patches] * sampler.offset).astype(np.float32)
    ok = sampler.visible(o, d.astype(np.float32), np.maximum(t - 2 * sampler.offset, 0).astype(np.float32))
    ok &= (patches.normal[cluster.patches] * d).sum(axis=1) > 0
    w = patches.area[cluster.patches]
    return float(w[ok].sum() / w.sum())


def enclosing_cone(directions, iterations=64) -> tuple:
    """(axis, half-angle) of a small cone holding the unit ``directions`` (n, 3): Badoiu-Clarkson
    steps toward the farthest direction (within a few per cent of the smallest cone)."""
    a = unit(directions.mean(axis=0)[None, :])[0]
    if not np.any(a):
        a = directions[0].copy()
    for i in range(iterations):
        far = directions[int(np.argmin(directions @ a))]
        a = unit((a + (far - a) / (i + 2))[None, :])[0]
    return a, float(np.arccos(np.clip((directions @ a).min(), -1.0, 1.0)))


def plan_lamps(patches, candidates, options, sampler, drop=None, notes=None, aims=None) -> tuple:
    """The candidate lamps (no irradiance yet): ([engine.lamps.Lamp], [kind name]) as the module
    docstring says, for the job's options (``offered_kinds``, ``max_lamps``, ``lamp_drop``): at each
    mounting position, every offered kind's ``offer_at``, then for each cluster the position sees
    (in front of its mounting surface) every offered kind's ``offer_for``. ``notes``: a list that
    gets a warning when no lamp can hang (every drop blocked); ``aims`` (engine.targets.TargetAims):
    the radiosity the other target kinds ask (target_clusters) and their mounts, the first
    positions (a painted highlight's: its mirror ray's landing point on a candidate surface)."""
    kinds = _offered(options)
    if not kinds:
        return [], []
    clusters = target_clusters(patches, aims=None if aims is None else aims.radiosity)
    M = positions_for(options.max_lamps, kinds, max(len(clusters), 1), int(np.count_nonzero(candidates)))
    drop = float(options.lamp_drop if options.lamp_drop is not None else default_drop(patches)) if drop is None \
        else float(drop)
    pos, nrm, _ = mount_positions(patches, candidates, M, drop, sampler)
    if aims is not None and len(aims.mounts):  # (first: the plan is cut at max_lamps)
        on = candidates[aims.mount_patches]
        n = patches.normal[aims.mount_patches[on]]
        pos, nrm = np.concatenate([aims.mounts[on] + drop * n, pos]), np.concatenate([n, nrm])
    if M and not len(pos) and notes is not None:
        notes.append(f"no candidate lamp can hang {drop:.3g} m in front of the surfaces that may hold lights "
                     "(something closer is in front of every one): the lamps are not offered; use a smaller --lamp-drop")
    size = float(patches.light_size or patches.max_patch_size)
    lamps, names = [], []
    for p, n in zip(pos, nrm):
        mount = Mounting(patches, p, n, size, lamps, names)
        seen = [c for c in clusters if _visible_share(sampler, p, c, patches) >= VISIBLE_SHARE]
        for kind in kinds:
            kind.offer_at(mount)
        for rank, c in enumerate(seen):
            axis, half = enclosing_cone(unit(c.points - p[None, :]))
            if axis @ n <= 0:  # the cluster is behind the mounting surface
                continue
            for kind in kinds:
                kind.offer_for(mount, rank, c, axis, half)
    return lamps[:options.max_lamps], names[:options.max_lamps]


def patch_radius(patches, sampler=None) -> np.ndarray:
    """(P,) m: each patch's bounding radius about its centre (its farthest triangle vertex); kept
    on ``sampler`` (the solve's, of these patches) when given: the candidate lamps and the lamp
    refinement both ask (1 s on a million triangles)."""
    if sampler is not None:
        if "_patch_radius" not in sampler.__dict__:
            sampler._patch_radius = patch_radius(patches)
        return sampler._patch_radius
    radius = np.zeros(patches.n_patches)
    corner = np.linalg.norm(patches.tri_vertices - patches.center[patches.tri_patch][:, None, :], axis=2)
    np.maximum.at(radius, patches.tri_patch, corner.max(axis=1))
    return radius


def lamp_reach(patches, lamps, radius) -> list:
    """Per lamp, the patches its light can reach (its kind's ``reach``; ``radius``: the patches'
    bounding radii, ``patch_radius``)."""
    return [lamp.kind.reach(lamp, patches, radius) for lamp in lamps]


def lamp_key(lamp) -> bytes:
    """A candidate lamp's identity: its kind and geometry (position, aim, axes, power, radius, cone,
    blend, size, shape, spread, angle, shadows), not its name (its place in the plan): the same lamp
    planned at another place of another plan has the same key."""
    h = hashlib.sha1(lamp.kind.name.encode())
    for a in (lamp.position, lamp.direction, lamp.axis_u, lamp.axis_v, lamp.power):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    h.update(repr(_lamp_scalars(lamp)).encode())
    return h.digest()


def _lamp_scalars(lamp):
    return (float(lamp.radius), float(lamp.spot_size), float(lamp.spot_blend), float(lamp.size_u),
            float(lamp.size_v), bool(lamp.ellipse), float(lamp.spread), float(lamp.angle),
            bool(lamp.cast_shadow), lamp.profile is None)


def lamp_seed(lamp, seed, scale) -> int:
    """The seed of a candidate lamp's irradiance: the job's ``seed`` and a hash of the lamp's kind
    and geometry in scale-free steps (scene.key_lengths of ``scale``, scene.key_scale: lengths
    over it, directions and angles as they are), so its numbers depend neither on the other lamps
    planned, nor on its place among them, nor on the scene's unit."""
    h = hashlib.sha1(lamp.kind.name.encode())
    lengths = np.concatenate([np.ravel(lamp.position), [lamp.radius, lamp.size_u, lamp.size_v]])
    h.update(key_lengths(lengths, scale).tobytes())
    free = np.concatenate([np.ravel(lamp.direction), np.ravel(lamp.axis_u), np.ravel(lamp.axis_v),
                           np.ravel(lamp.power), [lamp.spot_size, lamp.spot_blend, lamp.spread, lamp.angle]])
    h.update(key_lengths(free, 1.0).tobytes())
    h.update(repr(_lamp_scalars(lamp)[5:]).encode())
    return ((int(seed) & 0xFFFFFFFFFFFFFFFF) << 64) | int.from_bytes(h.digest()[:8], "little")


def lamps_irradiance(patches, lamps, sampler, seed=0, progress=None) -> np.ndarray:
    """(P, len(lamps)) each candidate lamp's direct irradiance per W (engine.lamps.lamp_irradiance,
    LAMP_POINTS receiver points per patch) on the patches its light can reach (``lamp_reach``),
    each lamp on its own seed (``lamp_seed``): a lamp computed alone has the numbers it has among
    others (pipeline.prepared keeps them between solves)."""
    H = np.zeros((patches.n_patches, len(lamps)))
    if not lamps:
        return H
    reach = lamp_reach(patches, lamps, patch_radius(patches, sampler))
    scale = key_scale(patches.tri_vertices)
    for i, lamp in enumerate(lamps):
        H[:, i] = lamp_irradiance(patches, [lamp], sampler=sampler, seed=lamp_seed(lamp, seed, scale),
                                  points_per_patch=LAMP_POINTS, only=[reach[i]])[:, 0, 0]
        if progress is not None:
            progress((i + 1) / len(lamps))
    return H


def offer_lamps(lights, patches, candidates, options, sampler, seed=0, progress=None, notes=None, aims=None):
    """``lights`` (the surface lights; None: none, over the candidate patches ``candidates``)
    followed by the candidate lamps (``plan_lamps``) that light at least one patch, each a light
    of its kind whose source is its direct irradiance per W (engine.lamps). Returns
    (LightSet, number of lamps planned); ``notes`` gets plan_lamps' warning; ``aims``: its."""
    lamps, kinds = plan_lamps(patches, candidates, options, sampler, notes=notes, aims=aims)
    if not lamps:
        return lights, 0
    H = lamps_irradiance(patches, lamps, sampler, seed, progress)
    lit = np.flatnonzero(H.max(axis=0) > 0)
    area = np.array([lamps[i].kind.area(lamps[i]) for i in lit])
    return append_lamps(lights, np.flatnonzero(candidates), patches.n_patches, [lamps[i] for i in lit],
                        [kinds[i] for i in lit], H[:, lit], area), len(lamps)
