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
from agri_envs.errors import SetupError
from agri_envs.sim2d.astar import descend, distance_field
from agri_envs.sim2d.polyline import Polyline

GOAL_TRIES = 4  # goals drawn at random before the goals known to fit are drawn from (fallback_mission)
FALLBACK_TRIES = 8  # goals known to fit tried (each fits up to rounding: the first one nearly always does)
SWEEPS = 4  # farthest-point sweeps per connected part of the floor (floor_reach)


class ChainDoesNotFit(SetupError):
    """The floor has no room for the whole chain behind the leader; the message names the limit."""


@dataclasses.dataclass(frozen=True)
class FloorReach:
    """How long a chain a floor holds: the free-floor distances from the goals a mission may draw.

    Attributes:
        candidates: Flat indices of the cells a goal is drawn from (free floor 0.35 m from obstacles, or all
            free floor when none is that roomy).
        bound: For each candidate, the free-floor distance (m) from it to one of a few far cells: a goal
            whose bound is at least ``min_goal_distance + (n_robots - 1) * spacing`` has room for the chain.
        longest: The largest bound (m): the longest free path from a goal that the floor holds.
    """

    candidates: np.ndarray
    bound: np.ndarray
    longest: float

    def max_robots(self, cfg: RobotChainConfig, lo: float | None = None) -> int:
        """The largest ``n_robots`` whose chain fits (0: not even the leader ``lo`` from the goal).

        Args:
            cfg: The env's config (``spacing``, ``min_goal_distance``).
            lo: The leader's least distance to the goal (m); None: ``min_goal_distance``.
        """
        lo = cfg.min_goal_distance if lo is None else lo
        if self.longest < lo:
            return 0
        return int(math.floor((self.longest - lo) / cfg.spacing + 1e-9)) + 1


def goal_candidates(cmap: ChainMap, cfg: RobotChainConfig) -> np.ndarray:
    """Flat indices of the cells :func:`plan_mission` draws a goal from."""
    free = cmap.free_cells
    roomy = free[cmap.wall_distance.ravel()[free] >= cfg.robot_radius + 0.35]
    return roomy if len(roomy) else free


def floor_reach(cmap: ChainMap, cfg: RobotChainConfig) -> FloorReach:
    """The free-floor distances from every goal candidate to the floor's far cells (farthest-point sweeps).

    In each connected part of the floor, a distance field from one candidate gives the cell farthest from
    it, a field from that cell the next farthest, and so on (``SWEEPS`` fields); a candidate's bound is its
    largest distance in these fields. The far cells are the ends of the floor's longest paths, so the
    largest bound is the floor's longest free path from a goal (equal to the exhaustive search over every
    candidate on the example map and the offices measured), found in a few distance fields. Deterministic:
    no random draw.
    """
    free = cmap.free_cells
    candidates = goal_candidates(cmap, cfg)
    width, res = cmap.grid.width, cmap.grid.resolution
    bound = np.full(len(candidates), -np.inf)
    unseen = np.ones(len(candidates), dtype=np.bool_)
    while unseen.any():  # one connected part of the floor per pass
        source = divmod(int(candidates[np.argmax(unseen)]), width)
        for _ in range(SWEEPS):
            field = distance_field(cmap.blocked, source).ravel() * res
            on_candidates = field[candidates]
            reached = np.isfinite(on_candidates)
            unseen &= ~reached
            bound = np.where(reached, np.maximum(bound, on_candidates), bound)
            on_free = np.where(np.isfinite(field[free]), field[free], -1.0)
            source = divmod(int(free[np.argmax(on_free)]), width)
    return FloorReach(candidates=candidates, bound=bound, longest=float(bound.max()) if len(bound) else 0.0)


def does_not_fit(cfg: RobotChainConfig, reaches: list[FloorReach], goal_distance: tuple[float, float] | None,
                 generated: bool) -> ChainDoesNotFit:
    """The one-line refusal of a chain too long for its floor(s): it names the largest ``n_robots`` they hold.

    Args:
        cfg: The env's config.
        reaches: The floors tried (one for a fixed map; the generated ones drawn for the episode).
        goal_distance: The episode's ``(lo, hi)`` option, if any.
        generated: The floors are generated from the arguments (then a larger floor is the other way out).
    """
    lo = cfg.min_goal_distance if goal_distance is None else goal_distance[0]
    need = lo + (cfg.n_robots - 1) * cfg.spacing
    longest = max(r.longest for r in reaches)
    holds = max(r.max_robots(cfg, lo) for r in reaches)
    if goal_distance is not None and holds >= cfg.n_robots:  # the floor holds the chain; the window is too narrow
        return ChainDoesNotFit(
            f"robot_chain_v1: no goal leaves the leader {goal_distance[0]:.2f}-{goal_distance[1]:.2f} m from it "
            f"(options['goal_distance']) with room behind for n_robots={cfg.n_robots}: widen the window"
        )
    floor = f"the {len(reaches)} floors drawn for this episode hold" if generated else "this floor holds"
    larger = {"office": "office_width / office_height", "greenhouse": "n_rows / row_length"}.get(cfg.scene)
    way_out = f", or a larger floor ({larger})" if larger else ""
    lead = "min_goal_distance" if goal_distance is None else "options['goal_distance'][0]"
    return ChainDoesNotFit(
        f"robot_chain_v1: {floor} at most n_robots={holds} at spacing={cfg.spacing} m (the longest free path "
        f"from a goal is {longest:.2f} m); n_robots={cfg.n_robots} needs {lead} + (n_robots - 1) * spacing = "
        f"{need:.2f} m. Use n_robots <= {holds}, a smaller spacing or {lead}{way_out}."
    )


def fallback_mission(
    cmap: ChainMap,
    cfg: RobotChainConfig,
    rng: np.random.Generator,
    goal_distance: tuple[float, float] | None,
    reach: FloorReach,
) -> Mission | None:
    """A mission whose goal is drawn (with ``rng``) among the goals known to leave room for the chain.

    What :func:`plan_mission` falls back to when its random goals all lie too central; None when the floor
    holds no such goal (the caller refuses the chain with :func:`does_not_fit`).
    """
    width = cmap.grid.width
    need = (cfg.n_robots - 1) * cfg.spacing
    lo, hi = goal_distance if goal_distance is not None else (cfg.min_goal_distance, np.inf)
    fits = reach.candidates[reach.bound >= lo + need]
    for _ in range(FALLBACK_TRIES if len(fits) else 0):
        goal = divmod(int(fits[rng.integers(len(fits))]), width)
        mission, _ = _mission_to(cmap, cfg, rng, goal, (lo, hi), need)
        if mission is not None:
            return mission
    return None


def _mission_to(
    cmap: ChainMap,
    cfg: RobotChainConfig,
    rng: np.random.Generator,
    goal: tuple[int, int],
    window: tuple[float, float],
    need: float,
) -> tuple[Mission | None, float]:
    """The mission to ``goal`` whose chain's tail is drawn (with ``rng``) ``window`` plus ``need`` m from it.

    Returns:
        The mission, or None when no free cell lies that far; and the farthest free-floor distance to the goal.
    """
    free = cmap.free_cells
    goal_cells = distance_field(cmap.blocked, goal)
    to_goal = goal_cells * cmap.grid.resolution
    on_free = to_goal.ravel()[free]
    reachable = on_free < np.inf
    lo, hi = window
    tails = free[reachable & (on_free >= lo + need) & (on_free <= hi + need)]
    if len(tails) == 0:
        return None, float(on_free[reachable].max()) if reachable.any() else 0.0
    tail = divmod(int(tails[rng.integers(len(tails))]), cmap.grid.width)
    line = Polyline(cmap.centres(np.array(descend(cmap.blocked, goal_cells, tail))))
    return _mission(cmap, cfg, goal_cells, cmap.cell(line.at(need)), line, to_goal), 0.0


@dataclasses.dataclass(frozen=True)
class Mission:
    """One episode's route and starting formation.

    Attributes:
        path_cells: ``(k, 2)`` path cells from start to goal (a shortest 8-connected path, as A* finds).
        path: The path in the world (m); its last point is the goal.
        positions: ``(n, 2)`` start positions of the robots, leader first (m), ``spacing`` apart along a
            free path behind the leader.
        to_goal: ``(H, W)`` free-floor distance (m) from every cell of the inflated map to the goal (inf
            where unreachable).
        formation: The line the chain stands on, from the last robot to the leader: robot k stands at arc
            length ``(n - 1 - k) * spacing``.
    """

    path_cells: np.ndarray
    path: Polyline
    positions: np.ndarray
    to_goal: np.ndarray
    formation: Polyline

    @property
    def astar_length(self) -> float:
        """Length of the path through the cell centres (m)."""
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


def plan_mission(
    cmap: ChainMap,
    cfg: RobotChainConfig,
    rng: np.random.Generator,
    goal_distance: tuple[float, float] | None = None,
) -> Mission:
    """Goal, start, path and the chain's places for one episode.

    A goal is drawn on roomy free floor (or given) and its free-floor distance field computed (the reward
    needs it too). Then the last robot's place is drawn among the cells at least ``min_goal_distance +
    (n - 1) * spacing`` from the goal along the free floor, and the chain stands on the shortest path from
    there to the goal, ``spacing`` apart, the leader at its head: the followers stand behind the leader on
    the backward extension of its own path, never nearer to the goal, and the leader starts at least
    ``min_goal_distance`` from it. A goal without such cells is drawn again (``GOAL_TRIES``). With a given
    start the leader stands there and the chain behind it along a free path that leads away from the goal.
    The leader's path is a shortest 8-connected path on the inflated map (what Alg. 1's A* finds), read
    off the goal's field.

    Args:
        cmap: The episode's map.
        cfg: The env's config.
        rng: The episode's random stream.
        goal_distance: ``(lo, hi)``: the leader starts between ``lo`` and ``hi`` metres from the goal along
            the free floor, instead of at least ``min_goal_distance`` (a drawn start only).

    Raises:
        ChainDoesNotFit: When no goal tried leaves room for the chain (the message says what to change).
        ValueError: For a given start or goal off the free floor, or without a path between them.
    """
    free = cmap.free_cells
    if len(free) == 0:
        raise ValueError("robot_chain_v1: the inflated map has no free cell for the robots")
    candidates = goal_candidates(cmap, cfg)
    width = cmap.grid.width
    res = cmap.grid.resolution
    n = cfg.n_robots
    need = (n - 1) * cfg.spacing
    start_given = given_cell(cmap, cfg.start, "start") if cfg.start else None
    goal_given = given_cell(cmap, cfg.goal, "goal") if cfg.goal else None
    farthest = 0.0  # the longest free-floor distance to a goal tried (for the error message)
    for _ in range(GOAL_TRIES):
        if goal_given is not None:
            goal = goal_given
        elif start_given is not None:
            # A given start: the goal is drawn among the cells far enough from it.
            from_start = distance_field(cmap.blocked, start_given).ravel() * res
            far = candidates[from_start[candidates] >= cfg.min_goal_distance]
            far = far[np.isfinite(from_start[far])]
            if len(far) == 0:
                raise ValueError(
                    f"robot_chain_v1: no goal lies {cfg.min_goal_distance} m from start={cfg.start}; "
                    "lower min_goal_distance"
                )
            goal = divmod(int(far[rng.integers(len(far))]), width)
        else:
            goal = divmod(int(candidates[rng.integers(len(candidates))]), width)
        if start_given is not None:
            goal_cells = distance_field(cmap.blocked, goal)
            to_goal = goal_cells * res
            if not np.isfinite(to_goal[start_given]):
                raise ValueError("robot_chain_v1: no path between start and goal on the inflated map")
            if to_goal[start_given] < cfg.min_goal_distance and goal_given is not None:
                raise ValueError(
                    f"robot_chain_v1: goal={cfg.goal} lies nearer than min_goal_distance={cfg.min_goal_distance} m "
                    f"to start={cfg.start}; lower min_goal_distance"
                )
            line = place_chain(cmap, cfg, start_given, to_goal)
            if line is not None:
                return _mission(cmap, cfg, goal_cells, start_given, line, to_goal)
            if goal_given is not None:
                break
            continue
        window = goal_distance if goal_distance is not None else (cfg.min_goal_distance, np.inf)
        mission, reached = _mission_to(cmap, cfg, rng, goal, window, need)
        if mission is not None:
            return mission
        farthest = max(farthest, reached)
        if goal_given is not None:
            break
    if start_given is not None:
        raise ChainDoesNotFit(
            f"robot_chain_v1: n_robots={n} need {need:.2f} m of free floor behind start={cfg.start} "
            "((n_robots - 1) * spacing, leading away from the goal); there is none. Use fewer robots, a smaller "
            "spacing, another start, or no start (one is drawn where the chain fits)."
        )
    raise ChainDoesNotFit(
        f"robot_chain_v1: n_robots={n} need a free path of min_goal_distance + (n_robots - 1) * spacing = "
        f"{cfg.min_goal_distance + need:.2f} m to the goal (the leader at least min_goal_distance from it, the "
        f"chain behind); the longest found on this map is {farthest:.2f} m. Use fewer robots, a smaller spacing or "
        "min_goal_distance, or a larger map (office_width / office_height, n_rows / row_length)."
    )


def _mission(
    cmap: ChainMap,
    cfg: RobotChainConfig,
    goal_cells: np.ndarray,
    start: tuple[int, int],
    line: Polyline,
    to_goal: np.ndarray,
) -> Mission:
    """The mission whose chain stands on ``line`` (from the last robot on), the leader at ``start``."""
    need = (cfg.n_robots - 1) * cfg.spacing
    formation = line.between(0.0, need)
    positions = np.array([formation.at(need - k * cfg.spacing) for k in range(cfg.n_robots)])
    cells = np.array(descend(cmap.blocked, goal_cells, start))
    return Mission(
        path_cells=cells, path=Polyline(cmap.centres(cells)), positions=positions, to_goal=to_goal, formation=formation
    )


def given_cell(cmap: ChainMap, xy: tuple, name: str) -> tuple[int, int]:
    """The cell of a given start or goal, which must lie on the inflated map's free floor."""
    cell = cmap.cell(np.array(xy, dtype=np.float64))
    if cmap.blocked[cell]:
        raise ValueError(f"robot_chain_v1: {name}={xy} is not on free floor (inflated map)")
    return cell


def place_chain(cmap: ChainMap, cfg: RobotChainConfig, start: tuple[int, int], to_goal: np.ndarray) -> Polyline | None:
    """A free path behind a given start for the followers, ``spacing`` apart; None if there is none.

    The path runs from the start to the cell farthest from the goal among those ``(n - 1) * spacing`` to
    ``(n - 1) * spacing + 1`` metres away along the free floor (a shortest path, so the chain stands
    straight where the floor allows). None also when a follower would stand nearer to the goal than the
    leader (a start in a room's far corner, its door toward the goal).

    Args:
        cmap: The map.
        cfg: The env's config.
        start: The leader's cell.
        to_goal: Free-floor distance (m) of every cell to the goal.

    Returns:
        The line from the last robot's place to the start (m), or None.
    """
    n = cfg.n_robots
    res = cmap.grid.resolution
    if n == 1:
        return Polyline(cmap.centres(np.array([start])))
    need = (n - 1) * cfg.spacing
    # Exact up to need + 1 m: only that far is searched.
    start_cells = distance_field(cmap.blocked, start, (need + 1.0) / res)
    from_start = start_cells * res
    reach = (from_start >= need) & (from_start <= need + 1.0)
    if not reach.any():
        return None
    cells = np.argwhere(reach)
    i, j = (int(v) for v in cells[int(np.argmax(to_goal[reach]))])
    tail = (i, j)
    tail_path = descend(cmap.blocked, start_cells, tail)
    if tail_path is None:
        return None
    line = Polyline(cmap.centres(np.array(tail_path)))
    back = line.length
    if back < need - 1e-6:
        return None
    followers = np.array([line.at(back - k * cfg.spacing) for k in range(1, n)])
    grid_cells = cmap.grid.world_to_cell(followers)
    rows = np.clip(grid_cells[:, 0], 0, cmap.grid.height - 1)
    cols = np.clip(grid_cells[:, 1], 0, cmap.grid.width - 1)
    if np.any(to_goal[rows, cols] < to_goal[start]):
        return None
    return line.between(back - need, back)  # from the last robot's place to the leader


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
