"""The blackbody lights' temperature range: its default and its two options, declared by the
Blackbody light colour and by Automatic (which solves with blackbody lights of this range unless
the targets ask for coloured light: engine/colours/auto.py). A module of its own, registering
nothing: Automatic is registered (and listed) first."""
from __future__ import annotations

from ..registry import Param

__all__ = ["DEFAULT_RANGE", "RANGE_PARAMS"]

#: the default range: warm white (2,700 K, an incandescent or warm LED) to daylight (6,500 K)
DEFAULT_RANGE = (2700.0, 6500.0)
RANGE_PARAMS = (Param("temperature_min", float, DEFAULT_RANGE[0], min=800.0, max=12000.0,
                      label="Min Temperature", soft_max=12000.0,
                      description="Blackbody lights: the lowest colour temperature, K"),
                Param("temperature_max", float, DEFAULT_RANGE[1], min=800.0, max=12000.0,
                      label="Max Temperature", soft_max=12000.0,
                      description="Blackbody lights: the highest colour temperature, K"))
