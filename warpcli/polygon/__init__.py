"""Polygon stage: reading polygon files and validating simple polygons.

One module per job, each importing only the ones above it in this list
(no cycles):

- `messages`: how values from files and coordinates appear in one-line messages;
- `predicates`: exact orientation signs, segment tests, the signed area;
- `validate`: the checks every polygon passes (crossings, clearance), with an
  n log n scan over pairs of edges;
- `shape`: the `Polygon` value, validated on construction, and `check_pair`;
- `formats`: polygon files (plain JSON, labelme, GeoJSON) and `read_polygon`;
- `outline`: the ring between a fixed outline and the cages inside it, cut
  into faces simple on both sides (`outline.cut_ring`), and ``--within``'s
  outline (`outline.outline_polygon`).

So ``messages, predicates <- validate <- shape <- formats <- outline``.
"""

from __future__ import annotations

from .formats import MAX_FILE_BYTES, read_polygon
from .predicates import signed_area
from .shape import COORD_LIMIT, Polygon, check_pair, cyclic_relabelling
from .validate import MIN_CLEARANCE, MIN_CLEARANCE_RELATIVE, clearance_floor, validate_points

__all__ = [
    "COORD_LIMIT",
    "MAX_FILE_BYTES",
    "MIN_CLEARANCE",
    "MIN_CLEARANCE_RELATIVE",
    "Polygon",
    "check_pair",
    "clearance_floor",
    "cyclic_relabelling",
    "read_polygon",
    "signed_area",
    "validate_points",
]
