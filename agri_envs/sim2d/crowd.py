"""People walking a route graph: along corridors, across row ends, and now and then into a robot's way.

Each person walks from node to node of an undirected graph at their own speed. When a robot is ahead
of them within ``notice_distance``, they either turn back at once or (with ``tease_prob``) stand still
in front of it for a while first, like the colleagues who "teased" the robot in Harik 2018, sec. 3.5.
People never walk into a robot; a robot that drives into a person has collided.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from agri_envs.sim2d.world import World2D

WALK, STAND = 0, 1


@dataclasses.dataclass(frozen=True)
class RouteGraph:
    """Where people may walk.

    Attributes:
        nodes: ``(k, 2)`` node positions (m).
        edges: ``(e, 2)`` node index pairs; people walk straight between connected nodes.
    """

    nodes: np.ndarray
    edges: np.ndarray

    def neighbours(self, i: int) -> list[int]:
        """Nodes connected to node ``i``, in increasing order."""
        return list(self.adjacency[i])

    @functools.cached_property
    def adjacency(self) -> tuple[tuple[int, ...], ...]:
        """The sorted neighbours of every node (computed once per graph)."""
        out: list[list[int]] = [[] for _ in range(len(self.nodes))]
        for a, b in self.edges.tolist():
            out[a].append(b)
            out[b].append(a)
        return tuple(tuple(sorted(n)) for n in out)


@dataclasses.dataclass(frozen=True)
class CrowdSpec:
    """How people look and behave.

    Attributes:
        radius: Body radius seen by sensors and physics (m).
        speed_range: Walking speeds are drawn uniformly from this range (m/s).
        notice_distance: A robot closer than this ahead of a person makes them react (m).
        tease_prob: Probability that a person stands in the robot's way instead of turning back.
        stand_range: Standing time when they do, drawn uniformly (s).
        min_start_distance: People start at least this far from the robot's start (m).
    """

    radius: float = 0.2
    speed_range: tuple[float, float] = (0.5, 1.0)
    notice_distance: float = 1.5
    tease_prob: float = 0.3
    stand_range: tuple[float, float] = (2.0, 6.0)
    min_start_distance: float = 3.0


class Crowd:
    """The people of a scene, stored as arrays (positions, headings, targets, timers)."""

    def __init__(self, world: World2D, graph: RouteGraph, spec: CrowdSpec, n: int) -> None:
        if n > len(world.movers):
            raise ValueError(f"the world reserves {len(world.movers)} mover slots, {n} people requested")
        self.world = world
        self.graph = graph
        self.spec = spec
        self.n = n
        self._adj = graph.adjacency
        self.pos = np.zeros((n, 2))
        self.prev_node = np.zeros(n, dtype=np.int64)
        self.next_node = np.zeros(n, dtype=np.int64)
        self.speed = np.zeros(n)
        self.mode = np.zeros(n, dtype=np.int64)
        self.timer = np.zeros(n)
        self.reacted = np.zeros(n, dtype=bool)

    def reset(self, rng: np.random.Generator, avoid: np.ndarray) -> None:
        """Place everyone on random edges at least ``min_start_distance`` from ``avoid`` (x, y)."""
        nodes = self.graph.nodes
        for i in range(self.n):
            for _ in range(200):
                a, b = self.graph.edges[rng.integers(len(self.graph.edges))]
                if rng.random() < 0.5:
                    a, b = b, a
                p = nodes[a] + rng.random() * (nodes[b] - nodes[a])
                if np.hypot(*(p - avoid[:2])) >= self.spec.min_start_distance:
                    break
            self.pos[i] = p
            self.prev_node[i], self.next_node[i] = a, b
            self.speed[i] = rng.uniform(*self.spec.speed_range)
            self.mode[i] = WALK
            self.timer[i] = 0.0
            self.reacted[i] = False
            self.world.place_mover(i, float(p[0]), float(p[1]), self.spec.radius)
        for i in range(self.n, len(self.world.movers)):  # unused slots far away
            self.world.place_mover(i, 1e6 + 10.0 * i, 1e6, self.spec.radius)

    def _robot_ahead(self, i: int, hx: float, hy: float, robots: list[list[float]]) -> bool:
        """Whether a robot is within ``notice_distance`` ahead of person ``i`` walking along ``(hx, hy)``."""
        px, py = self.pos[i].tolist()
        for rx, ry, reach in robots:
            dx, dy = rx - px, ry - py
            centre = math.hypot(dx, dy)
            if centre - reach < self.spec.notice_distance and dx * hx + dy * hy > 0.3 * centre:
                return True
        return False

    def plan(self, dt: float, robots: np.ndarray, rng: np.random.Generator) -> None:
        """Decide everyone's velocity for the next ``dt`` (the world's step then moves them).

        Args:
            dt: Step length (s).
            robots: ``(k, 3)`` robot centres and circumradii ``x, y, reach`` (m).
            rng: Generator for the random choices.
        """
        nodes = self.graph.nodes
        robot_rows = np.asarray(robots, dtype=np.float64).tolist()  # plain floats: cheaper in the loop below
        for i in range(self.n):
            vx = vy = 0.0
            if self.mode[i] == STAND:
                self.timer[i] -= dt
                if self.timer[i] <= 0.0:
                    self.mode[i] = WALK
                    self.prev_node[i], self.next_node[i] = self.next_node[i], self.prev_node[i]
            else:
                px, py = self.pos[i].tolist()
                nx, ny = nodes[self.next_node[i]].tolist()
                dist = math.hypot(nx - px, ny - py)
                if dist < 1e-6:  # arrived: walk on to a random neighbour, not straight back if possible
                    options = [j for j in self._adj[self.next_node[i]] if j != self.prev_node[i]]
                    if not options:
                        options = [int(self.prev_node[i])]
                    self.prev_node[i] = self.next_node[i]
                    self.next_node[i] = options[int(rng.integers(len(options)))]
                    nx, ny = nodes[self.next_node[i]].tolist()
                    dist = math.hypot(nx - px, ny - py)
                hx, hy = (nx - px) / dist, (ny - py) / dist
                if self._robot_ahead(i, hx, hy, robot_rows):
                    if not self.reacted[i] and rng.random() >= self.spec.tease_prob:
                        self.prev_node[i], self.next_node[i] = self.next_node[i], self.prev_node[i]
                    else:  # stand in the robot's way (or keep waiting for it to leave)
                        self.mode[i] = STAND
                        self.timer[i] = rng.uniform(*self.spec.stand_range) if not self.reacted[i] else 1.0
                    self.reacted[i] = True
                else:
                    self.reacted[i] = False
                    speed = min(float(self.speed[i]), dist / dt)  # stop exactly on the node
                    vx, vy = hx * speed, hy * speed
            self.world.set_mover_velocity(i, vx, vy)

    def sync_from_world(self) -> None:
        """Read back positions after the world stepped."""
        rows = self.world.mover_circles
        self.pos[:, 0] = rows[: self.n, 0]
        self.pos[:, 1] = rows[: self.n, 1]
