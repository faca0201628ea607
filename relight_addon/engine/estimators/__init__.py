"""Form-factor estimators (see engine.registry): each module registers a function
``estimate(patches, options, progress=None, cancel=None, pairs=None) -> FormFactors``;
``pairs`` = (receivers, sources) patch indices whose transfer decides the answer (targets x
candidate lights), for estimators that treat them specially."""
from . import kernel, raycast  # noqa: F401  (registration order = UI order)
