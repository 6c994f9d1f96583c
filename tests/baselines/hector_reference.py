"""The Hector SLAM of ``agri_baselines/hector_slam.py`` before its per-scan path was compiled, kept as an oracle.

``HectorSlam.update`` now runs the scan's endpoints, the coarse-to-fine matching and the map update each in one
compiled call (the points scaled to each level's cells once per level instead of once per pass); this copy of
the earlier implementation (numpy for the endpoints and the map update, Python over the levels, the kernels as
they were) is what ``test_hector_slam.py`` compares it with, pose and maps bit for bit, on recorded scans.
"""

import math

import numba
import numpy as np

from agri_baselines.hector_slam import _UNKNOWN_PROBABILITY, HectorSlamConfig, _log_odds


@numba.njit(cache=True, inline="always")
def _interpolate(prob: np.ndarray, mx: float, my: float) -> tuple[float, float, float, bool]:
    """Bilinear map value and its gradient (per cell) at map coordinates ``(mx, my)`` (eqs. 4-6)."""
    n_rows, n_cols = prob.shape
    ix = int(math.floor(mx))
    iy = int(math.floor(my))
    if ix < 0 or iy < 0 or ix + 1 >= n_cols or iy + 1 >= n_rows:
        return 0.0, 0.0, 0.0, False
    fx = mx - ix
    fy = my - iy
    v00 = prob[iy, ix]  # P00: (x0, y0)
    v10 = prob[iy, ix + 1]  # P10: (x1, y0)
    v01 = prob[iy + 1, ix]  # P01: (x0, y1)
    v11 = prob[iy + 1, ix + 1]  # P11: (x1, y1)
    value = (1.0 - fy) * ((1.0 - fx) * v00 + fx * v10) + fy * ((1.0 - fx) * v01 + fx * v11)
    # Eq. 5: x-differences weighted by the y factors; eq. 6: y-differences weighted by the x factors.
    dx = fy * (v11 - v01) + (1.0 - fy) * (v10 - v00)
    dy = fx * (v11 - v10) + (1.0 - fx) * (v01 - v00)
    return value, dx, dy, True


@numba.njit(cache=True)
def _matching_cost(
    prob: np.ndarray, cell: float, origin: float, points: np.ndarray, x: float, y: float, psi: float
) -> float:
    """``sum (1 - M(S_i))^2`` of the scan at pose ``(x, y, psi)``; points off the grid count as misses."""
    c = math.cos(psi)
    s = math.sin(psi)
    tx = (x - origin) / cell
    ty = (y - origin) / cell
    cost = 0.0
    for k in range(points.shape[0]):
        px = points[k, 0] / cell
        py = points[k, 1] / cell
        value, _, _, ok = _interpolate(prob, tx + c * px - s * py, ty + s * px + c * py)
        residual = 1.0 - value if ok else 1.0
        cost += residual * residual
    return cost


@numba.njit(cache=True)
def _gauss_newton(
    prob: np.ndarray,
    cell: float,
    origin: float,
    points: np.ndarray,
    pose: np.ndarray,
    iterations: int,
    max_angle_step: float,
    max_halvings: int,
) -> float:
    """Refine ``pose`` (in place, world frame) on one level; return the final matching cost.

    Each iteration solves ``H dxi = sum J^T (1 - M)`` with ``J = grad M * dS/dxi`` (Kohlbrecher eqs. 9-13).
    Translations are handled in map cells so that H is well scaled on every level. With
    ``max_halvings > 0`` a step must lower the cost, else it is halved up to that many times and the
    level ends when none does; ``max_halvings = 0`` takes every step, as hector_mapping does.
    """
    cost = _matching_cost(prob, cell, origin, points, pose[0], pose[1], pose[2])
    for _ in range(iterations):
        c = math.cos(pose[2])
        s = math.sin(pose[2])
        tx = (pose[0] - origin) / cell
        ty = (pose[1] - origin) / cell
        h00 = h01 = h02 = h11 = h12 = h22 = 0.0
        b0 = b1 = b2 = 0.0
        for k in range(points.shape[0]):
            px = points[k, 0] / cell
            py = points[k, 1] / cell
            mx = tx + c * px - s * py
            my = ty + s * px + c * py
            value, gx, gy, ok = _interpolate(prob, mx, my)
            if not ok:
                continue
            residual = 1.0 - value
            # dS/dpsi of the rotated point (map cells per radian).
            j2 = gx * (-s * px - c * py) + gy * (c * px - s * py)
            b0 += gx * residual
            b1 += gy * residual
            b2 += j2 * residual
            h00 += gx * gx
            h01 += gx * gy
            h02 += gx * j2
            h11 += gy * gy
            h12 += gy * j2
            h22 += j2 * j2
        if h00 == 0.0 or h11 == 0.0:
            break
        # Solve the symmetric 3x3 system by its adjugate (no LAPACK in the hot loop).
        a00 = h11 * h22 - h12 * h12
        a01 = h02 * h12 - h01 * h22
        a02 = h01 * h12 - h02 * h11
        det = h00 * a00 + h01 * a01 + h02 * a02
        if abs(det) < 1e-12:
            break
        a11 = h00 * h22 - h02 * h02
        a12 = h01 * h02 - h00 * h12
        a22 = h00 * h11 - h01 * h01
        dx = (a00 * b0 + a01 * b1 + a02 * b2) / det * cell
        dy = (a01 * b0 + a11 * b1 + a12 * b2) / det * cell
        dpsi = (a02 * b0 + a12 * b1 + a22 * b2) / det
        dpsi = min(max_angle_step, max(-max_angle_step, dpsi))
        if max_halvings == 0:
            pose[0] += dx
            pose[1] += dy
            pose[2] += dpsi
            continue
        accepted = False
        for _ in range(max_halvings + 1):
            new_cost = _matching_cost(prob, cell, origin, points, pose[0] + dx, pose[1] + dy, pose[2] + dpsi)
            if new_cost < cost:
                pose[0] += dx
                pose[1] += dy
                pose[2] += dpsi
                cost = new_cost
                accepted = True
                break
            dx *= 0.5
            dy *= 0.5
            dpsi *= 0.5
        if not accepted:
            break
    return cost


@numba.njit(cache=True, inline="always")
def _inside_free_space(log_odds: np.ndarray, x: int, y: int, threshold: float) -> bool:
    """Whether cell ``(x, y)`` and its eight neighbours all have log-odds below ``threshold``."""
    n_rows, n_cols = log_odds.shape
    for yy in range(max(0, y - 1), min(n_rows, y + 2)):
        for xx in range(max(0, x - 1), min(n_cols, x + 2)):
            if log_odds[yy, xx] >= threshold:
                return False
    return True


@numba.njit(cache=True)
def _update_grid(
    log_odds: np.ndarray,
    prob: np.ndarray,
    mark: np.ndarray,
    free_index: int,
    sx: float,
    sy: float,
    ends: np.ndarray,
    l_free: float,
    l_occupied: float,
    limit: float,
    free_space_guard: float,
) -> None:
    """Trace every beam from the sensor ``(sx, sy)`` to its endpoint (map cells); update each cell once.

    ``mark`` holds, per cell, the index of the last scan that touched it: ``free_index`` when a beam
    passed through, ``free_index + 1`` when one ended in it. An endpoint in a cell already freed in this
    scan takes back the free update, so a cell counts either as free or as hit, once. An endpoint deep in
    known free space (log-odds of the cell and its neighbours below ``free_space_guard``) marks nothing.
    """
    n_rows, n_cols = log_odds.shape
    occupied_index = free_index + 1
    x0 = int(math.floor(sx + 0.5))
    y0 = int(math.floor(sy + 0.5))
    if x0 < 0 or y0 < 0 or x0 >= n_cols or y0 >= n_rows:
        return
    for k in range(ends.shape[0]):
        x1 = int(math.floor(ends[k, 0] + 0.5))
        y1 = int(math.floor(ends[k, 1] + 0.5))
        if x1 < 0 or y1 < 0 or x1 >= n_cols or y1 >= n_rows:
            continue
        # Bresenham from (x0, y0) to (x1, y1), endpoint excluded.
        dx = abs(x1 - x0)
        dy = -abs(y1 - y0)
        step_x = 1 if x0 < x1 else -1
        step_y = 1 if y0 < y1 else -1
        err = dx + dy
        x = x0
        y = y0
        while x != x1 or y != y1:
            if mark[y, x] < free_index:
                mark[y, x] = free_index
                v = max(-limit, log_odds[y, x] + l_free)
                log_odds[y, x] = v
                prob[y, x] = 1.0 / (1.0 + math.exp(-v))
            e2 = 2 * err
            if e2 >= dy:
                err += dy
                x += step_x
            if e2 <= dx:
                err += dx
                y += step_y
        if mark[y1, x1] < occupied_index and not _inside_free_space(log_odds, x1, y1, free_space_guard):
            v = log_odds[y1, x1]
            if mark[y1, x1] == free_index:
                v -= l_free
            mark[y1, x1] = occupied_index
            v = min(limit, v + l_occupied)
            log_odds[y1, x1] = v
            prob[y1, x1] = 1.0 / (1.0 + math.exp(-v))


class ReferenceHectorSlam:
    """``HectorSlam`` as it was before its per-scan path was compiled (same arguments, same state)."""

    def __init__(
        self,
        config: HectorSlamConfig,
        beam_angles: np.ndarray,
        lidar_mount: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.config = config
        angles = np.asarray(beam_angles, dtype=np.float64) + lidar_mount[2]
        self._cos = np.cos(angles)
        self._sin = np.sin(angles)
        self._mount = np.array(lidar_mount, dtype=np.float64)
        self._l_free = _log_odds(config.update_free)
        self._l_occupied = _log_odds(config.update_occupied)
        # Grid origin: map coordinate 0 of every level lies this far from the start pose (m).
        self._origin = -0.5 * config.map_size * config.resolution
        self.log_odds = [np.zeros((config.map_size >> lvl,) * 2, np.float32) for lvl in range(config.levels)]
        self.prob = [np.zeros_like(g) for g in self.log_odds]
        self._mark = [np.zeros(g.shape, np.int32) for g in self.log_odds]
        self.reset()

    # -- state ----------------------------------------------------------------------------------------
    def reset(self, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """Clear the map and start a new one with the robot at ``pose`` (normally the origin)."""
        for lo, pr, mk in zip(self.log_odds, self.prob, self._mark, strict=True):
            lo.fill(0.0)
            pr.fill(_UNKNOWN_PROBABILITY)
            mk.fill(0)
        self._pose = np.array(pose, dtype=np.float64)
        self._motion = np.zeros(3)  # the last scan-to-scan motion of the estimate (map frame)
        self._last_map_pose: np.ndarray | None = None
        self._scan_index = 0
        self.scans = 0
        self.map_updates = 0

    @property
    def pose(self) -> np.ndarray:
        """Current robot pose estimate ``(x, y, yaw)`` in the map frame (m, m, rad); a copy."""
        return self._pose.copy()

    def cell_size(self, level: int) -> float:
        """Edge of a cell of ``level`` (m)."""
        return self.config.resolution * (1 << level)

    def world_to_map(self, xy: np.ndarray, level: int = 0) -> np.ndarray:
        """Map coordinates (cells, fractional) of points ``(..., 2)`` in the map frame."""
        return (np.asarray(xy, dtype=np.float64) - self._origin) / self.cell_size(level)

    # -- one scan ---------------------------------------------------------------------------------------
    def scan_points(self, ranges: np.ndarray) -> np.ndarray:
        """Endpoints ``(k, 2)`` of the valid beams in the robot frame (m); no-echo and too-short beams dropped."""
        r = np.asarray(ranges, dtype=np.float64)
        if r.shape != self._cos.shape:
            raise ValueError(f"HectorSlam: expected {self._cos.size} ranges, got shape {r.shape}")
        cfg = self.config
        valid = (r >= cfg.min_range) & (r < cfg.max_range - 1e-6)
        rv = r[valid]
        pts = np.empty((rv.size, 2))
        pts[:, 0] = self._mount[0] + rv * self._cos[valid]
        pts[:, 1] = self._mount[1] + rv * self._sin[valid]
        return pts

    def match(self, points: np.ndarray, initial: np.ndarray) -> np.ndarray:
        """Scan-to-map matching, coarse to fine, from ``initial``; returns the refined pose (a new array)."""
        cfg = self.config
        pose = np.array(initial, dtype=np.float64)
        for level in range(cfg.levels - 1, -1, -1):
            iterations = cfg.iterations_fine if level == 0 else cfg.iterations_coarse
            if iterations:
                _gauss_newton(
                    self.prob[level],
                    self.cell_size(level),
                    self._origin,
                    points,
                    pose,
                    iterations,
                    cfg.max_angle_step,
                    cfg.max_step_halvings,
                )
        pose[2] = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
        return pose

    def update_map(self, points: np.ndarray, pose: np.ndarray) -> None:
        """Integrate a scan (robot-frame endpoints) taken at ``pose`` into every level of the map."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        world = np.empty_like(points)
        world[:, 0] = pose[0] + c * points[:, 0] - s * points[:, 1]
        world[:, 1] = pose[1] + s * points[:, 0] + c * points[:, 1]
        sensor = pose[:2] + np.array([c * self._mount[0] - s * self._mount[1], s * self._mount[0] + c * self._mount[1]])
        self._scan_index += 2
        cfg = self.config
        for level in range(cfg.levels):
            cell = self.cell_size(level)
            ends = (world - self._origin) / cell
            sx, sy = (sensor - self._origin) / cell
            _update_grid(
                self.log_odds[level],
                self.prob[level],
                self._mark[level],
                self._scan_index,
                float(sx),
                float(sy),
                ends,
                self._l_free,
                self._l_occupied,
                cfg.log_odds_limit,
                -math.inf if cfg.free_space_guard is None else cfg.free_space_guard,
            )
        self._last_map_pose = pose.copy()
        self.map_updates += 1

    def update(self, ranges: np.ndarray) -> np.ndarray:
        """Process one scan: match it against the map (after the first), update the map when due.

        Args:
            ranges: One range per beam (m), ordered like ``beam_angles``.

        Returns:
            The new pose estimate ``(x, y, yaw)`` (a copy).
        """
        points = self.scan_points(ranges)
        self.scans += 1
        if self._last_map_pose is None:
            if len(points):
                self.update_map(points, self._pose)
            return self.pose
        if len(points) >= 3:
            before = self._pose
            guess = before + self._motion if self.config.constant_velocity else before
            self._pose = self.match(points, guess)
            step = self._pose - before
            step[2] = math.atan2(math.sin(step[2]), math.cos(step[2]))
            self._motion = step
        moved = self._pose - self._last_map_pose
        turned = abs(math.atan2(math.sin(moved[2]), math.cos(moved[2])))
        if math.hypot(moved[0], moved[1]) > self.config.update_distance or turned > self.config.update_angle:
            self.update_map(points, self._pose)
        return self.pose
