"""Free colours: every channel fitted on its own (NNLS per channel), the selections' own way; a
light's colour is whatever the three fits give."""
from __future__ import annotations

from ..registry import LIGHT_COLOURS


@LIGHT_COLOURS.register("free", "Free", "Each channel fitted on its own: a light's colour is whatever the fit "
                        "gives (it may be saturated, e.g. pure red)")
class Free:
    name = "free"
    free = True

    def describe(self, exitance) -> list:
        return [{} for _ in range(len(exitance))]

    def summary(self) -> dict:
        return {"mode": self.name}
