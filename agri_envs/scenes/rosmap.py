"""Scenes loaded from a ROS ``map_server`` map (PGM + YAML), so a user can train in a map of their own greenhouse."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from agri_envs.scenes.layout import Layout, start_facing
from agri_envs.sim2d.crowd import RouteGraph
from agri_envs.sim2d.geometry import Geometry
from agri_envs.sim2d.gridmap import grid_to_geometry, load_ros_map

#: A ROS map_server map of the default greenhouse, shipped as an example for ``scene="map"``.
EXAMPLE_MAP = Path(__file__).parent / "maps" / "example_greenhouse.yaml"


def map_waypoints(yaml_path: str | Path) -> np.ndarray | None:
    """The loop of waypoints ``(k, 2)`` a map YAML names under ``waypoints`` (m, map frame), or None.

    ``waypoints`` is this package's addition to the ``map_server`` format (ROS ignores other keys): a map
    can ship the mission that goes with it, as :data:`EXAMPLE_MAP` does.

    Raises:
        ValueError: When the key is there but is not a list of at least two (x, y) pairs.
    """
    meta = yaml.safe_load(Path(yaml_path).read_text(encoding="utf-8"))
    raw = meta.get("waypoints") if isinstance(meta, dict) else None
    if raw is None:
        return None
    try:
        pts = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError):
        pts = np.zeros((0,))
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.all(np.isfinite(pts)):
        raise ValueError(f"{yaml_path}: 'waypoints' must be a list of >= 2 (x, y) pairs, got {raw!r}")
    return pts


#: The waypoints of :data:`EXAMPLE_MAP` (Harik's loop 0 -> 1 -> ... -> 7 -> 0 through its three rows):
#: ``gym.make(..., scene="map", map_yaml=str(EXAMPLE_MAP))`` drives them when given no ``waypoints``.
EXAMPLE_WAYPOINTS: tuple[tuple[float, float], ...] = tuple(
    (float(x), float(y)) for x, y in map_waypoints(EXAMPLE_MAP)  # type: ignore[union-attr]
)


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
