"""Energy conservation, the paper's XDistribute (section 4): how the power of a suppressed
light is shared by the remaining ones. Each module registers one rule in DISTRIBUTIONS: a
class built once per problem (pairwise data between lights) whose ``raw(src, lights, valid)``
gives unnormalised non-negative weights (len(src), len(lights)); reduction.Distributor
normalises the rows to 1 so that the power per channel is conserved exactly."""
from . import distance, local, coplanar, uniform  # noqa: F401  (registration order = UI order)
