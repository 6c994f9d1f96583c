"""robot_chain_v0: a chain of small round robots led along an A* path (Apoorva, Gautam & Kala 2018).

PettingZoo module: ``parallel_env`` (the native :class:`RobotChainEnv`), ``raw_env`` (its AEC form through
``parallel_to_aec``) and ``env`` (the AEC form with PettingZoo's order-enforcing wrapper)::

    from agri_envs.chain import robot_chain_v0

    env = robot_chain_v0.parallel_env(n_robots=4, n_dynamic_obstacles=1)
    observations, infos = env.reset(seed=0)
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils import parallel_to_aec, wrappers

from agri_baselines.apoorva_chain import GhostParams, GhostRobot, Polyline
from agri_baselines.grid_astar import astar, distance_field
from agri_envs._actions import checked_action
from agri_envs._config import StrictConfig, param
from agri_envs.chain._kernels import observe
from agri_envs.chain.maps import ChainMap, OfficeParams, greenhouse_map, office_map, ros_map
from agri_envs.rover.layout import LayoutParams
from agri_envs.sim2d.diff_drive import DiffDriveSpec
from agri_envs.sim2d.geometry import Kind
from agri_envs.sim2d.raycast import sonar_ranges_many
from agri_envs.sim2d.sensors import SonarSpec
from agri_envs.sim2d.view import SceneView
from agri_envs.sim2d.world import World2D

#: Amigobot sonar directions (deg): six in front, two at the back.
SONAR_ANGLES_DEG = (90.0, 41.0, 15.0, -15.0, -41.0, -90.0, -145.0, 145.0)
OBS_SIZE = 23
_START_TRIES = 10  # sampled starts tried for one with room for the chain behind the leader
_PARK = 1.0e6  # where dynamic obstacles wait before they are dropped (far outside any map)


@dataclasses.dataclass(frozen=True)
class RobotChainConfig(StrictConfig):
    """Arguments of ``robot_chain_v0`` (each one a keyword of ``parallel_env`` / ``env``)."""

    n_robots: int = param(4, "robots in the chain (robot_0 leads)", low=1, high=256)
    scene: str = param("office", "kind of map", choices=("office", "greenhouse", "map"))
    map_yaml: str = param("", "ROS map_server map to load (scene='map')", valid="YAML path")
    layout_seed: int = param(-1, "seed of the generated map; -1 draws a new one every episode", low=-1, high=2**31 - 1)
    office_width: float = param(14.0, "office floor length along x (scene='office')", unit="m", low=6.0, high=100.0)
    office_height: float = param(9.0, "office floor depth along y (scene='office')", unit="m", low=5.0, high=100.0)
    office_rooms: int = param(3, "rooms on each side of the corridor (scene='office')", low=1, high=20)
    n_rows: int = param(3, "rows of plants (scene='greenhouse')", low=1, high=12)
    row_length: float = param(8.0, "length of the rows (scene='greenhouse')", unit="m", low=2.0, high=40.0)
    start: tuple = param((), "leader start (x, y); empty: sampled", unit="m", valid="() or (x, y)")
    goal: tuple = param((), "leader goal (x, y); empty: sampled", unit="m", valid="() or (x, y)")
    min_goal_distance: float = param(6.0, "shortest A* distance of a sampled goal", unit="m", low=0.0, high=500.0)
    n_dynamic_obstacles: int = param(1, "obstacles dropped into the leader's path", low=0, high=20)
    obstacle_radius: float = param(0.2, "radius of a dropped obstacle", unit="m", low=0.05, high=1.0)
    robot_radius: float = param(0.165, "robot radius (Amigobot: about 0.33 x 0.28 m)", unit="m", low=0.05, high=0.5)
    max_speed: float = param(0.4, "speed limit, both directions", unit="m/s", low=0.05, high=2.0)
    max_turn_rate: float = param(2.0, "angular speed limit", unit="rad/s", low=0.2, high=6.0)
    max_accel: float = param(1.0, "linear acceleration limit", unit="m/s^2", low=0.1, high=10.0)
    max_angular_accel: float = param(6.0, "angular acceleration limit", unit="rad/s^2", low=0.1, high=40.0)
    control_period: float = param(0.1, "time between actions", unit="s", low=0.01, high=0.5)
    sonar_range: float = param(3.0, "sonar maximum range", unit="m", low=0.5, high=10.0)
    sonar_aperture: float = param(0.9, "sonar cone opening angle", unit="rad", low=0.05, high=1.5)
    sonar_noise_std: float = param(0.005, "sonar Gaussian range noise", unit="m", low=0.0, high=0.5)
    spacing: float = param(0.55, "d_s: desired distance between neighbours", unit="m", low=0.2, high=5.0)
    max_gap: float = param(1.2, "Delta: a gap larger than this breaks the chain", unit="m", low=0.3, high=10.0)
    planning_margin: float = param(0.2, "clearance added to the robot radius for A*", unit="m", low=0.0, high=1.0)
    map_resolution: float = param(0.05, "grid cell size for planning", unit="m", low=0.01, high=0.5)
    ghost_speed: float = param(0.35, "v_F: ghost pseudo speed along the A* path", unit="m/s", low=0.01, high=5.0)
    ghost_back_speed: float = param(0.2, "v_B: ghost speed back toward a stuck leader", unit="m/s", low=0.0, high=5.0)
    ghost_leash: float = param(0.5, "eta: the ghost waits while the leader is farther", unit="m", low=0.1, high=10.0)
    ghost_patience: float = param(2.0, "T: time beyond eta before the ghost comes back", unit="s", low=0.0, high=60.0)
    goal_radius: float = param(0.3, "the leader has arrived within this distance", unit="m", low=0.05, high=2.0)
    max_cycles: int = param(1500, "steps before truncation", low=1, high=1_000_000)
    terminate_on_collision: bool = param(True, "end the episode when any robot touches anything")
    reward_progress: float = param(1.0, "per metre of leader progress along the A* path", low=0.0, high=100.0)
    reward_spacing: float = param(0.05, "penalty per step at relative spacing error 1", low=0.0, high=10.0)
    reward_strip: float = param(0.05, "penalty per step per metre of mean distance to the strip", low=0.0, high=10.0)
    reward_collision: float = param(10.0, "penalty per robot in contact", low=0.0, high=1000.0)
    reward_break: float = param(0.1, "penalty per step per gap larger than Delta", low=0.0, high=100.0)
    reward_success: float = param(10.0, "bonus when the leader arrives with the chain intact", low=0.0, high=1000.0)
    reward_time: float = param(0.005, "penalty per step", low=0.0, high=10.0)
    render_width: int = param(800, "width of rendered frames", unit="px", low=100, high=4000)

    def validate(self) -> None:
        """Check map, start/goal and spacing arguments fit together."""
        if self.scene == "map":
            if not self.map_yaml or not Path(self.map_yaml).is_file():
                raise ValueError(
                    "RobotChainConfig: scene='map' needs map_yaml, an existing ROS map YAML file "
                    f"(got {self.map_yaml!r})."
                )
        elif self.map_yaml:
            raise ValueError("RobotChainConfig: map_yaml applies only to scene='map'.")
        for name in ("start", "goal"):
            value = getattr(self, name)
            if value != () and (
                len(value) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value)
            ):
                raise ValueError(f"RobotChainConfig: {name} must be () or (x, y) in metres, got {value!r}.")
        if self.spacing < 2 * self.robot_radius + 0.05:
            raise ValueError(
                f"RobotChainConfig: spacing={self.spacing} m leaves no room between robots of radius "
                f"{self.robot_radius} m; use spacing >= {2 * self.robot_radius + 0.05:.2f}."
            )
        if self.max_gap <= self.spacing:
            raise ValueError(f"RobotChainConfig: max_gap ({self.max_gap}) must exceed spacing ({self.spacing}).")


class RobotChainEnv(ParallelEnv):  # type: ignore[misc]
    """A leader and its followers cross a mapped floor as a chain, around obstacles dropped in their way.

    ## Description

    ``n_robots`` round robots like the Amigobots of Apoorva et al. (2018) (radius ``robot_radius``, eight
    sonars) stand in a chain: ``robot_0`` leads, ``robot_k`` follows ``robot_{k-1}``. The leader must reach
    the goal; the others must follow at about ``spacing`` (d_s) from each other without a gap above
    ``max_gap`` (Delta), in as straight a line as possible (the elastic strip between the first and last
    robot), without touching walls, furniture, obstacles or each other. The map (an office floor, a
    greenhouse or a ROS map) is inflated by the robot radius plus ``planning_margin``, and A* plans the
    leader's path from start to goal on it; a ghost robot runs along that path ahead of the leader (sec.
    4.4). While the leader advances, ``n_dynamic_obstacles`` boxes drop onto the path ahead of it (Fig. 8d).
    Robots are solid pymunk bodies of the shared 2D world: they see and block each other.

    ## Action Space

    Every agent: ``Box(-1, 1, (2,), float32)``: ``[v, omega]`` scaled by ``max_speed`` (both directions) and
    ``max_turn_rate``; the achieved velocities follow within the acceleration limits. Values outside the
    box are clipped; NaN or inf, a wrong shape or an unknown agent raise ``ValueError``.

    ## Observation Space

    Every agent: ``Box(low, high, (23,), float32)`` (one space shared by all, for parameter sharing):

    | index | meaning | bounds |
    |---|---|---|
    | 0-7 | sonar ranges / ``sonar_range`` at 90, 41, 15, -15, -41, -90, -145, 145 deg | [0, 1] |
    | 8-9 | position ``(x, y)`` normalised by the map's bounds | [0, 1] |
    | 10-11 | ``sin(yaw)``, ``cos(yaw)`` | [-1, 1] |
    | 12-13 | predecessor in the robot's frame / 3 m (leader: the ghost) | [-1, 1] |
    | 14-15 | successor in the robot's frame / 3 m (0 for the last robot) | [-1, 1] |
    | 16 | 1 if there is a successor, else 0 | [0, 1] |
    | 17 | signed distance to the strip (first-last line; + on its left) / 3 m | [-1, 1] |
    | 18 | 1 for the leader, else 0 | [0, 1] |
    | 19-20 | achieved ``v / max_speed``, ``omega / max_turn_rate`` | [-1, 1] |
    | 21-22 | goal in the robot's frame / map diagonal | [-1, 1] |

    Positions come from each robot's localization and inter-robot communication as in the paper (exact here).

    ## Sensors

    Eight sonars per robot at the Amigobot's directions 90, 41, 15, -15, -41, -90, -145 and 145 deg, just
    inside the body's outline; each reports the nearest echo in its cone (``sonar_aperture``) up to
    ``sonar_range``, with Gaussian noise ``sonar_noise_std``. Other robots are obstacles to them.

    ## Rewards

    One cooperative reward, the same for every agent, the sum of these terms (each in ``info``):

    | term | formula |
    |---|---|
    | ``reward_progress`` | ``reward_progress * (s - s_prev)``, s the leader's arc length along the A* path |
    | ``reward_spacing`` | ``-reward_spacing * mean_k min(1, abs(gap_k - d_s) / d_s)`` |
    | ``reward_strip`` | ``-reward_strip * mean distance (m) of the robots to the strip`` |
    | ``reward_collision`` | ``-reward_collision * robots in contact this step`` |
    | ``reward_break`` | ``-reward_break * gaps larger than Delta`` |
    | ``reward_success`` | ``+reward_success`` when the episode ends in success |
    | ``reward_time`` | ``-reward_time`` every step |

    ## Starting State

    The map is generated from the episode seed (``layout_seed=-1``) or from ``layout_seed``. Start and goal
    are sampled on free floor at least 0.35 m from obstacles and ``min_goal_distance`` apart along the A*
    path (or given). The followers stand behind the leader along a free path away from the goal, ``spacing``
    apart and facing their predecessor; when no such path is long enough they fill the free floor nearest
    to the leader. A sampled start that leaves followers nearer to the goal than the leader (a room's far
    corner with the door toward the goal) is drawn again, up to 10 times. Obstacles drop when the leader
    has covered random fractions (0.15-0.7) of the path, onto the path 1.2-3 m ahead of it, only where at
    least a robot's width stays free beside them.

    ## Episode End

    Every agent terminates when the leader is within ``goal_radius`` of the goal (success if no robot ever
    touched anything and no gap exceeds Delta), or when any robot touches anything and
    ``terminate_on_collision``. Every agent is truncated after ``max_cycles`` steps.

    ## Info

    Per agent: true ``x``, ``y``, ``yaw``, ``v``, ``w`` and ``collision`` (this robot touched something this
    step). Shared by all agents: ``is_success``, ``leader_at_goal``, ``chain_intact``, ``collisions`` (robot
    contacts so far), ``max_gap`` (m, this episode), ``mean_strip_distance`` and ``max_strip_distance`` (m, this
    episode), ``leader_path_length``, ``astar_length`` (m), ``path_ratio``, ``episode_time`` (s) and the
    reward terms.

    ## Arguments

    Every argument is a field of :class:`RobotChainConfig`; unknown names and values out of range raise
    ``ValueError`` naming the argument and its valid range. Example::

        env = robot_chain_v0.parallel_env(n_robots=8, scene="greenhouse", n_dynamic_obstacles=2)

    ## Baselines

    ``apoorva-chain`` (A* + ghost + sonar potential field + elastic strip) and ``apoorva-chain-no-strip``.

    ## Version History

    * v0: initial release. Fixed since: the followers' start no longer lies between the leader and the
      goal when another sampled start avoids it (the documented starting state; spaces and reward unchanged).

    ## References

    Apoorva, R. Gautam and R. Kala, "Motion Planning for a Chain of Mobile Robots Using A* and Potential
    Field", Robotics 7(2):20, 2018.
    """

    metadata = {
        "name": "robot_chain_v0",
        "render_modes": ["rgb_array", "human"],
        "render_fps": 10,
        "is_parallelizable": True,
        "episode_metric_keys": (
            "collision",
            "collisions",
            "leader_at_goal",
            "chain_intact",
            "episode_time",
            "leader_path_length",
            "astar_length",
            "path_ratio",
            "mean_strip_distance",
            "max_strip_distance",
            "max_gap",
        ),
        "trace_keys": ("positions", "mean_strip_distance_now", "max_gap_now", "ghost_x", "ghost_y"),
    }

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        self.config = RobotChainConfig.from_kwargs(kwargs)
        self.render_mode = render_mode
        cfg = self.config
        self.robot_radius = cfg.robot_radius
        self.possible_agents = [f"robot_{k}" for k in range(cfg.n_robots)]
        self.agents: list[str] = []
        self.spec = DiffDriveSpec(
            length=2 * cfg.robot_radius,
            width=2 * cfg.robot_radius,
            max_speed=cfg.max_speed,
            max_reverse_speed=cfg.max_speed,
            max_turn_rate=cfg.max_turn_rate,
            max_accel=cfg.max_accel,
            max_angular_accel=cfg.max_angular_accel,
        )
        self.sonar = SonarSpec(
            aperture=cfg.sonar_aperture, min_range=0.01, max_range=cfg.sonar_range, noise_std=cfg.sonar_noise_std
        )
        angles = np.radians(SONAR_ANGLES_DEG)
        # Sonars sit 5 mm inside the outline, so the kernels never see the robot's own disc.
        self.sonar_offset = cfg.robot_radius - 0.005
        self.sonar_mounts = np.stack(
            [self.sonar_offset * np.cos(angles), self.sonar_offset * np.sin(angles), angles], axis=1
        )
        low = np.array([0.0] * 8 + [0, 0, -1, -1, -1, -1, -1, -1, 0, -1, 0, -1, -1, -1, -1], np.float32)
        high = np.ones(OBS_SIZE, np.float32)
        self._obs_space = spaces.Box(low, high, (OBS_SIZE,), np.float32)
        self._act_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.rel_scale = 3.0
        self._static_map: ChainMap | None = None
        if cfg.scene == "map":
            self._static_map = ros_map(cfg.map_yaml, cfg.robot_radius + cfg.planning_margin)
            canvas = self._static_map.geometry.bounds
        elif cfg.scene == "office":
            canvas = self._office_params().bounds()
        else:
            canvas = self._greenhouse_params().max_bounds()
        self.view = SceneView(render_mode, canvas, cfg.render_width, fps=10)
        self.world: World2D | None = None
        self.chain_map: ChainMap | None = None
        n_dyn = cfg.n_dynamic_obstacles
        self.state_space = spaces.Box(-np.inf, np.inf, (5 * cfg.n_robots + 4 + 3 * n_dyn,), np.float32)

    # -- spaces ----------------------------------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Box:
        """The observation space, the same object for every agent (parameter sharing)."""
        return self._obs_space

    def action_space(self, agent: str) -> spaces.Box:
        """The action space, the same object for every agent."""
        return self._act_space

    @property
    def map_bounds(self) -> np.ndarray:
        """``(xmin, ymin, xmax, ymax)`` of the current map (m): observation 8-9 is the position scaled by it."""
        if self.chain_map is None:
            raise RuntimeError("call reset() first")
        return self._bounds.copy()

    def observation_layout(self) -> dict[str, Any]:
        """Where things sit in an observation and how to scale them back (for scripted policies)."""
        return {
            "sonar": slice(0, 8),
            "xy": slice(8, 10),
            "sin_yaw": 10,
            "cos_yaw": 11,
            "predecessor": slice(12, 14),
            "successor": slice(14, 16),
            "has_successor": 16,
            "strip": 17,
            "is_leader": 18,
            "velocity": slice(19, 21),
            "goal": slice(21, 23),
            "sonar_max_range": self.config.sonar_range,
            "sonar_angles": self.sonar_mounts[:, 2].copy(),
            "sonar_offset": self.sonar_offset,
            "rel_scale": self.rel_scale,
            "max_speed": self.config.max_speed,
            "max_turn_rate": self.config.max_turn_rate,
        }

    # -- episode set-up --------------------------------------------------------------------------------
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """New map (unless fixed), start, goal, A* path, chain placement and obstacle schedule.

        ``options`` is accepted for API compatibility and unused (PettingZoo's API test passes some).
        """
        if seed is not None or not hasattr(self, "np_random"):
            self.np_random = np.random.default_rng(seed)
        cfg = self.config
        rng = self.np_random
        inflation = cfg.robot_radius + cfg.planning_margin
        layout_rng = rng if cfg.layout_seed < 0 else np.random.default_rng(cfg.layout_seed)
        if self._static_map is not None:
            cmap = self._static_map
        elif cfg.scene == "office":
            cmap = office_map(self._office_params(), layout_rng, inflation, cfg.map_resolution)
        else:
            cmap = greenhouse_map(self._greenhouse_params(), layout_rng, inflation, cfg.map_resolution)
        self.chain_map = cmap
        xmin, ymin, xmax, ymax = cmap.geometry.bounds
        self._bounds = np.array([xmin, ymin, xmax, ymax])
        self.diagonal = math.hypot(xmax - xmin, ymax - ymin)
        # A sampled start with no room behind it for the chain (a room's far corner) would put followers
        # between the leader and the goal: such a start is drawn again, up to _START_TRIES times, keeping the
        # draw with the fewest followers ahead (a given start is kept).
        best: tuple | None = None
        for _ in range(_START_TRIES):
            start_cell, goal_cell, path_cells = self._plan(cmap, rng)
            positions, ahead = self._place_chain(cmap, start_cell, goal_cell)
            if best is None or ahead < best[0]:
                best = (ahead, start_cell, goal_cell, path_cells, positions)
            if ahead == 0 or cfg.start:
                break
        assert best is not None
        _, start_cell, goal_cell, path_cells, positions = best
        path_xy = cmap.centres(np.array(path_cells))
        self.astar_cells = np.array(path_cells)
        self.astar_length = float(np.hypot(*np.diff(path_xy, axis=0).T).sum()) if len(path_xy) > 1 else 0.0
        self.goal = path_xy[-1].copy()
        self.path = Polyline(path_xy)
        n = cfg.n_robots
        self.world = World2D(cmap.geometry, n_movers=cfg.n_dynamic_obstacles)
        for k in range(cfg.n_dynamic_obstacles):
            self.world.place_mover(k, _PARK + 10.0 * k, _PARK, cfg.obstacle_radius)
        yaw = np.empty(n)
        for k in range(n):
            if k == 0:
                ahead = path_xy[min(len(path_xy) - 1, 6)] - positions[0]
            else:
                ahead = positions[k - 1] - positions[k]
            yaw[k] = math.atan2(ahead[1], ahead[0]) if np.any(ahead) else 0.0
        self.robots = [
            self.world.add_robot(self.spec, np.array([positions[k, 0], positions[k, 1], yaw[k]]), cfg.robot_radius)
            for k in range(n)
        ]
        self._robot_rows = np.array([r.circle_index for r in self.robots], dtype=np.int64)
        self.ghost = GhostRobot(
            self.path,
            GhostParams(
                v_forward=cfg.ghost_speed,
                v_back=cfg.ghost_back_speed,
                eta=cfg.ghost_leash,
                patience=cfg.ghost_patience,
                window=max(1.5, 4 * cfg.max_speed * cfg.control_period + 1.0),
            ),
            cfg.control_period,
        )
        self.ghost.reset(positions[0])
        self._ghost_xy = self.ghost.xy
        self._s_progress = self.ghost.s_leader
        # Obstacle schedule: drop k when the leader has covered fraction f_k of the path.
        self._drop_at = np.sort(rng.uniform(0.15, 0.7, cfg.n_dynamic_obstacles)) * self.astar_length
        self._dropped = np.zeros(cfg.n_dynamic_obstacles, dtype=bool)
        self._next_drop = 0
        self._n_dropped = 0
        self.agents = list(self.possible_agents)
        self._poses = np.array([r.pose for r in self.robots])
        self._steps = 0
        self._collisions = 0
        self._collided_any = False
        self._obs_buf = np.zeros((n, OBS_SIZE))
        self._stats = np.zeros(5)
        self._cmd_scale = np.array([cfg.max_speed, cfg.max_turn_rate])
        self._strip_sum = 0.0
        self._strip_max = 0.0
        self._strip_count = 0
        self._leader_path = 0.0
        self._vel = np.zeros((n, 2))
        self._sonar_out = np.empty((n, len(self.sonar_mounts)))
        self._trail = [self._poses[0, :2].copy()]
        self._last_collided = np.zeros(n, dtype=bool)
        self._terms = dict.fromkeys(("progress", "spacing", "strip", "collision", "break", "success", "time"), 0.0)
        self._done_success = False
        self._leader_arrived = False
        obs = self._observe()
        self._max_gap = float(self._stats[2])
        infos = self._infos()
        if self.render_mode == "human":
            self.render()
        return obs, infos

    def _office_params(self) -> OfficeParams:
        cfg = self.config
        return OfficeParams(width=cfg.office_width, height=cfg.office_height, rooms_per_side=cfg.office_rooms)

    def _greenhouse_params(self) -> LayoutParams:
        return LayoutParams(n_rows=self.config.n_rows, row_length=self.config.row_length)

    def _plan(self, cmap: ChainMap, rng: np.random.Generator) -> tuple[tuple[int, int], tuple[int, int], list]:
        """Start and goal cells (given or sampled) and the A* path between them."""
        cfg = self.config
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
                return (int(s[0]), int(s[1])), (int(g[0]), int(g[1])), path
            if cfg.start and cfg.goal:
                break
        raise ValueError("robot_chain_v0: no A* path between start and goal on the inflated map")

    def _place_chain(self, cmap: ChainMap, start: tuple[int, int], goal: tuple[int, int]) -> tuple[np.ndarray, int]:
        """Leader at the start; followers ``spacing`` apart along a free path behind it (or packed nearby).

        Returns:
            The ``(n, 2)`` positions, and how many followers stand ahead of the leader (nearer to the goal
            along the free floor than the leader).
        """
        cfg = self.config
        n = cfg.n_robots
        res = cmap.grid.resolution
        positions = np.zeros((n, 2))
        positions[0] = cmap.centres(np.array([start]))[0]
        if n == 1:
            return positions, 0
        need = (n - 1) * cfg.spacing
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
            f"robot_chain_v0: {n} robots do not fit on the free floor around the start; "
            "use fewer robots or a larger map"
        )

    # -- stepping --------------------------------------------------------------------------------------
    def step(
        self, actions: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], dict[str, float], dict[str, bool], dict[str, bool], dict[str, dict[str, Any]]]:
        """Apply every agent's ``[v, omega]`` for one control period (robots move in chain order)."""
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        if not self.agents:
            raise RuntimeError("the episode is over: call reset()")
        unknown = [a for a in actions if a not in self.agents]
        missing = [a for a in self.agents if a not in actions]
        if unknown or missing:
            raise ValueError(
                f"actions must name every live agent exactly: unknown {sorted(unknown)}, missing {sorted(missing)}"
            )
        cfg = self.config
        dt = cfg.control_period
        cmd = self._actions_array(actions)
        cmd *= self._cmd_scale
        world = self.world
        if self._next_drop < len(self._drop_at) and self.ghost.s_leader >= self._drop_at[self._next_drop]:
            self._drop_obstacles()
        if self._n_dropped:
            world.step(dt)
        lx, ly = self._poses[0, 0], self._poses[0, 1]
        poses = self._poses
        collided = world.drive_discs(self.robots, cmd, dt, poses, self._vel)
        self._steps += 1
        self._leader_path += math.hypot(poses[0, 0] - lx, poses[0, 1] - ly)
        if self.render_mode is not None:
            self._trail.append(poses[0, :2].copy())
        self._last_collided = collided
        n_col = int(collided.sum())
        self._collisions += n_col
        self._collided_any = self._collided_any or n_col > 0
        self.ghost.update(poses[0, :2])
        self._ghost_xy = self.ghost.xy
        s_new = self.ghost.s_leader
        progress = s_new - self._s_progress
        self._s_progress = s_new
        obs = self._observe()
        mean_strip, max_strip, max_gap, n_break, spacing_err = self._stats.tolist()
        self._max_gap = max(self._max_gap, max_gap)
        self._strip_sum += mean_strip
        self._strip_count += 1
        self._strip_max = max(self._strip_max, max_strip)
        arrived = math.hypot(poses[0, 0] - self.goal[0], poses[0, 1] - self.goal[1]) <= cfg.goal_radius
        self._leader_arrived = arrived
        success = arrived and not self._collided_any and n_break == 0
        self._done_success = success
        terms = {
            "progress": cfg.reward_progress * progress,
            "spacing": -cfg.reward_spacing * spacing_err,
            "strip": -cfg.reward_strip * mean_strip,
            "collision": -cfg.reward_collision * n_col,
            "break": -cfg.reward_break * n_break,
            "success": cfg.reward_success if success else 0.0,
            "time": -cfg.reward_time,
        }
        self._terms = terms
        reward = float(sum(terms.values()))
        terminated = arrived or (n_col > 0 and cfg.terminate_on_collision)
        truncated = (not terminated) and self._steps >= cfg.max_cycles
        infos = self._infos()
        agents = self.agents
        rewards = dict.fromkeys(agents, reward)
        terminations = dict.fromkeys(agents, bool(terminated))
        truncations = dict.fromkeys(agents, bool(truncated))
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminations, truncations, infos

    def _actions_array(self, actions: dict[str, Any]) -> np.ndarray:
        """``(n, 2)`` float64 actions in agent order, clipped to [-1, 1] (the shared action contract)."""
        agents = self.agents
        if len(actions) != len(agents) or any(a not in actions for a in agents):
            unknown = sorted(a for a in actions if a not in agents)
            missing = sorted(a for a in agents if a not in actions)
            raise ValueError(f"actions must name every live agent exactly once: unknown {unknown}, missing {missing}")
        try:
            a = np.array([actions[name] for name in agents], dtype=np.float64)
        except (ValueError, TypeError):
            a = np.empty(0)
        if a.shape != (len(agents), 2) or not math.isfinite(a.sum()):
            # One of them is malformed: let the shared check name it and say why.
            for name in agents:
                try:
                    checked_action(actions[name], 2)
                except ValueError as exc:
                    raise ValueError(f"{name}: {exc}") from None
        np.minimum(a, 1.0, out=a)
        np.maximum(a, -1.0, out=a)
        return a

    def _drop_obstacles(self) -> None:
        """Drop the next scheduled obstacle onto the path ahead of the leader (retried each step until it fits)."""
        cfg = self.config
        assert self.world is not None
        k = self._next_drop
        spot = self._drop_spot()
        if spot is not None:
            self.world.place_mover(k, float(spot[0]), float(spot[1]), cfg.obstacle_radius)
            self._dropped[k] = True
            self._next_drop += 1
            self._n_dropped += 1

    def _drop_spot(self) -> np.ndarray | None:
        """A point on the path 1.2-3 m ahead of the leader with room to pass it and clear of every robot."""
        cfg = self.config
        cmap = self.chain_map
        assert cmap is not None
        need = cfg.obstacle_radius + 2 * cfg.robot_radius + 0.25
        s0 = self.ghost.s_leader
        for ahead in np.arange(1.2, 3.0, 0.1):
            s = s0 + ahead
            if s > self.path.length - 1.0:
                break
            p = self.path.at(s)
            i, j = cmap.cell(p)
            if cmap.wall_distance[i, j] < need:
                continue
            d = np.hypot(self._poses[:, 0] - p[0], self._poses[:, 1] - p[1])
            if d.min() < cfg.obstacle_radius + cfg.robot_radius + 0.4:
                continue
            return p
        return None

    # -- observations, infos, state -------------------------------------------------------------------
    def _observe(self) -> dict[str, np.ndarray]:
        cfg = self.config
        assert self.world is not None
        poses = self._poses
        out = self._sonar_out
        sonar_ranges_many(
            poses,
            self.sonar_mounts,
            0.5 * cfg.sonar_aperture,
            cfg.sonar_range,
            self.world.circles,
            self.world.capsules,
            self._robot_rows,
            out,
        )
        ranges = out
        if cfg.sonar_noise_std > 0:
            ranges = out + cfg.sonar_noise_std * self.np_random.standard_normal(out.shape)
            np.clip(ranges, self.sonar.min_range, cfg.sonar_range, out=ranges)
        else:
            np.maximum(ranges, self.sonar.min_range, out=ranges)
        self._last_sonar = ranges
        gx, gy = self._ghost_xy
        obs = self._obs_buf
        observe(
            poses,
            self._vel,
            ranges,
            gx,
            gy,
            float(self.goal[0]),
            float(self.goal[1]),
            self._bounds,
            self.diagonal,
            self.rel_scale,
            cfg.sonar_range,
            cfg.max_speed,
            cfg.max_turn_rate,
            cfg.spacing,
            cfg.max_gap,
            obs,
            self._stats,
        )
        obs32 = obs.astype(np.float32)
        return dict(zip(self.agents, obs32, strict=True))

    def _infos(self) -> dict[str, dict[str, Any]]:
        cfg = self.config
        stats = self._stats
        gx, gy = self._ghost_xy
        shared = {
            "is_success": bool(self._done_success),
            "leader_at_goal": bool(self._leader_arrived),
            "chain_intact": bool(stats[3] == 0),
            "collisions": int(self._collisions),
            "max_gap": float(self._max_gap),
            "mean_strip_distance": float(self._strip_sum / self._strip_count) if self._strip_count else 0.0,
            "max_strip_distance": float(self._strip_max),
            "leader_path_length": float(self._leader_path),
            "astar_length": float(self.astar_length),
            "path_ratio": float(self._leader_path / self.astar_length) if self.astar_length > 0 else 1.0,
            "episode_time": self._steps * cfg.control_period,
            "ghost_x": gx,
            "ghost_y": gy,
            "mean_strip_distance_now": float(stats[0]),
            "max_gap_now": float(stats[2]),
        }
        for name, value in self._terms.items():
            shared["reward_" + name] = float(value)
        rows = self._poses.tolist()
        vel = self._vel.tolist()
        col = self._last_collided.tolist()
        return {
            a: {
                **shared,
                "x": rows[k][0],
                "y": rows[k][1],
                "yaw": rows[k][2],
                "v": vel[k][0],
                "w": vel[k][1],
                "collision": col[k],
            }
            for k, a in enumerate(self.agents)
        }

    def state(self) -> np.ndarray:
        """Global state: every robot's ``x, y, yaw, v, omega``, the ghost and the goal, the obstacles' ``x, y, r``."""
        if self.world is None:
            raise RuntimeError("call reset() before state()")
        parts = [
            np.hstack([self._poses, self._vel]).ravel(),
            self.ghost.point,
            self.goal,
            self.world.mover_circles.ravel(),
        ]
        return np.concatenate(parts).astype(np.float32)

    # -- rendering ---------------------------------------------------------------------------------------
    def render(self) -> np.ndarray | None:
        """Top-down frame: map, A* path, ghost, goal, strip, robots with sonar cones (``rgb_array``/``human``)."""
        rd = self.view.begin(None if self.chain_map is None or self.world is None else self.chain_map.geometry)
        if rd is None:
            return None
        assert self.world is not None
        rd.polyline(self.path.points, (200, 60, 60), 1)
        rd.path(np.array(self._trail))
        movers = self.world.mover_circles
        rd.circles(movers[movers[:, 0] < _PARK / 2], Kind.OBSTACLE)
        p = self._poses
        if len(p) >= 3:
            rd.polyline(np.array([p[0, :2], p[-1, :2]]), (150, 60, 200), 2)
        for k in range(len(p)):
            poses = np.array([[*self._sonar_origin(p[k], m), p[k, 2] + m[2]] for m in self.sonar_mounts]).reshape(-1, 3)
            rd.cones(poses, self._last_sonar[k], self.config.sonar_aperture)
        rd.round_robots(p, self.robot_radius)
        g = self.ghost.point
        rd.ring(float(g[0]), float(g[1]), 0.12, (120, 120, 255))
        rd.ring(float(self.goal[0]), float(self.goal[1]), self.config.goal_radius, (30, 160, 30))
        rd.text(
            [
                f"t = {self._steps * self.config.control_period:5.1f} s   robots {len(p)}   "
                f"collisions {self._collisions}   max gap {self._max_gap:.2f} m"
            ]
        )
        return self.view.present()

    @staticmethod
    def _sonar_origin(pose: np.ndarray, mount: np.ndarray) -> tuple[float, float]:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return pose[0] + c * mount[0] - s * mount[1], pose[1] + s * mount[0] + c * mount[1]

    def close(self) -> None:
        """Release the renderer and the pymunk world (idempotent; ``reset()`` builds a new world)."""
        self.view.close()
        if self.world is not None:
            self.world.close()
            self.world = None


def parallel_env(render_mode: str | None = None, **kwargs: Any) -> RobotChainEnv:
    """The native parallel env (see :class:`RobotChainEnv` for the arguments)."""
    return RobotChainEnv(render_mode=render_mode, **kwargs)


def raw_env(render_mode: str | None = None, **kwargs: Any) -> Any:
    """The AEC form, derived with PettingZoo's ``parallel_to_aec``."""
    return parallel_to_aec(parallel_env(render_mode=render_mode, **kwargs))


def env(render_mode: str | None = None, **kwargs: Any) -> Any:
    """The AEC form with PettingZoo's order-enforcing wrapper (the usual ``env()`` of a PettingZoo module)."""
    return wrappers.OrderEnforcingWrapper(raw_env(render_mode=render_mode, **kwargs))
