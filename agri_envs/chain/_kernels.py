"""Compiled per-step work of robot_chain_v0: observations and the chain's shape statistics in one pass."""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True)
def strip_geometry(poses: np.ndarray, signed: np.ndarray) -> None:
    """Signed distance of every robot to the strip (segment from the first to the last robot; + on its left).

    Fewer than three robots, or first and last on the same spot: all zero.
    """
    n = poses.shape[0]
    for k in range(n):
        signed[k] = 0.0
    if n < 3:
        return
    ax, ay = poses[0, 0], poses[0, 1]
    ex, ey = poses[n - 1, 0] - ax, poses[n - 1, 1] - ay
    l2 = ex * ex + ey * ey
    if l2 < 1e-12:
        return
    for k in range(1, n - 1):
        px, py = poses[k, 0] - ax, poses[k, 1] - ay
        t = min(1.0, max(0.0, (px * ex + py * ey) / l2))
        d = math.hypot(px - t * ex, py - t * ey)
        signed[k] = d if ex * py - ey * px >= 0.0 else -d


@numba.njit(cache=True)
def observe(
    poses: np.ndarray,
    vel: np.ndarray,
    ranges: np.ndarray,
    ghost_x: float,
    ghost_y: float,
    goal_x: float,
    goal_y: float,
    bounds: np.ndarray,
    diag: float,
    rel_scale: float,
    sonar_range: float,
    max_speed: float,
    max_turn: float,
    spacing: float,
    max_gap: float,
    out: np.ndarray,
    stats: np.ndarray,
) -> None:
    """Fill ``out`` (n, 23) with every agent's observation (layout in the env docstring) and ``stats``.

    ``stats``: mean and max distance to the strip, max gap, number of gaps above ``max_gap``, and the mean
    of ``min(1, |gap - d_s| / d_s)``.
    """
    n = poses.shape[0]
    signed = np.empty(n)
    strip_geometry(poses, signed)
    sx = bounds[2] - bounds[0]
    sy = bounds[3] - bounds[1]
    strip_sum = 0.0
    strip_max = 0.0
    gap_max = 0.0
    breaks = 0.0
    spacing_err = 0.0
    for k in range(n):
        x, y, th = poses[k, 0], poses[k, 1], poses[k, 2]
        c = math.cos(th)
        s = math.sin(th)
        row = out[k]
        for j in range(8):
            row[j] = min(1.0, max(0.0, ranges[k, j] / sonar_range))
        row[8] = min(1.0, max(0.0, (x - bounds[0]) / sx))
        row[9] = min(1.0, max(0.0, (y - bounds[1]) / sy))
        row[10] = s
        row[11] = c
        if k == 0:
            px, py = ghost_x, ghost_y
        else:
            px, py = poses[k - 1, 0], poses[k - 1, 1]
        dx, dy = px - x, py - y
        row[12] = min(1.0, max(-1.0, (c * dx + s * dy) / rel_scale))
        row[13] = min(1.0, max(-1.0, (-s * dx + c * dy) / rel_scale))
        if k + 1 < n:
            dx, dy = poses[k + 1, 0] - x, poses[k + 1, 1] - y
            row[14] = min(1.0, max(-1.0, (c * dx + s * dy) / rel_scale))
            row[15] = min(1.0, max(-1.0, (-s * dx + c * dy) / rel_scale))
            row[16] = 1.0
            gap = math.hypot(dx, dy)
            gap_max = max(gap_max, gap)
            if gap > max_gap:
                breaks += 1.0
            spacing_err += min(1.0, abs(gap - spacing) / spacing)
        else:
            row[14] = 0.0
            row[15] = 0.0
            row[16] = 0.0
        row[17] = min(1.0, max(-1.0, signed[k] / rel_scale))
        row[18] = 1.0 if k == 0 else 0.0
        row[19] = min(1.0, max(-1.0, vel[k, 0] / max_speed))
        row[20] = min(1.0, max(-1.0, vel[k, 1] / max_turn))
        dx, dy = goal_x - x, goal_y - y
        row[21] = min(1.0, max(-1.0, (c * dx + s * dy) / diag))
        row[22] = min(1.0, max(-1.0, (-s * dx + c * dy) / diag))
        a = abs(signed[k])
        strip_sum += a
        strip_max = max(strip_max, a)
    stats[0] = strip_sum / n
    stats[1] = strip_max
    stats[2] = gap_max
    stats[3] = breaks
    stats[4] = spacing_err / (n - 1) if n > 1 else 0.0
