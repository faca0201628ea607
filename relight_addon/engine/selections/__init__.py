"""Light selections (see engine.registry): each module registers one in SELECTIONS. The
paper's four (section 3) redistribute the power of the lights they drop (``distributes``);
the others fit non-negative exitances directly."""
from . import (greedy_swap, exitance_elimination, exitance_construction, error_elimination,  # noqa: F401
               error_construction, nnls_greedy, least_power)
