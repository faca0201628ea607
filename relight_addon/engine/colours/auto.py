"""Automatic: blackbody lights (engine/colours/blackbody.py, its default range) unless the
targets ask for colours no blackbody light of the range gives. Measured on the problem before the
selection: the every-light NNLS with free colours against the blackbody relaxation's
(engine.light_colour.relaxed_bound), both lower bounds on any number of lights. When blackbody
lights cannot come within AUTO_GAP of what free colours can (relative error), the targets ask for
coloured light (blue painted on a warm wood, say: only a bluish light gives it; grey paint is a
brightness, engine/paint.py): free colours,
and a note says so and what blackbody lights can reach. docs/benchmarks.md, "Light colour".
"""
from __future__ import annotations

from ..best_lights import lower_bounds
from ..light_colour import relaxed_bound
from ..registry import LIGHT_COLOURS

#: relative error: blackbody lights are chosen unless their bound is this much above free colours'
AUTO_GAP = 0.05


@LIGHT_COLOURS.register("auto", "Automatic", "Blackbody lights, unless the targets ask for colours no blackbody "
                        "light gives (then free colours, with a note)",
                        relaxation=True)  # (its choice: light_colour.relaxed_bound; engine/cost.py)
class Auto:
    name = "auto"
    free = False

    def __init__(self, options=None):
        self.options = options

    def choose(self, problem):
        """(the mode to solve with, a note)."""
        from .blackbody import DEFAULT_RANGE, Blackbody  # (imported here: the registry lists Automatic first)
        from .free import Free

        free = lower_bounds(problem.transfer, problem.b_target, 1, exhaustive_limit=0).nnls_relative
        warm = relaxed_bound(problem, DEFAULT_RANGE, 1).nnls_relative
        if warm <= free + AUTO_GAP:
            return Blackbody(), (f"light colour: blackbody ({DEFAULT_RANGE[0]:.0f}-{DEFAULT_RANGE[1]:.0f} K), chosen "
                                 f"automatically: any number of them can reach a relative error of {warm:.3g}, "
                                 f"free colours {free:.3g}")
        return Free(), (f"light colour: free, chosen automatically: the targets ask for coloured light (blackbody "
                        f"lights of {DEFAULT_RANGE[0]:.0f}-{DEFAULT_RANGE[1]:.0f} K cannot go below a relative error "
                        f"of {warm:.3g}, free colours can reach {free:.3g}); the lights may be saturated: choose "
                        "White or Blackbody to have them anyway")
