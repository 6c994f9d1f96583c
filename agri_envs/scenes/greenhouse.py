"""Greenhouse layout generator: walls, structural posts, rows of plants that grow, optional trees.

Coordinates: x runs along the rows, y across them; the origin is the inner lower-left corner of the walls.
Rows are separated by corridors; the first and the last corridor run between a row and a wall. Each
row is a line of plants (circles) with jittered spacing; structural posts stand in the row lines and
along the walls every ``post_spacing`` metres (they give a LIDAR-only localizer features along
otherwise repetitive rows). ``growth`` in [0, 1] enlarges the plants and grows leaves (thin capsules)
that reach into the corridors (Harik 2018, sec. 3.3: plant development through the season).

The default mission is the paper's loop 0 -> 1 -> ... -> 7 -> 0: a serpentine through every corridor,
with waypoints in the headlands past the row ends, returning to waypoint 0.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from agri_envs.scenes.layout import WALL_THICKNESS, Layout, start_facing
from agri_envs.sim2d.crowd import RouteGraph
from agri_envs.sim2d.geometry import GeometryBuilder, Kind

# Plant and leaf sizes across the season (growth 0 -> 1), metres.
PLANT_RADIUS = (0.06, 0.14)
LEAF_REACH = 0.18
LEAF_RADIUS = 0.015
TREE_RADIUS = (0.18, 0.28)
_PLANT, _TREE = int(Kind.PLANT), int(Kind.TREE)


@dataclasses.dataclass(frozen=True)
class LayoutParams:
    """Scene parameters of a generated greenhouse (see the env's Arguments table for ranges)."""

    n_rows: int = 3
    row_length: float = 6.0
    corridor_width: float = 1.2
    row_width: float = 0.4
    headland: float = 1.8
    plant_spacing: float = 0.4
    plant_jitter: float = 0.03
    growth: float = 0.0
    post_spacing: float = 3.0
    post_radius: float = 0.05
    n_trees: int = 0
    waypoint_offset: float = 0.8
    # Mediterranean greenhouses (González 2009, sec. 3.2): rows that are neither straight nor parallel,
    # corridors that are not equally wide. All zero by default (straight rows, one corridor width).
    row_incline: float = 0.0  # rad: each row is tilted by a uniform angle in [-row_incline, row_incline]
    row_bend: float = 0.0  # m: each row bows sideways by a uniform offset in [-row_bend, row_bend] at mid-length
    corridor_width_jitter: float = 0.0  # m: each corridor's width is corridor_width + U(-jitter, jitter)

    @classmethod
    def from_config(cls, config: object) -> LayoutParams:
        """The scene part of an env config: every field of this class the config also has (others keep defaults)."""
        names = [f.name for f in dataclasses.fields(cls) if hasattr(config, f.name)]
        return cls(**{name: getattr(config, name) for name in names})

    def max_intrusion(self) -> float:
        """How far plants or leaves can reach past the edge of a row bed at this growth (m)."""
        g = self.growth
        plant = PLANT_RADIUS[0] + g * (PLANT_RADIUS[1] - PLANT_RADIUS[0])
        reach = max(plant + g * LEAF_REACH + LEAF_RADIUS, TREE_RADIUS[0] + g * (TREE_RADIUS[1] - TREE_RADIUS[0]))
        return max(0.0, reach + self.plant_jitter - 0.5 * self.row_width)

    def narrowest_free_width(self) -> float:
        """Free width (m) of the narrowest corridor these parameters can generate, to the millimetre.

        The nominal width less the jitter, incline and bend narrowing and the plants' reach from both rows.
        Rounded, so that a margin met exactly passes: an inclined row's ``tan`` leaves 0.899997 m of 0.9 m.
        """
        return round(self.corridor_width - self.max_narrowing() - 2 * self.max_intrusion(), 3)

    @property
    def width(self) -> float:
        """Inner length of the greenhouse along the rows (m)."""
        return 2 * self.headland + self.row_length

    @property
    def height(self) -> float:
        """Inner width of the greenhouse across the rows (m)."""
        return (self.n_rows + 1) * self.corridor_width + self.n_rows * self.row_width

    def max_bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` (m) of the largest greenhouse these parameters generate (walls included)."""
        height = self.height + (self.n_rows + 1) * self.corridor_width_jitter
        return (-WALL_THICKNESS, -WALL_THICKNESS, self.width + WALL_THICKNESS, height + WALL_THICKNESS)

    def max_narrowing(self) -> float:
        """Worst-case loss of corridor width (m) from width jitter, inclined and bent rows (two rows per corridor)."""
        incline = 0.5 * self.row_length * math.tan(self.row_incline)
        return self.corridor_width_jitter + 2.0 * (incline + self.row_bend)

    def corridor_centres(self) -> np.ndarray:
        """Y of each corridor's centre line (m)."""
        pitch = self.corridor_width + self.row_width
        return 0.5 * self.corridor_width + pitch * np.arange(self.n_rows + 1)

    def row_centres(self) -> np.ndarray:
        """Y of each row's centre line (m)."""
        pitch = self.corridor_width + self.row_width
        return self.corridor_width + 0.5 * self.row_width + pitch * np.arange(self.n_rows)


def _corridor_end_ys(p: LayoutParams, corridors: tuple[np.ndarray, ...] | None) -> tuple[np.ndarray, np.ndarray]:
    """Y of each corridor's centre at its low-x and its high-x end (nominal straight rows without ``corridors``)."""
    if not corridors:
        ys = p.corridor_centres()
        return ys, ys
    return np.array([c[0, 1] for c in corridors]), np.array([c[-1, 1] for c in corridors])


def serpentine_waypoints(p: LayoutParams, corridors: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Waypoints 0, 1, ...: up and down every corridor in turn, ending where the loop can close."""
    x_left = p.headland - p.waypoint_offset
    x_right = p.headland + p.row_length + p.waypoint_offset
    y_left, y_right = _corridor_end_ys(p, corridors)
    pts: list[tuple[float, float]] = []
    for k in range(len(y_left)):
        ends = ((x_left, y_left[k]), (x_right, y_right[k]))
        pts.extend(ends if k % 2 == 0 else ends[::-1])
    if pts[-1][0] == x_right:  # odd number of corridors: come back along the first corridor
        pts.append((x_right, float(y_right[0])))
    return np.array(pts, dtype=np.float64)


def route_graph(p: LayoutParams, corridors: tuple[np.ndarray, ...] | None = None) -> RouteGraph:
    """People walk every corridor and the two headlands between corridor ends."""
    y_left, y_right = _corridor_end_ys(p, corridors)
    x_left = p.headland - p.waypoint_offset
    x_right = p.headland + p.row_length + p.waypoint_offset
    ys = y_left
    nodes = [(x_left, y) for y in y_left] + [(x_right, y) for y in y_right]
    k = len(ys)
    edges = [(i, i + k) for i in range(k)]
    edges += [(i, i + 1) for i in range(k - 1)] + [(k + i, k + i + 1) for i in range(k - 1)]
    return RouteGraph(nodes=np.array(nodes, dtype=np.float64), edges=np.array(edges, dtype=np.int64))


@dataclasses.dataclass(frozen=True)
class RowShapes:
    """Where the rows of one generated greenhouse run (straight, inclined or bent).

    Row ``r`` follows ``y = centre[r] + slope[r] * (x - x_mid) + bend[r] * (1 - |2 (x - x_mid) / row_length|)``
    between its ends ``x0 .. x1``: a straight line tilted by ``atan(slope)`` with a kink of ``bend`` metres
    at mid-length.

    Attributes:
        centre: ``(n_rows,)`` y of each row's centre at mid-length (m).
        slope: ``(n_rows,)`` tangent of each row's incline.
        bend: ``(n_rows,)`` sideways offset of each row's mid-point (m).
        x0: Low-x end of the rows (m).
        x1: High-x end of the rows (m).
        half_extent: Half-width of the crop across a row (m): the plants' radius, where the free space of
            a corridor ends (a row bed is wider than its plants).
        height: Inner width of the greenhouse across the rows (m).
    """

    centre: np.ndarray
    slope: np.ndarray
    bend: np.ndarray
    x0: float
    x1: float
    half_extent: float
    height: float

    def row_y(self, r: int, x: np.ndarray | float) -> np.ndarray:
        """Y of row ``r``'s centre line at ``x`` (m)."""
        return self.rows_y(x)[r]

    def rows_y(self, x: np.ndarray | float) -> np.ndarray:
        """``(n_rows, *x.shape)``: y of every row's centre line at ``x`` (m)."""
        xm = 0.5 * (self.x0 + self.x1)
        half = 0.5 * (self.x1 - self.x0)
        xa = np.asarray(x, dtype=np.float64)
        along = xa - xm
        kink = 1.0 - np.abs(along) / half
        shape = (-1,) + (1,) * xa.ndim
        return self.centre.reshape(shape) + self.slope.reshape(shape) * along + self.bend.reshape(shape) * kink

    def corridor_lines(self) -> tuple[np.ndarray, ...]:
        """Centre line of every corridor: midway between the plants of its two rows (or a row and a wall)."""
        xs = np.array([self.x0, 0.5 * (self.x0 + self.x1), self.x1])
        ys = self.rows_y(xs)
        n = len(self.centre)
        lines = []
        for k in range(n + 1):
            lo = ys[k - 1] + self.half_extent if k > 0 else np.zeros(3)
            hi = ys[k] - self.half_extent if k < n else np.full(3, self.height)
            lines.append(np.column_stack([xs, 0.5 * (lo + hi)]))
        return tuple(lines)


def row_shapes(p: LayoutParams, rng: np.random.Generator) -> RowShapes:
    """Draw the corridor widths, row inclines and bends (nothing is drawn for features that are off).

    Args:
        p: Scene parameters.
        rng: Source of the variation.

    Returns:
        The rows of one greenhouse; with the default parameters they are the straight rows at
        :meth:`LayoutParams.row_centres` and the greenhouse is :attr:`LayoutParams.height` wide.
    """
    n = p.n_rows
    widths = np.full(n + 1, p.corridor_width)
    if p.corridor_width_jitter > 0:
        widths += rng.uniform(-p.corridor_width_jitter, p.corridor_width_jitter, n + 1)
    slope = np.tan(rng.uniform(-p.row_incline, p.row_incline, n)) if p.row_incline > 0 else np.zeros(n)
    bend = rng.uniform(-p.row_bend, p.row_bend, n) if p.row_bend > 0 else np.zeros(n)
    if p.corridor_width_jitter > 0:
        centre = np.cumsum(widths[:-1]) + p.row_width * (0.5 + np.arange(n))
        height = float(widths.sum() + n * p.row_width)
    else:  # the rover's straight rows, exactly as before
        centre = p.row_centres()
        height = p.height
    return RowShapes(
        centre=centre,
        slope=slope,
        bend=bend,
        x0=p.headland,
        x1=p.headland + p.row_length,
        half_extent=PLANT_RADIUS[0] + p.growth * (PLANT_RADIUS[1] - PLANT_RADIUS[0]),
        height=height,
    )


@numba.njit(cache=True)
def _grow_plants(
    rng: np.random.Generator,
    xs: np.ndarray,
    ys: np.ndarray,
    is_tree: np.ndarray,
    jitter: float,
    plant_r: float,
    tree_r: float,
    growth: float,
    plants: np.ndarray,
    kinds: np.ndarray,
    leaves: np.ndarray,
) -> int:
    """Jitter each plant (or tree) at its slot and grow its leaves, drawing from ``rng`` slot by slot.

    Args:
        rng: Source of the jitter and leaves (NumPy's own stream: numba draws it exactly).
        xs: ``(n,)`` nominal x of each slot (m).
        ys: ``(n,)`` nominal y of each slot (m).
        is_tree: ``(n,)`` whether the slot holds a tree (no leaves) instead of a plant.
        jitter: Half-width of the uniform position jitter (m).
        plant_r: Plant radius (m).
        tree_r: Tree radius (m).
        growth: Season in [0, 1]: the chance that a leaf grows on each side, and its length.
        plants: ``(n, 3)`` output circles ``x, y, r``.
        kinds: ``(n,)`` output :class:`Kind` of each circle.
        leaves: ``(2n, 5)`` output leaf capsules.

    Returns:
        The number of leaves written.
    """
    n_leaves = 0
    for k in range(xs.shape[0]):
        px = xs[k] + rng.uniform(-jitter, jitter)
        py = ys[k] + rng.uniform(-jitter, jitter)
        plants[k, 0] = px
        plants[k, 1] = py
        if is_tree[k]:
            plants[k, 2] = tree_r
            kinds[k] = _TREE
            continue
        plants[k, 2] = plant_r
        kinds[k] = _PLANT
        # Leaves: the older the plant, the more (and longer) leaves reach out sideways.
        for side in (-1.0, 1.0):
            if rng.random() < growth:
                angle = side * math.pi / 2 + rng.uniform(-0.6, 0.6)
                reach = plant_r + growth * LEAF_REACH * rng.uniform(0.5, 1.0)
                leaves[n_leaves, 0] = px
                leaves[n_leaves, 1] = py
                leaves[n_leaves, 2] = px + reach * math.cos(angle)
                leaves[n_leaves, 3] = py + reach * math.sin(angle)
                leaves[n_leaves, 4] = LEAF_RADIUS
                n_leaves += 1
    return n_leaves


def generate_layout(p: LayoutParams, rng: np.random.Generator) -> Layout:
    """Build the greenhouse: walls, posts, plants (jittered, grown), leaves and trees.

    Rows are straight and corridors equally wide unless ``row_incline``, ``row_bend`` or
    ``corridor_width_jitter`` say otherwise (see :func:`row_shapes`).

    Args:
        p: Scene parameters.
        rng: Source of the jitter, leaves, tree positions and row shapes.

    Returns:
        The layout with its default serpentine mission and the corridors' centre lines.
    """
    shapes = row_shapes(p, rng)
    b = GeometryBuilder()
    w, h = p.width, shapes.height
    t = 0.5 * WALL_THICKNESS
    for x0, y0, x1, y1 in (
        (-t, -t, w + t, -t),
        (w + t, -t, w + t, h + t),
        (w + t, h + t, -t, h + t),
        (-t, h + t, -t, -t),
    ):
        b.capsule(x0, y0, x1, y1, t, Kind.WALL)
    # Posts along the walls, in line with the row posts.
    x0 = p.headland
    x1 = p.headland + p.row_length
    post_xs = np.arange(x0, x1 + 1e-9, p.post_spacing)
    if len(post_xs) == 0 or post_xs[-1] < x1 - 1e-9:
        post_xs = np.append(post_xs, x1)
    inset = p.post_radius + 0.02
    for x in post_xs:
        b.circle(x, inset, p.post_radius, Kind.POST)
        b.circle(x, h - inset, p.post_radius, Kind.POST)
    g = p.growth
    plant_r = PLANT_RADIUS[0] + g * (PLANT_RADIUS[1] - PLANT_RADIUS[0])
    tree_r = TREE_RADIUS[0] + g * (TREE_RADIUS[1] - TREE_RADIUS[0])
    n_plants = max(1, int(math.floor(p.row_length / p.plant_spacing)))
    tree_slot = np.zeros((p.n_rows, n_plants), dtype=np.bool_)
    if p.n_trees > 0:
        picks = rng.choice(p.n_rows * n_plants, size=min(p.n_trees, p.n_rows * n_plants), replace=False)
        tree_slot.ravel()[picks] = True
    xs = x0 + (np.arange(n_plants) + 0.5) * (p.row_length / n_plants)
    # A post stands where a plant would be too close to it.
    planted = np.abs(post_xs[None, :] - xs[:, None]).min(axis=1) >= plant_r + p.post_radius + 0.02
    xs = xs[planted]
    ys = shapes.rows_y(xs).ravel()
    plants = np.empty((len(ys), 3))
    kinds = np.empty(len(ys), dtype=np.int64)
    leaves = np.empty((2 * len(ys), 5))
    n_leaves = _grow_plants(
        rng,
        np.tile(xs, p.n_rows),
        ys,
        tree_slot[:, planted].ravel(),
        p.plant_jitter,
        plant_r,
        tree_r,
        g,
        plants,
        kinds,
        leaves,
    )
    post_ys = shapes.rows_y(post_xs)
    for row in range(p.n_rows):
        b.circles(np.column_stack([post_xs, post_ys[row], np.full(len(post_xs), p.post_radius)]), Kind.POST)
        b.circles(plants[row * len(xs) : (row + 1) * len(xs)], kinds[row * len(xs) : (row + 1) * len(xs)])
    b.capsules(leaves[:n_leaves], Kind.LEAF)
    geometry = b.build((-WALL_THICKNESS, -WALL_THICKNESS, w + WALL_THICKNESS, h + WALL_THICKNESS))
    corridors = shapes.corridor_lines()
    shaped = p.row_incline > 0 or p.row_bend > 0 or p.corridor_width_jitter > 0
    ends = corridors if shaped else None  # straight rows: the rover's waypoints exactly as before
    waypoints = serpentine_waypoints(p, ends)
    mission = np.array([*range(1, len(waypoints)), 0])
    return Layout(
        geometry=geometry,
        waypoints=waypoints,
        mission=mission,
        start_pose=start_facing(waypoints, 1),
        routes=route_graph(p, ends),
        corridors=corridors,
    )
