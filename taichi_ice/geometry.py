"""The old public name of the polygon functions: a re-export of ``polygon`` and ``polygon_ti``.

Code written against ``taichi_ice.geometry.overlap`` keeps working: the name is here. The
functions live in ``polygon`` (NumPy only: importing it starts no Taichi) and their Taichi
twins in ``polygon_ti``; code inside ``taichi_ice`` imports those two, never this module
(importing it loads Taichi, through ``polygon_ti``).
"""

from .physics.polygon import (
    CONVEXITY_RTOL,
    ROTATION_REDUCED_MAX,
    Overlap,
    boundary_crossings,
    check_polygon,
    diamond,
    edge_normals,
    facing_gap,
    facing_separated,
    intersection_polygon,
    longest_edge,
    mass_properties,
    min_penetration_axis,
    min_width,
    overlap,
    rectangle,
    rotation,
    sat_separated,
    signed_area,
    transform,
)
from .physics.polygon_ti import (
    edge_normals_ti,
    facing_gap_ti,
    min_penetration_axis_ti,
    overlap_normals_ti,
    overlap_ti,
    rotation_ti,
    sat_separated_ti,
)

__all__ = [
    "CONVEXITY_RTOL",
    "ROTATION_REDUCED_MAX",
    "Overlap",
    "boundary_crossings",
    "check_polygon",
    "diamond",
    "edge_normals",
    "edge_normals_ti",
    "facing_gap",
    "facing_gap_ti",
    "facing_separated",
    "intersection_polygon",
    "longest_edge",
    "mass_properties",
    "min_penetration_axis",
    "min_penetration_axis_ti",
    "min_width",
    "overlap",
    "overlap_normals_ti",
    "overlap_ti",
    "rectangle",
    "rotation",
    "rotation_ti",
    "sat_separated",
    "sat_separated_ti",
    "signed_area",
    "transform",
]
