"""Differential-drive (skid-steer) body driven as a unicycle (Harik 2018, eq. 1).

The body is commanded with a linear velocity ``u`` and an angular velocity ``r``; the achieved
velocities follow the command within acceleration limits, are saturated by the velocity limits, and the
pose integrates eq. 1 exactly (motion along a circular arc over each step).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from agri_envs._actions import checked_action


@dataclasses.dataclass(frozen=True)
class DiffDriveSpec:
    """Size and limits of a differential-drive body.

    Attributes:
        length: Footprint length along the heading (m).
        width: Footprint width (m).
        max_speed: Largest forward speed (m/s).
        max_reverse_speed: Largest backward speed (m/s, positive number).
        max_turn_rate: Largest angular speed (rad/s).
        max_accel: Largest linear acceleration (m/s^2).
        max_angular_accel: Largest angular acceleration (rad/s^2).
    """

    length: float = 0.6
    width: float = 0.5
    max_speed: float = 0.6
    max_reverse_speed: float = 0.3
    max_turn_rate: float = 1.2
    max_accel: float = 1.0
    max_angular_accel: float = 3.0

    @classmethod
    def with_limits(
        cls,
        length: float,
        width: float,
        max_speed: float,
        max_turn_rate: float,
        max_accel: float,
        max_angular_accel: float,
        reverse_fraction: float,
    ) -> DiffDriveSpec:
        """A body of this footprint whose reverse speed limit is ``reverse_fraction`` of the forward one."""
        return cls(
            length=length,
            width=width,
            max_speed=max_speed,
            max_reverse_speed=reverse_fraction * max_speed,
            max_turn_rate=max_turn_rate,
            max_accel=max_accel,
            max_angular_accel=max_angular_accel,
        )

    def command(self, action: Any) -> tuple[float, float]:
        """The velocities ``(v, w)`` (m/s, rad/s) commanded by an action ``[u, r]`` in [-1, 1]^2 (checked, clipped).

        ``u >= 0`` scales the forward limit, ``u < 0`` the reverse one; ``r`` scales the turn-rate limit.

        Raises:
            ValueError: For an action that is not two finite numbers (see :func:`agri_envs._actions.checked_action`).
        """
        u, r = checked_action(action, 2).tolist()
        return u * (self.max_speed if u >= 0 else self.max_reverse_speed), r * self.max_turn_rate

    def __post_init__(self) -> None:
        for name in ("length", "width", "max_speed", "max_turn_rate", "max_accel", "max_angular_accel"):
            if not getattr(self, name) > 0:
                raise ValueError(f"DiffDriveSpec: {name} must be > 0, got {getattr(self, name)}")
        if self.max_reverse_speed < 0:
            raise ValueError("DiffDriveSpec: max_reverse_speed must be >= 0")

    @property
    def circumradius(self) -> float:
        """Distance from the centre to a footprint corner (m)."""
        return 0.5 * math.hypot(self.length, self.width)


def unicycle_arc(pose: np.ndarray, v: float, w: float, dt: float) -> np.ndarray:
    """Exact solution of eq. 1 over ``dt`` for constant ``(v, w)``: the pose after moving along an arc."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    if abs(w) < 1e-9:
        return np.array([x + v * dt * math.cos(th), y + v * dt * math.sin(th), th])
    th1 = th + w * dt
    k = v / w
    return np.array(
        [
            x + k * (math.sin(th1) - math.sin(th)),
            y - k * (math.cos(th1) - math.cos(th)),
            math.atan2(math.sin(th1), math.cos(th1)),
        ]
    )


def limit_velocity(
    spec: DiffDriveSpec, v: float, w: float, v_cmd: float, w_cmd: float, dt: float
) -> tuple[float, float]:
    """Velocities after one step of tracking the command within acceleration and velocity limits."""
    v_cmd = min(spec.max_speed, max(-spec.max_reverse_speed, v_cmd))
    w_cmd = min(spec.max_turn_rate, max(-spec.max_turn_rate, w_cmd))
    dv = spec.max_accel * dt
    dw = spec.max_angular_accel * dt
    v_new = v + min(dv, max(-dv, v_cmd - v))
    w_new = w + min(dw, max(-dw, w_cmd - w))
    return v_new, w_new
