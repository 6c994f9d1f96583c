"""The chain's robot: a small round Amigobot-like body, its limits and its eight sonars."""

from __future__ import annotations

import numpy as np

from agri_envs.chain.config import RobotChainConfig
from agri_envs.sim2d.diff_drive import DiffDriveSpec
from agri_envs.sim2d.sensors import SonarArray, SonarSpec

#: Amigobot sonar directions (deg): six in front, two at the back.
SONAR_ANGLES_DEG = (90.0, 41.0, 15.0, -15.0, -41.0, -90.0, -145.0, 145.0)
#: Sonars sit this far inside the outline (m), so the kernels never see the robot's own disc.
SONAR_INSET = 0.005


def body_spec(cfg: RobotChainConfig) -> DiffDriveSpec:
    """A round differential-drive body of radius ``robot_radius`` with the config's limits (same both ways)."""
    d = 2 * cfg.robot_radius
    return DiffDriveSpec.with_limits(
        d, d, cfg.max_speed, cfg.max_turn_rate, cfg.max_accel, cfg.max_angular_accel, reverse_fraction=1.0
    )


def sonar_array(cfg: RobotChainConfig) -> SonarArray:
    """The eight sonars at :data:`SONAR_ANGLES_DEG`, just inside the body's outline."""
    angles = np.radians(SONAR_ANGLES_DEG)
    offset = cfg.robot_radius - SONAR_INSET
    mounts = np.stack([offset * np.cos(angles), offset * np.sin(angles), angles], axis=1)
    spec = SonarSpec(
        aperture=cfg.sonar_aperture, min_range=0.01, max_range=cfg.sonar_range, noise_std=cfg.sonar_noise_std
    )
    return SonarArray(spec, mounts)
