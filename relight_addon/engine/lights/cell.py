"""A light cell: one candidate patch of about the light size, emitting on its own."""
from .surface import register_surface_kind

CELL = register_surface_kind("cell", "Light Cell", "One candidate patch of about the light size")
