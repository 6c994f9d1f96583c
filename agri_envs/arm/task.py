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


def _field(info: Any, key: str, default: float) -> np.ndarray | float:
    """``info[key]`` of one info dict, or of every dict of a batch (SB3's HER passes an array of dicts)."""
    if isinstance(info, Mapping):
        return float(info.get(key, default))
    if isinstance(info, Iterable):
        return np.array([float(i.get(key, default)) for i in info])
    return default


def _scalar_or_array(x: Any, dtype: type) -> Any:
    arr: np.ndarray = np.asarray(x, dtype=dtype)
    return arr.item() if arr.ndim == 0 else arr


class HarvestTask:
    """Harvest every cluster (any order), then (``return_home``) bring the clamp back to its home pose.

    The *designated* target (the ``desired_goal``) is the unharvested cluster nearest the clamp when the
    previous target was harvested, and the home pose once all are (``return_home``). Any cluster whose
    goal is reached counts as harvested, designated or not. The designated target switches one step after
    its harvest, so the step's reward always equals ``compute_reward`` of the observation it comes with
    (HER needs that). The *final* target is home, or the last cluster when ``return_home`` is False:
    reaching it without a collision ends the episode with success.

    A step with a collision costs ``(time_limit + 1) * worst_step`` on top of the goal term, where
    ``worst_step`` is the largest penalty one uncrashed step can earn: a crash always costs more than
    spending the whole time budget without one (see the env's Rewards section).
    """

    #: Bound of the dense reward's position error (m): the arm reaches less than 1 m, goals lie within it.
    MAX_POSITION_ERROR = 2.0

    def __init__(
        self,
        position_tolerance: float,
        orientation_tolerance: float,
        reward_type: str,
        orientation_weight: float,
        return_home: bool = True,
        terminate_on_collision: bool = True,
    ) -> None:
        self.position_tolerance = position_tolerance
        self.orientation_tolerance = orientation_tolerance
        self.reward_type = reward_type
        self.orientation_weight = orientation_weight
        self.return_home = return_home
        self.terminate_on_collision = terminate_on_collision
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

    @property
    def worst_step(self) -> float:
        """The largest penalty of one step without a collision (sparse: 1; dense: the error bound)."""
        if self.reward_type == "sparse":
            return 1.0
        return self.MAX_POSITION_ERROR + self.orientation_weight * np.pi

    def collision_cost(self, time_limit: np.ndarray | float) -> np.ndarray | float:
        """Penalty of a colliding step in an episode of ``time_limit`` steps: more than any uncrashed episode."""
        return (np.asarray(time_limit, dtype=np.float64) + 1.0) * self.worst_step

    @property
    def final_target(self) -> bool:
        """Whether the designated target is the episode's last one (reaching it ends the episode)."""
        if self.return_home:
            return self.target < 0
        return int((~self.harvested).sum()) <= 1

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
        axis angle (rad). Both minus :meth:`collision_cost` of ``info["time_limit"]`` when
        ``info["collision"]``. Batched over leading axes (``info`` a dict or an array of dicts).
        """
        if self.reward_type == "sparse":
            base = -(~self.reached(achieved, desired)).astype(np.float64)
        else:
            pos, ang = goal_errors(achieved, desired)
            base = -(pos + self.orientation_weight * ang)
        cost = self.collision_cost(_field(info, "time_limit", 0.0))
        reward = base - cost * _field(info, "collision", 0.0)
        return _scalar_or_array(reward, np.float64)

    def compute_terminated(self, achieved: np.ndarray, desired: np.ndarray, info: Any) -> np.ndarray | bool:
        """Episode end (batched like :meth:`compute_reward`): the final target reached, or a collision.

        Reads ``info["final_target"]`` (the goal is the episode's last) and ``info["collision"]``.
        """
        collision = np.asarray(_field(info, "collision", 0.0)) > 0.5
        final = np.asarray(_field(info, "final_target", 0.0)) > 0.5
        done = final & self.reached(achieved, desired) & ~collision
        if self.terminate_on_collision:
            done = done | collision
        return _scalar_or_array(done, bool)

    def compute_truncated(self, achieved: np.ndarray, desired: np.ndarray, info: Any) -> np.ndarray | bool:
        """Time limit (batched like :meth:`compute_reward`): ``info["elapsed_steps"] >= info["time_limit"]``.

        An episode that terminates on the same step is not truncated.
        """
        over = np.asarray(_field(info, "elapsed_steps", 0.0)) >= np.asarray(_field(info, "time_limit", np.inf))
        return _scalar_or_array(over & ~np.asarray(self.compute_terminated(achieved, desired, info)), bool)

    def begin_step(self, achieved: np.ndarray) -> None:
        """Switch the designated target if it was harvested on the previous step."""
        if self._switch:
            self.target = self._nearest(achieved)
            self._switch = False

    def evaluate(self, achieved: np.ndarray, collision: bool, time_limit: int) -> dict[str, Any]:
        """Outcome of the step that brought the clamp to ``achieved``: harvests, success, reward terms.

        Returns:
            Flat dict: ``reward`` (for the goal in this step's observation), ``harvested_now`` (indices),
            ``is_success`` (the final target reached without a collision), ``final_target``, ``collision``,
            ``distance`` (m) and ``angle_error`` (rad) to the designated goal.
        """
        desired = self.desired_goal
        final = self.final_target
        reward = self.compute_reward(achieved, desired, {"collision": collision, "time_limit": time_limit})
        reached_final = bool(final and not collision and self.reached(achieved, desired))
        now: list[int] = []
        if not collision:
            left = np.flatnonzero(~self.harvested)
            if left.size:
                hit = left[self.reached(achieved[None], self.goals[left])]
                now = [int(i) for i in hit]
                self.harvested[hit] = True
                if self.target in now:
                    self._switch = True
        pos, ang = goal_errors(achieved, desired)
        return {
            "reward": reward,
            "harvested_now": now,
            "is_success": reached_final,
            "final_target": final,
            "collision": collision,
            "distance": float(pos),
            "angle_error": float(ang),
        }
