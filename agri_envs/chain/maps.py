"""Scenes for the robot chain: a generated office floor (Apoorva 2018, sec. 5), a greenhouse, or a ROS map.

Every scene comes as a :class:`ChainMap`: the static geometry the world and the sensors use, its occupancy
grid, and the grid inflated by the robot radius plus a margin (the paper's "padded image", Fig. 6b) on
which A* plans and start, goal and chain positions are sampled. Unknown cells of a loaded map count as
blocked for planning.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import ndimage

from agri_envs.rover.layout import LayoutParams, generate_layout
from agri_envs.sim2d.geometry import Geometry, GeometryBuilder, Kind
from agri_envs.sim2d.gridmap import OccupancyGrid, grid_to_geometry, load_ros_map, rasterize

WALL = 0.05  # half thickness of office walls (m)


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

    def cell(self, xy: np.ndarray) -> tuple[int, int]:
        """``(row, col)`` of the cell holding world point ``xy`` (clamped into the grid)."""
        i, j = self.grid.world_to_cell(np.asarray(xy, dtype=np.float64)).tolist()
        return min(max(i, 0), self.grid.height - 1), min(max(j, 0), self.grid.width - 1)

    def centres(self, cells: np.ndarray) -> np.ndarray:
        """World centres ``(n, 2)`` of cells ``(n, 2)``."""
        return self.grid.cell_to_world(np.asarray(cells).reshape(-1, 2))


def make_chain_map(geometry: Geometry, grid: OccupancyGrid, inflation: float) -> ChainMap:
    """Inflate a scene's grid by ``inflation`` metres (Euclidean distance transform)."""
    obstacle = (grid.data >= 50) | (grid.data < 0)
    if obstacle.all():
        raise ValueError("the map has no free cell")
    distance = ndimage.distance_transform_edt(~obstacle) * grid.resolution
    # Cells touching the map's border count as next to an obstacle: nothing is known beyond it.
    h, w = obstacle.shape
    rows = (np.arange(h) + 0.5) * grid.resolution
    cols = (np.arange(w) + 0.5) * grid.resolution
    border = np.minimum(np.minimum(rows, rows[::-1])[:, None], np.minimum(cols, cols[::-1])[None, :])
    distance = np.minimum(distance, border)
    return ChainMap(geometry=geometry, grid=grid, blocked=distance <= inflation, wall_distance=distance)


@dataclasses.dataclass(frozen=True)
class OfficeParams:
    """A generated office floor: a central corridor with rooms on both sides, each with one door.

    Attributes:
        width: Floor length along x (m).
        height: Floor depth along y (m).
        rooms_per_side: Rooms along each side of the corridor.
        corridor_width: Free width of the corridor (m).
        door_width: Width of each room's door (m).
        n_furniture: Boxes (desks, cabinets) placed in the rooms.
    """

    width: float = 14.0
    height: float = 9.0
    rooms_per_side: int = 3
    corridor_width: float = 2.2
    door_width: float = 1.4
    n_furniture: int = 4

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` (m) of the floor and its outer walls."""
        return (-WALL, -WALL, self.width + WALL, self.height + WALL)


def generate_office(p: OfficeParams, rng: np.random.Generator) -> Geometry:
    """Outer walls, a corridor along x, rooms above and below it with jittered doors, furniture in the rooms."""
    b = GeometryBuilder()
    w, h = p.width, p.height
    for x0, y0, x1, y1 in ((0, 0, w, 0), (w, 0, w, h), (w, h, 0, h), (0, h, 0, 0)):
        b.capsule(x0, y0, x1, y1, WALL, Kind.WALL)
    y_lo = 0.5 * (h - p.corridor_width)
    y_hi = 0.5 * (h + p.corridor_width)
    room_w = w / p.rooms_per_side
    for y_wall, y_far in ((y_lo, 0.0), (y_hi, h)):
        for k in range(p.rooms_per_side):
            x0, x1 = k * room_w, (k + 1) * room_w
            if k > 0:
                b.capsule(x0, y_wall, x0, y_far, WALL, Kind.WALL)
            margin = 0.35 + WALL
            d0 = rng.uniform(x0 + margin, x1 - margin - p.door_width)
            if d0 > x0:
                b.capsule(x0, y_wall, d0, y_wall, WALL, Kind.WALL)
            b.capsule(d0 + p.door_width, y_wall, x1, y_wall, WALL, Kind.WALL)
            # Furniture against the far wall, clear of the door's line.
            for _ in range(max(0, p.n_furniture // (2 * p.rooms_per_side) + int(rng.random() < 0.5))):
                fw, fd = rng.uniform(0.5, 1.0), rng.uniform(0.4, 0.6)
                fx = rng.uniform(x0 + 0.2, x1 - 0.2 - fw)
                if y_far == 0.0:
                    b.box(fx, WALL, fx + fw, WALL + fd, Kind.OBSTACLE)
                else:
                    b.box(fx, h - WALL - fd, fx + fw, h - WALL, Kind.OBSTACLE)
    return b.build(p.bounds())


def office_map(p: OfficeParams, rng: np.random.Generator, inflation: float, resolution: float) -> ChainMap:
    """A generated office as a :class:`ChainMap`."""
    geometry = generate_office(p, rng)
    return make_chain_map(geometry, rasterize(geometry, resolution), inflation)


def greenhouse_map(p: LayoutParams, rng: np.random.Generator, inflation: float, resolution: float) -> ChainMap:
    """The rover's generated greenhouse (rows of plants between walls) as a :class:`ChainMap`."""
    geometry = generate_layout(p, rng).geometry
    return make_chain_map(geometry, rasterize(geometry, resolution), inflation)


def ros_map(yaml_path: str, inflation: float) -> ChainMap:
    """A ROS ``map_server`` map (PGM + YAML, the shared loader) as a :class:`ChainMap`.

    The sensors and the physics see the occupied cells as boxes; unknown cells are fenced in as well.
    """
    grid = load_ros_map(yaml_path)
    geometry = grid_to_geometry(grid, unknown_occupied=True)
    return make_chain_map(geometry, grid, inflation)


def geodesic_distance(blocked: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """Shortest 8-connected path length (cells) from ``start`` to every cell (inf where unreachable)."""
    from agri_baselines.grid_astar import distance_field

    return distance_field(blocked, start)


def diagonal(chain_map: ChainMap) -> float:
    """Diagonal of the scene's bounds (m)."""
    xmin, ymin, xmax, ymax = chain_map.geometry.bounds
    return math.hypot(xmax - xmin, ymax - ymin)
