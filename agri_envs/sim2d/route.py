"""Progress along an ordered route of points: the shaping both 2D waypoint tasks pay for.

The robot drives to ``targets[index]``; a target counts as reached within ``radius`` of the robot centre,
and the next one becomes current. Progress is measured on the *distance to go* to the current target,
``d + turn_distance * |alpha|`` (d its distance, alpha its bearing from the robot's heading): with
``turn_distance = max_speed / max_turn_rate`` a turn toward the target counts as the metres the robot
could drive in the time the turn takes. While one target is current, the progress of a stretch of driving
is a potential difference, so driving or turning back and forth earns nothing; when a target is reached
the next one starts from its own distance to go (no jump is paid or charged).
"""

from __future__ import annotations

import math

import numpy as np


class RouteProgress:
    """The current target of a route of points, and the progress made toward it.

    Args:
        targets: ``(k, 2)`` points to reach, in order (m).
        radius: A target counts as reached within this distance of the robot centre (m).
        turn_distance: Metres of distance to go per radian of heading error (m/rad).
    """

    def __init__(self, targets: np.ndarray, radius: float, turn_distance: float = 0.0) -> None:
        self.targets = np.asarray(targets, dtype=np.float64)
        self.radius = radius
        self.turn_distance = turn_distance
        self.index = 0
        self._last_to_go = 0.0

    def reset(self, pose: np.ndarray, index: int = 0) -> None:
        """Start with the robot at ``pose``, driving to target ``index`` (earlier ones count as reached)."""
        self.index = index
        self._last_to_go = self.to_go(pose)

    @property
    def done(self) -> bool:
        """True once every target was reached."""
        return self.index >= len(self.targets)

    @property
    def current(self) -> np.ndarray:
        """The target being driven to (the last one once done)."""
        return self.targets[min(self.index, len(self.targets) - 1)]

    @property
    def following(self) -> np.ndarray:
        """The target after the current one (the last one when the current is the last)."""
        return self.targets[min(self.index + 1, len(self.targets) - 1)]

    def distance(self, pose: np.ndarray) -> float:
        """Distance d from the robot centre to the current target (m)."""
        t = self.current
        return math.hypot(t[0] - pose[0], t[1] - pose[1])

    def bearing(self, pose: np.ndarray) -> float:
        """Angle alpha of the current target seen from the robot's heading, in (-pi, pi] (rad)."""
        t = self.current
        theta = math.atan2(t[1] - pose[1], t[0] - pose[0])
        a = theta - pose[2]
        return math.atan2(math.sin(a), math.cos(a))

    def to_go(self, pose: np.ndarray) -> float:
        """Distance to go to the current target: ``d + turn_distance * |alpha|`` (m)."""
        return self._to_go(self.distance(pose), self.bearing(pose))

    def _to_go(self, d: float, alpha: float) -> float:
        return d + self.turn_distance * abs(alpha)

    def advance(self, pose: np.ndarray) -> tuple[float, bool, float, float]:
        """Move along the route for the robot's new pose.

        Returns:
            ``(progress, reached, d, alpha)``: the decrease of the distance to go since the last call (m),
            whether the current target was reached (the next one is current now), and the distance and
            bearing of the (new) current target.
        """
        d, alpha = self.distance(pose), self.bearing(pose)
        progress = self._last_to_go - self._to_go(d, alpha)
        reached = False
        if not self.done and d < self.radius:
            self.index += 1
            reached = True
            d, alpha = self.distance(pose), self.bearing(pose)
        self._last_to_go = self._to_go(d, alpha)
        return progress, reached, d, alpha
