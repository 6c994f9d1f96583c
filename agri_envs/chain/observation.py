"""The chain's observation: one 29-value vector per robot, one space shared by every agent (parameter sharing).

The layout is in the env's Observation Space table; :meth:`ChainObservation.layout` gives scripted policies
the slices and scales. A robot sees its own sonars, pose and velocity, and what its neighbours tell it
(their positions and velocities, and the predecessor's recent trail); the leader sees the ghost robot
in its predecessor's place. The compiled kernels (:mod:`agri_envs.chain._kernels`) fill every robot's
vector and the chain's shape statistics in one pass.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from agri_envs.chain._kernels import OBS_SIZE, TRAIL_STEP, observe, record_trails
from agri_envs.chain.config import RobotChainConfig
from agri_envs.chain.robot import SONAR_INSET
from agri_envs.sim2d.polyline import Polyline
from agri_envs.sim2d.sensors import SonarArray

#: Neighbours and the slot are observed in the robot's frame divided by this (m).
REL_SCALE = 3.0
#: The goal's distance is observed divided by this (m), clipped to 1.
GOAL_SCALE = 10.0

__all__ = ["GOAL_SCALE", "OBS_SIZE", "REL_SCALE", "ChainObservation", "Trails"]


class Trails:
    """Every robot's recent trail: where it has been, a point each :data:`TRAIL_STEP` metres it moves.

    A follower's slot is the point of its predecessor's trail ``spacing`` metres behind the predecessor:
    where the follower stands in a chain at rest (the paper's follower "fetching its previous position").
    At reset each trail holds the start formation behind its robot, so every follower starts on its slot.

    Args:
        n: Robots.
        spacing: ``d_s`` (m); the trails keep at least this much.
    """

    def __init__(self, n: int, spacing: float) -> None:
        self.capacity = int(math.ceil(spacing / TRAIL_STEP)) + 8
        self.xy = np.zeros((n, self.capacity, 2))
        self.s = np.zeros((n, self.capacity))
        self.head = np.zeros(n, dtype=np.int64)
        self.count = np.zeros(n, dtype=np.int64)

    def reset(self, formation: Polyline, spacing: float) -> None:
        """Robot k's trail: the formation line behind it, as if it had driven along it to its place.

        Args:
            formation: The line the chain stands on, from the last robot (arc length 0) to the leader; robot
                k stands at arc length ``(n - 1 - k) * spacing``.
            spacing: ``d_s`` (m).
        """
        n, cap = self.s.shape
        end = (n - 1 - np.arange(n))[:, None] * spacing
        # The last `cap` points of each trail, TRAIL_STEP apart, ending at the robot (none before the formation).
        arcs = end - TRAIL_STEP * np.arange(cap)[::-1][None, :]
        count = np.minimum(cap, (end[:, 0] / TRAIL_STEP).astype(np.int64) + 1)
        arcs = np.maximum(arcs, 0.0)
        self.xy[:] = formation.at_many(arcs.ravel()).reshape(n, cap, 2)
        self.s[:] = arcs
        # The points sit at the ring's end; the oldest valid one is `count` back from the head.
        self.head[:] = cap - 1
        self.count[:] = count

    def record(self, poses: np.ndarray) -> None:
        """Add each robot's position to its trail once it has moved far enough."""
        record_trails(poses, self.xy, self.s, self.head, self.count)


class ChainObservation:
    """Reads the robots' sonars and builds their observations.

    Args:
        cfg: The env's config.
        sonars: The sonar array every robot carries.
    """

    def __init__(self, cfg: RobotChainConfig, sonars: SonarArray) -> None:
        self.cfg = cfg
        self.sonars = sonars
        low = -np.ones(OBS_SIZE, np.float32)
        low[0:10] = 0.0
        low[24:26] = 0.0
        low[28] = 0.0
        self.space = spaces.Box(low, np.ones(OBS_SIZE, np.float32), (OBS_SIZE,), np.float32)
        n = cfg.n_robots
        self.obs = np.zeros((n, OBS_SIZE))
        #: The chain's shape this step: mean and max strip distance, largest gap, gaps above Delta, spacing error.
        self.stats = np.zeros(5)
        self._sonar_out = np.empty((n, len(sonars)))
        self.last_sonar = self._sonar_out
        self._consts = np.array(
            [REL_SCALE, cfg.sonar_range, cfg.max_speed, cfg.max_turn_rate, cfg.spacing, cfg.max_gap, GOAL_SCALE]
        )
        self._ghost = np.zeros(4)

    def __call__(
        self,
        poses: np.ndarray,
        vel: np.ndarray,
        world: Any,
        skip: np.ndarray,
        ghost_xy: tuple[float, float],
        ghost_velocity: tuple[float, float],
        trails: Trails,
        goal: np.ndarray,
        bounds: np.ndarray,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """``(n, 29)`` float32 observations of the robots at ``poses`` (updates :attr:`stats`, :attr:`last_sonar`)."""
        ranges = self.sonars.ranges_many(poses, world.circles, world.capsules, skip, rng, self._sonar_out)
        self.last_sonar = ranges
        g = self._ghost
        g[0], g[1] = ghost_xy
        g[2], g[3] = ghost_velocity
        observe(
            poses,
            vel,
            ranges,
            g,
            trails.xy,
            trails.s,
            trails.head,
            trails.count,
            goal,
            bounds,
            self._consts,
            self.obs,
            self.stats,
        )
        return self.obs.astype(np.float32)

    def layout(self) -> dict[str, Any]:
        """Where things sit in an observation and how to scale them back (for scripted policies)."""
        return {
            "sonar": slice(0, 8),
            "xy": slice(8, 10),
            "sin_yaw": 10,
            "cos_yaw": 11,
            "velocity": slice(12, 14),
            "predecessor": slice(14, 16),
            "predecessor_velocity": slice(16, 18),
            "slot": slice(18, 20),
            "successor": slice(20, 22),
            "successor_velocity": slice(22, 24),
            "has_successor": 24,
            "is_leader": 25,
            "goal_direction": slice(26, 28),
            "goal_distance": 28,
            "sonar_max_range": self.cfg.sonar_range,
            "sonar_angles": self.sonars.mounts[:, 2].copy(),
            "sonar_offset": self.cfg.robot_radius - SONAR_INSET,
            "rel_scale": REL_SCALE,
            "velocity_scale": 2.0 * self.cfg.max_speed,
            "goal_scale": GOAL_SCALE,
            "max_speed": self.cfg.max_speed,
            "max_turn_rate": self.cfg.max_turn_rate,
        }
