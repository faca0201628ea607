"""Closed-form diffuse form factors (J. R. Howell, "A Catalog of Radiation
Heat Transfer Configure Factors", cases C-11, C-14, C-41).

Pure math, used as the independent reference for the ray-cast form factors.
All three are the fraction of the power leaving surface 1 (a Lambertian
emitter) that arrives at surface 2. The point-to-rectangle configuration
factors (Howell B-3, B-2) and the enclosure's mean interreflected illuminance
are CIE 171:2006's analytical references (tests/test_cie171.py). ``*_polygons`` return the matching
geometry (surface 1 then surface 2, as (n, 3) vertex arrays whose fan
triangulation faces the other surface) for building test scenes with
``scene.polygon_faceset``; ``box_polygons`` is a closed box with
inward-facing walls.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = [
    "parallel_rectangles",
    "perpendicular_rectangles",
    "coaxial_disks",
    "parallel_rectangles_polygons",
    "perpendicular_rectangles_polygons",
    "coaxial_disks_polygons",
    "box_polygons",
    "point_parallel_rectangle",
    "point_perpendicular_rectangle",
    "point_to_parallel_rectangle",
    "point_to_perpendicular_rectangle",
    "enclosure_interreflected_illuminance",
]


def _positive(**kw):
    for name, v in kw.items():
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"{name} must be a positive finite length, got {v}")


def parallel_rectangles(a: float, b: float, c: float) -> float:
    """Identical, parallel, directly opposed rectangles a x b at distance c (Howell C-11)."""
    _positive(a=a, b=b, c=c)
    X, Y = a / c, b / c
    sx, sy = math.sqrt(1 + X * X), math.sqrt(1 + Y * Y)
    return 2.0 / (math.pi * X * Y) * (
        0.5 * math.log((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y))
        + X * sy * math.atan(X / sy)
        + Y * sx * math.atan(Y / sx)
        - X * math.atan(X)
        - Y * math.atan(Y)
    )


def perpendicular_rectangles(l: float, w: float, h: float) -> float:
    """Two rectangles at 90 degrees sharing an edge of length ``l`` (Howell C-14).

    Surface 1 has width ``w`` (perpendicular to the shared edge), surface 2 has
    height ``h``. Returns F_12.
    """
    _positive(l=l, w=w, h=h)
    W, H = w / l, h / l
    W2, H2 = W * W, H * H
    s = math.sqrt(H2 + W2)
    log_term = (
        math.log((1 + W2) * (1 + H2) / (1 + W2 + H2))
        + W2 * math.log(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2)))
        + H2 * math.log(H2 * (1 + H2 + W2) / ((1 + H2) * (H2 + W2)))
    )
    return (W * math.atan(1 / W) + H * math.atan(1 / H) - s * math.atan(1 / s) + 0.25 * log_term) / (math.pi * W)


def coaxial_disks(r1: float, r2: float, h: float) -> float:
    """Parallel coaxial disks, radius r1 (emitter) and r2, at distance h (Howell C-41)."""
    _positive(r1=r1, r2=r2, h=h)
    R1, R2 = r1 / h, r2 / h
    X = 1 + (1 + R2 * R2) / (R1 * R1)
    return 0.5 * (X - math.sqrt(X * X - 4 * (R2 / R1) ** 2))


def parallel_rectangles_polygons(a: float, b: float, c: float):
    """Rectangle a x b at z=0 facing +z, and its copy at z=c facing -z."""
    lo = np.array([[0, 0, 0], [a, 0, 0], [a, b, 0], [0, b, 0]], dtype=np.float64)
    hi = np.array([[0, 0, c], [0, b, c], [a, b, c], [a, 0, c]], dtype=np.float64)
    return [lo, hi]


def perpendicular_rectangles_polygons(l: float, w: float, h: float):
    """Shared edge along y (length l) at x=z=0; surface 1 (width w) in the plane
    z=0 (x in [0, w]) facing +z, surface 2 (height h) in the plane x=0 facing +x."""
    s1 = np.array([[0, 0, 0], [w, 0, 0], [w, l, 0], [0, l, 0]], dtype=np.float64)
    s2 = np.array([[0, 0, 0], [0, l, 0], [0, l, h], [0, 0, h]], dtype=np.float64)
    return [s1, s2]


def coaxial_disks_polygons(r1: float, r2: float, h: float, sides: int = 256):
    """Regular ``sides``-gons with the areas of disks r1 (z=0, facing +z) and r2
    (z=h, facing -z). Equal-area polygons: with 256 sides the polygon's
    circumradius differs from the disk radius by 0.01 % (1 - sqrt(sin(x)/x),
    x = 2 pi / sides), and its shape error changes the form factor less than that."""
    x = 2 * math.pi / sides
    k = math.sqrt(x / math.sin(x))  # circumradius / radius for equal area
    ang = np.arange(sides) * x
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(sides)], axis=1)
    d1 = ring * (r1 * k)
    d2 = (ring * (r2 * k))[::-1] + np.array([0.0, 0.0, h])
    return [d1, d2]


def box_polygons(size=(1.0, 1.0, 1.0)):
    """The six walls of an axis-aligned box [0, sx] x [0, sy] x [0, sz], facing inwards."""
    sx, sy, sz = size
    q = np.array
    return [
        q([[0, 0, 0], [sx, 0, 0], [sx, sy, 0], [0, sy, 0]], dtype=np.float64),  # floor, +z
        q([[0, 0, sz], [0, sy, sz], [sx, sy, sz], [sx, 0, sz]], dtype=np.float64),  # ceiling, -z
        q([[0, 0, 0], [0, sy, 0], [0, sy, sz], [0, 0, sz]], dtype=np.float64),  # x=0, +x
        q([[sx, 0, 0], [sx, 0, sz], [sx, sy, sz], [sx, sy, 0]], dtype=np.float64),  # x=sx, -x
        q([[0, 0, 0], [0, 0, sz], [sx, 0, sz], [sx, 0, 0]], dtype=np.float64),  # y=0, +y
        q([[0, sy, 0], [sx, sy, 0], [sx, sy, sz], [0, sy, sz]], dtype=np.float64),  # y=sy, -y
    ]


def point_parallel_rectangle(a: float, b: float, c: float) -> float:
    """A planar point element facing a parallel rectangle a x b at distance c, its normal through
    a corner of the rectangle (Howell B-3): the configuration factor, so that a Lambertian
    rectangle of exitance M gives the point the illuminance M x this. Odd in ``a`` and in ``b``
    (a signed corner, for superposition: ``point_to_parallel_rectangle``)."""
    _positive(c=c)
    if a == 0.0 or b == 0.0:
        return 0.0
    X, Y = abs(a) / c, abs(b) / c
    sx, sy = math.sqrt(1 + X * X), math.sqrt(1 + Y * Y)
    f = (X / sx * math.atan(Y / sx) + Y / sy * math.atan(X / sy)) / (2 * math.pi)
    return math.copysign(1.0, a) * math.copysign(1.0, b) * f


def point_perpendicular_rectangle(w: float, h: float, d: float) -> float:
    """A planar point element and a rectangle in a plane perpendicular to the element's, the
    rectangle's edge of length ``w`` lying in the element's plane at distance ``d`` from it, one end
    of that edge at the foot of the perpendicular from the element, the other side ``h`` rising in
    front of the element (Howell B-2): F = (atan(w/d) - d/s atan(w/s)) / (2 pi), s = sqrt(d^2 + h^2).
    Odd in ``w`` (a signed corner, for superposition: ``point_to_perpendicular_rectangle``)."""
    _positive(d=d)
    if w == 0.0 or h <= 0.0:
        return 0.0
    s = math.hypot(d, h)
    aw = abs(w)
    return math.copysign(1.0, w) * (math.atan(aw / d) - d / s * math.atan(aw / s)) / (2 * math.pi)


def point_to_parallel_rectangle(u0: float, u1: float, v0: float, v1: float, c: float) -> float:
    """A point element facing a parallel rectangle [u0, u1] x [v0, v1] (coordinates in the
    rectangle's plane, measured from the foot of the element's normal) at distance c: four
    signed corners of ``point_parallel_rectangle``."""
    f = point_parallel_rectangle
    return f(u1, v1, c) - f(u0, v1, c) - f(u1, v0, c) + f(u0, v0, c)


def point_to_perpendicular_rectangle(u0: float, u1: float, h0: float, h1: float, d: float) -> float:
    """A point element and a rectangle in a perpendicular plane at distance d: [u0, u1] along the
    line where the two planes meet (measured from the foot of the perpendicular from the element),
    [h0, h1] (0 <= h0 < h1) the heights above the element's plane, on the side it faces:
    ``point_perpendicular_rectangle`` by superposition."""
    if not (0.0 <= h0 < h1):
        raise ValueError(f"the rectangle must lie in front of the element: heights 0 <= h0 < h1, got {h0}, {h1}")
    f = point_perpendicular_rectangle
    return f(u1, h1, d) - f(u0, h1, d) - f(u1, h0, d) + f(u0, h0, d)


def enclosure_interreflected_illuminance(flux: float, area: float, reflectance: float) -> float:
    """A closed enclosure of total area ``area`` and one reflectance rho (< 1) everywhere, into
    which a source sends ``flux``: its area-mean interreflected illuminance Phi rho / (A (1 - rho))
    (flux conservation: every reflected lumen lands on the enclosure again; the integrating
    sphere's formula, CIE 171:2006's reference of its empty room). Uniform over a sphere; over
    any other enclosure this is the mean only."""
    if not (0.0 <= reflectance < 1.0):
        raise ValueError(f"reflectance must be in [0, 1), got {reflectance}")
    _positive(area=area)
    return flux * reflectance / (area * (1.0 - reflectance))
