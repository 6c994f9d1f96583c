"""Axis-aligned boxes and the configuration-space collision test of Luo eqs. 6-9 (pure numpy).

Obstacles are AABBs given by ``P_min`` and ``P_max`` (sec. 2.2). The arm is a point set ``P_link``
(:class:`~agri_envs.arm.robot_model.PointSet`); a configuration ``E`` collides when any point lies in any
box (eqs. 6-8: Gamma(E) > 0), and a path ``H_part`` is free when no configuration on it collides (eq. 9).
"""

from __future__ import annotations

import numpy as np

from agri_envs.arm.kinematics import link_frames
from agri_envs.arm.robot_model import PointSet, point_set


def box_distance(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distance from points (..., 3) to boxes (B, 3)/(B, 3): shape (..., B), zero inside."""
    p = points[..., None, :]
    gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.sqrt(np.sum(gap * gap, axis=-1))


class ArmCollisionModel:
    """Gamma(E) of eq. 7 for batches of configurations against a set of boxes.

    Args:
        lo: Box minima, shape (B, 3) (m).
        hi: Box maxima, shape (B, 3) (m).
        margin: Extra clearance added around every box (m).
        spacing: d_min of eq. 7, the spacing of the arm's points (m).
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, margin: float = 0.0, spacing: float = 0.02) -> None:
        self.points: PointSet = _cached_point_set(spacing)
        self.set_boxes(lo, hi)
        self.margin = margin

    def set_boxes(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Replace the obstacle boxes."""
        self.lo = np.asarray(lo, dtype=np.float64).reshape(-1, 3)
        self.hi = np.asarray(hi, dtype=np.float64).reshape(-1, 3)

    def gamma(self, q: np.ndarray) -> np.ndarray:
        """Eq. 7: number of arm points inside a (grown) box, for joint values of shape (N, 6): shape (N,)."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 6)
        if len(self.lo) == 0:
            return np.zeros(len(q), dtype=np.int64)
        pts = self.points.world(link_frames(q))  # (N, m, 3)
        grow = (self.points.radius + self.margin)[None, :, None]
        inside = np.ones((len(q), len(grow[0]), len(self.lo)), dtype=bool)  # (N, m, B)
        for k in range(3):
            c = pts[:, :, k, None]
            inside &= (c >= self.lo[:, k] - grow) & (c <= self.hi[:, k] + grow)
        return inside.reshape(len(q), -1).sum(axis=1)

    def collides(self, q: np.ndarray) -> np.ndarray:
        """Eq. 8: Omega(E) for joint values of shape (N, 6) (or (6,)): boolean, shape (N,)."""
        return self.gamma(q) > 0


_POINT_SETS: dict[float, PointSet] = {}


def _cached_point_set(spacing: float) -> PointSet:
    if spacing not in _POINT_SETS:
        _POINT_SETS[spacing] = point_set(spacing)
    return _POINT_SETS[spacing]
