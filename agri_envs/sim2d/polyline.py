"""Polylines parametrised by arc length: planned paths, the ghost's track, the chain's start line."""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numba
import numpy as np


@numba.njit(cache=True)
def _project(
    points: np.ndarray, cumulative: np.ndarray, x: float, y: float, k0: int, k1: int, s_from: float, s_to: float
) -> float:
    """Arc length in ``[s_from, s_to]`` of the path point nearest to ``(x, y)`` (segments ``k0 .. k1 - 1``)."""
    best = math.inf
    s_best = max(s_from, cumulative[k0])
    for k in range(k0, k1):
        ax, ay = points[k, 0], points[k, 1]
        ex, ey = points[k + 1, 0] - ax, points[k + 1, 1] - ay
        l2 = ex * ex + ey * ey
        length = math.sqrt(l2)
        if length <= 1e-12:
            continue
        t_lo = max(0.0, (s_from - cumulative[k]) / length)
        t_hi = min(1.0, (s_to - cumulative[k]) / length)
        if t_lo > t_hi:
            continue
        t = min(t_hi, max(t_lo, ((x - ax) * ex + (y - ay) * ey) / l2))
        qx, qy = ax + t * ex - x, ay + t * ey - y
        d = qx * qx + qy * qy
        if d < best:
            best = d
            s_best = cumulative[k] + t * length
    return s_best


class Polyline:
    """A path parametrised by arc length.

    Args:
        points: ``(k, 2)`` vertices (m), ``k >= 1``.
    """

    def __init__(self, points: np.ndarray) -> None:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(p) == 0:
            raise ValueError("Polyline: needs at least one point")
        if len(p) == 1:
            p = np.vstack([p, p])
        self.points = p
        seg = np.hypot(*np.diff(p, axis=0).T)
        self.cumulative = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.cumulative[-1])
        self._lists: tuple[list[float], list[tuple[float, float]]] | None = None

    def _as_lists(self) -> tuple[list[float], list[tuple[float, float]]]:
        """Arc lengths and vertices as Python floats (fast scalar lookups), made on first use."""
        if self._lists is None:
            self._lists = (self.cumulative.tolist(), [(float(a), float(b)) for a, b in self.points.tolist()])
        return self._lists

    def at(self, s: float) -> np.ndarray:
        """Point at arc length ``s`` (clamped to the ends)."""
        x, y = self.xy_at(s)
        return np.array([x, y])

    def at_many(self, s: np.ndarray) -> np.ndarray:
        """Points ``(k, 2)`` at arc lengths ``s`` (clamped to the ends), in one vectorised pass."""
        a = np.clip(np.asarray(s, dtype=np.float64), 0.0, self.length)
        return np.stack(
            [np.interp(a, self.cumulative, self.points[:, 0]), np.interp(a, self.cumulative, self.points[:, 1])], -1
        )

    def xy_at(self, s: float) -> tuple[float, float]:
        """:meth:`at` as two floats."""
        c, pts = self._as_lists()
        s = min(max(s, 0.0), self.length)
        k = min(max(bisect.bisect_right(c, s) - 1, 0), len(c) - 2)
        span = c[k + 1] - c[k]
        t = 0.0 if span <= 0 else (s - c[k]) / span
        (ax, ay), (bx, by) = pts[k], pts[k + 1]
        return ax + t * (bx - ax), ay + t * (by - ay)

    def between(self, s_from: float, s_to: float) -> Polyline:
        """The part of the path from arc length ``s_from`` to ``s_to`` (clamped; ends interpolated)."""
        lo = min(max(s_from, 0.0), self.length)
        hi = min(max(s_to, lo), self.length)
        inner = self.points[(self.cumulative > lo) & (self.cumulative < hi)]
        return Polyline(np.vstack([self.at(lo)[None], inner, self.at(hi)[None]]))

    def project(self, xy: np.ndarray, s_from: float, s_to: float) -> float:
        """Arc length of the point of the path nearest to ``xy``, searched between ``s_from`` and ``s_to``."""
        c = self._as_lists()[0]
        k0 = max(0, bisect.bisect_right(c, s_from) - 1)
        k1 = min(len(c) - 1, bisect.bisect_left(c, s_to) + 1)
        if k1 <= k0:
            return min(max(s_from, 0.0), self.length)
        s = _project(self.points, self.cumulative, float(xy[0]), float(xy[1]), k0, k1, s_from, s_to)
        return min(max(s, s_from), s_to)


class PathProgress:
    """How far along a path the robot is, and the path ahead of it in the robot's frame.

    Each :meth:`update` projects the robot centre on the path no more than ``back`` metres behind and
    ``forward`` metres ahead of its last arc length, so a path that folds back on itself (a serpentine's next
    corridor, a few metres to the side) is never mistaken for the stretch the robot is on.

    Args:
        path: The path.
        back: How far back along the path a projection may move (m).
        forward: How far ahead along the path a projection may move (m).
    """

    def __init__(self, path: Polyline, back: float = 0.5, forward: float = 3.0) -> None:
        self.path = path
        self.back = back
        self.forward = forward
        self.s = 0.0

    def reset(self, pose: np.ndarray) -> float:
        """Start at the path point nearest ``pose`` within ``forward`` of the path's start; its arc length."""
        self.s = self.path.project(np.asarray(pose[:2]), 0.0, self.forward)
        return self.s

    def update(self, pose: np.ndarray) -> float:
        """Move to the path point nearest ``pose`` within the window around the last one; its arc length."""
        self.s = self.path.project(np.asarray(pose[:2]), max(0.0, self.s - self.back), self.s + self.forward)
        return self.s

    def ahead(self, pose: np.ndarray, distances: Sequence[float]) -> np.ndarray:
        """Path points ``distances`` metres beyond the current arc length (clamped to the end), ``(k, 2)``.

        Each row is ``(ahead, left)`` of the robot at ``pose = (x, y, yaw)`` (m).
        """
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        c, s = math.cos(yaw), math.sin(yaw)
        out = []
        for d in distances:  # a few points a step: scalar lookups beat numpy's per-call overhead (4x here)
            px, py = self.path.xy_at(self.s + float(d))
            out.append((c * (px - x) + s * (py - y), -s * (px - x) + c * (py - y)))
        return np.array(out)
