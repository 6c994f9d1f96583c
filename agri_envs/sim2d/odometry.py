"""Proprioceptive pose sources: wheel odometry with a gyro, track encoders, a compass.

Each model holds its own state and draws its noise from the generator it is given (the env's
``np_random``), so the env decides the order of the draws; none knows about Gymnasium.
"""

from __future__ import annotations

import math

import numpy as np


class WheelOdometry:
    """Dead reckoning of a unicycle from noisy speeds and a biased gyro (it drifts).

    Args:
        noise: Relative standard deviation of each measured speed.
        gyro_bias_std: Standard deviation of the turn-rate bias drawn once per episode (rad/s).
    """

    def __init__(self, noise: float, gyro_bias_std: float) -> None:
        self.noise = noise
        self.gyro_bias_std = gyro_bias_std
        self.gyro_bias = 0.0

    def draw_bias(self, rng: np.random.Generator) -> None:
        """Draw the episode's gyro bias (nothing is drawn when its std is 0)."""
        self.gyro_bias = float(rng.normal(0.0, self.gyro_bias_std)) if self.gyro_bias_std else 0.0

    def integrate(self, pose: np.ndarray, v: float, w: float, dt: float, rng: np.random.Generator) -> np.ndarray:
        """The estimate ``(x, y, yaw)`` after driving at the true speeds ``v``, ``w`` for ``dt`` (midpoint rule)."""
        v = v * (1.0 + self.noise * rng.standard_normal())
        w = w * (1.0 + self.noise * rng.standard_normal()) + self.gyro_bias
        x, y, th = pose
        th_mid = th + 0.5 * w * dt
        return np.array(
            [
                x + v * dt * math.cos(th_mid),
                y + v * dt * math.sin(th_mid),
                math.atan2(math.sin(th + w * dt), math.cos(th + w * dt)),
            ]
        )


class Compass:
    """A heading sensor with a constant bias and Gaussian noise.

    Args:
        noise_std: Standard deviation of the noise (rad).
        bias: Constant heading bias (rad).
    """

    def __init__(self, noise_std: float, bias: float) -> None:
        self.noise_std = noise_std
        self.bias = bias

    def read(self, yaw: float, rng: np.random.Generator) -> float:
        """The measured heading in ``(-pi, pi]`` of a body whose true heading is ``yaw``."""
        h = float(yaw) + self.bias
        if self.noise_std > 0:
            h += self.noise_std * float(rng.standard_normal())
        return math.atan2(math.sin(h), math.cos(h))


class TrackOdometry:
    """Track (or wheel) encoders of a differential drive, integrated along a given heading (González 2009, 3.3).

    Args:
        gauge: Distance between the tracks (m).
        noise: Relative standard deviation of each track-speed measurement.
        scale_std: Standard deviation of each encoder's scale error, drawn once per episode (drift).
    """

    def __init__(self, gauge: float, noise: float, scale_std: float) -> None:
        self.gauge = gauge
        self.noise = noise
        self.scale_std = scale_std
        self.scale = np.ones(2)
        self.estimate = np.zeros(2)
        self.v = 0.0
        self.w = 0.0

    def draw_scale(self, rng: np.random.Generator) -> None:
        """Draw the episode's encoder scale errors (nothing is drawn when their std is 0)."""
        self.scale = 1.0 + self.scale_std * rng.standard_normal(2) if self.scale_std else np.ones(2)

    def reset(self, xy: np.ndarray) -> None:
        """Start the estimate at ``xy`` with zero measured speeds."""
        self.estimate = np.asarray(xy, dtype=np.float64)[:2].copy()
        self.v = 0.0
        self.w = 0.0

    def update(self, v: float, w: float, heading: float, dt: float, rng: np.random.Generator) -> None:
        """Measure the track speeds of a body moving at ``v``, ``w`` and advance the estimate along ``heading``."""
        half = 0.5 * self.gauge
        tracks = np.array([v - w * half, v + w * half]) * self.scale
        if self.noise > 0:
            tracks = tracks * (1.0 + self.noise * rng.standard_normal(2))
        self.v = float(0.5 * (tracks[0] + tracks[1]))
        self.w = float((tracks[1] - tracks[0]) / self.gauge)
        self.estimate = self.estimate + self.v * dt * np.array([math.cos(heading), math.sin(heading)])
