"""Bodies (rectangle, box, polygon, mesh) and point placement (grids, random, Lloyd)."""

from harness.geometry.bodies import BodyGeom, body_geometry, box, mesh_body, polygon, rectangle
from harness.geometry.placement import (
    LloydResult,
    grid_points,
    lloyd,
    neighbour_pairs,
    random_points,
)

__all__ = [
    "BodyGeom",
    "body_geometry",
    "box",
    "mesh_body",
    "polygon",
    "rectangle",
    "LloydResult",
    "grid_points",
    "lloyd",
    "neighbour_pairs",
    "random_points",
]
