"""The chain's observation: one 23-value vector per robot, one space shared by every agent (parameter sharing).

The layout is in the env's Observation Space table; :meth:`ChainObservation.layout` gives scripted policies
the slices and scales. The compiled kernel (:mod:`agri_envs.chain._kernels`) fills every robot's vector and
the chain's shape statistics in one pass.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from agri_envs.chain._kernels import observe
from agri_envs.chain.config import RobotChainConfig
from agri_envs.chain.robot import SONAR_INSET
from agri_envs.sim2d.sensors import SonarArray

OBS_SIZE = 23
#: Neighbours and the strip are observed in the robot's frame divided by this (m).
REL_SCALE = 3.0


class ChainObservation:
    """Reads the robots' sonars and builds their observations.

    Args:
        cfg: The env's config.
        sonars: The sonar array every robot carries.
    """

    def __init__(self, cfg: RobotChainConfig, sonars: SonarArray) -> None:
        self.cfg = cfg
        self.sonars = sonars
        low = np.array([0.0] * 8 + [0, 0, -1, -1, -1, -1, -1, -1, 0, -1, 0, -1, -1, -1, -1], np.float32)
        self.space = spaces.Box(low, np.ones(OBS_SIZE, np.float32), (OBS_SIZE,), np.float32)
        n = cfg.n_robots
        self.obs = np.zeros((n, OBS_SIZE))
        #: The chain's shape this step: mean and max strip distance, largest gap, gaps above Delta, spacing error.
        self.stats = np.zeros(5)
        self._sonar_out = np.empty((n, len(sonars)))
        self.last_sonar = self._sonar_out

    def __call__(
        self,
        poses: np.ndarray,
        vel: np.ndarray,
        world: Any,
        skip: np.ndarray,
        ghost_xy: tuple[float, float],
        goal: np.ndarray,
        bounds: np.ndarray,
        diagonal: float,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """``(n, 23)`` float32 observations of the robots at ``poses`` (updates :attr:`stats`, :attr:`last_sonar`)."""
        cfg = self.cfg
        ranges = self.sonars.ranges_many(poses, world.circles, world.capsules, skip, rng, self._sonar_out)
        self.last_sonar = ranges
        observe(
            poses,
            vel,
            ranges,
            ghost_xy[0],
            ghost_xy[1],
            float(goal[0]),
            float(goal[1]),
            bounds,
            diagonal,
            REL_SCALE,
            cfg.sonar_range,
            cfg.max_speed,
            cfg.max_turn_rate,
            cfg.spacing,
            cfg.max_gap,
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
            "predecessor": slice(12, 14),
            "successor": slice(14, 16),
            "has_successor": 16,
            "strip": 17,
            "is_leader": 18,
            "velocity": slice(19, 21),
            "goal": slice(21, 23),
            "sonar_max_range": self.cfg.sonar_range,
            "sonar_angles": self.sonars.mounts[:, 2].copy(),
            "sonar_offset": self.cfg.robot_radius - SONAR_INSET,
            "rel_scale": REL_SCALE,
            "max_speed": self.cfg.max_speed,
            "max_turn_rate": self.cfg.max_turn_rate,
        }
