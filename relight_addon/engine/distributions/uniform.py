"""UniformDistribute: w = 1/p over the p remaining lights."""
from __future__ import annotations

import numpy as np

from ..registry import DISTRIBUTIONS


@DISTRIBUTIONS.register("uniform", "Uniform", "Suppressed power is shared by all remaining lights")
class Uniform:
    def __init__(self, problem):
        pass

    def raw(self, src, lights, valid):
        return valid.astype(np.float64)
