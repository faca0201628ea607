"""A group: about 2 x 2 neighbouring light cells of one object and orientation, one exitance."""
from .surface import register_surface_kind

GROUP = register_surface_kind("group", "Cell Group", "About 2 x 2 neighbouring light cells sharing one exitance")
