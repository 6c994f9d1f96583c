"""What a scene generator returns: the static geometry with its mission, routes for people and corridors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from agri_envs.sim2d.crowd import RouteGraph
from agri_envs.sim2d.geometry import Geometry

#: Thickness of generated walls (m).
WALL_THICKNESS = 0.1


@dataclasses.dataclass(frozen=True)
class Layout:
    """A generated (or loaded) scene with its mission.

    Attributes:
        geometry: Static obstacles.
        waypoints: ``(k, 2)`` numbered waypoints (m); the robot starts at waypoint 0.
        mission: Indices of the waypoints to visit, in order (by default 1, 2, ..., k-1, 0: the loop).
        start_pose: Robot start ``(x, y, yaw)``.
        routes: Where people walk.
        corridors: Centre line of every corridor as a ``(k, 2)`` polyline from its low-x to its high-x end
            (generated greenhouses only; empty otherwise).
    """

    geometry: Geometry
    waypoints: np.ndarray
    mission: np.ndarray
    start_pose: np.ndarray
    routes: RouteGraph
    corridors: tuple[np.ndarray, ...] = ()

    @property
    def targets(self) -> np.ndarray:
        """``(len(mission), 2)`` positions to visit, in order."""
        return self.waypoints[self.mission]


def start_facing(waypoints: np.ndarray, target: int) -> np.ndarray:
    """Pose at waypoint 0 facing waypoint ``target``."""
    d = waypoints[target] - waypoints[0]
    return np.array([waypoints[0, 0], waypoints[0, 1], math.atan2(d[1], d[0])])
