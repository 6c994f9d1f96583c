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
    """Weights of the named reward terms (see the env docstring's Rewards section).

    Attributes:
        progress: Reward per metre of progress toward the current waypoint (distance to go, see
            :meth:`WaypointTask.to_go`).
        waypoint: Bonus per waypoint reached.
        success: Bonus when the mission is complete.
        collision: Fixed part of the crash penalty; the whole penalty is :meth:`collision_cost`.
        clearance: Penalty per metre driven at zero clearance (linear in the shortfall below the safety
            margin).
        time: Penalty per step.
    """

    progress: float = 3.0
    waypoint: float = 1.0
    success: float = 10.0
    collision: float = 20.0
    clearance: float = 6.0
    time: float = 0.01

    def collision_cost(self, steps_left: int) -> float:
        """The penalty of a crash with ``steps_left`` steps to go before the time limit.

        It is the fixed ``collision`` weight plus what stopping on the spot and waiting out the time limit
        would cost instead: the time penalty of the remaining steps (a robot that stands still drives no
        metres, so it pays no clearance penalty). A crash therefore always costs more than stopping, by
        at least ``collision``, whatever the mission, its time limit and the moment of the crash.
        """
        return self.collision + max(0, steps_left) * self.time


def mission_time_limit(
    start_pose: np.ndarray,
    targets: np.ndarray,
    max_speed: float,
    max_turn_rate: float,
    control_period: float,
    speed_fraction: float = 0.5,
    wait_time: float = 0.0,
) -> int:
    """Steps a competent driver needs for a waypoint mission, at ``speed_fraction`` of the speed limits.

    The route is the polyline from the start through every target; the turning is the sum of the heading
    changes at its corners (including the first one, from the start heading). Driving the route at
    ``speed_fraction * max_speed`` and turning at ``speed_fraction * max_turn_rate`` one after the other,
    plus ``wait_time`` (for example for people standing in the way), gives the time limit.

    Args:
        start_pose: Robot start ``(x, y, yaw)`` (m, rad).
        targets: ``(k, 2)`` waypoints in the order they are visited (m).
        max_speed: Forward speed limit (m/s).
        max_turn_rate: Turn rate limit (rad/s).
        control_period: Seconds per step.
        speed_fraction: Fraction of the limits the driver is granted, in (0, 1].
        wait_time: Extra seconds granted (s), >= 0.

    Returns:
        The limit in steps (at least 1).

    Raises:
        ValueError: If ``speed_fraction`` is outside (0, 1] or ``wait_time`` is negative.
    """
    if not 0.0 < speed_fraction <= 1.0:
        raise ValueError(f"speed_fraction must be in (0, 1], got {speed_fraction}")
    if wait_time < 0.0:
        raise ValueError(f"wait_time must be >= 0, got {wait_time}")
    pts = np.vstack([np.asarray(start_pose, dtype=np.float64)[None, :2], np.asarray(targets, dtype=np.float64)])
    seg = np.diff(pts, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    seg = seg[lengths > 1e-9]
    headings = np.concatenate([[float(start_pose[2])], np.arctan2(seg[:, 1], seg[:, 0])])
    turns = np.abs(np.arctan2(np.sin(np.diff(headings)), np.cos(np.diff(headings))))
    seconds = (
        float(lengths.sum()) / (speed_fraction * max_speed)
        + float(turns.sum()) / (speed_fraction * max_turn_rate)
        + wait_time
    )
    return max(1, math.ceil(seconds / control_period))


class WaypointTask:
    """Visit ``targets`` in order; a target counts as reached within ``radius`` (d_min) of the robot centre.

    Progress is measured on the distance to go (:meth:`to_go`): the distance to the current target plus
    ``turn_distance`` metres per radian of heading error, so turning toward the target is progress too.
    """

    def __init__(
        self,
        targets: np.ndarray,
        radius: float,
        safety_margin: float,
        weights: RewardWeights,
        max_steps: int,
        turn_distance: float = 0.0,
    ) -> None:
        self.targets = np.asarray(targets, dtype=np.float64)
        self.radius = radius
        self.turn_distance = turn_distance
        self.safety_margin = safety_margin
        self.weights = weights
        self.max_steps = max_steps
        self.steps = 0
        self.index = 0
        self._last_to_go = 0.0

    def reset(self, pose: np.ndarray, index: int = 0) -> None:
        """Start the mission with the robot at ``pose``, driving to target ``index`` (earlier ones count as reached)."""
        self.index = index
        self.steps = 0
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
        """Distance d (eq. 2) from the robot centre to the current target (m)."""
        t = self.current
        return math.hypot(t[0] - pose[0], t[1] - pose[1])

    def bearing(self, pose: np.ndarray) -> float:
        """Angle alpha = theta - beta (eqs. 3-4) of the current target seen from the robot (rad)."""
        t = self.current
        theta = math.atan2(t[1] - pose[1], t[0] - pose[0])
        a = theta - pose[2]
        return math.atan2(math.sin(a), math.cos(a))

    def to_go(self, pose: np.ndarray) -> float:
        """Distance to go to the current target: ``d + turn_distance * |alpha|`` (m).

        With ``turn_distance = max_speed / max_turn_rate`` this is the time a robot at its speed limits needs
        to turn toward the target and drive there, in metres of driving.
        """
        return self._to_go(self.distance(pose), self.bearing(pose))

    def _to_go(self, d: float, alpha: float) -> float:
        return d + self.turn_distance * abs(alpha)

    def evaluate(
        self, pose: np.ndarray, collided: bool, clearance: float, travelled: float = 0.0, step: bool = True
    ) -> dict[str, float | bool | int]:
        """Advance the mission for the robot's new pose and return the step's outcome and reward terms.

        Args:
            pose: The robot's true pose ``(x, y, yaw)`` after the step.
            collided: Whether the robot touched anything during the step.
            clearance: Distance from the robot's body to the nearest obstacle or person (m).
            travelled: Distance the robot's centre moved during the step (m).
            step: False for the outcome at reset, which is not a step (no time passes).
        """
        w = self.weights
        if step:
            self.steps += 1
        d, alpha = self.distance(pose), self.bearing(pose)
        progress = self._last_to_go - self._to_go(d, alpha)
        reached = False
        if not self.done and d < self.radius:
            self.index += 1
            reached = True
            d, alpha = self.distance(pose), self.bearing(pose)
        self._last_to_go = self._to_go(d, alpha)
        success = self.done
        shortfall = max(0.0, self.safety_margin - clearance) / self.safety_margin if self.safety_margin > 0 else 0.0
        terms = {
            "reward_progress": w.progress * progress,
            "reward_waypoint": w.waypoint * float(reached),
            "reward_success": w.success * float(success),
            "reward_collision": -w.collision_cost(self.max_steps - self.steps) * float(collided),
            "reward_clearance": -w.clearance * min(1.0, shortfall) * travelled,
            "reward_time": -w.time * float(step),
        }
        reward = 0.0
        for value in terms.values():  # added left to right, as the batched env adds them (not sum()'s algorithm)
            reward += value
        return {
            **terms,
            "reward": reward,
            "is_success": success,
            "collision": collided,
            "waypoint_reached": reached,
            "waypoint_index": self.index,
            "distance_to_waypoint": d,
            "bearing_to_waypoint": alpha,
        }
