"""White lights: each light is a power times white (1, 1, 1) in Blender's linear Rec.709, the
same light in every channel (engine.light_colour: the selections run on the stacked problem)."""
from __future__ import annotations

import numpy as np

from ..best_lights import lower_bounds
from ..light_colour import fit_colours
from ..registry import LIGHT_COLOURS


@LIGHT_COLOURS.register("white", "White", "Each light is a power times white")
class White:
    name = "white"
    free = False

    def colours(self, problem) -> np.ndarray:
        return np.ones((problem.n_lights, 3))

    def fit(self, columns, b, colours, refit=True, upper=None):
        """(exitance (k, 3), error): the best powers of these lights, white (``upper``: fit_colours')."""
        e, err, _ = fit_colours(columns, b, np.ones((columns[0].shape[1], 3)), upper=upper)
        return e, err

    def certificate(self, problem, view, bounds, k_max):
        """The view's certificate (``bounds``, or else found now) is of white lights exactly."""
        if bounds is None:
            bounds = view.real_bounds(lower_bounds(view.transfer, view.b_target, k_max))
        return bounds

    def describe(self, exitance) -> list:
        return [{} for _ in range(len(exitance))]

    def summary(self) -> dict:
        return {"mode": self.name}
