"""Where a chain episode starts and ends (the env's Starting State).

Start and goal on the inflated map, the A* path between them, the chain placed behind the leader, and
where dropped obstacles land.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from agri_envs.chain.config import RobotChainConfig
from agri_envs.chain.maps import ChainMap
from agri_envs.sim2d.astar import astar, distance_field
from agri_envs.sim2d.polyline import Polyline

START_TRIES = 10  # sampled starts tried for one with room for the chain behind the leader


@dataclasses.dataclass(frozen=True)
class Mission:
    """One episode's route and starting formation.

    Attributes:
        path_cells: ``(k, 2)`` A* path cells from start to goal.
        path: The A* path in the world (m); its last point is the goal.
        positions: ``(n, 2)`` start positions of the robots, leader first (m).
    """

    path_cells: np.ndarray
    path: Polyline
    positions: np.ndarray

    @property
    def astar_length(self) -> float:
        """Length of the A* path through the cell centres (m)."""
        xy = self.path.points
        return float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(self.path_cells) > 1 else 0.0

    def start_yaws(self) -> np.ndarray:
        """Each robot faces its predecessor; the leader a few cells along its path."""
        positions, xy = self.positions, self.path.points
        yaw = np.empty(len(positions))
        for k in range(len(positions)):
            if k == 0:
                ahead = xy[min(len(self.path_cells) - 1, 6)] - positions[0]
            else:
                ahead = positions[k - 1] - positions[k]
            yaw[k] = math.atan2(ahead[1], ahead[0]) if np.any(ahead) else 0.0
        return yaw


def plan_mission(cmap: ChainMap, cfg: RobotChainConfig, rng: np.random.Generator) -> Mission:
    """Start, goal, A* path and the chain's places for one episode.

    A sampled start with no room behind it for the chain (a room's far corner) would put followers between
    the leader and the goal: such a start is drawn again, up to ``START_TRIES`` times, keeping the draw with
    the fewest followers ahead (a given start is kept).
    """
    best: tuple | None = None
    for _ in range(START_TRIES):
        start_cell, goal_cell, path_cells, from_start = plan_route(cmap, cfg, rng)
        positions, ahead = place_chain(cmap, cfg, start_cell, goal_cell, from_start)
        if best is None or ahead < best[0]:
            best = (ahead, path_cells, positions)
        if ahead == 0 or cfg.start:
            break
    assert best is not None
    _, path_cells, positions = best
    cells = np.array(path_cells)
    return Mission(path_cells=cells, path=Polyline(cmap.centres(cells)), positions=positions)


def plan_route(
    cmap: ChainMap, cfg: RobotChainConfig, rng: np.random.Generator
) -> tuple[tuple[int, int], tuple[int, int], list, np.ndarray | None]:
    """Start and goal cells (given or sampled) and the A* path between them.

    Also returns the free-floor distance (m) from the start to every cell when it was computed (a sampled
    goal), else None.
    """
    free = ~cmap.blocked
    roomy = free & (cmap.wall_distance >= cfg.robot_radius + 0.35)
    candidates = np.argwhere(roomy if roomy.any() else free)
    if len(candidates) == 0:
        raise ValueError("robot_chain_v0: the inflated map has no free cell for the robots")

    def given(xy: tuple, name: str) -> tuple[int, int]:
        cell = cmap.cell(np.array(xy, dtype=np.float64))
        if cmap.blocked[cell]:
            raise ValueError(f"robot_chain_v0: {name}={xy} is not on free floor (inflated map)")
        return cell

    res = cmap.grid.resolution
    for _ in range(200):
        s = given(cfg.start, "start") if cfg.start else tuple(candidates[rng.integers(len(candidates))])
        dist = None
        if cfg.goal:
            g = given(cfg.goal, "goal")
        else:
            dist = distance_field(cmap.blocked, s) * res
            ok = candidates[dist[candidates[:, 0], candidates[:, 1]] >= cfg.min_goal_distance]
            ok = ok[np.isfinite(dist[ok[:, 0], ok[:, 1]])] if len(ok) else ok
            if len(ok) == 0:
                if cfg.start:
                    raise ValueError(
                        f"robot_chain_v0: no goal lies {cfg.min_goal_distance} m from start={cfg.start}; "
                        "lower min_goal_distance"
                    )
                continue
            g = tuple(ok[rng.integers(len(ok))])
        path = astar(cmap.blocked, s, g)
        if path is not None:
            return (int(s[0]), int(s[1])), (int(g[0]), int(g[1])), path, dist
        if cfg.start and cfg.goal:
            break
    raise ValueError("robot_chain_v0: no A* path between start and goal on the inflated map")


def place_chain(
    cmap: ChainMap,
    cfg: RobotChainConfig,
    start: tuple[int, int],
    goal: tuple[int, int],
    from_start: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Leader at the start; followers ``spacing`` apart along a free path behind it (or packed nearby).

    ``from_start`` is the free-floor distance (m) from the start to every cell, when the caller has it.

    Returns:
        The ``(n, 2)`` positions, and how many followers stand ahead of the leader (nearer to the goal
        along the free floor than the leader).
    """
    n = cfg.n_robots
    res = cmap.grid.resolution
    positions = np.zeros((n, 2))
    positions[0] = cmap.centres(np.array([start]))[0]
    if n == 1:
        return positions, 0
    need = (n - 1) * cfg.spacing
    if from_start is None:
        from_start = distance_field(cmap.blocked, start) * res
    to_goal = distance_field(cmap.blocked, goal) * res

    def ahead() -> int:
        cells = cmap.grid.world_to_cell(positions[1:])
        rows = np.clip(cells[:, 0], 0, cmap.grid.height - 1)
        cols = np.clip(cells[:, 1], 0, cmap.grid.width - 1)
        return int(np.sum(to_goal[rows, cols] < to_goal[start]))

    reach = np.isfinite(from_start) & (from_start <= need + 1.0) & (from_start >= need)
    if reach.any():
        # The cell at the right distance that lies farthest from the goal: "behind" the leader.
        cells = np.argwhere(reach)
        tail = tuple(cells[int(np.argmax(to_goal[reach]))])
        tail_path = astar(cmap.blocked, start, tail)
        if tail_path is not None:
            line = Polyline(cmap.centres(np.array(tail_path)))
            if line.length >= need - 1e-6:
                for k in range(1, n):
                    positions[k] = line.at(k * cfg.spacing)
                return positions, ahead()
    # Packed start: free cells by distance from the leader, at least `spacing` from every robot placed.
    order = np.argwhere(np.isfinite(from_start))
    order = order[np.argsort(from_start[order[:, 0], order[:, 1]], kind="stable")]
    xy = cmap.centres(order)
    placed = 1
    min_d2 = (max(2 * cfg.robot_radius + 0.1, 0.8 * cfg.spacing)) ** 2
    for p in xy:
        d2 = ((positions[:placed] - p) ** 2).sum(axis=1)
        if d2.min() >= min_d2:
            positions[placed] = p
            placed += 1
            if placed == n:
                return positions, ahead()
    raise ValueError(
        f"robot_chain_v0: {n} robots do not fit on the free floor around the start; use fewer robots or a larger map"
    )


def drop_spot(
    cmap: ChainMap, cfg: RobotChainConfig, path: Polyline, s_leader: float, poses: np.ndarray
) -> np.ndarray | None:
    """A point on the path 1.2-3 m ahead of the leader with room to pass it and clear of every robot."""
    need = cfg.obstacle_radius + 2 * cfg.robot_radius + 0.25
    for ahead in np.arange(1.2, 3.0, 0.1):
        s = s_leader + ahead
        if s > path.length - 1.0:
            break
        p = path.at(s)
        i, j = cmap.cell(p)
        if cmap.wall_distance[i, j] < need:
            continue
        d = np.hypot(poses[:, 0] - p[0], poses[:, 1] - p[1])
        if d.min() < cfg.obstacle_radius + cfg.robot_radius + 0.4:
            continue
        return p
    return None
