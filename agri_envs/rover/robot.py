"""The rover of Harik 2018 (sec. 2.1): a 4WD skid-steer base with a SICK TiM561 and six HC-SR04 sonars."""

from __future__ import annotations

import math

import numpy as np

from agri_envs.sim2d.diff_drive import DiffDriveSpec

LENGTH = 0.6  # m, IG52-DB4 base with its frame
WIDTH = 0.5  # m
# LIDAR at the lower front, facing forward. The robot's own body is not part of its scans (as if the
# 270 deg sensor protruded from the front), so the rear beams are not blocked by the chassis.
LIDAR_MOUNT = (0.28, 0.0, 0.0)
# Six sonars: two on each side, one at the front, one at the back (x, y, yaw in the body frame).
SONAR_MOUNTS = np.array(
    [
        [0.30, 0.0, 0.0],
        [0.15, 0.25, math.pi / 2],
        [-0.15, 0.25, math.pi / 2],
        [-0.30, 0.0, math.pi],
        [-0.15, -0.25, -math.pi / 2],
        [0.15, -0.25, -math.pi / 2],
    ]
)
SONAR_NAMES = ("front", "left_front", "left_rear", "back", "right_rear", "right_front")


def rover_spec(max_speed: float, max_turn_rate: float, max_accel: float, max_angular_accel: float) -> DiffDriveSpec:
    """The rover's footprint with the given limits (reverse speed is half the forward speed)."""
    return DiffDriveSpec.with_limits(LENGTH, WIDTH, max_speed, max_turn_rate, max_accel, max_angular_accel, 0.5)
