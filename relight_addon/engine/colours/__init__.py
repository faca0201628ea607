"""Light colour modes (see engine.registry, engine.light_colour): each module registers one in
LIGHT_COLOURS, a class whose instance (made from the job's options) says what colours the lights
may have."""
from . import auto, free, white, blackbody, one_colour  # noqa: F401
