"""The Fitorobot of González et al. (2009, sec. 2): a tracked 0.7 x 1.5 m, 756 kg vehicle with seven sonars.

Differential (track) steering driven as a unicycle; the mass shows as low accelerations. Sensors: seven
ultrasonic range finders (three on each side, one at the front), a magnetic compass and one incremental
encoder per track.
"""

from __future__ import annotations

import math

import numpy as np

from agri_envs.sim2d.diff_drive import DiffDriveSpec

LENGTH = 1.5  # m
WIDTH = 0.7  # m
MASS = 756.0  # kg, with the phytosanitary tank full
TRACK_GAUGE = 0.55  # m between the track centre lines (for the encoders' left/right speeds)
#: Sonar mounts (x, y, yaw) in the body frame: front, then left front/middle/rear, right front/middle/rear.
SONAR_MOUNTS = np.array(
    [
        [0.75, 0.0, 0.0],
        [0.6, 0.35, math.pi / 2],
        [0.0, 0.35, math.pi / 2],
        [-0.6, 0.35, math.pi / 2],
        [0.6, -0.35, -math.pi / 2],
        [0.0, -0.35, -math.pi / 2],
        [-0.6, -0.35, -math.pi / 2],
    ]
)
SONAR_NAMES = ("front", "left_front", "left_middle", "left_rear", "right_front", "right_middle", "right_rear")
#: Ultrasonic range finders: 0.1-4 m, 20 deg cone.
SONAR_MIN_RANGE = 0.1
SONAR_MAX_RANGE = 4.0
SONAR_APERTURE = math.radians(20.0)


def fitorobot_spec(max_speed: float, max_turn_rate: float, max_accel: float, max_angular_accel: float) -> DiffDriveSpec:
    """The Fitorobot's footprint with the given limits (it reverses at half its forward speed)."""
    return DiffDriveSpec.with_limits(LENGTH, WIDTH, max_speed, max_turn_rate, max_accel, max_angular_accel, 0.5)
