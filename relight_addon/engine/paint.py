"""What painted colour means (no bpy).

An artist who paints grey on an orange desk asks for *that brightness* on the desk, not for a
grey desk: Vertex Paint shows the paint, not the lit surface, and a grey brush is the one an
artist picks to say "this bright". Read literally (the desk's radiance grey), only a bluish
light gives it (the orange reflects little blue), and the automatic light colour answered grey
paint on warm surfaces with saturated blue lights (issue 34: the classroom's desks).

The rule: a painted colour whose chroma ((max - min) / max of its channels) is below
NEUTRAL_CHROMA is a brightness: the target is the radiance the surface has under white light of
that luminance, luminance(paint) x reflectance / luminance(reflectance) per channel (the same
Rec.709 luminance as the paint). A colour with chroma (the artist picked a hue) is asked for as
painted. Measured on the orange desk (reflectance 0.8, 0.4, 0.15; paint 0.35 grey; two ceiling
cells): read literally, the automatic light colour chose free colours, blue lights of exitance
(0.58, 1.16, 3.08) and (1.47, 2.99, 8.05) W/m^2; read as a brightness, blackbody lights of
(1.01, 0.95, 1.00) and (2.56, 2.41, 2.54) W/m^2, relative error 0.028, the desk's luminance 3 %
below the painted one (tests/test_engine_paint.py).
"""
from __future__ import annotations

import numpy as np

from .units import luminance_weighted

__all__ = ["NEUTRAL_CHROMA", "neutral_as_brightness"]

#: paint whose channels differ by less than this share of the largest is neutral (a brightness)
NEUTRAL_CHROMA = 0.02
#: a surface whose luminance reflectance is below this keeps its paint as painted (nothing to tint)
MIN_TINT_REFLECTANCE = 1e-3


def neutral_as_brightness(target, target_radiosity, reflectance) -> np.ndarray:
    """(F, 3) the targets' radiosity with every neutral paint read as a brightness on its face's
    reflectance (the module docstring); other faces as they are."""
    b = np.asarray(target_radiosity, dtype=np.float64)
    rho = np.asarray(reflectance, dtype=np.float64)
    top = b.max(axis=1)
    y_rho = luminance_weighted(rho)
    neutral = (np.asarray(target, dtype=bool) & (top > 0) & (b.max(axis=1) - b.min(axis=1) < NEUTRAL_CHROMA * top)
               & (y_rho >= MIN_TINT_REFLECTANCE))
    if not neutral.any():
        return b
    out = b.copy()
    out[neutral] = (luminance_weighted(b[neutral]) / y_rho[neutral])[:, None] * rho[neutral]
    return out
