"""The harvesting task: goals, the batched reward, harvest events and success (pure numpy).

A goal is 9 numbers: the clamp-centre position (m), its approach axis (tool z) and its pallet axis (tool
x). A goal is *reached* when the position is within ``position_tolerance`` and both axes within
``orientation_tolerance`` (rad) of the desired ones. One :meth:`HarvestTask.evaluate` call per step
produces the dict that termination, reward and ``info`` all read.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from agri_envs.arm.scene import Scene

GOAL_DIM = 9


def goal_errors(achieved: np.ndarray, desired: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error (m) and the larger of the two axis angles (rad), for goals of shape (..., 9)."""
    a = np.asarray(achieved, dtype=np.float64)
    d = np.asarray(desired, dtype=np.float64)
    pos = np.linalg.norm(a[..., :3] - d[..., :3], axis=-1)
    angles = []
    for k in (3, 6):
        u, v = a[..., k : k + 3], d[..., k : k + 3]
        cos = np.sum(u * v, axis=-1) / np.maximum(np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1), 1e-12)
        angles.append(np.arccos(np.clip(cos, -1.0, 1.0)))
    return pos, np.maximum(angles[0], angles[1])


def _collisions(info: Any) -> np.ndarray | float:
    """``info["collision"]`` of one info dict, or of every dict of a batch (SB3's HER passes an array)."""
    if isinstance(info, Mapping):
        return float(bool(info.get("collision", False)))
    if isinstance(info, Iterable):
        return np.array([float(bool(i.get("collision", False))) for i in info])
    return 0.0


class HarvestTask:
    """Harvest every cluster (any order), then bring the clamp back to its home pose.

    The *designated* target (the ``desired_goal``) is the unharvested cluster nearest the clamp when the
    previous target was harvested, and the home pose once all are. Any cluster whose goal is reached
    counts as harvested, designated or not. The designated target switches one step after its harvest,
    so the step's reward always equals ``compute_reward`` of the observation it comes with (HER needs
    that).
    """

    def __init__(
        self,
        position_tolerance: float,
        orientation_tolerance: float,
        reward_type: str,
        collision_penalty: float,
        orientation_weight: float,
    ) -> None:
        self.position_tolerance = position_tolerance
        self.orientation_tolerance = orientation_tolerance
        self.reward_type = reward_type
        self.collision_penalty = collision_penalty
        self.orientation_weight = orientation_weight
        self.goals = np.zeros((0, GOAL_DIM))
        self.home_goal = np.zeros(GOAL_DIM)
        self.harvested = np.zeros(0, dtype=bool)
        self.target = -1
        self._switch = False

    def reset(self, scene: Scene, home_goal: np.ndarray, achieved: np.ndarray) -> None:
        """Start an episode in ``scene`` with the clamp at ``achieved``."""
        # Goals are kept at the observation's float32 precision, so rewards equal compute_reward(obs goals).
        self.goals = np.array([c.goal() for c in scene.clusters]).reshape(-1, GOAL_DIM).astype(np.float32)
        self.goals = self.goals.astype(np.float64)
        self.home_goal = np.asarray(home_goal, dtype=np.float64)
        self.harvested = np.zeros(len(self.goals), dtype=bool)
        self._switch = False
        self.target = self._nearest(achieved)

    def _nearest(self, achieved: np.ndarray) -> int:
        left = np.flatnonzero(~self.harvested)
        if left.size == 0:
            return -1
        dist = np.linalg.norm(self.goals[left, :3] - achieved[:3], axis=1)
        return int(left[int(np.argmin(dist))])

    @property
    def desired_goal(self) -> np.ndarray:
        """The designated target's goal (home once everything is harvested)."""
        return self.home_goal if self.target < 0 else self.goals[self.target]

    def reached(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        """Whether goals are reached (batched over leading axes)."""
        pos, ang = goal_errors(achieved, desired)
        return (pos <= self.position_tolerance) & (ang <= self.orientation_tolerance)

    def compute_reward(self, achieved: np.ndarray, desired: np.ndarray, info: Any) -> np.ndarray | float:
        """The env's reward for (batches of) goals.

        Sparse: 0 when the goal is reached, else -1; dense: minus the position error (m) and the weighted
        axis angle (rad). Both minus ``collision_penalty`` when ``info["collision"]``. Batched over leading axes.
        """
        if self.reward_type == "sparse":
            base = -(~self.reached(achieved, desired)).astype(np.float64)
        else:
            pos, ang = goal_errors(achieved, desired)
            base = -(pos + self.orientation_weight * ang)
        reward = base - self.collision_penalty * _collisions(info)
        return float(reward) if np.ndim(reward) == 0 else reward

    def begin_step(self, achieved: np.ndarray) -> None:
        """Switch the designated target if it was harvested on the previous step."""
        if self._switch:
            self.target = self._nearest(achieved)
            self._switch = False

    def evaluate(self, achieved: np.ndarray, collision: bool) -> dict[str, Any]:
        """Outcome of the step that brought the clamp to ``achieved``: harvests, success, reward terms.

        Returns:
            Flat dict: ``reward`` (for the goal in this step's observation), ``harvested_now`` (indices),
            ``is_success`` (all harvested and home reached), ``collision``, ``distance`` (m) and
            ``angle_error`` (rad) to the designated goal.
        """
        desired = self.desired_goal
        reward = self.compute_reward(achieved, desired, {"collision": collision})
        now: list[int] = []
        if not collision:
            left = np.flatnonzero(~self.harvested)
            if left.size:
                hit = left[self.reached(achieved[None], self.goals[left])]
                now = [int(i) for i in hit]
                self.harvested[hit] = True
                if self.target in now:
                    self._switch = True
        home = bool(self.harvested.all() and self.target < 0 and self.reached(achieved, self.home_goal))
        pos, ang = goal_errors(achieved, desired)
        return {
            "reward": reward,
            "harvested_now": now,
            "is_success": home and not collision,
            "collision": collision,
            "distance": float(pos),
            "angle_error": float(ang),
        }
