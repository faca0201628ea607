"""Units and the constants that convert them: the one place (no bpy).

Relight works in SI radiometric units: lengths in m, areas in m^2, radiosity B and exitance e
in W/m^2, power in W, radiance L in W/(m^2 sr). Blender's emission strength x colour, the
painted ``relight_target`` colours and the baked ``relight_radiosity`` layer are radiance; a
Lambertian (diffuse) surface of radiance L has exitance pi L. Photometric quantities use the
luminous efficacy of 683 lm/W and the luminance weights of linear Rec.709 (Blender's scene
linear colour space), so illuminance E_v (lx) = 683 x (0.2126 E_r + 0.7152 E_g + 0.0722 E_b)
with E in W/m^2 per channel.

Import these; never copy them.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["TINY", "MAX_REFLECTANCE", "MIN_REFLECTANCE_LUX", "LUMENS_PER_WATT", "REC709_LUMINANCE", "exitance_from_radiance",
           "radiance_from_exitance", "illuminance_lux", "irradiance_from_lux", "luminous_flux_lm", "luminance_cd",
           "luminance_weighted", "CYCLES_IES_LUMENS_PER_WATT", "CYCLES_IES_CANDELA_FACTOR", "cycles_ies_candela"]

#: a floor under a divisor (a norm, a length, a sum of weights), so that a zero stays zero instead
#: of dividing by zero: ``x / max(d, TINY)`` is ``x / d`` for any d a scene holds, and 0 where
#: d is 0 (and x with it); far below every physical quantity, so it never changes a result
TINY = 1e-300

#: reflectance of an exported material is clamped to [0, MAX_REFLECTANCE] (with a warning):
#: a reflectance of 1 or more creates energy; the engine's forward solver clamps to the same value
MAX_REFLECTANCE = 0.99

#: a face's illuminance is read from its radiosity (E = B / reflectance) where every channel
#: reflects at least this; an illuminance target on a face reflecting less is refused
MIN_REFLECTANCE_LUX = 0.01

#: luminous efficacy of the photometric standard: 683 lm per W at 555 nm
LUMENS_PER_WATT = 683.0

#: luminance weights of linear Rec.709 RGB (Blender's scene linear), summing to 1
REC709_LUMINANCE = (0.2126, 0.7152, 0.0722)


def exitance_from_radiance(radiance):
    """Exitance (W/m^2) of a Lambertian surface of radiance ``radiance`` (W/(m^2 sr)): pi L."""
    return math.pi * radiance


def radiance_from_exitance(exitance):
    """Radiance (W/(m^2 sr)) of a Lambertian surface of exitance or radiosity ``exitance`` (W/m^2): e / pi."""
    return exitance / math.pi


def luminous_flux_lm(power_rgb) -> np.ndarray:
    """Luminous flux (lm) of a radiant power (..., 3) in W per channel (a lamp's, a light's)."""
    return LUMENS_PER_WATT * (np.asarray(power_rgb, dtype=np.float64) @ np.asarray(REC709_LUMINANCE))


def irradiance_from_lux(lux) -> np.ndarray:
    """The irradiance (W/m^2 per channel, the same in each: white light) of an illuminance (lx):
    lux / 683 (the luminance weights sum to 1, so illuminance_lux of it gives the lux back)."""
    return np.asarray(lux, dtype=np.float64) / LUMENS_PER_WATT


def illuminance_lux(irradiance_rgb) -> np.ndarray:
    """Illuminance (lx) of an RGB irradiance (..., 3) in W/m^2 per channel."""
    return LUMENS_PER_WATT * (np.asarray(irradiance_rgb, dtype=np.float64) @ np.asarray(REC709_LUMINANCE))


def luminance_cd(radiance_rgb) -> np.ndarray:
    """Luminance (cd/m^2) of an RGB radiance (..., 3) in W/(m^2 sr) per channel."""
    return LUMENS_PER_WATT * luminance_weighted(radiance_rgb)


def luminance_weighted(rgb) -> np.ndarray:
    """The Rec.709 luminance-weighted mean of RGB values (..., 3) (the weights sum to 1)."""
    return np.asarray(rgb, dtype=np.float64) @ np.asarray(REC709_LUMINANCE)


#: the luminous efficacy Cycles assumes for an IES profile's candela (intern/cycles/util/ies.cpp,
#: ``IESFile::parse``: D65's 177.83 lm/W), not LUMENS_PER_WATT: the spectrum of a file is unknown
CYCLES_IES_LUMENS_PER_WATT = 177.83

#: what Cycles multiplies an IES file's candela by (with its multipliers) to get the IES Texture
#: node's value: 4 pi / 177.83 (its literal 0.0706650768394). A Point lamp of Power P (colour x
#: gain c) whose emission Strength is that value x the node's Strength S has the radiant intensity
#: I = c P S cd(direction) / 177.83 W/sr per channel (P / (4 pi) of an isotropic Point lamp, times
#: the node's value); Relight reads it in candela with 683 lm/W (``cycles_ies_candela``)
CYCLES_IES_CANDELA_FACTOR = 4.0 * math.pi / CYCLES_IES_LUMENS_PER_WATT


def cycles_ies_candela(power_rgb, candela) -> np.ndarray:
    """The luminous intensity (cd, Relight's 683 lm/W and Rec.709 weights) that Cycles renders from
    an IES profile of ``candela`` (as the file gives it, multipliers applied) on a Point lamp emitting
    ``power_rgb`` (3,) W per channel (colour x Power x its gain x the node's Strength):
    683 / 177.83 x luminance(power) x candela, 3.84 x the file's candela at 1 W of white."""
    return LUMENS_PER_WATT * luminance_weighted(power_rgb) * np.asarray(candela, dtype=np.float64) / \
        CYCLES_IES_LUMENS_PER_WATT
