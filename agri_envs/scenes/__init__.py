"""Scene generators shared by the 2D envs: greenhouse rows, office floors, ROS maps.

Every generator returns plain geometry (and, for the navigation scenes, a :class:`Layout` with its mission);
none imports an env, so rover, coverage and chain all draw their worlds from here:

* :mod:`~agri_envs.scenes.greenhouse`: walls, posts and rows of growing plants (straight, or inclined, bent
  and unequally spaced as in Almería), with the serpentine mission (:class:`LayoutParams`).
* :mod:`~agri_envs.scenes.office`: Harik's office corridor (:class:`CorridorParams`) and Apoorva's office
  floor of rooms (:class:`OfficeFloorParams`).
* :mod:`~agri_envs.scenes.rosmap`: scenes from a ROS ``map_server`` map (:data:`EXAMPLE_MAP` ships with
  the package, with its loop of :data:`EXAMPLE_WAYPOINTS`).
"""

from __future__ import annotations

from agri_envs.scenes.greenhouse import LayoutParams, generate_layout
from agri_envs.scenes.layout import Layout
from agri_envs.scenes.office import CorridorParams, OfficeFloorParams, generate_office_corridor, generate_office_floor
from agri_envs.scenes.rosmap import EXAMPLE_MAP, EXAMPLE_WAYPOINTS, layout_from_map, map_geometry, map_waypoints

__all__ = [
    "EXAMPLE_MAP",
    "EXAMPLE_WAYPOINTS",
    "CorridorParams",
    "Layout",
    "LayoutParams",
    "OfficeFloorParams",
    "generate_layout",
    "generate_office_corridor",
    "generate_office_floor",
    "layout_from_map",
    "map_geometry",
    "map_waypoints",
]
