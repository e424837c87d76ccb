"""visualization_msgs/Marker's numbers that the obstacles use, the obstacles' topics, and how a marker names its
obstacle: one definition for the controller's intake (:mod:`.obstacle_io`), the markers it publishes
(:mod:`.obstacle_markers`) and the viewers (``app/view/obstacles_view.py``), light enough for the viewers'
parsers to import (no coal, no pinocchio)."""

from __future__ import annotations

from typing import Any, Final

CUBE, SPHERE, CYLINDER, MESH_RESOURCE = 1, 2, 3, 10
ADD, DELETE, DELETEALL = 0, 2, 3
TYPES: Final = {CUBE: "CUBE", SPHERE: "SPHERE", CYLINDER: "CYLINDER", MESH_RESOURCE: "MESH_RESOURCE"}
OBSTACLES_TOPIC: Final = "/dualarm/obstacles"
LIVE_TOPIC: Final = "/collision_objects"


def marker_name(marker: Any) -> str:
    """An obstacle's name from its marker: ``ns`` for id 0, else ``<ns>_<id>`` (``marker`` for an empty ns)."""
    ns = str(marker.ns) or "marker"
    return ns if marker.id == 0 else f"{ns}_{marker.id}"
