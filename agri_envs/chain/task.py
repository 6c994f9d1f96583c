"""The chain's task (Apoorva 2018): the ghost robot that leads along the A* path, and one ``evaluate()``.

:class:`ChainTask` decides what progress, success, failure and reward mean, from one dict that feeds
termination, the reward and ``info`` alike (the habit of :class:`agri_envs.rover.task.WaypointTask`). The
ghost runs along the A* path ahead of the leader (sec. 4.4: pseudo speed ``v_F``, back speed ``v_B``,
leash ``eta``, patience ``T``); the leader sees it in its observation, as a follower sees its predecessor.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from agri_envs.sim2d.polyline import Polyline


@dataclasses.dataclass(frozen=True)
class GhostParams:
    """The ghost robot of sec. 4.4.

    Attributes:
        v_forward: ``v_F``, pseudo speed along the A* path (m/s).
        v_back: ``v_B``, speed at which the ghost comes back when the leader is stuck (m/s).
        eta: ``eta``, the ghost waits while the leader is farther than this (m).
        patience: ``T``, time the leader may stay beyond ``eta`` before the ghost comes back (s).
        window: How far ahead of its last projection the leader's nearest path point is searched (m).
    """

    v_forward: float = 0.4
    v_back: float = 0.2
    eta: float = 0.8
    patience: float = 2.0
    window: float = 1.5

    def __post_init__(self) -> None:
        for name in ("v_forward", "eta", "window"):
            if not getattr(self, name) > 0:
                raise ValueError(f"GhostParams: {name} must be > 0, got {getattr(self, name)}")
        if self.v_back < 0 or self.patience < 0:
            raise ValueError("GhostParams: v_back and patience must be >= 0")


class GhostRobot:
    """A point that runs along the A* path ahead of the leader (Alg. 4, part a).

    Args:
        path: The A* path.
        params: Speeds and thresholds.
        dt: Control period (s).
    """

    def __init__(self, path: Polyline, params: GhostParams, dt: float) -> None:
        self.path = path
        self.params = params
        self.dt = dt
        self.s = 0.0
        self.s_leader = 0.0
        self._waited = 0.0

    def reset(self, leader_xy: np.ndarray) -> None:
        """Put the ghost on the path point nearest to the leader (``s = argmin d(tau_A(s), q_1)``)."""
        self.s_leader = self.path.project(np.asarray(leader_xy, dtype=np.float64), 0.0, self.params.window)
        self.s = self.s_leader
        self._waited = 0.0

    @property
    def point(self) -> np.ndarray:
        """The ghost's position ``g = tau_A(s)``."""
        return self.path.at(self.s)

    @property
    def xy(self) -> tuple[float, float]:
        """:attr:`point` as two floats."""
        return self.path.xy_at(self.s)

    def update(self, leader_xy: np.ndarray) -> np.ndarray:
        """Advance (``+v_F``), hold, or come back (``-v_B`` after ``T``), and return the new ``g``."""
        p = self.params
        xy = np.asarray(leader_xy, dtype=np.float64)
        # The leader's own place on the path, searched forward from where it was (delta(s) > 0).
        self.s_leader = self.path.project(xy, self.s_leader, self.s_leader + p.window)
        gx, gy = self.path.xy_at(self.s)
        if math.hypot(gx - xy[0], gy - xy[1]) > p.eta:
            if self._waited > p.patience:
                self.s -= p.v_back * self.dt
            else:
                self._waited += self.dt
        else:
            self.s += p.v_forward * self.dt
            self._waited = 0.0
        self.s = min(max(self.s, self.s_leader), self.path.length)
        return self.path.at(self.s)


@dataclasses.dataclass(frozen=True)
class ChainWeights:
    """Weights of the reward terms (see the env's Rewards section)."""

    progress: float = 1.0
    spacing: float = 0.05
    strip: float = 0.05
    collision: float = 10.0
    chain_break: float = 0.1
    success: float = 10.0
    time: float = 0.005


#: The reward terms, in the order they are summed (each reported in ``info`` as ``reward_<name>``).
TERMS = ("progress", "spacing", "strip", "collision", "break", "success", "time")


class ChainTask:
    """Lead the chain along the A* path to the goal, in shape and without touching anything.

    Args:
        path: The leader's A* path; its last point is the goal.
        ghost: Speeds and thresholds of the ghost robot.
        weights: Reward weights.
        dt: Control period (s).
        goal_radius: The leader has arrived within this distance of the goal (m).
        terminate_on_collision: End the episode when any robot touches anything.
    """

    def __init__(
        self,
        path: Polyline,
        ghost: GhostParams,
        weights: ChainWeights,
        dt: float,
        goal_radius: float,
        terminate_on_collision: bool,
    ) -> None:
        self.path = path
        self.goal = path.points[-1].copy()
        self.ghost = GhostRobot(path, ghost, dt)
        self.weights = weights
        self.goal_radius = goal_radius
        self.terminate_on_collision = terminate_on_collision

    def reset(self, leader_xy: np.ndarray) -> None:
        """Put the ghost at the leader and clear the episode's statistics."""
        self.ghost.reset(leader_xy)
        self.ghost_xy = self.ghost.xy
        self._s_progress = self.ghost.s_leader
        self.progress = 0.0
        self.collisions = 0
        self.collided_any = False
        self.max_gap = 0.0  # the env sets the start's largest gap once it has observed the chain
        self.strip_sum = 0.0
        self.strip_count = 0
        self.strip_max = 0.0
        self.terms = dict.fromkeys(TERMS, 0.0)
        self.success = False
        self.leader_arrived = False

    def move_ghost(self, leader_xy: np.ndarray) -> None:
        """Advance the ghost for the leader's new position and record the leader's progress along the path."""
        self.ghost.update(leader_xy)
        self.ghost_xy = self.ghost.xy
        s_new = self.ghost.s_leader
        self.progress = s_new - self._s_progress
        self._s_progress = s_new

    def evaluate(self, leader_xy: np.ndarray, n_collided: int, shape: list[float]) -> dict[str, Any]:
        """Reward terms, success and termination of one step (after :meth:`move_ghost`).

        Args:
            leader_xy: The leader's position (m).
            n_collided: Robots in contact this step.
            shape: The chain's shape this step: mean and max strip distance (m), largest gap (m), gaps
                larger than Delta, mean relative spacing error (the observation kernel's statistics).

        Returns:
            ``reward_<term>`` for every term, ``reward`` (their sum), ``is_success``, ``leader_at_goal``,
            ``chain_intact`` and ``terminated``.
        """
        w = self.weights
        mean_strip, max_strip, max_gap, n_break, spacing_err = shape
        self.collisions += n_collided
        self.collided_any = self.collided_any or n_collided > 0
        self.max_gap = max(self.max_gap, max_gap)
        self.strip_sum += mean_strip
        self.strip_count += 1
        self.strip_max = max(self.strip_max, max_strip)
        arrived = math.hypot(leader_xy[0] - self.goal[0], leader_xy[1] - self.goal[1]) <= self.goal_radius
        self.leader_arrived = arrived
        self.success = arrived and not self.collided_any and n_break == 0
        terms = {
            "progress": w.progress * self.progress,
            "spacing": -w.spacing * spacing_err,
            "strip": -w.strip * mean_strip,
            "collision": -w.collision * n_collided,
            "break": -w.chain_break * n_break,
            "success": w.success if self.success else 0.0,
            "time": -w.time,
        }
        self.terms = terms
        outcome: dict[str, Any] = {"reward_" + name: value for name, value in terms.items()}
        outcome.update(
            reward=float(sum(terms.values())),
            is_success=self.success,
            leader_at_goal=arrived,
            chain_intact=n_break == 0,
            terminated=arrived or (n_collided > 0 and self.terminate_on_collision),
        )
        return outcome
