"""Hector-style 2D SLAM from a planar LIDAR alone (Kohlbrecher et al. 2011), as used on Harik's rover.

The map is a stack of occupancy grids in log-odds, each level half the resolution of the previous one.
For every scan the pose is found by Gauss-Newton matching of the scan endpoints against the map, from
the coarsest level to the finest, starting at the previous pose (no odometry, no motion model). The
matcher minimises ``sum_i (1 - M(S_i(xi)))^2`` over ``xi = (x, y, psi)`` (Kohlbrecher eqs. 7-13), where
``M`` is the occupancy probability interpolated bilinearly between the four cells around a point and
its gradient is the analytic derivative of that interpolation (eqs. 4-6). Note: the public ROS
``hector_mapping`` code weights the x and y differences of the gradient with the wrong interpolation
factors (it uses the x factor for the x derivative); this module implements the paper's formula, and
``tests/baselines/test_hector_slam.py`` checks it against finite differences.

The map is updated only when the pose has moved or turned past a threshold since the last update. Every
beam is traced with Bresenham's algorithm; each cell is updated at most once per scan (a cell that is
both crossed by one beam and hit by another counts as hit), which keeps the log-odds a count of scans.
Three additions of ours, on by default and switchable (``free_space_guard=None, max_step_halvings=0,
constant_velocity=False`` give plain Hector): a beam that ends inside space the map knows to be free is
taken for a moving object and is not mapped; a Gauss-Newton step must lower the matching cost (else it
is halved); and the matching starts from the pose extrapolated at the last scan-to-scan motion of the
SLAM's own estimate (a constant-velocity prediction, as KISS-ICP makes; still no odometry). Without the
first, a person who stands in front of the robot for two map updates becomes part of the map, and when
they walk away the matcher follows them along a featureless corridor; without the second, the coarse
level occasionally takes a 0.6 m step when the robot faces a wall across an open headland. Both were
seen in ``corridor`` and ``plant-development``; the numbers are in the report under
``harik-apf-hector-plain``. Without the third, a 180 deg turn on the spot a few decimetres from the end
wall of the office corridor (0.05 rad between scans, the matcher starting from the previous pose each
time) now and then slid the estimate sideways until the map took in a wrong scan and the pose was lost
(2 of 20 repeatability missions on validation seeds, ATE 1.5 m and 0.4 m; replayed from their recorded
scans, both stay under 0.15 m with the prediction).

A caller with wheel odometry may pass the motion it measured since the previous scan to :meth:`HectorSlam.update`
(``odometry``): the match then starts from the previous pose moved on by it, as hector_mapping does with an odometry
frame, instead of from the prediction. ``harik-apf`` passes none (the paper's SLAM runs on the LIDAR alone).

Grid conventions: level ``l`` has cells of ``resolution * 2**l`` metres and ``map_size >> l`` cells per
side; the value of cell ``(i, j)`` (row ``i`` along y, column ``j`` along x) sits at the *integer*
map coordinate ``(j, i)``, and the start pose (the map frame's origin) is the centre of the grid. This
module is a pure algorithm: numpy and numba only, no Gymnasium.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numba
import numpy as np

# Cells of unknown occupancy have log-odds 0, i.e. probability 0.5, as in hector_mapping.
_UNKNOWN_PROBABILITY = 0.5


@dataclasses.dataclass(frozen=True)
class HectorSlamConfig:
    """Parameters of :class:`HectorSlam` (defaults after ROS ``hector_mapping``, unless noted).

    Attributes:
        resolution: Cell size of the finest level (m). ROS: ``map_resolution`` 0.05.
        levels: Number of grid levels, each half the resolution of the previous. ROS: ``map_multi_res_levels`` 2-3.
        map_size: Cells per side of the finest level; the map covers ``map_size * resolution`` metres,
            centred on the start pose. ROS: ``map_size`` 1024 (51.2 m at 5 cm).
        update_free: Occupancy probability of a cell a beam passes through. ROS: ``update_factor_free`` 0.4.
        update_occupied: Occupancy probability of a cell a beam ends in. ROS: ``update_factor_occupied`` 0.9.
        update_distance: The map is updated after the pose moved this far since the last update (m).
            ROS: ``map_update_distance_thresh`` 0.4.
        update_angle: ... or turned this much (rad). The issue's 0.06 rad (ROS ships 0.9).
        min_range: Beams shorter than this are ignored (m); the TiM561's minimum is 0.05 m.
        max_range: Beams at or beyond this are no-echo readings and ignored (m); the TiM561's maximum.
        iterations_fine: Gauss-Newton iterations on the finest level. ROS: 5.
        iterations_coarse: Gauss-Newton iterations on each coarser level. ROS: 3.
        max_angle_step: Largest heading change of one Gauss-Newton step (rad). ROS: 0.2.
        max_step_halvings: A Gauss-Newton step that does not lower the matching cost is halved up to this
            many times before the level gives up (a safeguard of ours against the long steps an
            ill-conditioned coarse level can take); 0 takes every step, as hector_mapping does.
        log_odds_limit: Log-odds are clamped to +-this, so the map can follow changes (people, growth).
        free_space_guard: Not in hector_mapping (an addition of ours, switchable): a beam ending in a cell
            that lies, with its eight neighbours, in known free space (all log-odds below this value: each
            crossed by beams at least twice more often than hit) is taken for a moving object, such as a
            person stepping into a corridor the robot has seen empty, and does not mark its cell occupied;
            it still clears the cells it crosses. ``None`` gives plain Hector, which maps a person who
            stands still for two map updates and then follows them when they walk away.
        constant_velocity: Not in hector_mapping (an addition of ours, switchable): each scan is matched
            from the previous pose moved on by the motion between the two scans before it (the SLAM's own
            estimates, no odometry). False matches from the previous pose, as hector_mapping does without
            an odometry guess.
    """

    resolution: float = 0.05
    levels: int = 3
    map_size: int = 1024
    update_free: float = 0.4
    update_occupied: float = 0.9
    update_distance: float = 0.4
    update_angle: float = 0.06
    min_range: float = 0.05
    max_range: float = 10.0
    iterations_fine: int = 5
    iterations_coarse: int = 3
    max_angle_step: float = 0.2
    max_step_halvings: int = 3
    log_odds_limit: float = 50.0
    free_space_guard: float | None = -0.5
    constant_velocity: bool = True

    def __post_init__(self) -> None:
        if not (self.resolution > 0 and math.isfinite(self.resolution)):
            raise ValueError(f"HectorSlamConfig: resolution must be > 0 m, got {self.resolution}")
        if not 1 <= self.levels <= 6:
            raise ValueError(f"HectorSlamConfig: levels must be in [1, 6], got {self.levels}")
        if self.map_size < 16 or self.map_size % (1 << (self.levels - 1)):
            raise ValueError(
                f"HectorSlamConfig: map_size must be >= 16 and divisible by 2**(levels-1), got {self.map_size}"
            )
        if not 0.0 < self.update_free < 0.5 < self.update_occupied < 1.0:
            raise ValueError("HectorSlamConfig: need 0 < update_free < 0.5 < update_occupied < 1")
        if self.update_distance < 0 or self.update_angle < 0:
            raise ValueError("HectorSlamConfig: update_distance and update_angle must be >= 0")
        if not 0 <= self.min_range < self.max_range:
            raise ValueError("HectorSlamConfig: need 0 <= min_range < max_range")
        if self.iterations_fine < 1 or self.iterations_coarse < 0:
            raise ValueError("HectorSlamConfig: need iterations_fine >= 1 and iterations_coarse >= 0")
        if self.max_angle_step <= 0 or self.log_odds_limit <= 0:
            raise ValueError("HectorSlamConfig: max_angle_step and log_odds_limit must be > 0")


def _log_odds(p: float) -> float:
    return math.log(p / (1.0 - p))


# --------------------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------------------


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
def interpolate_map(prob: np.ndarray, mxy: np.ndarray) -> np.ndarray:
    """Map value and gradient at many map coordinates: ``(n, 2) -> (n, 3)`` of ``(M, dM/dx, dM/dy)``.

    Points outside the grid get ``nan``. Gradients are per cell (divide by the cell size for metres).
    """
    out = np.empty((mxy.shape[0], 3))
    for k in range(mxy.shape[0]):
        v, dx, dy, ok = _interpolate(prob, mxy[k, 0], mxy[k, 1])
        if ok:
            out[k, 0] = v
            out[k, 1] = dx
            out[k, 2] = dy
        else:
            out[k, :] = np.nan
    return out


@numba.njit(cache=True)
def _matching_cost(
    prob: np.ndarray, cell: float, origin: float, px: np.ndarray, py: np.ndarray, x: float, y: float, psi: float
) -> float:
    """``sum (1 - M(S_i))^2`` of the scan at pose ``(x, y, psi)``; points off the grid count as misses.

    ``px, py``: the scan's endpoints in cells of this level (robot frame).
    """
    c = math.cos(psi)
    s = math.sin(psi)
    tx = (x - origin) / cell
    ty = (y - origin) / cell
    cost = 0.0
    for k in range(px.shape[0]):
        value, _, _, ok = _interpolate(prob, tx + c * px[k] - s * py[k], ty + s * px[k] + c * py[k])
        residual = 1.0 - value if ok else 1.0
        cost += residual * residual
    return cost


@numba.njit(cache=True)
def _normal_equations(
    prob: np.ndarray, cell: float, origin: float, px: np.ndarray, py: np.ndarray, x: float, y: float, psi: float
) -> tuple[float, float, float, float, float, float, float, float, float, float]:
    """One pass over the scan at pose ``(x, y, psi)``: the Gauss-Newton sums and the matching cost.

    Returns ``(h00, h01, h02, h11, h12, h22, b0, b1, b2, cost)``: ``H`` and ``b`` of ``H dxi = sum J^T (1 - M)``
    over the points on the grid (Kohlbrecher eqs. 9-13), and :func:`_matching_cost` (off-grid points count as
    misses), each summed in point order, so each equals what a pass computing it alone gives.
    """
    c = math.cos(psi)
    s = math.sin(psi)
    tx = (x - origin) / cell
    ty = (y - origin) / cell
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    b0 = b1 = b2 = 0.0
    cost = 0.0
    for k in range(px.shape[0]):
        mx = tx + c * px[k] - s * py[k]
        my = ty + s * px[k] + c * py[k]
        value, gx, gy, ok = _interpolate(prob, mx, my)
        residual = 1.0 - value if ok else 1.0
        cost += residual * residual
        if not ok:
            continue
        # dS/dpsi of the rotated point (map cells per radian).
        j2 = gx * (-s * px[k] - c * py[k]) + gy * (c * px[k] - s * py[k])
        b0 += gx * residual
        b1 += gy * residual
        b2 += j2 * residual
        h00 += gx * gx
        h01 += gx * gy
        h02 += gx * j2
        h11 += gy * gy
        h12 += gy * j2
        h22 += j2 * j2
    return h00, h01, h02, h11, h12, h22, b0, b1, b2, cost


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

    The cost of a tried pose and the next iteration's sums there come from one pass over the scan
    (:func:`_normal_equations`): an accepted step's pass is the next iteration's.
    """
    n = points.shape[0]
    px = np.empty(n)  # the endpoints in cells of this level, once for every pass over them
    py = np.empty(n)
    for k in range(n):
        px[k] = points[k, 0] / cell
        py[k] = points[k, 1] / cell
    h00, h01, h02, h11, h12, h22, b0, b1, b2, cost = _normal_equations(
        prob, cell, origin, px, py, pose[0], pose[1], pose[2]
    )
    for iteration in range(iterations):
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
            if iteration + 1 < iterations:
                h00, h01, h02, h11, h12, h22, b0, b1, b2, _ = _normal_equations(
                    prob, cell, origin, px, py, pose[0], pose[1], pose[2]
                )
            continue
        accepted = False
        for _ in range(max_halvings + 1):
            tried = _normal_equations(prob, cell, origin, px, py, pose[0] + dx, pose[1] + dy, pose[2] + dpsi)
            if tried[9] < cost:
                pose[0] += dx
                pose[1] += dy
                pose[2] += dpsi
                h00, h01, h02, h11, h12, h22, b0, b1, b2, cost = tried
                accepted = True
                break
            dx *= 0.5
            dy *= 0.5
            dpsi *= 0.5
        if not accepted:
            break
    return cost


@numba.njit(cache=True)
def _match_levels(
    probs: tuple[np.ndarray, ...],
    resolution: float,
    origin: float,
    points: np.ndarray,
    pose: np.ndarray,
    iterations_fine: int,
    iterations_coarse: int,
    max_angle_step: float,
    max_halvings: int,
) -> None:
    """Gauss-Newton on every level, coarsest first, refining ``pose`` in place (:meth:`HectorSlam.match`)."""
    for level in range(len(probs) - 1, -1, -1):
        iterations = iterations_fine if level == 0 else iterations_coarse
        if iterations:
            cell = resolution * (1 << level)
            _gauss_newton(probs[level], cell, origin, points, pose, iterations, max_angle_step, max_halvings)


@numba.njit(cache=True)
def _scan_endpoints(
    ranges: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    mount_x: float,
    mount_y: float,
    min_range: float,
    no_echo: float,
) -> np.ndarray:
    """Endpoints ``(k, 2)`` in the robot frame of the beams with ``min_range <= r < no_echo`` (in beam order)."""
    n = 0
    for r in ranges:
        if r >= min_range and r < no_echo:
            n += 1
    points = np.empty((n, 2))
    k = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if r >= min_range and r < no_echo:
            points[k, 0] = mount_x + r * cos[i]
            points[k, 1] = mount_y + r * sin[i]
            k += 1
    return points


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


@numba.njit(cache=True)
def _update_levels(
    log_odds: tuple[np.ndarray, ...],
    probs: tuple[np.ndarray, ...],
    marks: tuple[np.ndarray, ...],
    scan_index: int,
    points: np.ndarray,
    x: float,
    y: float,
    c: float,
    s: float,
    sensor_x: float,
    sensor_y: float,
    origin: float,
    resolution: float,
    l_free: float,
    l_occupied: float,
    limit: float,
    free_space_guard: float,
) -> None:
    """Integrate a scan into every level (:meth:`HectorSlam.update_map`).

    The robot-frame endpoints ``points`` were taken at ``(x, y)`` with heading cosine ``c`` and sine ``s``, from
    the sensor at ``(sensor_x, sensor_y)`` (map frame, m).
    """
    n = points.shape[0]
    world = np.empty((n, 2))
    for k in range(n):
        world[k, 0] = x + c * points[k, 0] - s * points[k, 1]
        world[k, 1] = y + s * points[k, 0] + c * points[k, 1]
    ends = np.empty((n, 2))
    for level in range(len(log_odds)):
        cell = resolution * (1 << level)
        for k in range(n):
            ends[k, 0] = (world[k, 0] - origin) / cell
            ends[k, 1] = (world[k, 1] - origin) / cell
        _update_grid(
            log_odds[level],
            probs[level],
            marks[level],
            scan_index,
            (sensor_x - origin) / cell,
            (sensor_y - origin) / cell,
            ends,
            l_free,
            l_occupied,
            limit,
            free_space_guard,
        )


# --------------------------------------------------------------------------------------------------
# The SLAM
# --------------------------------------------------------------------------------------------------


class HectorSlam:
    """Multi-resolution occupancy-grid SLAM with Gauss-Newton scan matching (one robot).

    Args:
        config: Parameters (see :class:`HectorSlamConfig`).
        beam_angles: Angle of every beam in the sensor frame (rad), as the scan's ranges are ordered.
        lidar_mount: ``(x, y, yaw)`` of the LIDAR on the robot (m, m, rad); the SLAM estimates the pose of
            the robot, not of the sensor.

    Example::

        slam = HectorSlam(HectorSlamConfig(), beam_angles, (0.28, 0.0, 0.0))
        slam.reset()
        for ranges in scans:
            x, y, yaw = slam.update(ranges)
    """

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
        # The same arrays as tuples, for the compiled per-scan path (one call over every level).
        self._levels = (tuple(self.log_odds), tuple(self.prob), tuple(self._mark))
        self._no_echo = config.max_range - 1e-6
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
        mount = self._mount
        return _scan_endpoints(r, self._cos, self._sin, mount[0], mount[1], self.config.min_range, self._no_echo)

    def match(self, points: np.ndarray, initial: np.ndarray) -> np.ndarray:
        """Scan-to-map matching, coarse to fine, from ``initial``; returns the refined pose (a new array)."""
        cfg = self.config
        pose = np.array(initial, dtype=np.float64)
        _match_levels(
            self._levels[1],
            cfg.resolution,
            self._origin,
            points,
            pose,
            cfg.iterations_fine,
            cfg.iterations_coarse,
            cfg.max_angle_step,
            cfg.max_step_halvings,
        )
        pose[2] = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
        return pose

    def update_map(self, points: np.ndarray, pose: np.ndarray) -> None:
        """Integrate a scan (robot-frame endpoints) taken at ``pose`` into every level of the map."""
        c, s = math.cos(pose[2]), math.sin(pose[2])
        m = self._mount
        sensor = pose[:2] + np.array([c * m[0] - s * m[1], s * m[0] + c * m[1]])
        self._scan_index += 2
        cfg = self.config
        _update_levels(
            *self._levels,
            self._scan_index,
            np.ascontiguousarray(points, dtype=np.float64),
            pose[0],
            pose[1],
            c,
            s,
            sensor[0],
            sensor[1],
            self._origin,
            cfg.resolution,
            self._l_free,
            self._l_occupied,
            cfg.log_odds_limit,
            -math.inf if cfg.free_space_guard is None else cfg.free_space_guard,
        )
        self._last_map_pose = pose.copy()
        self.map_updates += 1

    def update(self, ranges: np.ndarray, odometry: tuple[float, float, float] | None = None) -> np.ndarray:
        """Process one scan: match it against the map (after the first), update the map when due.

        Args:
            ranges: One range per beam (m), ordered like ``beam_angles``.
            odometry: The robot's motion since the previous scan as its odometry measured it, ``(forward,
                left, turn)`` in the robot's frame at that scan (m, m, rad); the matching then starts from
                the previous pose moved on by it (hector_mapping's odometry guess) instead of the
                configured prediction. None: no odometry.

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
            if odometry is not None:
                c, s = math.cos(before[2]), math.sin(before[2])
                forward, left, turn = odometry
                guess = before + np.array([c * forward - s * left, s * forward + c * left, turn])
            else:
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

    # -- export ------------------------------------------------------------------------------------------
    def occupancy_grid(self, level: int = 0, start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Any:
        """The map of ``level`` as an :class:`agri_envs.sim2d.gridmap.OccupancyGrid` (ROS semantics).

        Args:
            level: Grid level (0 = finest).
            start_pose: World pose of the map frame's origin (the robot's start pose), so the grid can be
                compared with the scene; the default keeps the map frame.
        """
        from agri_envs.sim2d.gridmap import UNKNOWN, OccupancyGrid  # no Gymnasium until a grid is asked for

        lo = self.log_odds[level]
        data = np.rint(100.0 * self.prob[level]).astype(np.int8)
        data[lo == 0.0] = UNKNOWN
        cell = self.cell_size(level)
        x0, y0, th = start_pose
        # Cell values sit at integer map coordinates, so cell (0, 0) spans [-0.5, 0.5) cells around the origin.
        corner = self._origin - 0.5 * cell
        c, s = math.cos(th), math.sin(th)
        origin = (x0 + c * corner - s * corner, y0 + s * corner + c * corner, th)
        return OccupancyGrid(data, cell, origin)
