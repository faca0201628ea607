"""A luminaire's measured light distribution, and how Cycles renders it (no bpy).

``Photometry`` is what a photometric file says (LM-63, lm63.py; EULUMDAT, eulumdat.py): its
angles and candela, multipliers applied. ``CyclesProfile`` is that table as Cycles' IES Texture
node evaluates it, read from Cycles' source (Blender 4.2 to 5.x):

- ``intern/cycles/util/ies.cpp``, ``IESFile::parse``: only the text from the first line starting
  ``TILT=`` is read (the keywords before it are not); commas are blanks. TILT=INCLUDE: its block
  is skipped; TILT=NONE or a file name: the rest of that line is skipped. **The tilt is ignored.**
  Then the number of lamps, the lumens per lamp (**ignored**: the candela are absolute), the
  candela multiplier, the numbers of vertical and horizontal angles, the photometric type (1 C,
  2 B, 3 A), the units and the luminous opening's width, length and height (**ignored**: the
  emitter is the lamp's own point or sphere), the ballast factor and the ballast-lamp photometric
  factor (both **multiply** the candela, as the multiplier does), the input watts (ignored). Every
  candela is multiplied by 4 pi / 177.83 (``engine.units.CYCLES_IES_CANDELA_FACTOR``: D65's
  luminous efficacy, 177.83 lm/W, not 683).
- ``IESFile::process_type_c``: horizontal angles starting at 90 are shifted down by 90 (a file of
  90..270 becomes 0..180); one horizontal angle: the distribution is the same in every plane;
  a last angle of 90 is mirrored to 180 (180 - h), then a last angle of 180 to 360 (360 - h); a
  table that stops one step short of 360 gets its 0 plane again at 360. Vertical angles as given
  (0..90, 0..180, 90..180). ``process_type_b``: the table is transposed (the horizontal angles
  become the vertical ones) and each axis covering 0..90 is mirrored to -90..90, then every axis
  is shifted by +90: a type B file renders as a type C table with its axes swapped, whatever
  type B's horizontal polar axis should be. (Type A, which Relight refuses, is shifted likewise.)
- ``kernel/util/ies.h``, ``kernel_ies_interp`` and ``svm_node_ies`` (``kernel/svm/ies.h``): the
  direction in the lamp's own frame (X, Y, Z of its object; a lamp shines along -Z), normalised;
  vertical angle v = acos(-z) (0 straight down the lamp's -Z), horizontal angle
  h = atan2(x, y) + pi (so h = 0 along the lamp's -Y, 90 along -X, 180 along +Y, 270 along +X).
  Outside the table's angles (v < first or v >= last, h likewise) the value is 0. Within,
  Catmull-Rom cubic interpolation (``cubic_interp``) along v in each of the four horizontal
  planes about h (the points beyond an end: the neighbour mirrored at v = 0 when the table starts
  at 0, at v = 180 when it ends at 180, else the end value repeated), then along h (wrapping
  around when the table covers 0..360), clamped at 0. Angles are float32 as Cycles keeps them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..units import CYCLES_IES_CANDELA_FACTOR, TINY

__all__ = ["Photometry", "PhotometryError", "CyclesProfile", "TYPE_A", "TYPE_B", "TYPE_C"]

#: LM-63's photometric types
TYPE_C, TYPE_B, TYPE_A = 1, 2, 3
#: Cycles' angle comparisons (util/ies.cpp ``angle_close``)
ANGLE_CLOSE = 1e-4


class PhotometryError(ValueError):
    """A photometric file Relight cannot read: the message names the file's line and the cause."""


@dataclass(frozen=True)
class Photometry:
    """A luminaire's light distribution as its file gives it.

    v_angles (n_v,) and h_angles (n_h,) in degrees (type C: v from the nadir, h the C planes);
    candela (n_h, n_v): the luminous intensity with the file's multipliers applied, as Cycles
    applies them (the candela multiplier, the ballast factor, the ballast-lamp factor); lumens:
    the rated flux of the luminaire's lamps (n_lamps x lumens per lamp; -1: absolute photometry);
    watts: its input watts; size (width, length, height) m of its luminous opening (Cycles ignores
    it); tilt: the TILT line's value (NONE, INCLUDE or a file name; Cycles ignores it);
    keywords: the file's keywords ({"MANUFAC": ..., ...}); notes: what of the file is not
    modelled (as Cycles does not render it), each a short phrase.
    """

    photometric_type: int
    v_angles: np.ndarray
    h_angles: np.ndarray
    candela: np.ndarray
    lumens: float = -1.0
    n_lamps: int = 1
    watts: float = 0.0
    size: tuple = (0.0, 0.0, 0.0)
    tilt: str = "NONE"
    keywords: dict = field(default_factory=dict)
    notes: tuple = ()

    def __post_init__(self):
        v = np.asarray(self.v_angles, dtype=np.float64).reshape(-1)
        h = np.asarray(self.h_angles, dtype=np.float64).reshape(-1)
        c = np.asarray(self.candela, dtype=np.float64)
        if c.shape != (len(h), len(v)):
            raise PhotometryError(f"the candela table is {c.shape}, not (horizontal {len(h)}, vertical {len(v)})")
        object.__setattr__(self, "v_angles", v)
        object.__setattr__(self, "h_angles", h)
        object.__setattr__(self, "candela", c)

    def flux_lm(self, n=181) -> float:
        """The luminous flux (lm) of the distribution as Cycles renders it (integrated over the
        sphere, n x 2n directions): the luminaire's output, whatever its ``lumens`` field."""
        return CyclesProfile.of(self).flux(n) / CYCLES_IES_CANDELA_FACTOR


def cubic_interp(a, b, c, d, x):
    """Cycles' Catmull-Rom cubic (util/math_base.h)."""
    return 0.5 * (((d + 3.0 * (b - c) - a) * x + (2.0 * a - 5.0 * b + 4.0 * c - d)) * x + (c - a)) * x + b


@dataclass(frozen=True)
class CyclesProfile:
    """An IES profile as Cycles' kernel holds it: h (n_h,) and v (n_v,) float32 radians, values
    (n_h, n_v) float32, the file's candela x CYCLES_IES_CANDELA_FACTOR (W/sr per W of the lamp's
    Power x 4 pi: the factor of an isotropic Point lamp's radiance)."""

    h: np.ndarray
    v: np.ndarray
    values: np.ndarray

    @classmethod
    def of(cls, ph: Photometry) -> "CyclesProfile":
        """Cycles' processing of ``ph`` (IESFile::process; the module's docstring)."""
        h = [float(np.float32(x)) for x in ph.h_angles]
        v = [float(np.float32(x)) for x in ph.v_angles]
        rows = [list(np.float32(ph.candela[i] * CYCLES_IES_CANDELA_FACTOR)) for i in range(len(h))]
        close = lambda a, b: abs(a - b) < ANGLE_CLOSE  # noqa: E731
        if ph.photometric_type == TYPE_B:
            rows = [list(r) for r in zip(*rows)]  # transposed: (n_v, n_h)
            h, v = v, h
            if close(h[0], 0.0):
                n = len(h)
                h = [90.0 - h[i] for i in range(n - 1, 0, -1)] + [90.0 + x for x in h]
                rows = [rows[i] for i in range(n - 1, 0, -1)] + rows
            else:
                h = [x + 90.0 for x in h]
            if close(v[0], 0.0):
                n = len(v)
                v = [90.0 - v[i] for i in range(n - 1, 0, -1)] + [90.0 + x for x in v]
                rows = [[r[j] for j in range(n - 1, 0, -1)] + list(r) for r in rows]
            else:
                v = [x + 90.0 for x in v]
        elif ph.photometric_type == TYPE_C:
            if close(h[0], 90.0):
                h = [x - 90.0 for x in h]
            if len(h) == 1:
                h = [0.0, 360.0]
                rows = [rows[0], rows[0]]
            if close(h[-1], 90.0):
                n = len(h)
                h = h + [180.0 - h[i] for i in range(n - 2, -1, -1)]
                rows = rows + [rows[i] for i in range(n - 2, -1, -1)]
            if close(h[-1], 180.0):
                n = len(h)
                h = h + [360.0 - h[i] for i in range(n - 2, -1, -1)]
                rows = rows + [rows[i] for i in range(n - 2, -1, -1)]
            if close(h[0], 0.0) and not close(h[-1], 360.0) and len(h) > 1:
                gap = 360.0 - h[-1]
                if close(h[-1] - h[-2], gap) or close(h[1] - h[0], gap):
                    h = h + [360.0]
                    rows = rows + [rows[0]]
        else:
            raise PhotometryError(f"photometric type {ph.photometric_type} is not read (types C = 1 and B = 2)")
        f32 = np.float32
        return cls(np.array(h, dtype=f32) * f32(math.pi / 180), np.array(v, dtype=f32) * f32(math.pi / 180),
                   np.array(rows, dtype=f32))

    # -- evaluation ----------------------------------------------------------------------
    def at(self, h_angle, v_angle) -> np.ndarray:
        """The node's value (before its Strength) at horizontal and vertical angles (rad, arrays
        of one shape): kernel_ies_interp."""
        h_angle = np.asarray(h_angle, dtype=np.float64)
        v_angle = np.asarray(v_angle, dtype=np.float64)
        H, V, T = self.h.astype(np.float64), self.v.astype(np.float64), self.values.astype(np.float64)
        nh, nv = len(H), len(V)
        if nh < 2 or nv < 2:
            return np.zeros(np.broadcast(h_angle, v_angle).shape)
        inside = (v_angle >= V[0]) & (v_angle < V[-1]) & (h_angle >= H[0]) & (h_angle < H[-1])
        wrap_h = H[0] < 1e-7 and H[-1] > 2 * math.pi - 1e-7
        wrap_vlow = V[0] < 1e-7
        wrap_vhigh = V[-1] > math.pi - 1e-7
        # the first index whose next angle is >= the angle (Cycles' linear search), within the table
        hi = np.clip(np.searchsorted(H, h_angle, side="left") - 1, 0, nh - 2)
        vi = np.clip(np.searchsorted(V, v_angle, side="left") - 1, 0, nv - 2)
        hf = (h_angle - H[hi]) / np.maximum(H[hi + 1] - H[hi], TINY)
        vf = (v_angle - V[vi]) / np.maximum(V[vi + 1] - V[vi], TINY)

        def vertical(h_row):
            b, c = T[h_row, vi], T[h_row, vi + 1]
            a = np.where(vi > 0, T[h_row, np.maximum(vi - 1, 0)], T[h_row, 1] if wrap_vlow else b)
            d = np.where(vi + 2 < nv, T[h_row, np.minimum(vi + 2, nv - 1)], T[h_row, nv - 2] if wrap_vhigh else c)
            return cubic_interp(a, b, c, d, vf)

        b = vertical(hi)
        c = vertical(hi + 1)
        a = np.where(hi > 0, vertical(np.maximum(hi - 1, 0)), vertical(np.full_like(hi, nh - 2)) if wrap_h else b)
        d = np.where(hi + 2 < nh, vertical(np.minimum(hi + 2, nh - 1)), vertical(np.full_like(hi, 1)) if wrap_h else b)
        out = np.maximum(cubic_interp(a, b, c, d, hf), 0.0)
        return np.where(inside, out, 0.0)

    def along(self, local) -> np.ndarray:
        """The node's value along directions ``local`` (n, 3) in the lamp's frame (svm_node_ies)."""
        local = np.asarray(local, dtype=np.float64)
        w = local / np.maximum(np.linalg.norm(local, axis=-1, keepdims=True), TINY)
        v = np.arccos(np.clip(-w[..., 2], -1.0, 1.0))
        h = np.arctan2(w[..., 0], w[..., 1]) + math.pi
        return self.at(h, v)

    def flux(self, n=181) -> float:
        """The integral of the node's value over the sphere (midpoint rule, n x 2n cells)."""
        v = (np.arange(n) + 0.5) * math.pi / n
        h = (np.arange(2 * n) + 0.5) * math.pi / n
        hh, vv = np.meshgrid(h, v, indexing="ij")
        return float(np.sum(self.at(hh, vv) * np.sin(vv)) * (math.pi / n) ** 2)
