"""Blackbody lights: each light is a power times the blackbody colour of a temperature in the
user's range (default 2,700-6,500 K), Blender's conversion (engine.light_colour.blackbody_rec709:
the Blackbody node's, a Light's ``temperature_color``). The selections run with each light at the
temperature it alone fits best; every configuration's temperatures are then refitted; the
certificate is the cone relaxation's (engine.light_colour)."""
from __future__ import annotations

import numpy as np

from ..light_colour import (blackbody_rec709, fit_colours, relaxed_bound, solo_temperatures,
                            temperature_grid, temperature_of)
from ..registry import LIGHT_COLOURS
from .blackbody_range import DEFAULT_RANGE, RANGE_PARAMS

@LIGHT_COLOURS.register("blackbody", "Blackbody", "Each light is a power times a blackbody colour, its "
                        "temperature in the range set (Blender's Blackbody colours)",
                        params=RANGE_PARAMS, relaxation=True)  # (its certificate: light_colour.relaxed_bound; engine/cost.py)
class Blackbody:
    name = "blackbody"
    free = False
    refits = True  # every configuration's temperatures refitted (engine.reduction.in_colour)

    def __init__(self, temperature_min=DEFAULT_RANGE[0], temperature_max=DEFAULT_RANGE[1]):
        self.range = (float(temperature_min), float(temperature_max))
        self.grid = temperature_grid(*self.range)  # (ValueError: a range outside Blender's, or reversed)
        self._solo = None  # (the problem's key, its lights' solo colours)

    def colours(self, problem) -> np.ndarray:
        """(n, 3) each light at the temperature it alone fits the targets best (the selection's)."""
        T = problem.transfer
        key = (id(problem), id(T[0]), id(T[1]), id(T[2]), id(problem.b_target))
        if self._solo is None or self._solo[0] != key:
            self._solo = (key, blackbody_rec709(solo_temperatures(problem, self.grid)))
        return self._solo[1]

    def fit(self, columns, b, colours, refit=True, upper=None):
        """(exitance (k, 3), error): the best powers and temperatures of these lights, from the
        temperatures of ``colours`` (k, 3) (``refit`` False: those temperatures, powers only)."""
        temps = temperature_of(colours, *self.range)
        e, err, _ = fit_colours(columns, b, blackbody_rec709(temps), temps if refit else None, self.range, upper)
        return e, err

    def certificate(self, problem, view, bounds, k_max):
        """The cone relaxation's bound (the view's is of its fixed temperatures only)."""
        return relaxed_bound(problem, self.range, k_max)

    def describe(self, exitance) -> list:
        """Per light (rows of ``exitance`` (k, 3)): its temperature, K (of the range's grid)."""
        temps = temperature_of(exitance, *self.range)
        return [{"temperature_K": float(t)} for t in temps]

    def summary(self) -> dict:
        return {"mode": self.name, "range_K": list(self.range), "temperature_steps": len(self.grid)}
