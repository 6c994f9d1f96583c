"""Scenes loaded from a ROS ``map_server`` map (PGM + YAML), so a user can train in a map of their own greenhouse."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agri_envs.scenes.layout import Layout, start_facing
from agri_envs.sim2d.crowd import RouteGraph
from agri_envs.sim2d.geometry import Geometry
from agri_envs.sim2d.gridmap import grid_to_geometry, load_ros_map

#: A ROS map_server map of the default greenhouse, shipped as an example for ``scene="map"``.
EXAMPLE_MAP = Path(__file__).parent / "maps" / "example_greenhouse.yaml"


def map_geometry(yaml_path: str | Path, unknown_occupied: bool = False) -> Geometry:
    """The static scene of a ROS map: occupied cells (and unknown ones if ``unknown_occupied``) as boxes."""
    return grid_to_geometry(load_ros_map(yaml_path), unknown_occupied=unknown_occupied)


def layout_from_map(geometry: Geometry, waypoints: np.ndarray) -> Layout:
    """A scene loaded from an occupancy map, with the user's waypoints as the loop mission.

    People walk the waypoint loop (the user picked those points on free floor, as on Harik's Fig. 13).
    """
    pts = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
    k = len(pts)
    routes = RouteGraph(nodes=pts.copy(), edges=np.array([(i, (i + 1) % k) for i in range(k)], dtype=np.int64))
    return Layout(
        geometry=geometry,
        waypoints=pts,
        mission=np.array([*range(1, k), 0]),
        start_pose=start_facing(pts, 1),
        routes=routes,
    )
