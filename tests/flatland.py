"""Exact 2-D ("flatland") radiosity scenes for the inverse and reduction tests.

The paper's figures 3-10 are 2-D views of rooms. In 2-D, Hottel's
crossed-strings rule gives the exact diffuse form factor between two mutually
visible segments i, j of a convex enclosure:

    F_ij = (crossed strings - uncrossed strings) / (2 L_i)

so these scenes carry closed-form form factors (reciprocity L_i F_ij = L_j F_ji
and closed-room row sums of exactly 1 hold to rounding), independent of the
engine's ray-cast form factors. "Area" is the segment length (m), centres and
normals are embedded in 3-D with z = 0.
"""
from __future__ import annotations

import numpy as np


def crossed_strings(a, b):
    """Form factors (n, n) between segments a[i] -> b[i] of a convex polygon (no occlusion)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    d = lambda p, q: np.linalg.norm(p[:, None, :] - q[None, :, :], axis=2)  # noqa: E731
    p1 = d(a, a) + d(b, b)
    p2 = d(a, b) + d(b, a)
    L = np.linalg.norm(b - a, axis=1)
    F = np.abs(p2 - p1) / (2.0 * L[:, None])
    # segments on one line (same wall) do not see each other
    t = (b - a) / L[:, None]
    nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)
    off = np.abs(np.einsum("ik,ijk->ij", nrm, a[None, :, :] - a[:, None, :]))
    same_line = (np.abs(nrm @ nrm.T) > 1 - 1e-12) & (off < 1e-12) & (off.T < 1e-12)
    F[same_line] = 0.0
    return F


def room(width=4.0, height=3.0, n_per_wall=(8, 6, 8, 6), reflectance=0.5):
    """A closed rectangular 2-D room [0, width] x [0, height], walls split into equal segments.

    Walls in order: floor (y=0), right (x=width), ceiling (y=height), left (x=0),
    counter-clockwise, normals pointing inside. Returns a dict with F, area,
    center (P, 3), normal (P, 3), wall (P,) names, pos (P,) coordinate along the
    wall (x for floor/ceiling, y for walls), reflectance (P, 3).
    """
    W, H = float(width), float(height)
    corners = [((0, 0), (W, 0), (0, 1), "floor"), ((W, 0), (W, H), (-1, 0), "right"),
               ((W, H), (0, H), (0, -1), "ceiling"), ((0, H), (0, 0), (1, 0), "left")]
    A, B, N, wall, pos = [], [], [], [], []
    for (p, q, nr, name), k in zip(corners, n_per_wall):
        p, q = np.asarray(p, float), np.asarray(q, float)
        for i in range(k):
            s, t = p + (q - p) * i / k, p + (q - p) * (i + 1) / k
            A.append(s)
            B.append(t)
            N.append(nr)
            wall.append(name)
            mid = 0.5 * (s + t)
            pos.append(mid[0] if name in ("floor", "ceiling") else mid[1])
    A, B = np.asarray(A), np.asarray(B)
    F = crossed_strings(A, B)
    P = len(A)
    center = np.zeros((P, 3))
    center[:, :2] = 0.5 * (A + B)
    normal = np.zeros((P, 3))
    normal[:, :2] = np.asarray(N, float)
    rho = np.broadcast_to(np.asarray(reflectance, dtype=np.float64), (P, 3)) if np.ndim(reflectance) <= 1 \
        else np.asarray(reflectance, dtype=np.float64)
    return dict(F=F, area=np.linalg.norm(B - A, axis=1), center=center, normal=normal,
                wall=np.asarray(wall), pos=np.asarray(pos), reflectance=np.array(rho, dtype=np.float64))
