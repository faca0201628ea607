"""A polygon light: every cell of one of the artist's polygons, one exitance (as one emissive
material would make the whole polygon glow)."""
from .surface import register_surface_kind

POLYGON = register_surface_kind("polygon", "Whole Polygon", "All the cells of one polygon sharing one exitance")
