"""Automatic: blackbody lights (engine/colours/blackbody.py, of the range set: --temperature-min /
--temperature-max, default 2,700-6,500 K) unless the targets ask for colours no blackbody light of
the range gives. Measured on the problem before the selection: the every-light NNLS with free
colours against the blackbody relaxation's (engine.light_colour.relaxed_bound), both lower bounds
on any number of lights. When blackbody lights cannot come within AUTO_GAP of what free colours
can (relative error), the targets ask for coloured light (blue painted on a warm wood, say: only a
bluish light gives it; grey paint is a brightness, engine/paint.py): free colours,
and a note says so and what blackbody lights can reach. docs/benchmarks.md, "Light colour".
"""
from __future__ import annotations

from ..best_lights import lower_bounds
from ..light_colour import relaxed_bound
from ..registry import LIGHT_COLOURS
from .blackbody_range import DEFAULT_RANGE, RANGE_PARAMS

#: relative error: blackbody lights are chosen unless their bound is this much above free colours'
AUTO_GAP = 0.05


@LIGHT_COLOURS.register("auto", "Automatic", "Blackbody lights, unless the targets ask for colours no blackbody "
                        "light gives (then free colours, with a note)",
                        params=RANGE_PARAMS,  # (the blackbody lights' range, when it chooses them)
                        relaxation=True)  # (its choice: light_colour.relaxed_bound; engine/cost.py)
class Auto:
    name = "auto"
    free = False

    def __init__(self, temperature_min=DEFAULT_RANGE[0], temperature_max=DEFAULT_RANGE[1]):
        from .blackbody import Blackbody  # (imported here: the registry lists Automatic first)

        # the range set, else the default (ValueError: a bad range, at once)
        self.blackbody = Blackbody(temperature_min, temperature_max)

    def choose(self, problem):
        """(the mode to solve with, a note)."""
        from .free import Free

        blackbody = self.blackbody
        lo, hi = blackbody.range
        free = lower_bounds(problem.transfer, problem.b_target, 1, exhaustive_limit=0).nnls_relative
        warm = relaxed_bound(problem, blackbody.range, 1).nnls_relative
        if warm <= free + AUTO_GAP:
            return blackbody, (f"light colour: blackbody ({lo:.0f}-{hi:.0f} K), chosen automatically: any number "
                               f"of them can reach a relative error of {warm:.3g}, free colours {free:.3g}")
        return Free(), (f"light colour: free, chosen automatically: the targets ask for coloured light (blackbody "
                        f"lights of {lo:.0f}-{hi:.0f} K cannot go below a relative error "
                        f"of {warm:.3g}, free colours can reach {free:.3g}); the lights may be saturated: choose "
                        "White or Blackbody to have them anyway")
