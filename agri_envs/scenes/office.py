"""Office scenes: Harik's office corridor (GreenhouseNav) and Apoorva's office floor (the robot chain).

Two different offices with two names: :class:`CorridorParams` is one straight corridor with door recesses
(Harik 2018, sec. 2.4), :class:`OfficeFloorParams` a floor of rooms on both sides of a central corridor
(Apoorva 2018, sec. 5).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from agri_envs.scenes.layout import WALL_THICKNESS, Layout, start_facing
from agri_envs.sim2d.crowd import RouteGraph
from agri_envs.sim2d.geometry import Geometry, GeometryBuilder, Kind


@dataclasses.dataclass(frozen=True)
class CorridorParams:
    """An office corridor like Harik's experiments (sec. 2.4, Figs. 13-16): walls with door recesses.

    Attributes:
        length: Corridor length (m).
        width: Corridor width between the walls (m).
        door_spacing: Distance between door recesses along each wall (m).
        door_width: Width of a recess (m).
        door_depth: Depth of a recess (m).
        route: ``"experiment"``: the mission 0 -> 1 -> 2 -> 3 -> 2 -> 0 of sec. 3.4 (Figs. 14-16);
            ``"repeatability"``: 0 -> 2 -> 3 -> 4 -> 0 of sec. 3.5 (Fig. 17).
    """

    length: float = 14.0
    width: float = 1.6
    door_spacing: float = 3.5
    door_width: float = 0.9
    door_depth: float = 0.3
    route: str = "experiment"

    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` (m) of the corridor, its walls and door recesses."""
        t, d = WALL_THICKNESS, self.door_depth
        return (-t - d, -t - d, self.length + t, self.width + t + d)


#: The office-corridor missions (waypoint indices after the start at waypoint 0), Harik secs. 3.4 and 3.5.
ROUTES: dict[str, tuple[int, ...]] = {"experiment": (1, 2, 3, 2, 0), "repeatability": (2, 3, 4, 0)}


def generate_office_corridor(p: CorridorParams, rng: np.random.Generator) -> Layout:
    """A straight office corridor with door recesses and cabinets; waypoints force 180 deg turns.

    The ``experiment`` mission is the paper's 0 -> 1 -> 2 -> 3 -> 2 -> 0 along the corridor: waypoint 1 lies
    at the far end and 3 near the start, so the robot turns around at 1 and at 3 (and again at 2 on the way
    back). The ``repeatability`` mission is sec. 3.5's 0 -> 2 -> 3 -> 4 -> 0, with waypoint 4 between 2 and
    the far end: the robot turns around at every waypoint. The paper gives the waypoints only on a map
    (Fig. 13) whose scale the text does not state; these positions are ours, chosen so that both missions
    have the 180 deg turns the text describes.
    """
    b = GeometryBuilder()
    t = 0.5 * WALL_THICKNESS
    w, h = p.length, p.width
    b.capsule(-t, -t, -t, h + t, t, Kind.WALL)
    b.capsule(w + t, -t, w + t, h + t, t, Kind.WALL)
    yc = 0.5 * h
    door_nodes: list[tuple[float, float]] = []  # people come out of and go into the doors
    for y_wall, outward in ((-t, -1.0), (h + t, 1.0)):
        offset = rng.uniform(0.8, 1.6)
        x = 0.0
        doors = np.arange(offset, w - p.door_width - 0.5, p.door_spacing)
        for d0 in doors:
            d0 += rng.uniform(-0.3, 0.3)
            d1 = d0 + p.door_width
            door_nodes.append((0.5 * (d0 + d1), (0.0 if outward < 0 else h) + outward * 0.5 * p.door_depth))
            b.capsule(x - t, y_wall, d0, y_wall, t, Kind.WALL)
            # The recess: a door set back into the wall, with its frame.
            y_back = y_wall + outward * p.door_depth
            b.capsule(d0, y_wall, d0, y_back, t, Kind.WALL)
            b.capsule(d1, y_wall, d1, y_back, t, Kind.WALL)
            b.capsule(d0, y_back, d1, y_back, t, Kind.WALL)
            x = d1
        b.capsule(x - t, y_wall, w + t, y_wall, t, Kind.WALL)
    # A few cabinets along the walls between doors: features for the LIDAR, obstacles for the sides.
    for _ in range(3):
        cx = rng.uniform(2.0, w - 2.0)
        side = rng.integers(2)
        depth = 0.25
        y0, y1 = (0.0, depth) if side == 0 else (h - depth, h)
        b.box(cx - 0.3, y0, cx + 0.3, y1, Kind.OBSTACLE)
    geometry = b.build(p.bounds())
    waypoints = np.array([[1.0, yc], [w - 1.0, yc], [0.55 * w, yc], [0.25 * w, yc], [0.8 * w, yc]])
    if p.route not in ROUTES:
        raise ValueError(f"CorridorParams.route={p.route!r} is invalid; expected one of {sorted(ROUTES)}")
    mission = np.array(ROUTES[p.route])
    # People walk the centre line between doors and step into doorways: every dead end is a recess, so
    # someone who turns back from the robot can always get out of its way.
    door_nodes.sort()
    nodes = [(x, yc) for x, _ in door_nodes] + door_nodes
    k = len(door_nodes)
    edges = [(i, i + 1) for i in range(k - 1)] + [(i, k + i) for i in range(k)]
    routes = RouteGraph(nodes=np.array(nodes, dtype=np.float64), edges=np.array(edges, dtype=np.int64))
    return Layout(
        geometry=geometry,
        waypoints=waypoints,
        mission=mission,
        start_pose=start_facing(waypoints, int(mission[0])),
        routes=routes,
    )


#: Half thickness of office-floor walls (m).
OFFICE_WALL = 0.05


@dataclasses.dataclass(frozen=True)
class OfficeFloorParams:
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
        return (-OFFICE_WALL, -OFFICE_WALL, self.width + OFFICE_WALL, self.height + OFFICE_WALL)


def generate_office_floor(p: OfficeFloorParams, rng: np.random.Generator) -> Geometry:
    """Outer walls, a corridor along x, rooms above and below it with jittered doors, furniture in the rooms."""
    b = GeometryBuilder()
    w, h = p.width, p.height
    for x0, y0, x1, y1 in ((0, 0, w, 0), (w, 0, w, h), (w, h, 0, h), (0, h, 0, 0)):
        b.capsule(x0, y0, x1, y1, OFFICE_WALL, Kind.WALL)
    y_lo = 0.5 * (h - p.corridor_width)
    y_hi = 0.5 * (h + p.corridor_width)
    room_w = w / p.rooms_per_side
    for y_wall, y_far in ((y_lo, 0.0), (y_hi, h)):
        for k in range(p.rooms_per_side):
            x0, x1 = k * room_w, (k + 1) * room_w
            if k > 0:
                b.capsule(x0, y_wall, x0, y_far, OFFICE_WALL, Kind.WALL)
            margin = 0.35 + OFFICE_WALL
            d0 = rng.uniform(x0 + margin, x1 - margin - p.door_width)
            if d0 > x0:
                b.capsule(x0, y_wall, d0, y_wall, OFFICE_WALL, Kind.WALL)
            b.capsule(d0 + p.door_width, y_wall, x1, y_wall, OFFICE_WALL, Kind.WALL)
            # Furniture against the far wall, clear of the door's line.
            for _ in range(max(0, p.n_furniture // (2 * p.rooms_per_side) + int(rng.random() < 0.5))):
                fw, fd = rng.uniform(0.5, 1.0), rng.uniform(0.4, 0.6)
                fx = rng.uniform(x0 + 0.2, x1 - 0.2 - fw)
                if y_far == 0.0:
                    b.box(fx, OFFICE_WALL, fx + fw, OFFICE_WALL + fd, Kind.OBSTACLE)
                else:
                    b.box(fx, h - OFFICE_WALL - fd, fx + fw, h - OFFICE_WALL, Kind.OBSTACLE)
    return b.build(p.bounds())
