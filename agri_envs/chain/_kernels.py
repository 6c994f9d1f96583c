"""Compiled per-step work of robot_chain_v1: trails, observations, the chain's shape and the distance to go.

Everything a step needs beyond driving the robots and reading the sonars runs here in a few numba calls:
each robot's recorded trail (the paper's follower "fetching its previous position", sec. 8), every agent's
observation, the chain's shape statistics, and each robot's free-floor distance to the goal (the reward's
potential).
"""

from __future__ import annotations

import math

import numba
import numpy as np

#: A robot's trail gets a new point once the robot has moved this far from the last one (m).
TRAIL_STEP = 0.02
OBS_SIZE = 29


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
def record_trails(poses: np.ndarray, xy: np.ndarray, s: np.ndarray, head: np.ndarray, count: np.ndarray) -> None:
    """Append each robot's position to its trail (a ring of points) once it has moved :data:`TRAIL_STEP`.

    Args:
        poses: ``(n, 3)`` robot poses.
        xy: ``(n, L, 2)`` trail points.
        s: ``(n, L)`` arc length of each trail point along its trail (m).
        head: ``(n,)`` slot of each trail's newest point.
        count: ``(n,)`` points held (at most L).
    """
    n, cap = s.shape
    for k in range(n):
        h = head[k]
        d = math.hypot(poses[k, 0] - xy[k, h, 0], poses[k, 1] - xy[k, h, 1])
        if d >= TRAIL_STEP:
            nh = (h + 1) % cap
            xy[k, nh, 0] = poses[k, 0]
            xy[k, nh, 1] = poses[k, 1]
            s[k, nh] = s[k, h] + d
            head[k] = nh
            count[k] = min(count[k] + 1, cap)


@numba.njit(cache=True)
def trail_point_behind(
    x: float, y: float, xy: np.ndarray, s: np.ndarray, head: int, count: int, back: float
) -> tuple[float, float]:
    """The point ``back`` metres behind ``(x, y)`` (the robot now) along its trail (the oldest point if shorter)."""
    cap = s.shape[0]
    px, py = x, y
    # The robot's own position is the trail's virtual newest point.
    s_now = s[head] + math.hypot(x - xy[head, 0], y - xy[head, 1])
    target = s_now - back
    s_prev = s_now
    for i in range(count):
        idx = (head - i) % cap
        qx, qy, sq = xy[idx, 0], xy[idx, 1], s[idx]
        if sq <= target:
            span = s_prev - sq
            t = (target - sq) / span if span > 1e-12 else 0.0
            return qx + t * (px - qx), qy + t * (py - qy)
        px, py, s_prev = qx, qy, sq
    return px, py


@numba.njit(cache=True)
def observe(
    poses: np.ndarray,
    vel: np.ndarray,
    ranges: np.ndarray,
    ghost: np.ndarray,
    trail_xy: np.ndarray,
    trail_s: np.ndarray,
    trail_head: np.ndarray,
    trail_count: np.ndarray,
    goal: np.ndarray,
    bounds: np.ndarray,
    consts: np.ndarray,
    out: np.ndarray,
    stats: np.ndarray,
) -> None:
    """Fill ``out`` (n, 29) with every agent's observation (layout in the env docstring) and ``stats``.

    Args:
        poses: ``(n, 3)`` robot poses.
        vel: ``(n, 2)`` achieved ``v, omega``.
        ranges: ``(n, 8)`` sonar ranges (m).
        ghost: ``(x, y, vx, vy)`` of the ghost robot (the leader's predecessor).
        trail_xy: The robots' trails (:func:`record_trails`).
        trail_s: Their arc lengths.
        trail_head: Their newest points.
        trail_count: Their point counts.
        goal: ``(x, y)`` of the goal.
        bounds: ``(xmin, ymin, xmax, ymax)`` of the map.
        consts: ``rel_scale, sonar_range, max_speed, max_turn_rate, spacing, max_gap, goal_scale``.
        out: ``(n, 29)`` observations, filled.
        stats: Filled with the mean and max distance to the strip, the max gap, the number of gaps above
            ``max_gap`` and the mean of ``min(1, |gap - d_s| / d_s)``.
    """
    rel_scale, sonar_range, max_speed, max_turn = consts[0], consts[1], consts[2], consts[3]
    spacing, max_gap, goal_scale = consts[4], consts[5], consts[6]
    vel_scale = 2.0 * max_speed
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
        vx, vy = vel[k, 0] * c, vel[k, 0] * s
        row = out[k]
        for j in range(8):
            row[j] = min(1.0, max(0.0, ranges[k, j] / sonar_range))
        row[8] = min(1.0, max(0.0, (x - bounds[0]) / sx))
        row[9] = min(1.0, max(0.0, (y - bounds[1]) / sy))
        row[10] = s
        row[11] = c
        row[12] = min(1.0, max(-1.0, vel[k, 0] / max_speed))
        row[13] = min(1.0, max(-1.0, vel[k, 1] / max_turn))
        if k == 0:
            px, py, pvx, pvy = ghost[0], ghost[1], ghost[2], ghost[3]
            slot_x, slot_y = px, py
        else:
            px, py = poses[k - 1, 0], poses[k - 1, 1]
            pc, ps = math.cos(poses[k - 1, 2]), math.sin(poses[k - 1, 2])
            pvx, pvy = vel[k - 1, 0] * pc, vel[k - 1, 0] * ps
            slot_x, slot_y = trail_point_behind(
                px, py, trail_xy[k - 1], trail_s[k - 1], trail_head[k - 1], trail_count[k - 1], spacing
            )
        dx, dy = px - x, py - y
        row[14] = min(1.0, max(-1.0, (c * dx + s * dy) / rel_scale))
        row[15] = min(1.0, max(-1.0, (-s * dx + c * dy) / rel_scale))
        dvx, dvy = pvx - vx, pvy - vy
        row[16] = min(1.0, max(-1.0, (c * dvx + s * dvy) / vel_scale))
        row[17] = min(1.0, max(-1.0, (-s * dvx + c * dvy) / vel_scale))
        dx, dy = slot_x - x, slot_y - y
        row[18] = min(1.0, max(-1.0, (c * dx + s * dy) / rel_scale))
        row[19] = min(1.0, max(-1.0, (-s * dx + c * dy) / rel_scale))
        if k + 1 < n:
            dx, dy = poses[k + 1, 0] - x, poses[k + 1, 1] - y
            row[20] = min(1.0, max(-1.0, (c * dx + s * dy) / rel_scale))
            row[21] = min(1.0, max(-1.0, (-s * dx + c * dy) / rel_scale))
            qc, qs = math.cos(poses[k + 1, 2]), math.sin(poses[k + 1, 2])
            dvx, dvy = vel[k + 1, 0] * qc - vx, vel[k + 1, 0] * qs - vy
            row[22] = min(1.0, max(-1.0, (c * dvx + s * dvy) / vel_scale))
            row[23] = min(1.0, max(-1.0, (-s * dvx + c * dvy) / vel_scale))
            row[24] = 1.0
            gap = math.hypot(dx, dy)
            gap_max = max(gap_max, gap)
            if gap > max_gap:
                breaks += 1.0
            spacing_err += min(1.0, abs(gap - spacing) / spacing)
        else:
            for j in range(20, 25):
                row[j] = 0.0
        row[25] = 1.0 if k == 0 else 0.0
        dx, dy = goal[0] - x, goal[1] - y
        d = math.hypot(dx, dy)
        if d > 1e-9:
            row[26] = (c * dx + s * dy) / d
            row[27] = (-s * dx + c * dy) / d
        else:
            row[26] = 0.0
            row[27] = 0.0
        row[28] = min(1.0, d / goal_scale)
        a = abs(signed[k])
        strip_sum += a
        strip_max = max(strip_max, a)
    stats[0] = strip_sum / n
    stats[1] = strip_max
    stats[2] = gap_max
    stats[3] = breaks
    stats[4] = spacing_err / (n - 1) if n > 1 else 0.0


@numba.njit(cache=True)
def distances_to_go(
    poses: np.ndarray,
    field: np.ndarray,
    blocked: np.ndarray,
    frame: np.ndarray,
    window: int,
    far: float,
    goal: np.ndarray,
    radii: np.ndarray,
    excess: np.ndarray,
) -> int:
    """Each robot's free-floor distance to the goal beyond its arrival radius; returns how many have arrived.

    The free-floor distance is the goal's distance field (m) at the robot's cell. A robot standing on a cell
    of the inflated map that planning avoids (it may pass nearer to a wall than the planning margin) takes
    the best free cell within ``window`` cells: that cell's distance plus the straight line to it (``far``
    when there is none). ``excess[k] = max(0, distance - radii[k])``; robot k has arrived when its straight
    distance to the goal is at most ``radii[k]`` (the success rule).

    Args:
        poses: ``(n, 3)`` robot poses.
        field: ``(H, W)`` the goal's free-floor distance field (m; inf where unreachable).
        blocked: ``(H, W)`` cells of the inflated map that planning avoids.
        frame: The grid's ``(origin_x, origin_y, cos yaw, sin yaw, resolution)`` (ROS map conventions).
        window: Half-width (cells) of the search for a free cell round a robot on a blocked one.
        far: The distance of a robot with no free cell in reach (m).
        goal: ``(x, y)`` of the goal.
        radii: ``(n,)`` arrival radii (m).
        excess: ``(n,)`` filled with each robot's distance beyond its radius (m).
    """
    h, w = field.shape
    ox, oy, cy_, sy_, res = frame[0], frame[1], frame[2], frame[3], frame[4]
    arrived = 0
    for k in range(poses.shape[0]):
        x, y = poses[k, 0], poses[k, 1]
        lx, ly = cy_ * (x - ox) + sy_ * (y - oy), -sy_ * (x - ox) + cy_ * (y - oy)
        j = int(math.floor(lx / res))
        i = int(math.floor(ly / res))
        best = far
        if 0 <= i < h and 0 <= j < w and not blocked[i, j] and field[i, j] < far:
            best = field[i, j]
        else:
            for a in range(max(0, i - window), min(h, i + window + 1)):
                cy = (a + 0.5) * res
                for b in range(max(0, j - window), min(w, j + window + 1)):
                    if blocked[a, b]:
                        continue
                    f = field[a, b]
                    if f >= best:
                        continue
                    f += math.hypot((b + 0.5) * res - lx, cy - ly)
                    if f < best:
                        best = f
        excess[k] = max(0.0, best - radii[k])
        if math.hypot(goal[0] - x, goal[1] - y) <= radii[k]:
            arrived += 1
    return arrived
