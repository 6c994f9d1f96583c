"""Scenes for the robot chain: a generated office floor (Apoorva 2018, sec. 5), a greenhouse, or a ROS map.

Every scene comes as a :class:`ChainMap`: the static geometry the world and the sensors use, its occupancy
grid, and the grid inflated by the robot radius plus a margin (the paper's "padded image", Fig. 6b) on
which A* plans and start, goal and chain positions are sampled. Unknown cells of a loaded map count as
blocked for planning.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from agri_envs.scenes.greenhouse import LayoutParams, generate_layout
from agri_envs.scenes.office import OfficeFloorParams, generate_office_floor
from agri_envs.sim2d.distance import euclidean_distance_transform
from agri_envs.sim2d.geometry import Geometry
from agri_envs.sim2d.gridmap import OccupancyGrid, grid_to_geometry, load_ros_map, rasterize


@dataclasses.dataclass(frozen=True)
class ChainMap:
    """A static scene with its planning grids.

    Attributes:
        geometry: Static obstacles (walls, furniture, plants).
        grid: Occupancy grid of the scene (ROS conventions, row 0 = lowest y).
        blocked: ``(H, W)`` bool, cells a robot centre may not occupy (obstacles inflated by the robot
            radius plus the planning margin; unknown cells are blocked too).
        wall_distance: ``(H, W)`` distance (m) from each cell centre to the nearest occupied or unknown cell.
    """

    geometry: Geometry
    grid: OccupancyGrid
    blocked: np.ndarray
    wall_distance: np.ndarray

    @functools.cached_property
    def free_cells(self) -> np.ndarray:
        """Flat indices (row-major) of the cells a robot centre may occupy (not :attr:`blocked`)."""
        return np.flatnonzero(~self.blocked.ravel())

    def cell(self, xy: np.ndarray) -> tuple[int, int]:
        """``(row, col)`` of the cell holding world point ``xy`` (clamped into the grid)."""
        i, j = self.grid.world_to_cell(np.asarray(xy, dtype=np.float64)).tolist()
        return min(max(i, 0), self.grid.height - 1), min(max(j, 0), self.grid.width - 1)

    def centres(self, cells: np.ndarray) -> np.ndarray:
        """World centres ``(n, 2)`` of cells ``(n, 2)``."""
        return self.grid.cell_to_world(np.asarray(cells).reshape(-1, 2))


def block_disc(cmap: ChainMap, blocked: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """A copy of ``blocked`` with every cell whose centre lies within ``radius`` of ``centre`` blocked too.

    Args:
        cmap: The map whose grid ``blocked`` belongs to.
        blocked: ``(H, W)`` bool.
        centre: ``(x, y)`` (m).
        radius: (m).
    """
    out = blocked.copy()
    i0, j0 = cmap.cell(np.asarray(centre, dtype=np.float64) - radius)
    i1, j1 = cmap.cell(np.asarray(centre, dtype=np.float64) + radius)
    rows, cols = np.mgrid[i0 : i1 + 1, j0 : j1 + 1]
    xy = cmap.centres(np.stack([rows.ravel(), cols.ravel()], axis=1))
    inside = np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) <= radius
    out[rows.ravel()[inside], cols.ravel()[inside]] = True
    return out


def make_chain_map(geometry: Geometry, grid: OccupancyGrid, inflation: float) -> ChainMap:
    """Inflate a scene's grid by ``inflation`` metres (Euclidean distance transform)."""
    obstacle = (grid.data >= 50) | (grid.data < 0)
    if obstacle.all():
        raise ValueError("the map has no free cell")
    distance = euclidean_distance_transform(~obstacle) * grid.resolution
    # Cells touching the map's border count as next to an obstacle: nothing is known beyond it.
    h, w = obstacle.shape
    rows = (np.arange(h) + 0.5) * grid.resolution
    cols = (np.arange(w) + 0.5) * grid.resolution
    border = np.minimum(np.minimum(rows, rows[::-1])[:, None], np.minimum(cols, cols[::-1])[None, :])
    distance = np.minimum(distance, border)
    return ChainMap(geometry=geometry, grid=grid, blocked=distance <= inflation, wall_distance=distance)


def office_map(p: OfficeFloorParams, rng: np.random.Generator, inflation: float, resolution: float) -> ChainMap:
    """A generated office as a :class:`ChainMap`."""
    geometry = generate_office_floor(p, rng)
    return make_chain_map(geometry, rasterize(geometry, resolution), inflation)


def greenhouse_map(p: LayoutParams, rng: np.random.Generator, inflation: float, resolution: float) -> ChainMap:
    """A generated greenhouse (rows of plants between walls, :mod:`agri_envs.scenes.greenhouse`) as a ChainMap."""
    geometry = generate_layout(p, rng).geometry
    return make_chain_map(geometry, rasterize(geometry, resolution), inflation)


def ros_map(yaml_path: str, inflation: float) -> ChainMap:
    """A ROS ``map_server`` map (PGM + YAML, the shared loader) as a :class:`ChainMap`.

    The sensors and the physics see the occupied cells as boxes; unknown cells are fenced in as well.
    """
    grid = load_ros_map(yaml_path)
    geometry = grid_to_geometry(grid, unknown_occupied=True)
    return make_chain_map(geometry, grid, inflation)
