"""A robot's own memory of the place: where it drove and where its range sensors echoed, seen from its pose.

The robot keeps a coarse grid in its odometry frame and marks in it, every control period, the cell under
its estimated centre (channel ``visited``) and the cell of each range reading's echo (channel ``echo``: the
sensory map of González 2009, eq. 2, with the echo placed along the sensor's axis). The observation is a
robot-centred window of that grid, turned with the robot's estimated heading: row ``a`` lies
``(a - (n - 1) / 2) * cell`` metres ahead of the robot, column ``b`` the same distance to its left. Only
the robot's own estimates and readings go in, so the memory drifts with its odometry, as a real one would.

The two kernels are plain numba functions of arrays, so a batched env can call them per world.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

#: The memory's channels, in order.
CHANNELS = ("visited", "echo")


@numba.njit(cache=True)
def _cell_of(x: float, y: float, x0: float, y0: float, cell: float, ny: int, nx: int) -> tuple[int, int]:
    """Grid cell ``(row, column)`` of a point, or ``(-1, -1)`` outside the grid."""
    i = int(math.floor((y - y0) / cell))
    j = int(math.floor((x - x0) / cell))
    if 0 <= i < ny and 0 <= j < nx:
        return i, j
    return -1, -1


@numba.njit(cache=True)
def mark_memory(
    grid: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    x: float,
    y: float,
    sensor_poses: np.ndarray,
    ranges: np.ndarray,
    max_range: float,
) -> None:
    """Mark the robot's cell as visited and each echo's cell (readings below ``max_range``) in ``grid``.

    Args:
        grid: ``(2, ny, nx)`` memory, channel 0 visited, 1 echo; cell ``[i, j]`` covers
            ``x0 + [j, j + 1) * cell``, ``y0 + [i, i + 1) * cell``.
        x0: Grid origin x (m).
        y0: Grid origin y (m).
        cell: Cell size (m).
        x: Estimated robot x (m).
        y: Estimated robot y (m).
        sensor_poses: ``(k, 3)`` estimated ``(x, y, yaw)`` of each range sensor in the grid's frame.
        ranges: ``(k,)`` readings (m); ``max_range`` means no echo.
        max_range: The sensors' maximum range (m).
    """
    ny, nx = grid.shape[1], grid.shape[2]
    i, j = _cell_of(x, y, x0, y0, cell, ny, nx)
    if i >= 0:
        grid[0, i, j] = 1.0
    for k in range(ranges.shape[0]):
        r = ranges[k]
        if r >= max_range:
            continue
        ex = sensor_poses[k, 0] + r * math.cos(sensor_poses[k, 2])
        ey = sensor_poses[k, 1] + r * math.sin(sensor_poses[k, 2])
        i, j = _cell_of(ex, ey, x0, y0, cell, ny, nx)
        if i >= 0:
            grid[1, i, j] = 1.0


@numba.njit(cache=True)
def egocentric_view(
    grid: np.ndarray, x0: float, y0: float, cell: float, x: float, y: float, yaw: float, out: np.ndarray
) -> None:
    """Fill ``out`` (``(channels, n, n)``) with the grid seen from ``(x, y, yaw)``: row ahead, column left.

    View cell ``(a, b)`` samples the grid cell under the point ``(a - (n - 1) / 2) * cell`` ahead of the
    robot and ``(b - (n - 1) / 2) * cell`` to its left (nearest cell); points off the grid read 0.
    """
    ny, nx = grid.shape[1], grid.shape[2]
    n = out.shape[1]
    c, s = math.cos(yaw), math.sin(yaw)
    half = 0.5 * (n - 1)
    for a in range(n):
        ahead = (a - half) * cell
        for b in range(n):
            left = (b - half) * cell
            i, j = _cell_of(x + c * ahead - s * left, y + s * ahead + c * left, x0, y0, cell, ny, nx)
            for ch in range(out.shape[0]):
                out[ch, a, b] = grid[ch, i, j] if i >= 0 else 0.0


@dataclasses.dataclass(frozen=True)
class EgoMapSpec:
    """Size of the memory.

    Attributes:
        cell: Cell size of the grid and of the view (m).
        size: View cells per side (the robot at the centre): the view spans ``size * cell`` metres.
        margin: Free rim of the grid around the scene's bounds, for odometry drift (m).
    """

    cell: float = 0.5
    size: int = 16
    margin: float = 4.0


class EgoMap:
    """The memory of one robot: a grid over the scene in its odometry frame, and its egocentric view.

    Args:
        spec: Cell size, view size and margin.
    """

    def __init__(self, spec: EgoMapSpec | None = None) -> None:
        self.spec = spec or EgoMapSpec()
        self.grid = np.zeros((len(CHANNELS), 1, 1))
        self.origin = (0.0, 0.0)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Shape of the observation: ``(channels, size, size)``."""
        return (len(CHANNELS), self.spec.size, self.spec.size)

    def reset(self, bounds: tuple[float, float, float, float]) -> None:
        """Forget everything; the grid covers ``bounds`` (``xmin, ymin, xmax, ymax``, m) plus the margin."""
        xmin, ymin, xmax, ymax = bounds
        m, c = self.spec.margin, self.spec.cell
        self.origin = (xmin - m, ymin - m)
        nx = int(math.ceil((xmax - xmin + 2 * m) / c))
        ny = int(math.ceil((ymax - ymin + 2 * m) / c))
        self.grid = np.zeros((len(CHANNELS), ny, nx))

    def update(self, pose: np.ndarray, sensor_poses: np.ndarray, ranges: np.ndarray, max_range: float) -> None:
        """Mark the estimated pose's cell as visited and every echo's cell (see :func:`mark_memory`)."""
        x0, y0 = self.origin
        mark_memory(
            self.grid,
            x0,
            y0,
            self.spec.cell,
            float(pose[0]),
            float(pose[1]),
            np.ascontiguousarray(sensor_poses, dtype=np.float64),
            np.ascontiguousarray(ranges, dtype=np.float64),
            float(max_range),
        )

    def view(self, pose: np.ndarray) -> np.ndarray:
        """The ``(channels, size, size)`` window around the estimated pose, turned with its heading (float32)."""
        out = np.zeros(self.shape)
        x0, y0 = self.origin
        egocentric_view(self.grid, x0, y0, self.spec.cell, float(pose[0]), float(pose[1]), float(pose[2]), out)
        return out.astype(np.float32)
