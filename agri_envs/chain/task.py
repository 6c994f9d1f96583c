"""The chain's task (Apoorva 2018): the ghost robot that leads along the A* path, and one ``evaluate()``.

The task is the paper's (Fig. 8f): every robot reaches the goal, as a chain.

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
    """Weights of the reward terms (see the env's Rewards section).

    ``spacing``, ``strip`` and ``time`` are what the term costs over a whole episode of ``max_cycles``
    steps at its worst; the other weights are paid once.
    """

    progress: float = 1.0
    spacing: float = 1.0
    strip: float = 0.5
    time: float = 1.0
    collision: float = 10.0
    chain_break: float = 10.0
    success: float = 10.0

    @property
    def step_cost(self) -> float:
        """The most the per-step penalties (time, spacing, strip) cost over a whole episode."""
        return self.time + self.spacing + self.strip


#: The reward terms, in the order they are summed (each reported in ``info`` as ``reward_<name>``).
TERMS = ("progress", "spacing", "strip", "time", "collision", "break", "forfeit", "success")


class ChainTask:
    """Bring every robot of the chain to the goal, in shape and without touching anything (the paper's task).

    The reward is ordered by construction (the env's Rewards section proves it):

    * a contact or a break that ends the episode pays no progress for its step and charges this step and
      every step left at the worst per-step cost (``forfeit``), so it costs more than stopping in place,
      whenever it happens;
    * progress is the change of a potential, minus the mean free-floor distance the robots still have to go
      (each beyond its arrival radius), so over any episode it sums to at most the potential at the start,
      and a success pays that whole sum (the potential counts as 0 once the chain has arrived); with
      ``success > time + spacing + strip`` a success then pays more than any episode without one, however
      late it comes and however long the chain (every term is a mean over robots or gaps).

    Args:
        path: The leader's A* path; its last point is the goal.
        ghost: Speeds and thresholds of the ghost robot.
        weights: Reward weights.
        dt: Control period (s).
        goal_radius: The leader has arrived within this distance of the goal (m).
        max_cycles: The episode's step limit (the per-step penalties are spread over it).
        terminate_on_collision: End the episode when any robot touches anything.
        terminate_on_break: End the episode when a gap exceeds Delta.
    """

    def __init__(
        self,
        path: Polyline,
        ghost: GhostParams,
        weights: ChainWeights,
        dt: float,
        goal_radius: float,
        max_cycles: int,
        terminate_on_collision: bool,
        terminate_on_break: bool,
    ) -> None:
        self.path = path
        self.goal = path.points[-1].copy()
        self.ghost = GhostRobot(path, ghost, dt)
        self.weights = weights
        self.goal_radius = goal_radius
        self.max_cycles = max_cycles
        self.terminate_on_collision = terminate_on_collision
        self.terminate_on_break = terminate_on_break

    def reset(self, leader_xy: np.ndarray, potential: float) -> None:
        """Put the ghost at the leader and clear the episode's statistics.

        Args:
            leader_xy: The leader's start (m).
            potential: Minus the mean distance (m) the robots have to go at the start.
        """
        self.ghost.reset(leader_xy)
        self.ghost_xy = self.ghost.xy
        self.ghost_velocity = (0.0, 0.0)
        self.potential = potential
        self.steps = 0
        self.collisions = 0
        self.collided_any = False
        self.broken_any = False
        self.max_gap = 0.0  # the env sets the start's largest gap once it has observed the chain
        self.strip_sum = 0.0
        self.strip_count = 0
        self.strip_max = 0.0
        self.terms = dict.fromkeys(TERMS, 0.0)
        self.success = False
        self.leader_arrived = False
        self.arrived = 0

    def move_ghost(self, leader_xy: np.ndarray) -> None:
        """Advance the ghost for the leader's new position (its velocity is observed by the leader)."""
        gx, gy = self.ghost_xy
        self.ghost.update(leader_xy)
        self.ghost_xy = self.ghost.xy
        dt = self.ghost.dt
        self.ghost_velocity = ((self.ghost_xy[0] - gx) / dt, (self.ghost_xy[1] - gy) / dt)

    def evaluate(
        self, leader_xy: np.ndarray, n_collided: int, shape: list[float], potential: float, arrived: int, n: int
    ) -> dict[str, Any]:
        """Reward terms, success and termination of one step (after :meth:`move_ghost`).

        Args:
            leader_xy: The leader's position (m).
            n_collided: Robots in contact this step.
            shape: The chain's shape this step: mean and max strip distance (m), largest gap (m), gaps
                larger than Delta, mean relative spacing error (the observation kernel's statistics).
            potential: Minus the mean distance (m) the robots still have to go beyond their arrival radii.
            arrived: Robots within their arrival radius of the goal.
            n: Robots in the chain.

        Returns:
            ``reward_<term>`` for every term, ``reward`` (their sum), ``is_success``, ``leader_at_goal``,
            ``chain_intact`` and ``terminated``.
        """
        w = self.weights
        mean_strip, max_strip, max_gap, n_break, spacing_err = shape
        self.steps += 1
        crashed = n_collided > 0
        broke = n_break > 0
        self.collisions += n_collided
        self.collided_any = self.collided_any or crashed
        self.broken_any = self.broken_any or broke
        self.max_gap = max(self.max_gap, max_gap)
        self.strip_sum += mean_strip
        self.strip_count += 1
        self.strip_max = max(self.strip_max, max_strip)
        self.leader_arrived = math.hypot(leader_xy[0] - self.goal[0], leader_xy[1] - self.goal[1]) <= self.goal_radius
        self.arrived = arrived
        self.success = arrived == n and not self.collided_any and not self.broken_any
        failed = (crashed and self.terminate_on_collision) or (broke and self.terminate_on_break)
        per_step = 1.0 / self.max_cycles
        if failed:
            # The rest of the episode at the worst per-step cost, this step included; no progress.
            spacing_err, strip_err, progress = 1.0, 1.0, 0.0
            forfeit = -w.step_cost * per_step * max(0, self.max_cycles - self.steps)
        else:
            strip_err = min(1.0, mean_strip)
            progress = w.progress * ((0.0 if self.success else potential) - self.potential)
            forfeit = 0.0
        self.potential = potential
        terms = {
            "progress": progress,
            "spacing": -w.spacing * per_step * spacing_err,
            "strip": -w.strip * per_step * strip_err,
            "time": -w.time * per_step,
            "collision": -w.collision if crashed else 0.0,
            "break": -w.chain_break if broke else 0.0,
            "forfeit": forfeit,
            "success": w.success if self.success else 0.0,
        }
        self.terms = terms
        outcome: dict[str, Any] = {"reward_" + name: value for name, value in terms.items()}
        outcome.update(
            reward=float(sum(terms.values())),
            is_success=self.success,
            leader_at_goal=self.leader_arrived,
            chain_intact=not broke,
            terminated=self.success or failed,
        )
        return outcome
