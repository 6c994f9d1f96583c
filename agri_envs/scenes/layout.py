"""What a scene generator returns: the static geometry with its mission, routes for people and corridors."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Hashable

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


class LayoutCache:
    """Scenes that never change between episodes (a fixed layout seed, a loaded map), built once and kept.

    Generating a scene costs more than the rest of a reset; one that a fixed seed determines is the same
    every time, so an env builds it once per key and reuses it (the layouts are never modified).

    Args:
        size: How many scenes to keep (reset options may switch between a few layout seeds); the oldest goes.
    """

    def __init__(self, size: int = 16) -> None:
        self.size = size
        self._layouts: dict[Hashable, Layout] = {}

    def get(self, key: Hashable, build: Callable[[], Layout]) -> Layout:
        """The layout kept under ``key``, or ``build()``'s, kept from now on."""
        layout = self._layouts.get(key)
        if layout is None:
            if len(self._layouts) >= self.size:
                del self._layouts[next(iter(self._layouts))]
            layout = self._layouts[key] = build()
        return layout
