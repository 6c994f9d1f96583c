"""The robot chain env (Apoorva, Gautam & Kala 2018): composition of map, robots, sensors and task, and the API.

The parts live beside it: :mod:`~agri_envs.chain.config` (arguments), :mod:`~agri_envs.chain.robot` (body,
limits, sonar mounts), :mod:`~agri_envs.chain.mission` (start, goal, A* path, formation, obstacle drops),
:mod:`~agri_envs.chain.task` (the ghost robot and one ``evaluate()`` for reward, success and termination),
:mod:`~agri_envs.chain.observation` (the 29-value observation and the robots' trails). Users import the
versioned module :mod:`agri_envs.chain.robot_chain_v1`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agri_envs._actions import checked_agent_actions
from agri_envs.chain import robot
from agri_envs.chain._kernels import distances_to_go
from agri_envs.chain.config import RobotChainConfig
from agri_envs.chain.maps import ChainMap, block_disc, greenhouse_map, office_map, ros_map
from agri_envs.chain.mission import (
    ChainDoesNotFit,
    FloorReach,
    Mission,
    does_not_fit,
    drop_spot,
    fallback_mission,
    floor_reach,
    plan_mission,
)
from agri_envs.chain.observation import ChainObservation, Trails
from agri_envs.chain.task import ChainTask
from agri_envs.scenes.distribution import largest_scenes
from agri_envs.sim2d.astar import distance_field
from agri_envs.sim2d.geometry import Kind, enclosing_bounds
from agri_envs.sim2d.polyline import Polyline
from agri_envs.sim2d.render import TopDownRenderer
from agri_envs.sim2d.view import SceneView
from agri_envs.sim2d.world import World2D

_PARK = 1.0e6  # where dynamic obstacles wait before they are dropped (far outside any map)
LAYOUT_TRIES = 3  # generated maps drawn for an episode with random goals
FALLBACK_LAYOUTS = 16  # further generated maps drawn (goals known to fit) before a chain that fits none is refused
SCENE_TRIES = 8  # floors drawn from a distribution before a chain that fits none is refused


def _floor_bounds(cfg: RobotChainConfig) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` of the largest generated floor of ``cfg`` (office or greenhouse)."""
    if cfg.scene == "office":
        return cfg.office_params().bounds()
    return cfg.greenhouse_params().max_bounds()


class RobotChainEnv(ParallelEnv):  # type: ignore[misc]
    """A leader and its followers cross a mapped floor as a chain, around obstacles dropped in their way.

    ## Description

    ``n_robots`` round robots like the Amigobots of Apoorva et al. (2018) (radius ``robot_radius``, eight
    sonars) stand in a chain: ``robot_0`` leads, ``robot_k`` follows ``robot_{k-1}``. Every robot must reach
    the goal, as in the paper's Fig. 8f: the leader onto it, its followers close behind, keeping about
    ``spacing`` (d_s) from each other and never a gap above ``max_gap`` (Delta), in as straight a line as
    possible (the elastic strip between the first and last robot), without touching walls, furniture,
    obstacles or each other. The map (an office floor, a greenhouse or a ROS map) is inflated by the robot
    radius plus ``planning_margin``; the leader's path is a shortest 8-connected path on it from start to
    goal (what the paper's A*, Alg. 1, finds), and a ghost robot runs along it ahead of the leader (sec.
    4.4). While the leader advances, ``n_dynamic_obstacles`` boxes drop onto the path ahead of it (Fig. 8d).
    Robots are solid bodies of the shared 2D world: they see and block each other.

    ## Action Space

    Every agent: ``Box(-1, 1, (2,), float32)``: ``[v, omega]`` scaled by ``max_speed`` (both directions) and
    ``max_turn_rate``; the achieved velocities follow within the acceleration limits. Values outside the
    box are clipped; NaN or inf, a wrong shape or an unknown agent raise ``ValueError``.

    ## Observation Space

    Every agent: ``Box(low, high, (29,), float32)`` (one space shared by all, for parameter sharing). All
    vectors are in the robot's own frame (x ahead, y to its left):

    | index | meaning | bounds |
    |---|---|---|
    | 0-7 | sonar ranges / ``sonar_range`` at 90, 41, 15, -15, -41, -90, -145, 145 deg | [0, 1] |
    | 8-9 | position ``(x, y)`` normalised by the map's bounds | [0, 1] |
    | 10-11 | ``sin(yaw)``, ``cos(yaw)`` | [-1, 1] |
    | 12-13 | own achieved ``v / max_speed``, ``omega / max_turn_rate`` | [-1, 1] |
    | 14-15 | predecessor's position / 3 m (leader: the ghost's) | [-1, 1] |
    | 16-17 | predecessor's velocity minus own / (2 ``max_speed``) (leader: the ghost's) | [-1, 1] |
    | 18-19 | slot: the predecessor's trail point ``spacing`` behind it / 3 m (leader: the ghost) | [-1, 1] |
    | 20-21 | successor's position / 3 m (0 for the last robot) | [-1, 1] |
    | 22-23 | successor's velocity minus own / (2 ``max_speed``) (0 for the last robot) | [-1, 1] |
    | 24 | 1 if there is a successor, else 0 | [0, 1] |
    | 25 | 1 for the leader, else 0 | [0, 1] |
    | 26-27 | unit vector toward the goal (0 on it) | [-1, 1] |
    | 28 | straight distance to the goal / 10 m, clipped | [0, 1] |

    What a robot knows of the others comes from its neighbours, as in the paper (positions and velocities
    shared over the network, exact here); the predecessor's trail is the paper's follower "fetching its
    previous position" (sec. 8): each robot records a point every 2 cm it moves, and the slot is where a
    follower stands in a chain at rest behind it. At the start every follower stands on its slot.

    ## Sensors

    Eight sonars per robot at the Amigobot's directions 90, 41, 15, -15, -41, -90, -145 and 145 deg, just
    inside the body's outline; each reports the nearest echo in its cone (``sonar_aperture``) up to
    ``sonar_range``, with Gaussian noise ``sonar_noise_std``. Other robots are obstacles to them.

    ## Rewards

    One cooperative reward, the same for every agent, the sum of these terms (each in ``info``). ``T`` is
    ``max_cycles``; ``D_k`` is robot k's free-floor distance to the goal (the goal's 8-connected distance
    field on the inflated map, round the dropped obstacles once they are down) and
    ``R_k = goal_radius + k * arrival_stretch * spacing`` its arrival radius; the potential is
    ``Phi = -mean_k max(0, D_k - R_k)``, counted as 0 once the episode succeeds.

    | term | formula |
    |---|---|
    | ``reward_progress`` | ``reward_progress * (Phi_new - Phi_old)`` (0 on a step ending in a contact or break) |
    | ``reward_spacing`` | ``-reward_spacing / T * mean_k min(1, abs(gap_k - d_s) / d_s)`` |
    | ``reward_strip`` | ``-reward_strip / T * min(1, mean distance (m) of the robots to the strip)`` |
    | ``reward_time`` | ``-reward_time / T`` every step |
    | ``reward_collision`` | ``-reward_collision`` on a step with any robot in contact |
    | ``reward_break`` | ``-reward_break`` on a step with any gap above Delta |
    | ``reward_forfeit`` | ``-(time + spacing + strip) / T`` per step left, on a step ending in a contact or break |
    | ``reward_success`` | ``+reward_success`` when the episode ends in success |

    On a step that ends the episode in a contact or break, that step's spacing and strip penalties are
    charged at their worst (1).

    The terms are ordered (``tests/envs/test_chain_reward.py`` checks it):

    * **A contact or a break costs more than stopping in place**, whenever it happens: stopping until the time
      limit costs at most ``(time + spacing + strip) / T`` per step; the contact or break charges that for
      every step left plus ``reward_collision`` (``reward_break``) and pays no progress for its step.
    * **Reaching the goal as a chain pays most**, whatever the moment and the chain length: the progress of
      any episode sums to at most ``-Phi`` at its start, a success pays all of it, and every episode pays the
      per-step penalties, at most ``time + spacing + strip`` in all; so a success pays more than any episode
      without one, as long as ``reward_success > reward_time + reward_spacing + reward_strip`` (checked). Every
      term is a mean over robots or gaps, or one flat amount: none grows with the chain.

    ## Starting State

    The map is generated from the episode seed (``layout_seed=-1``) or from ``layout_seed``. A goal is drawn
    on free floor at least 0.35 m from obstacles (or given). The last robot's place is drawn among the cells
    at least ``min_goal_distance + (n_robots - 1) * spacing`` from the goal along the free floor, and the
    chain stands on the shortest path from there to the goal, ``spacing`` apart along it, the leader at its
    head: the followers stand behind the leader on the backward extension of its own path, each farther from
    the goal than its predecessor, facing it, all at rest: the chain is intact. (With a given ``start`` the
    leader stands there and the chain behind it along a free path that leads away from the goal.) A goal
    without such cells is drawn again (4 goals; a generated map is drawn anew up to 3 times); when all of
    them lie too central, the goal is drawn (from the same stream) among the goals known to leave room for
    the chain, so that a floor that holds the chain holds it for every seed (on generated floors, up to 16
    more are drawn until one holds it). A chain its floor cannot hold
    is refused with a ``ValueError`` (``ChainDoesNotFit``) naming the largest ``n_robots`` the floor holds:
    at construction for a fixed floor (``scene="map"`` or ``layout_seed >= 0``, without ``start``/``goal``),
    else at ``reset`` when none of the floors drawn holds it. Obstacles drop when the
    leader has covered random fractions (0.15-0.7) of the path, onto the path 1.2-3 m ahead of it, only
    where at least a robot's width stays free beside them.

    With ``scene_distribution="robust"`` (default ``"off"``) each episode first draws its floor and its number
    of dropped obstacles from :data:`agri_envs.chain.distribution.ROBUST` (office floors of 14-24 x 9-14 m
    with 2-4 rooms a side, greenhouses of 2-8 rows of 6-20 m, 0-12 obstacles), with the episode's own
    Generator; ``env.episode_config`` holds the episode's arguments. A drawn floor that holds no chain of
    ``n_robots`` is drawn again (8 floors, then the refusal above). The arguments it draws cannot be given
    beside it, nor ``scene="map"``, a ``layout_seed`` or a ``start``/``goal``. The world holds the most
    obstacles any episode drops (the state's obstacle part has that size), parking those it does not drop.

    ## Episode End

    Success (every agent terminates): every robot k is within ``R_k`` of the goal (straight distance) at
    the same step, and so far no robot has touched anything and no gap has exceeded Delta. The leader's
    arrival (within ``goal_radius``) does not end the episode: the followers close up behind it while it
    holds at the goal. Failure (every agent terminates): any robot touches anything
    (``terminate_on_collision``) or any gap exceeds Delta (``terminate_on_break``). Every agent is truncated
    after ``max_cycles`` steps.

    ## Info

    Per agent: true ``x``, ``y``, ``yaw``, ``v``, ``w``, ``collision`` (this robot touched something this
    step). Shared by all agents: ``is_success``, ``leader_at_goal``, ``robots_at_goal`` (robots within their
    arrival radius), ``chain_intact`` (no gap above Delta this step), ``collisions`` (robot contacts so far),
    ``max_gap`` (m, this episode), ``mean_strip_distance`` and ``max_strip_distance`` (m, this episode),
    ``leader_path_length``, ``astar_length`` (m), ``path_ratio``, ``episode_time`` (s), ``distance_to_go``
    (``-Phi``, m) and the reward terms.

    ## Arguments

    Every argument is a field of :class:`RobotChainConfig`; unknown names and values out of range raise
    ``ValueError`` naming the argument and its valid range. Example::

        env = robot_chain_v1.parallel_env(n_robots=8, scene="greenhouse", n_dynamic_obstacles=2)

    ## Baselines

    ``apoorva-chain`` (A* + ghost + sonar potential field + elastic strip along the leader's trail), and its
    ablations ``apoorva-chain-alg6`` (the printed strip) and ``apoorva-chain-no-strip``; the learned
    ``ppo-chain`` (one network shared by every robot).

    ## Version History

    * v1: the paper's task. Success needs every robot at the goal (robot k within
      ``goal_radius + k * arrival_stretch * spacing``), with no contact and no gap above Delta at any step;
      the episode goes on after the leader arrives; a gap above Delta ends it (``terminate_on_break``). The
      start is always an intact chain standing on the backward extension of the leader's path: no more
      packed starts, a chain that does not fit raises ``ValueError``. The goal is drawn first, then the
      chain's place; ``reset(options={"goal_distance": (lo, hi)})`` draws short missions (training
      curricula). New observation (29 values):
      neighbours' relative velocities, the follower's slot on its predecessor's trail, the goal as a
      direction and a distance; the strip distance and the map-sized goal vector are gone. New reward:
      progress of every robot toward arriving (free-floor distance, round dropped obstacles), per-episode
      penalty budgets, a contact or break forfeits the rest of the episode, ordered as stated above.
      Resets reuse fixed maps, the robots' bodies and the world, and search the free floor with a
      bucket-queue Dijkstra (about 10x faster). v0 is gone (no code kept: its task, spaces and reward all
      changed, and its leaderboard entries with it). Later, without a version change (every episode that
      started before starts the same): a reset whose random goals all lie too central falls back to goals
      known to fit, where it raised before (8 robots on the example map: 13 of 500 seeds); a chain the floor
      cannot hold is refused naming the largest ``n_robots`` it holds, up front for a fixed floor. New argument
      ``scene_distribution`` (default ``"off"``: every episode as before), ``"robust"`` drawing floors and
      obstacles per episode.
    * v0: initial release (success when the leader arrived with the chain intact at that moment).

    ## References

    Apoorva, R. Gautam and R. Kala, "Motion Planning for a Chain of Mobile Robots Using A* and Potential
    Field", Robotics 7(2):20, 2018.
    """

    metadata: dict[str, Any] = {
        "name": "robot_chain_v1",
        "render_modes": ["rgb_array", "human"],
        "render_fps": 10,
        "is_parallelizable": True,
        "episode_metric_keys": (
            "collision",
            "collisions",
            "leader_at_goal",
            "robots_at_goal",
            "chain_intact",
            "episode_time",
            "leader_path_length",
            "astar_length",
            "path_ratio",
            "mean_strip_distance",
            "max_strip_distance",
            "max_gap",
            "distance_to_go",
        ),
        "trace_keys": ("positions", "mean_strip_distance_now", "max_gap_now", "ghost_x", "ghost_y"),
    }

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        self.config = RobotChainConfig.from_kwargs(kwargs)
        cfg = self.config
        self.robot_radius = cfg.robot_radius
        self.possible_agents = [f"robot_{k}" for k in range(cfg.n_robots)]
        self.agents: list[str] = []
        #: The robots' body (kept under the name ``spec`` that earlier versions used).
        self.spec = robot.body_spec(cfg)
        self.sonars = robot.sonar_array(cfg)
        self.observation = ChainObservation(cfg, self.sonars)
        self.trails = Trails(cfg.n_robots, cfg.spacing)
        self._act_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self._inflation = cfg.robot_radius + cfg.planning_margin
        self._fixed_map: ChainMap | None = None  # a loaded map, or the generated one of a fixed layout_seed
        self._fixed_reach: FloorReach | None = None  # how long a chain the fixed map holds (when first needed)
        #: The distribution each episode's floor and obstacles are drawn from (None: the arguments' own).
        self.distribution = cfg.distribution()
        #: The arguments of the current episode: the config, with the floor drawn from the distribution if any.
        self.episode_config = cfg
        if self.distribution is not None:
            self.distribution.refuse_given(kwargs, f"robot_chain_v1: scene_distribution={cfg.scene_distribution!r}")
        largest = largest_scenes(self.distribution, cfg)
        #: Obstacles the world holds: the most any episode drops.
        self.n_obstacle_bodies = max(c.n_dynamic_obstacles for c in largest)
        if cfg.scene == "map":
            self._fixed_map = ros_map(cfg.map_yaml, self._inflation)
            canvas = self._fixed_map.geometry.bounds
        else:
            canvas = enclosing_bounds(_floor_bounds(c) for c in largest)
        if cfg.layout_seed >= 0 and cfg.scene != "map":
            self._draw_map(None)  # the fixed layout, made once (it draws nothing from the episode's stream)
        if self._fixed_map is not None and not cfg.start and not cfg.goal:
            # Knowable here: a chain its fixed floor cannot hold is refused now, not at some reset.
            reach = self._reach(self._fixed_map)
            if reach.max_robots(cfg) < cfg.n_robots:
                raise does_not_fit(cfg, [reach], None, generated=False)
        self.view = SceneView(render_mode, canvas, cfg.render_width, self.metadata["render_fps"])
        self.render_mode = render_mode
        self.world: World2D | None = None
        self.chain_map: ChainMap | None = None
        self.task: ChainTask | None = None
        self._radii = np.array(cfg.arrival_radii())
        self._excess = np.zeros(cfg.n_robots)
        n_dyn = self.n_obstacle_bodies
        self.state_space = spaces.Box(-np.inf, np.inf, (5 * cfg.n_robots + 4 + 3 * n_dyn,), np.float32)

    # -- spaces ----------------------------------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Box:
        """The observation space, the same object for every agent (parameter sharing)."""
        return self.observation.space

    def action_space(self, agent: str) -> spaces.Box:
        """The action space, the same object for every agent."""
        return self._act_space

    @property
    def map_bounds(self) -> np.ndarray:
        """``(xmin, ymin, xmax, ymax)`` of the current map (m): observation 8-9 is the position scaled by it."""
        if self.chain_map is None:
            raise RuntimeError("call reset() first")
        return self._bounds.copy()

    @property
    def path(self) -> Polyline:
        """The leader's path of this episode (m)."""
        if self.task is None:
            raise RuntimeError("call reset() first")
        return self.task.path

    @property
    def goal(self) -> np.ndarray:
        """The goal (m), the last point of :attr:`path`."""
        if self.task is None:
            raise RuntimeError("call reset() first")
        return self.task.goal

    @property
    def arrival_radii(self) -> np.ndarray:
        """``(n,)`` robot k has arrived within ``arrival_radii[k]`` of the goal (m)."""
        return self._radii.copy()

    def observation_layout(self) -> dict[str, Any]:
        """Where things sit in an observation and how to scale them back (for scripted policies)."""
        return self.observation.layout()

    def close(self) -> None:
        """Release the renderer and the pymunk world (idempotent; ``reset()`` builds a new world)."""
        self.view.close(self.world)
        self.world = None

    # -- episode set-up --------------------------------------------------------------------------------
    def _draw_map(self, rng: np.random.Generator | None) -> ChainMap:
        """The episode's map: the fixed one, or a new one drawn with ``rng`` (unused with a fixed layout_seed)."""
        cfg = self.episode_config
        if self._fixed_map is not None:
            return self._fixed_map
        layout_rng = rng if cfg.layout_seed < 0 else np.random.default_rng(cfg.layout_seed)
        assert layout_rng is not None
        if cfg.scene == "office":
            cmap = office_map(cfg.office_params(), layout_rng, self._inflation, cfg.map_resolution)
        else:
            cmap = greenhouse_map(cfg.greenhouse_params(), layout_rng, self._inflation, cfg.map_resolution)
        if cfg.layout_seed >= 0:
            self._fixed_map = cmap  # the same map every episode: made once
        return cmap

    def _reach(self, cmap: ChainMap) -> FloorReach:
        """How long a chain ``cmap`` holds (computed once for a fixed map)."""
        if cmap is not self._fixed_map:
            return floor_reach(cmap, self.episode_config)
        if self._fixed_reach is None:
            self._fixed_reach = floor_reach(cmap, self.config)
        return self._fixed_reach

    def _plan(
        self, rng: np.random.Generator, goal_distance: tuple[float, float] | None
    ) -> tuple[ChainMap, Mission]:
        """Map and mission of an episode: random goals first, then goals known to fit the chain.

        Random goals on each generated map (drawn anew up to ``LAYOUT_TRIES`` times) come first, as they
        always did, so that an episode that found room this way stays the same. When every one of them lies
        too central, a goal is drawn (from the same stream) among those known to leave room for the chain,
        on the maps tried in turn, then on up to ``FALLBACK_LAYOUTS`` new generated ones: a floor that holds
        the chain holds it for every seed.

        Raises:
            ChainDoesNotFit: When none of the floors holds the chain; the message names the largest
                ``n_robots`` they hold.
        """
        cfg = self.episode_config
        tried: list[ChainMap] = []
        for attempt in range(LAYOUT_TRIES):
            cmap = self._draw_map(rng)
            try:
                return cmap, plan_mission(cmap, cfg, rng, goal_distance)
            except ChainDoesNotFit:
                last = self._fixed_map is not None or attempt == LAYOUT_TRIES - 1
                if (cfg.start or cfg.goal) and last:  # a given start or goal: no other goal to fall back to
                    raise
                tried.append(cmap)
                if self._fixed_map is not None:
                    break
        reaches = []
        generated = self._fixed_map is None
        for k in range(len(tried) + (FALLBACK_LAYOUTS if generated else 0)):
            cmap = tried[k] if k < len(tried) else self._draw_map(rng)  # then new floors, as long as none holds it
            reaches.append(reach := self._reach(cmap))
            mission = fallback_mission(cmap, cfg, rng, goal_distance, reach)
            if mission is not None:
                return cmap, mission
        raise does_not_fit(cfg, reaches, goal_distance, generated=generated)

    def _plan_episode(
        self, rng: np.random.Generator, goal_distance: tuple[float, float] | None
    ) -> tuple[ChainMap, Mission]:
        """The episode's arguments (drawn, under a distribution), map and mission.

        Under a distribution, a drawn floor that holds no chain of ``n_robots`` is drawn again (from the same
        stream), up to ``SCENE_TRIES`` times; the last refusal is raised.
        """
        if self.distribution is None:
            return self._plan(rng, goal_distance)
        for _ in range(SCENE_TRIES - 1):
            self.episode_config = self.config.replace(**self.distribution.sample(rng)[1])
            try:
                return self._plan(rng, goal_distance)
            except ChainDoesNotFit:
                pass
        self.episode_config = self.config.replace(**self.distribution.sample(rng)[1])
        return self._plan(rng, goal_distance)  # the last floor: its refusal is the episode's

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """New map (unless fixed), goal, start, path, chain placement and obstacle schedule.

        Args:
            seed: Seed of the episode's random stream.
            options: ``{"goal_distance": (lo, hi)}`` draws this episode's leader start between ``lo`` and
                ``hi`` metres from the goal along the free floor (a training curriculum's short missions)
                instead of at least ``min_goal_distance``. Other keys are ignored (PettingZoo's API test
                passes one).

        Raises:
            ValueError: When the chain does not fit behind any start tried (the message says what to change),
                or for a malformed ``goal_distance``.
        """
        goal_distance = None
        if options and "goal_distance" in options:
            try:
                lo, hi = (float(v) for v in options["goal_distance"])
            except (TypeError, ValueError):
                raise ValueError(
                    f"reset: options['goal_distance'] must be (lo, hi) in metres, got {options['goal_distance']!r}"
                ) from None
            if not (0.0 <= lo <= hi):
                raise ValueError(f"reset: options['goal_distance'] needs 0 <= lo <= hi, got ({lo}, {hi})")
            goal_distance = (lo, hi)
        if seed is not None or not hasattr(self, "np_random"):
            self.np_random = np.random.default_rng(seed)
        cfg = self.config
        rng = self.np_random
        cmap, mission = self._plan_episode(rng, goal_distance)
        episode = self.episode_config
        self.chain_map = cmap
        xmin, ymin, xmax, ymax = cmap.geometry.bounds
        self._bounds = np.array([xmin, ymin, xmax, ymax])
        ox, oy, oyaw = cmap.grid.origin
        self._frame = np.array([ox, oy, math.cos(oyaw), math.sin(oyaw), cmap.grid.resolution])
        self._window = int(math.ceil(self._inflation / cmap.grid.resolution)) + 2
        self._to_goal = mission.to_goal
        self._blocked = cmap.blocked
        gi, gj = (int(v) for v in mission.path_cells[-1])
        self._goal_cell = (gi, gj)
        self._goal_xy = mission.path.points[-1].copy()
        finite = mission.to_goal[np.isfinite(mission.to_goal)]
        self._far = float(finite.max()) + 1.0
        positions = mission.positions
        self.astar_cells = mission.path_cells
        self.astar_length = mission.astar_length
        yaw = mission.start_yaws()
        poses = np.column_stack([positions, yaw])
        if self.world is None:
            self.world = World2D(cmap.geometry, n_movers=self.n_obstacle_bodies)
            self.robots = self.world.add_disc_robots(self.spec, poses, cfg.robot_radius)
        else:  # the same bodies, in the new scene (nothing to do for a fixed map)
            self.world.set_scene(cmap.geometry)
            self.world.place_robots(self.robots, poses)
        for k in range(self.n_obstacle_bodies):
            self.world.place_mover(k, _PARK + 10.0 * k, _PARK, cfg.obstacle_radius)
        self._robot_rows = np.array([r.circle_index for r in self.robots], dtype=np.int64)
        task = ChainTask(
            mission.path,
            cfg.ghost_params(),
            cfg.weights(),
            cfg.control_period,
            cfg.goal_radius,
            cfg.max_cycles,
            cfg.terminate_on_collision,
            cfg.terminate_on_break,
        )
        self._poses = poses
        self._vel = np.zeros((cfg.n_robots, 2))
        self.trails.reset(mission.formation, cfg.spacing)
        arrived = self._to_go()
        task.reset(positions[0], -float(self._excess.mean()))
        task.arrived = arrived
        self.task = task
        # Obstacle schedule: drop k when the leader has covered fraction f_k of the path.
        self._drop_at = np.sort(rng.uniform(0.15, 0.7, episode.n_dynamic_obstacles)) * self.astar_length
        self._next_drop = 0
        self._n_dropped = 0
        self.agents = list(self.possible_agents)
        self._steps = 0
        self._cmd_scale = np.array([cfg.max_speed, cfg.max_turn_rate])
        self._leader_path = 0.0
        self._trail = [self._poses[0, :2].copy()]
        self._last_collided = np.zeros(cfg.n_robots, dtype=bool)
        obs = self._observe()
        task.max_gap = float(self.observation.stats[2])
        infos = self._infos()
        if self.render_mode == "human":
            self.render()
        return obs, infos

    # -- stepping --------------------------------------------------------------------------------------
    def step(
        self, actions: dict[str, Any]
    ) -> tuple[dict[str, np.ndarray], dict[str, float], dict[str, bool], dict[str, bool], dict[str, dict[str, Any]]]:
        """Apply every agent's ``[v, omega]`` for one control period (robots move in chain order)."""
        if self.world is None or self.task is None:
            raise RuntimeError("call reset() before step()")
        if not self.agents:
            raise RuntimeError("the episode is over: call reset()")
        cfg = self.config
        dt = cfg.control_period
        cmd = checked_agent_actions(actions, self.agents, 2)
        cmd *= self._cmd_scale
        world, task = self.world, self.task
        if self._next_drop < len(self._drop_at) and task.ghost.s_leader >= self._drop_at[self._next_drop]:
            self._drop_obstacle()
        poses = self._poses
        lx, ly = poses[0, 0], poses[0, 1]
        collided = world.drive_discs(self.robots, cmd, dt, poses, self._vel)
        self._steps += 1
        self._leader_path += math.hypot(poses[0, 0] - lx, poses[0, 1] - ly)
        if self.render_mode is not None:
            self._trail.append(poses[0, :2].copy())
        self._last_collided = collided
        self.trails.record(poses)
        task.move_ghost(poses[0, :2])
        obs = self._observe()
        arrived = self._to_go()
        outcome = task.evaluate(
            poses[0, :2],
            int(collided.sum()),
            self.observation.stats.tolist(),
            -float(self._excess.mean()),
            arrived,
            cfg.n_robots,
        )
        terminated = bool(outcome["terminated"])
        truncated = (not terminated) and self._steps >= cfg.max_cycles
        infos = self._infos()
        agents = self.agents
        rewards = dict.fromkeys(agents, outcome["reward"])
        terminations = dict.fromkeys(agents, terminated)
        truncations = dict.fromkeys(agents, bool(truncated))
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminations, truncations, infos

    def _to_go(self) -> int:
        """Fill each robot's free-floor distance beyond its arrival radius; return how many have arrived."""
        assert self.chain_map is not None
        return int(
            distances_to_go(
                self._poses,
                self._to_goal,
                self._blocked,
                self._frame,
                self._window,
                self._far,
                self._goal_xy,
                self._radii,
                self._excess,
            )
        )

    def _drop_obstacle(self) -> None:
        """Drop the next scheduled obstacle onto the path ahead of the leader (retried each step until it fits)."""
        assert self.world is not None and self.task is not None and self.chain_map is not None
        cfg = self.episode_config
        spot = drop_spot(self.chain_map, cfg, self.task.path, self.task.ghost.s_leader, self._poses)
        if spot is not None:
            self.world.place_mover(self._next_drop, float(spot[0]), float(spot[1]), cfg.obstacle_radius)
            self._next_drop += 1
            self._n_dropped += 1
            # The free-floor distance to go now runs round the obstacle (the robots' centres stay a robot
            # radius from it); the path and the ghost keep the plan made on the static map.
            blocked = block_disc(self.chain_map, self._blocked, spot, cfg.obstacle_radius + cfg.robot_radius)
            field = distance_field(blocked, self._goal_cell) * self.chain_map.grid.resolution
            if np.isfinite(field[self.chain_map.cell(self._poses[0, :2])]):
                self._blocked, self._to_goal = blocked, field

    # -- observations, infos, state -------------------------------------------------------------------
    def _observe(self) -> dict[str, np.ndarray]:
        assert self.world is not None and self.task is not None
        obs = self.observation(
            self._poses,
            self._vel,
            self.world,
            self._robot_rows,
            self.task.ghost_xy,
            self.task.ghost_velocity,
            self.trails,
            self.task.goal,
            self._bounds,
            self.np_random,
        )
        return dict(zip(self.agents, obs, strict=True))

    def _infos(self) -> dict[str, dict[str, Any]]:
        task = self.task
        assert task is not None
        stats = self.observation.stats
        gx, gy = task.ghost_xy
        shared = {
            "is_success": bool(task.success),
            "leader_at_goal": bool(task.leader_arrived),
            "robots_at_goal": int(task.arrived),
            "chain_intact": bool(stats[3] == 0),
            "collisions": int(task.collisions),
            "max_gap": float(task.max_gap),
            "mean_strip_distance": float(task.strip_sum / task.strip_count) if task.strip_count else 0.0,
            "max_strip_distance": float(task.strip_max),
            "leader_path_length": float(self._leader_path),
            "astar_length": float(self.astar_length),
            "path_ratio": float(self._leader_path / self.astar_length) if self.astar_length > 0 else 1.0,
            "episode_time": self._steps * self.config.control_period,
            "distance_to_go": -float(task.potential),
            "ghost_x": gx,
            "ghost_y": gy,
            "mean_strip_distance_now": float(stats[0]),
            "max_gap_now": float(stats[2]),
        }
        for name, value in task.terms.items():
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
        if self.world is None or self.task is None:
            raise RuntimeError("call reset() before state()")
        parts = [
            np.hstack([self._poses, self._vel]).ravel(),
            self.task.ghost.point,
            self.task.goal,
            self.world.mover_circles.ravel(),
        ]
        return np.concatenate(parts).astype(np.float32)

    # -- rendering ---------------------------------------------------------------------------------------
    def render(self) -> np.ndarray | None:
        """Top-down frame: map, A* path, ghost, goal, strip, robots with sonar cones (``rgb_array``/``human``)."""
        return self.view.render(
            None if self.world is None or self.chain_map is None else self.chain_map.geometry, self._draw
        )

    def _draw(self, rd: TopDownRenderer) -> list[str]:
        assert self.world is not None and self.task is not None
        cfg = self.config
        rd.polyline(self.task.path.points, (200, 60, 60), 1)
        rd.path(np.array(self._trail))
        movers = self.world.mover_circles
        rd.circles(movers[movers[:, 0] < _PARK / 2], Kind.OBSTACLE)
        p = self._poses
        if len(p) >= 3:
            rd.polyline(np.array([p[0, :2], p[-1, :2]]), (150, 60, 200), 2)
        for k in range(len(p)):
            rd.cones(self.sonars.poses_in_world(p[k]), self.observation.last_sonar[k], cfg.sonar_aperture)
        rd.round_robots(p, self.robot_radius)
        g = self.task.ghost.point
        rd.ring(float(g[0]), float(g[1]), 0.12, (120, 120, 255))
        rd.ring(float(self.task.goal[0]), float(self.task.goal[1]), cfg.goal_radius, (30, 160, 30))
        t, task = self._steps * cfg.control_period, self.task
        return [f"t = {t:5.1f} s   robots {len(p)}   collisions {task.collisions}   max gap {task.max_gap:.2f} m"]
