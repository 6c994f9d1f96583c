"""The waypoint mission: which waypoint is next, when the mission succeeds, and the reward terms.

One :meth:`WaypointTask.evaluate` call per step produces the dict that termination, reward and ``info``
all read, so they never disagree.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class RewardWeights:
    """Weights of the named reward terms (see the env docstring's Rewards section)."""

    progress: float = 1.0
    waypoint: float = 2.0
    success: float = 10.0
    collision: float = 10.0
    clearance: float = 0.05
    time: float = 0.005


class WaypointTask:
    """Visit ``targets`` in order; a target counts as reached within ``radius`` (d_min) of the robot centre."""

    def __init__(self, targets: np.ndarray, radius: float, safety_margin: float, weights: RewardWeights) -> None:
        self.targets = np.asarray(targets, dtype=np.float64)
        self.radius = radius
        self.safety_margin = safety_margin
        self.weights = weights
        self.index = 0
        self._last_distance = 0.0

    def reset(self, pose: np.ndarray) -> None:
        """Start the mission with the robot at ``pose``."""
        self.index = 0
        self._last_distance = self.distance(pose)

    @property
    def done(self) -> bool:
        """True once every target was reached."""
        return self.index >= len(self.targets)

    @property
    def current(self) -> np.ndarray:
        """The target being driven to (the last one once done)."""
        return self.targets[min(self.index, len(self.targets) - 1)]

    def distance(self, pose: np.ndarray) -> float:
        """Distance d (eq. 2) from the robot centre to the current target (m)."""
        t = self.current
        return math.hypot(t[0] - pose[0], t[1] - pose[1])

    def bearing(self, pose: np.ndarray) -> float:
        """Angle alpha = theta - beta (eqs. 3-4) of the current target seen from the robot (rad)."""
        t = self.current
        theta = math.atan2(t[1] - pose[1], t[0] - pose[0])
        a = theta - pose[2]
        return math.atan2(math.sin(a), math.cos(a))

    def evaluate(self, pose: np.ndarray, collided: bool, clearance: float) -> dict[str, float | bool | int]:
        """Advance the mission for the robot's new pose and return the step's outcome and reward terms."""
        w = self.weights
        d = self.distance(pose)
        progress = self._last_distance - d
        reached = False
        if not self.done and d < self.radius:
            self.index += 1
            reached = True
            d = self.distance(pose)
        self._last_distance = d
        success = self.done
        shortfall = max(0.0, self.safety_margin - clearance) / self.safety_margin if self.safety_margin > 0 else 0.0
        terms = {
            "reward_progress": w.progress * progress,
            "reward_waypoint": w.waypoint * float(reached),
            "reward_success": w.success * float(success),
            "reward_collision": -w.collision * float(collided),
            "reward_clearance": -w.clearance * shortfall,
            "reward_time": -w.time,
        }
        return {
            **terms,
            "reward": float(sum(terms.values())),
            "is_success": success,
            "collision": collided,
            "waypoint_reached": reached,
            "waypoint_index": self.index,
            "distance_to_waypoint": d,
            "bearing_to_waypoint": self.bearing(pose),
        }
