"""Is a light one a lighting designer would hang? (no bpy)

Two measures, both independent of the scene's scale and units:

- **utilisation**: the share of a light's flux that arrives on the painted targets (the
  irradiance it gives them, interreflections included, times their area, over its power), as a
  designer's utilisation factor (0.3-0.7 for a work plane under ceiling luminaires). A light
  whose utilisation is below MIN_UTILISATION sends more than 99.9 % of its light elsewhere: to
  reach its targets it needs a power far beyond what they receive. It is named, with the best
  utilisation any candidate light of the scene reaches (when that too is low, no light of the
  scene reaches the targets well: they see the candidate surfaces at grazing angles, from far
  away, or only through reflections);
- **luminance** of a surface light (its exitance / pi, in cd/m^2): above MAX_LUMINANCE no
  luminaire's emitting surface is that bright (an LED downlight's aperture is about 10^5 cd/m^2;
  only the sun's disc, 1.6 x 10^9, is brighter).
"""
from __future__ import annotations

import numpy as np

from .units import luminance_cd, luminance_weighted, radiance_from_exitance

__all__ = ["MIN_UTILISATION", "MAX_LUMINANCE", "utilisation", "implausible_lights", "implausible_notes",
           "implausible_mark"]

#: below this share of its flux arriving on the targets, a light is named
MIN_UTILISATION = 1e-3
#: cd/m^2: a surface light brighter than this is named
MAX_LUMINANCE = 1e7
#: a target channel reflecting less than this is left out of the irradiance (its radiosity says
#: nothing of the light arriving there)
MIN_REFLECTANCE = 0.01


def utilisation(problem, lights=None) -> np.ndarray:
    """(n,) the share of each light's flux (of ``lights``, indices; all when None) that arrives on
    the targets of ``problem`` (an InverseProblem), averaged over the channels by their
    luminance weights: sum_t A_t E_t / P, with E_t = B_t / reflectance_t from the light's column
    of the transfer (radiosity per unit strength) and P its power per unit strength."""
    idx = np.arange(problem.n_lights) if lights is None else np.asarray(lights, dtype=np.int64)
    t = problem.targets
    rho = problem.reflectance[t]
    w = np.where(rho >= MIN_REFLECTANCE, problem.area[t][:, None] / np.where(rho >= MIN_REFLECTANCE, rho, 1.0), 0.0)
    flux = np.stack([w[:, c] @ problem.transfer[c][:, idx] for c in range(3)], axis=1)  # (n, 3) W per unit strength
    watts = np.asarray(problem.light_watts, dtype=np.float64)[idx]
    return np.where(watts > 0, luminance_weighted(flux) / np.where(watts > 0, watts, 1.0), 0.0)


def implausible_lights(problem) -> np.ndarray:
    """(n_lights,) bool: the candidate lights a solve leaves out, those that send less than
    MIN_UTILISATION of their light to the targets while another sends at least 10 x that (when
    none does, none is left out, and the final lights are named with the cause instead)."""
    u = utilisation(problem)
    if not len(u) or u.max() < 10 * MIN_UTILISATION:
        return np.zeros(len(u), dtype=bool)
    return u < MIN_UTILISATION


def implausible_notes(problem, records, chosen) -> list:
    """Warnings naming the lights of a configuration (``chosen``: light indices, ``records``: their
    report records, in that order) that send less than MIN_UTILISATION of their light to the
    targets, or whose surface is brighter than MAX_LUMINANCE; each record gets its
    ``utilisation``."""
    if not len(chosen):
        return []
    u = utilisation(problem, chosen)
    best = None
    notes = []
    for rec, share in zip(records, u):
        rec["utilisation"] = float(share)
        what = f"{rec['object']} ({rec['kind']}, {rec['power']:.3g} W)"
        if share < MIN_UTILISATION:
            if best is None:
                best = float(utilisation(problem).max())
            why = ("no candidate light reaches the targets well (the best sends "
                   f"{best:.2%} of its light to them): they see the allowed surfaces at grazing angles, from far away "
                   "or only through reflections; allow lights nearer the targets" if best < 10 * MIN_UTILISATION else
                   f"other candidate lights send up to {best:.2%} of theirs")
            notes.append(f"{what} sends {share:.3%} of its light to the painted targets: {why}")
        cd = _luminance(rec)
        if cd > MAX_LUMINANCE:
            notes.append(f"{what} is {cd:.3g} cd/m^2 bright, more than any luminaire's emitting surface "
                         f"({MAX_LUMINANCE:.0e} cd/m^2): a small light asked for much light")
    return notes


def _luminance(rec) -> float:
    """A surface light's luminance (cd/m^2) from its report record; 0 for a lamp."""
    if rec.get("exitance") is None:
        return 0.0
    return float(luminance_cd(radiance_from_exitance(np.asarray(rec["exitance"], dtype=np.float64))))


def implausible_mark(rec) -> str:
    """A few words marking a light whose record (with its ``utilisation``, implausible_notes') is
    implausible, for a list of lights; "" when it is not."""
    share = rec.get("utilisation")
    if share is not None and share < MIN_UTILISATION:
        return f"{share:.2%} reaches the targets"
    cd = _luminance(rec)
    return f"{cd:.2g} cd/m\u00b2" if cd > MAX_LUMINANCE else ""
