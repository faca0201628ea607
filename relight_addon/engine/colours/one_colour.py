"""One colour per light: each light any single chromaticity, chosen with the light (no
per-channel freedom in the selection). The selections run on the problem with each light's colour
fixed at the one it alone fits the targets best (per channel, the best non-negative multiple of
its column: engine.light_colour.solo_colours), a light on in every channel or in none; each
configuration found is then refitted with its lights' colours free (NNLS per channel on those
lights), so a light keeps one colour of its own, as a gel chosen for it. Any non-negative RGB is
a power times one chromaticity, so the configurations allowed are free colours': the certificate
is the free problem's (best_lights.lower_bounds), exact for it."""
from __future__ import annotations

import numpy as np

from ..best_lights import lower_bounds
from ..light_colour import fit_per_channel, solo_colours
from ..registry import LIGHT_COLOURS


@LIGHT_COLOURS.register("one-colour", "One Colour per Light", "Each light any one colour, chosen with the light "
                        "(the selection keeps a light's channels together)")
class OneColour:
    name = "one-colour"
    free = False
    refits = True  # every configuration's colours refitted (engine.reduction.in_colour)

    def colours(self, problem) -> np.ndarray:
        return solo_colours(problem)

    def fit(self, columns, b, colours, refit=True, upper=None):
        """(exitance (k, 3), error): NNLS per channel on these lights (``refit`` False: their
        colours ``colours`` kept, the powers fitted)."""
        from ..light_colour import fit_colours

        if not refit:
            e, err, _ = fit_colours(columns, b, colours, upper=upper)
            return e, err
        return fit_per_channel(columns, b, upper)

    def certificate(self, problem, view, bounds, k_max):
        """The free problem's certificate: the configurations allowed are free colours'."""
        return lower_bounds(problem.transfer, problem.b_target, k_max)

    def describe(self, exitance) -> list:
        return [{} for _ in range(len(exitance))]

    def summary(self) -> dict:
        return {"mode": self.name}
