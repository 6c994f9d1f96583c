"""GreenhouseNav-v2: waypoint navigation of a LIDAR rover between greenhouse rows (Harik 2018)."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agri_envs.rover import robot as rover
from agri_envs.rover.config import GreenhouseNavConfig
from agri_envs.rover.task import WaypointTask, mission_time_limit
from agri_envs.scenes.distribution import largest_scenes
from agri_envs.scenes.greenhouse import LayoutParams, generate_layout
from agri_envs.scenes.layout import Layout, LayoutCache
from agri_envs.scenes.office import CorridorParams, generate_office_corridor
from agri_envs.scenes.rosmap import layout_from_map, map_geometry
from agri_envs.sim2d.crowd import Crowd, CrowdSpec
from agri_envs.sim2d.geometry import Kind, enclosing_bounds
from agri_envs.sim2d.gridmap import rasterize
from agri_envs.sim2d.odometry import WheelOdometry
from agri_envs.sim2d.render import TopDownRenderer
from agri_envs.sim2d.sensors import Lidar, SonarArray, hc_sr04, tim561
from agri_envs.sim2d.view import SceneView
from agri_envs.sim2d.world import World2D

__all__ = ["GreenhouseNavConfig", "GreenhouseNavEnv", "SyncTimeLimit"]


class GreenhouseNavEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """Drive a LIDAR rover through a waypoint loop between greenhouse rows, among walking people.

    ## Description

    The robot of Harik & Korsæth (2018), a 0.6 x 0.5 m four-wheel skid-steer base driven as a unicycle
    (eq. 1), must visit an ordered list of waypoints in a greenhouse: by default the paper's loop
    0 -> 1 -> ... -> 7 -> 0, a serpentine through every corridor between three rows of plants. Walls,
    structural posts, plants (which grow with ``growth`` and reach into the corridors with their leaves),
    optional trees and walking people are obstacles. The world is a top-view pymunk space; robot motion
    is substepped near obstacles so that it never tunnels through them.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: ``[u, r]``, the commanded linear and angular velocity, scaled by
    ``max_speed`` (forward; half of it backward) and ``max_turn_rate``. The achieved velocities follow
    within the acceleration limits. Actions outside the box are clipped; NaN or inf raises ``ValueError``.

    ## Observation Space

    A ``Dict`` of float32 boxes (ranges normalised by the sensor's maximum range):

    | key | shape | bounds | meaning |
    |---|---|---|---|
    | ``lidar`` | (lidar_beams,) | [0, 1] | LIDAR ranges / 10 m, min-pooled over equal sectors of the 270 deg scan |
    | ``sonar`` | (6,) | [0, 1] | sonar ranges / 4 m: front, left front, left rear, back, right rear, right front |
    | ``velocity`` | (2,) | [-1, 1] | achieved ``u / max_speed`` and ``r / max_turn_rate`` |
    | ``waypoint`` | (3,) | [0, 1] x [-1, 1]^2 | d / diagonal, sin(alpha), cos(alpha) from the estimated pose (1) |
    | ``next_waypoint`` | (3,) | [0, 1] x [-1, 1]^2 | the same for the waypoint after it (the last one: itself) (1) |
    | ``target`` | (2,) | [-1, 1] | current waypoint in the robot's start frame / diagonal (2) |
    | ``scan`` | (811,) | [0, 1] | full-resolution scan / 10 m (only when ``full_scan=True``) |

    (1) absent when ``localization="none"``; (2) only when ``localization="none"``. ``diagonal`` is the
    greenhouse's inner diagonal (m).

    ## Sensors

    SICK TiM561 LIDAR at the lower front (270 deg, 811 beams at 0.33 deg, 0.05-10 m, 15 Hz, Gaussian
    noise ``lidar_noise_std``, dropouts ``lidar_dropout`` returning max range); six HC-SR04 sonars (two
    per side, one front, one back; 0.02-4 m; each reports the nearest echo inside its 15 deg cone).
    Localization: ``ground_truth`` (the true pose), ``odometry`` (wheel odometry with relative speed
    noise and a per-episode gyro bias: it drifts), or ``none`` (no pose at all: the policy must estimate it,
    e.g. with Hector SLAM on the full scan).

    ## Rewards

    ``reward = progress + waypoint + success + collision + clearance + time`` with

    | term | formula |
    |---|---|
    | ``reward_progress`` | ``reward_progress * (g_prev - g)``, g = d + (max_speed / max_turn_rate) * abs(alpha) |
    | ``reward_waypoint`` | ``+reward_waypoint`` when a waypoint is reached |
    | ``reward_success`` | ``+reward_success`` when the last one is reached |
    | ``reward_collision`` | ``-(reward_collision + (T - t) * reward_time)`` on contact at step t (1) |
    | ``reward_clearance`` | ``-reward_clearance * s * ds``, s = ``max(0, safety_margin - clearance) / safety_margin`` |
    | ``reward_time`` | ``-reward_time`` every step |

    (1) T is the step limit in force (see Episode End); g is the distance to go to the current waypoint
    (d its true distance, alpha its true bearing): a turn toward the waypoint counts as the metres the
    robot could drive in the time the turn takes; ``ds`` is the distance the robot drove in the step
    (m). Each term is reported in ``info`` under its name. Why the weights are what they are:

    * **A crash always costs more than any way of avoiding it.** The cheapest way to avoid a crash is to
      stop and wait: a robot that stands still drives no metres, so it pays only the time penalty of the
      steps left. The crash costs exactly that plus a fixed 20, whatever the mission, its time limit and
      the moment of the crash (20 + 24.6 at the start of the default mission). In v1 the crash also carried
      a whole episode of clearance penalty (137.7 on the default scene); PPO then learned to stand still
      in three 1.2M-step runs.
    * **Safety margins matter.** Inside ``safety_margin`` (0.25 m, about half the free space on either
      side of the robot in a default corridor) every metre driven costs up to 6, twice the progress it
      earns: driving past an obstacle closer than half the margin loses more than the progress gains, so
      hugging a row or cutting a corner at 5 cm never pays. The penalty is per metre, not per step, so
      that waiting for a person to step aside costs nothing but time.
    * **Progress drives the task.** 3 per metre of distance to go (a potential difference, so driving or
      turning back and forth earns nothing; with distance alone, PPO stopped at the first waypoint, where
      the next one lies 90 deg to the side and turning earned nothing), 1 per waypoint and 10 for the
      whole mission: the default loop returns about 129 when driven well (with 1 per metre PPO learned to
      stand still).
    * **Waiting costs.** 0.01 per step (24.6 over the default time limit): a twelfth of what a step at full
      speed earns (0.12), enough that standing still is a place to wait for a person to step aside, never
      to rest (at 0.002 per step PPO stopped for good at the first hard turn in six runs); a crash still
      costs 20 more than waiting out the limit (see the first point).

    ## Starting State

    The robot stands at waypoint 0 facing waypoint 1, with a uniform jitter of +-5 cm and +-0.1 rad; people
    start on their routes at least 3 m away. With ``layout_seed=-1`` the plant jitter, leaves and trees
    are drawn anew from the episode seed; otherwise they come from ``layout_seed`` (the same greenhouse
    every episode). ``reset(options={"growth": g, "n_trees": k, "layout_seed": s})`` overrides these
    three scene arguments for one episode. ``reset(options={"start_waypoint": k})`` starts the mission at
    waypoint k instead: the robot stands on waypoint k - 1 facing along the leg that led there (same
    jitter), waypoints before k count as reached, and the time limit covers the rest of the route (a
    training curriculum; evaluation always starts at 0); ``"start_waypoint": "random"`` draws k from
    1 .. n - 1 with the episode's Generator, once the mission (and its length n) is known.

    With ``scene_distribution="training"`` (default ``"off"``) each episode first draws its scene from the
    env's training distribution (:data:`agri_envs.rover.distribution.TRAINING`), with the episode's own
    Generator: a family (greenhouse 60 %, office corridor 40 %), then each of its arguments from its range
    (greenhouse: ``n_rows`` 2..4, ``row_length`` [4, 8] m, ``corridor_width`` [1.1, 1.5] m, ``growth``
    [0, 1], ``n_trees`` 0..8, ``n_people`` 0..3, ``people_tease_prob`` [0, 0.6]; corridor: ``office_length``
    [10, 18] m, ``office_width`` [1.3, 1.8] m, either ``office_route``, ``mission_cycles`` 1..3, ``n_people``
    0..1, ``people_tease_prob`` [0, 0.6]). The drawn arguments replace the config's for that episode
    (``env.unwrapped.episode_config``; reset options still apply on top); the distance scale of the
    observation is the drawn scene's diagonal, as it would be in an env made with those arguments. The
    arguments it draws cannot also be given to ``gym.make``. Training uses seeds below 100000; held-out
    suites (100000 and up) run the plain env, and ``greenhouse-generalization`` lies outside every range.
    ``scene_distribution="robust"`` (:data:`agri_envs.rover.distribution.ROBUST`) widens it along the stress
    suites' axes and also draws the robot's ``max_speed`` (0.6-1.4 m/s) per episode; the observation's
    velocity and the action are then scaled by the drawn limit. Its draws need the single env
    (``gym.make_vec`` with ``vectorization_mode="sync"``): the batched form keeps one robot for all sub-envs.

    ## Episode End

    Terminated when the last waypoint is reached (success) or, with ``terminate_on_collision``, when the
    robot touches an obstacle or a person. Truncated at the time limit, which by default follows the
    mission: the route from the start through every waypoint (all ``mission_cycles``) driven at
    ``time_limit_speed_fraction`` (0.5) of ``max_speed``, plus its corners turned at the same fraction of
    ``max_turn_rate``, plus ``time_limit_wait`` (6 s) per person per cycle for people standing in the way.
    The default scene gets 2,455 steps (163.7 s); ``harik-apf-gt`` needs about 1,700. An explicit
    ``gym.make(..., max_episode_steps=N)`` wins over the computed limit. ``info["max_episode_steps"]``
    always gives the limit in force; the truncating step sets ``info["truncated"]`` and explains it in
    ``info["truncation_reason"]``.

    With ``frame_skip`` k > 1 (ALE's frameskip) each step holds the action for k control periods and
    observes once, at the end; its reward and the ``reward_*`` terms in ``info`` are sums over the periods,
    and it stops early at the period that ends the episode. Time limits and ``info["max_episode_steps"]``
    count control periods; an explicit ``max_episode_steps=N`` means N steps, that is N * k periods. Training
    with a held action uses it to skip the observations nobody reads (``agri train``'s ``action_repeat``).

    ## Info

    ``is_success``, ``collision``, ``clearance`` (m), ``min_clearance`` (m, over the episode),
    ``waypoint_index``, ``waypoints_reached``, ``n_waypoints``, ``distance_to_waypoint`` (m),
    ``bearing_to_waypoint`` (rad), true pose ``x``, ``y``, ``yaw``, estimated pose ``est_x``, ``est_y``,
    ``est_yaw`` (equal to the true one under ``ground_truth``, absent under ``none``), ``v``, ``w``,
    ``path_length`` (m), ``episode_time`` (s), ``max_episode_steps`` (the limit in force), ``truncated``,
    ``truncation_reason`` (only on the truncating step) and the reward terms.

    ## Arguments

    Every argument is a field of :class:`GreenhouseNavConfig`; unknown names and values out of range raise
    ``ValueError`` naming the argument and its valid range.

    | argument | default | unit | valid | meaning |
    |---|---|---|---|---|
    | ``scene`` | 'greenhouse' |  | one of 'greenhouse', 'corridor', 'map' | kind of scene |
    | ``map_yaml`` | '' |  | YAML path, e.g. EXAMPLE_MAP | ROS map_server map to load (scene='map') |
    | ``waypoints`` | () | m | >= 2 (x, y) | loop of waypoints in the map frame (scene='map'; () takes the map YAML's) |
    | ``n_rows`` | 3 |  | in [1, 12] | rows of plants |
    | ``row_length`` | 6 | m | in [2.0, 40.0] | length of each row |
    | ``corridor_width`` | 1.2 | m | in [0.8, 3.0] | free width between rows (and between outer rows and walls) |
    | ``row_width`` | 0.4 | m | in [0.2, 1.5] | width of a row bed |
    | ``headland`` | 1.8 | m | in [1.2, 5.0] | free space between row ends and the end walls |
    | ``plant_spacing`` | 0.4 | m | in [0.15, 2.0] | distance between plants along a row |
    | ``plant_jitter`` | 0.03 | m | in [0.0, 0.1] | uniform jitter of plant positions |
    | ``growth`` | 0 |  | in [0.0, 1.0] | season: plant size and leaves reaching into corridors |
    | ``post_spacing`` | 3 | m | in [1.0, 20.0] | distance between structural posts along rows and walls |
    | ``n_trees`` | 0 |  | in [0, 50] | trees placed at random plant positions (Harik Fig. 10) |
    | ``layout_seed`` | -1 |  | in [-1, 2147483647] | seed of the scene layout; -1 draws a new layout every episode |
    | ``scene_distribution`` | 'off' |  | one of 'off', 'training', 'robust' | per-episode scenes (see Starting State) |
    | ``office_length`` | 14 | m | in [6.0, 60.0] | corridor length (scene='corridor') |
    | ``office_width`` | 1.6 | m | in [1.0, 4.0] | corridor width (scene='corridor') |
    | ``office_route`` | 'experiment' |  | one of 'experiment', 'repeatability' | corridor mission: Harik 3.4 or 3.5 |
    | ``n_people`` | 2 |  | in [0, 20] | people walking the corridors and headlands |
    | ``people_tease_prob`` | 0.3 |  | in [0.0, 1.0] | chance that a person stands in the robot's way for a while |
    | ``max_speed`` | 0.6 | m/s | in [0.1, 2.0] | forward speed limit (reverse: half of it) |
    | ``max_turn_rate`` | 1.2 | rad/s | in [0.2, 4.0] | angular speed limit |
    | ``max_accel`` | 1 | m/s^2 | in [0.1, 10.0] | linear acceleration limit |
    | ``max_angular_accel`` | 3 | rad/s^2 | in [0.1, 20.0] | angular acceleration limit |
    | ``control_period`` | 0.06667 | s | in [0.01, 0.5] | time between actions (the LIDAR's 15 Hz) |
    | ``frame_skip`` | 1 |  | in [1, 16] | control periods per step (action held, observed once at the end) |
    | ``lidar_beams`` | 90 |  | in [1, 811] | LIDAR beams in the observation (min-pooled from the full scan) |
    | ``full_scan`` | False |  | True or False | add the full-resolution 811-beam scan as observation key 'scan' |
    | ``lidar_noise_std`` | 0.02 | m | in [0.0, 0.5] | LIDAR Gaussian range noise (TiM561 statistical error) |
    | ``lidar_dropout`` | 0.01 |  | in [0.0, 0.5] | probability that a LIDAR beam returns no echo (max range) |
    | ``sonar_noise_std`` | 0.01 | m | in [0.0, 0.5] | sonar Gaussian range noise |
    | ``localization`` | 'ground_truth' |  | one of 'ground_truth', 'odometry', 'none' | pose source |
    | ``odometry_noise`` | 0.05 |  | in [0.0, 0.5] | relative std of wheel-odometry speed errors |
    | ``odometry_gyro_bias`` | 0.01 | rad/s | in [0.0, 0.2] | std of the per-episode turn-rate bias of odometry |
    | ``waypoint_radius`` | 0.3 | m | in [0.05, 2.0] | d_min: a waypoint is reached within this distance |
    | ``mission_cycles`` | 1 |  | in [1, 100] | times the mission is driven in one episode (Harik sec. 3.5: 10) |
    | ``terminate_on_collision`` | True |  | True or False | end the episode when the robot touches anything |
    | ``safety_margin`` | 0.25 | m | in [0.0, 1.0] | clearance below which the clearance penalty applies |
    | ``reward_progress`` | 3 |  | in [0.0, 100.0] | weight of progress toward the waypoint (per metre) |
    | ``reward_waypoint`` | 1 |  | in [0.0, 100.0] | bonus per waypoint reached |
    | ``reward_success`` | 10 |  | in [0.0, 1000.0] | bonus when the mission is complete |
    | ``reward_collision`` | 20 |  | in [0.0, 1000.0] | fixed part of the crash penalty (see Rewards) |
    | ``reward_clearance`` | 6 |  | in [0.0, 100.0] | penalty per metre driven at zero clearance (linear in shortfall) |
    | ``reward_time`` | 0.01 |  | in [0.0, 10.0] | penalty per step |
    | ``time_limit_speed_fraction`` | 0.5 |  | in [0.05, 1.0] | time limit: mission at this fraction of speed limits |
    | ``time_limit_wait`` | 6 | s | in [0.0, 120.0] | default time limit: extra time per person per mission cycle |
    | ``render_width`` | 800 | px | in [100, 4000] | width of rendered frames |

    Example::

        env = gym.make("agri_envs/GreenhouseNav-v2", n_rows=4, growth=0.6, n_people=3, full_scan=True)

    Batched: ``gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=64, **kwargs)`` steps 64 of these worlds in one
    compiled loop (:class:`~agri_envs.rover.vector.GreenhouseNavVectorEnv`), each sub-env's episodes bit for bit
    this env's for the same seed and actions, with Gymnasium's autoreset modes and per-sub-env reset options.

    ## Baselines

    ``harik-apf-gt``: the paper's APF controller (eqs. 12-14) on the ground-truth pose (privileged).

    ## Version History

    * v0: initial release.
    * v1: learnable and honest. The time limit follows the mission instead of a fixed 2,250 steps (which
      truncated even ``harik-apf-gt`` with 4 or more rows) and ``info`` says when and why an episode was
      truncated. The crash penalty now exceeds a whole episode of time and clearance penalties (it was 10,
      less than a full episode of time penalty, 11.25); the safety margin grew from 0.15 to 0.25 m and its
      penalty applies over that wider band; progress pays 3 per metre instead of 1; the waypoint bonus fell
      from 2 to 1 and the time penalty from 0.005 to 0.002 per step. New arguments ``time_limit_speed_fraction`` and
      ``time_limit_wait``.
    * v2: the crash penalty is the fixed part (now 20) plus the time penalty of the steps left, instead of
      a whole episode of time and clearance penalties; the clearance penalty is paid per metre driven inside
      the margin (6 per metre at zero clearance) instead of per step (0.05), so that stopping costs only
      time; the time penalty rose from 0.002 to 0.01 per step; progress counts the heading error toward
      the waypoint as distance to go; new observation
      ``next_waypoint`` (the route is known, so a driver can line up for the next leg). With v1's
      penalties PPO learned to stand still. Later, without a version change (the defaults are unchanged):
      the ``frame_skip`` argument; the batched form (``gym.make_vec``) and resets that reuse the pymunk world;
      the ``scene_distribution`` argument (a scene drawn per episode from the training distribution); its
      ``"robust"`` value, which also draws the robot's ``max_speed`` per episode (single envs only).

    ## References

    E. H. C. Harik and A. Korsæth, "Combining Hector SLAM and Artificial Potential Field for Autonomous
    Navigation Inside a Greenhouse", Robotics 7(2):22, 2018.
    """

    metadata = {
        "render_modes": ["rgb_array", "human"],
        "render_fps": 15,
        "episode_metric_keys": (
            "collision",
            "path_length",
            "min_clearance",
            "episode_time",
            "waypoints_reached",
            "n_waypoints",
        ),
        "trace_keys": (
            "x",
            "y",
            "yaw",
            "est_x",
            "est_y",
            "est_yaw",
            "distance_to_waypoint",
            "bearing_to_waypoint",
            "waypoint_index",
            "clearance",
        ),
    }

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        self.config = GreenhouseNavConfig.from_kwargs(kwargs)
        cfg = self.config
        self.robot_spec = rover.rover_spec(cfg.max_speed, cfg.max_turn_rate, cfg.max_accel, cfg.max_angular_accel)
        self.lidar = Lidar(
            tim561(noise_std=cfg.lidar_noise_std, dropout_prob=cfg.lidar_dropout, mount=rover.LIDAR_MOUNT)
        )
        self.sonars = SonarArray(hc_sr04(noise_std=cfg.sonar_noise_std), rover.SONAR_MOUNTS)
        self.odometry = WheelOdometry(cfg.odometry_noise, cfg.odometry_gyro_bias)
        #: The training distribution each episode's scene is drawn from (None: the arguments' own scene).
        self.distribution = cfg.distribution()
        if self.distribution is not None:
            self.distribution.refuse_given(kwargs, f"GreenhouseNav: scene_distribution={cfg.scene_distribution!r}")
        if cfg.scene == "map":
            self._map_geometry = map_geometry(cfg.map_yaml)
        #: The arguments of the current episode: the config, with the scene drawn from the distribution if any.
        self.episode_config = cfg
        self.diagonal = self._extent(cfg)[0]
        # One canvas that holds the largest scene of every family.
        canvas = enclosing_bounds(self._extent(c)[1] for c in largest_scenes(self.distribution, cfg))
        self.view = SceneView(render_mode, canvas, cfg.render_width, self.metadata["render_fps"])
        self.render_mode = render_mode
        n = self.lidar.spec.n_beams
        # Equal sectors of the full scan for min-pooling to `lidar_beams` values.
        self._pool_edges = np.linspace(0, n, cfg.lidar_beams + 1).round().astype(np.int64)[:-1]
        #: The centre angle (rad, LIDAR frame) of each sector the ``lidar`` observation min-pools: where a
        #: controller that reads only the observation places each pooled range.
        self.lidar_sector_angles = np.array(
            [sector.mean() for sector in np.split(self.lidar.spec.beam_angles, self._pool_edges[1:])]
        )
        obs: dict[str, spaces.Space[Any]] = {
            "lidar": spaces.Box(0.0, 1.0, (cfg.lidar_beams,), np.float32),
            "sonar": spaces.Box(0.0, 1.0, (len(self.sonars),), np.float32),
            "velocity": spaces.Box(-1.0, 1.0, (2,), np.float32),
        }
        if cfg.localization == "none":
            obs["target"] = spaces.Box(-1.0, 1.0, (2,), np.float32)
        else:
            polar = spaces.Box(np.array([0, -1, -1], np.float32), np.ones(3, np.float32), dtype=np.float32)
            obs["waypoint"] = polar
            obs["next_waypoint"] = polar
        if cfg.full_scan:
            obs["scan"] = spaces.Box(0.0, 1.0, (n,), np.float32)
        self.observation_space = spaces.Dict(obs)  # type: ignore[assignment]
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.layout: Layout | None = None
        self.world: World2D | None = None
        #: Set by :class:`SyncTimeLimit` from ``gym.make(..., max_episode_steps=N)``; None: sized to the mission.
        self.explicit_max_episode_steps: int | None = None
        self.max_episode_steps = 0
        self.time_limit_source = ""
        self._trail: list[tuple[float, float]] = []
        self._scenes = LayoutCache()  # scenes that never change: fixed layout seeds, the map

    # -- episode set-up --------------------------------------------------------------------------------
    def _extent(self, cfg: GreenhouseNavConfig) -> tuple[float, tuple[float, float, float, float]]:
        """The scene's diagonal (m; it scales waypoint distances) and the canvas that holds it."""
        if cfg.scene == "greenhouse":
            lp = cfg.layout_params()
            return math.hypot(lp.width, lp.height), lp.max_bounds()
        if cfg.scene == "corridor":
            return math.hypot(cfg.office_length, cfg.office_width), cfg.office_params().bounds()
        xmin, ymin, xmax, ymax = self._map_geometry.bounds
        return math.hypot(xmax - xmin, ymax - ymin), (xmin, ymin, xmax, ymax)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Build a new scene and mission, place robot and people (see Starting State)."""
        overrides = dict(options or {})
        start_waypoint = overrides.pop("start_waypoint", 0)
        if start_waypoint != "random" and (
            isinstance(start_waypoint, bool) or not isinstance(start_waypoint, (int, np.integer))
        ):
            raise ValueError(
                f"reset option start_waypoint={start_waypoint!r} ({type(start_waypoint).__name__}) must be an integer "
                "or 'random'"
            )
        # Checked before anything of the env changes, so a bad option leaves the env as it was.
        allowed = ("growth", "n_trees", "layout_seed", "start_waypoint")
        cfg = self.config.with_options(overrides, allowed)
        super().reset(seed=seed)
        if self.distribution is not None:  # the scene of this episode, from the episode's own Generator
            _, drawn = self.distribution.sample(self.np_random)
            cfg = self.config.replace(**drawn).with_options(overrides, allowed)
        layout = self._scene(cfg)
        targets = np.tile(layout.targets, (cfg.mission_cycles, 1))
        if start_waypoint == "random":  # a mission drawn with the scene: its length is known only now
            start_waypoint = int(self.np_random.integers(1, len(targets))) if len(targets) > 1 else 0
        if not 0 <= start_waypoint < len(targets):  # checked before the env's scene is replaced
            raise ValueError(f"reset option start_waypoint must be in [0, {len(targets) - 1}], got {start_waypoint}")
        self.layout = layout
        self.episode_config = cfg
        self.diagonal = self._extent(cfg)[0]
        start_pose = self._arrival_pose(targets, int(start_waypoint))
        start = start_pose + self.np_random.uniform([-0.05, -0.05, -0.1], [0.05, 0.05, 0.1])
        if self.distribution is not None:  # the robot's limits too, where the distribution draws them
            self.robot_spec = rover.rover_spec(cfg.max_speed, cfg.max_turn_rate, cfg.max_accel, cfg.max_angular_accel)
        if self.world is None or len(self.world.movers) != cfg.n_people:  # the first episode builds the world ...
            if self.world is not None:
                self.world.close()
            self.world = World2D(layout.geometry, n_movers=cfg.n_people)
            self.robot = self.world.add_robot(self.robot_spec, start)
        else:  # ... later ones move what is in it
            self.world.set_scene(layout.geometry)
            self.world.place_robot(self.robot, start)
            self.robot.spec = self.robot_spec
        self.crowd = Crowd(self.world, self.layout.routes, CrowdSpec(tease_prob=cfg.people_tease_prob), cfg.n_people)
        self.crowd.reset(self.np_random, start)
        self.max_episode_steps, self.time_limit_source = self._time_limit(start_pose, targets[start_waypoint:])
        self.task = WaypointTask(
            targets,
            cfg.waypoint_radius,
            cfg.safety_margin,
            cfg.reward_weights(),
            self.max_episode_steps,
            turn_distance=cfg.max_speed / cfg.max_turn_rate,
        )
        self.task.reset(start, index=int(start_waypoint))
        self._start_pose = start.copy()
        self._estimate = start.copy()
        self.odometry.draw_bias(self.np_random)
        self._steps = 0
        self._path_length = 0.0
        clearance = self.world.clearance(self.robot)
        self._min_clearance = clearance
        self._trail = [(float(start[0]), float(start[1]))]
        outcome = self.task.evaluate(self.robot.pose, False, clearance, step=False)
        obs = self._observe()
        info = self._info(outcome, clearance)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def close(self) -> None:
        """Release the renderer and the pymunk world (idempotent; ``reset()`` builds a new world)."""
        self.view.close(self.world)
        self.world = None

    # -- stepping --------------------------------------------------------------------------------------
    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Apply ``[u, r]`` for ``frame_skip`` control periods and return the Gymnasium 5-tuple."""
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        v_cmd, w_cmd = self.robot_spec.command(action)
        terms: dict[str, float] = {}
        reached = False
        for _ in range(self.config.frame_skip):
            outcome, clearance = self._advance(v_cmd, w_cmd)
            for key, value in outcome.items():
                if key.startswith("reward"):
                    terms[key] = terms.get(key, 0.0) + float(value)
            reached = reached or bool(outcome["waypoint_reached"])
            terminated = bool(outcome["is_success"]) or (outcome["collision"] and self.config.terminate_on_collision)
            truncated = not terminated and self._steps >= self.max_episode_steps
            if terminated or truncated:
                break
        outcome.update(terms, waypoint_reached=reached)  # a skipped step reports the sums of its periods
        obs = self._observe()
        info = self._info(outcome, clearance)
        info["truncated"] = truncated
        if truncated:
            info["truncation_reason"] = (
                f"time limit: {self.max_episode_steps} steps ({self.max_episode_steps * self.config.control_period:.1f}"
                f" s, {self.time_limit_source}) reached at waypoint {self.task.index}/{len(self.task.targets)}"
            )
        if self.render_mode == "human":
            self.render()
        return obs, terms["reward"], terminated, truncated, info

    def _advance(self, v_cmd: float, w_cmd: float) -> tuple[dict[str, Any], float]:
        """One control period: people plan, physics, odometry, and the task's outcome; no observation."""
        assert self.world is not None
        dt = self.config.control_period
        robot = self.robot
        reach = np.array([[robot.pose[0], robot.pose[1], self.robot_spec.circumradius]])
        self.crowd.plan(dt, reach, self.np_random)
        self.world.step(dt)
        self.crowd.sync_from_world()
        before = robot.pose
        collided = self.world.drive(robot, v_cmd, w_cmd, dt)
        travelled = math.hypot(robot.pose[0] - before[0], robot.pose[1] - before[1])
        self._path_length += travelled
        self._update_estimate(dt)
        self._steps += 1
        clearance = self.world.clearance(robot)
        self._min_clearance = min(self._min_clearance, clearance)
        self._trail.append((float(robot.pose[0]), float(robot.pose[1])))
        return self.task.evaluate(robot.pose, collided, clearance, travelled), clearance

    def _scene(self, cfg: GreenhouseNavConfig) -> Layout:
        """The episode's scene: drawn from the episode's generator, or the one a fixed seed (or the map) gives."""
        if cfg.scene == "map":
            return self._scenes.get("map", lambda: layout_from_map(self._map_geometry, cfg.map_mission()))
        if cfg.scene == "greenhouse":
            params: LayoutParams | CorridorParams = cfg.layout_params()
            generate: Any = generate_layout
        else:
            params, generate = cfg.office_params(), generate_office_corridor
        if cfg.layout_seed < 0:
            return generate(params, self.np_random)
        return self._scenes.get(
            (params, cfg.layout_seed), lambda: generate(params, np.random.default_rng(cfg.layout_seed))
        )

    def _arrival_pose(self, targets: np.ndarray, k: int) -> np.ndarray:
        """Where the mission starts: the layout's start for ``k = 0``, else waypoint ``k - 1`` as reached.

        The robot stands on waypoint ``k - 1`` facing along the leg that led there (from the start or from
        waypoint ``k - 2``), as a driver that just reached it would.
        """
        assert self.layout is not None
        if k == 0:
            return self.layout.start_pose
        here = targets[k - 1]
        before = targets[k - 2] if k >= 2 else self.layout.start_pose[:2]
        return np.array([here[0], here[1], math.atan2(here[1] - before[1], here[0] - before[0])])

    def _time_limit(self, start_pose: np.ndarray, targets: np.ndarray) -> tuple[int, str]:
        """The episode's step limit and where it comes from (see Episode End)."""
        cfg = self.episode_config
        if self.explicit_max_episode_steps is not None:  # env steps of frame_skip control periods each
            return int(self.explicit_max_episode_steps) * cfg.frame_skip, "explicit max_episode_steps"
        assert self.layout is not None
        steps = mission_time_limit(
            start_pose,
            targets,
            cfg.max_speed,
            cfg.max_turn_rate,
            cfg.control_period,
            speed_fraction=cfg.time_limit_speed_fraction,
            wait_time=cfg.time_limit_wait * cfg.n_people * cfg.mission_cycles,
        )
        return steps, f"mission at {cfg.time_limit_speed_fraction:g} of the speed limits"

    def _update_estimate(self, dt: float) -> None:
        if self.config.localization == "ground_truth":
            self._estimate = self.robot.pose.copy()
        elif self.config.localization == "odometry":
            self._estimate = self.odometry.integrate(self._estimate, self.robot.v, self.robot.w, dt, self.np_random)

    # -- observation and info ---------------------------------------------------------------------------
    def _observe(self) -> dict[str, np.ndarray]:
        assert self.world is not None
        pose = self.robot.pose
        world = self.world
        rng = self.np_random
        scan = self.lidar.scan(pose, world.circles, world.capsules, rng)
        self._last_scan = scan
        self._last_sonar = self.sonars.ranges(pose, world.circles, world.capsules, rng)
        spec = self.robot_spec
        obs = {
            "lidar": (np.minimum.reduceat(scan, self._pool_edges) / self.lidar.spec.max_range).astype(np.float32),
            "sonar": (self._last_sonar / self.sonars.spec.max_range).astype(np.float32),
            "velocity": np.array([self.robot.v / spec.max_speed, self.robot.w / spec.max_turn_rate], np.float32),
        }
        if self.config.localization == "none":
            obs["target"] = np.clip(self._in_start_frame(self.task.current) / self.diagonal, -1, 1).astype(np.float32)
        else:
            obs["waypoint"] = self._polar(self.task.current)
            obs["next_waypoint"] = self._polar(self.task.following)
        if self.config.full_scan:
            obs["scan"] = (scan / self.lidar.spec.max_range).astype(np.float32)
        return obs

    def _polar(self, point: np.ndarray) -> np.ndarray:
        """``[d / diagonal, sin(alpha), cos(alpha)]`` of ``point`` seen from the estimated pose."""
        x, y, yaw = self._estimate
        d = math.hypot(point[0] - x, point[1] - y)
        alpha = math.atan2(point[1] - y, point[0] - x) - yaw
        return np.array([min(1.0, d / self.diagonal), math.sin(alpha), math.cos(alpha)], np.float32)

    def _in_start_frame(self, point: np.ndarray) -> np.ndarray:
        x0, y0, th0 = self._start_pose
        dx, dy = point[0] - x0, point[1] - y0
        c, s = math.cos(th0), math.sin(th0)
        return np.array([c * dx + s * dy, -s * dx + c * dy])

    def _info(self, outcome: dict[str, Any], clearance: float) -> dict[str, Any]:
        pose = self.robot.pose
        info = dict(outcome)
        info.pop("reward")
        info.update(
            clearance=float(clearance),
            min_clearance=float(self._min_clearance),
            waypoints_reached=int(self.task.index),
            n_waypoints=len(self.task.targets),
            x=float(pose[0]),
            y=float(pose[1]),
            yaw=float(pose[2]),
            v=float(self.robot.v),
            w=float(self.robot.w),
            path_length=float(self._path_length),
            episode_time=self._steps * self.config.control_period,
            max_episode_steps=int(self.max_episode_steps),
            truncated=False,
        )
        if self.config.localization != "none":
            est = self._estimate
            info.update(est_x=float(est[0]), est_y=float(est[1]), est_yaw=float(est[2]))
        info["is_success"] = bool(info["is_success"])
        info["collision"] = bool(info["collision"])
        return info

    # -- public helpers for baselines, reports and users -----------------------------------------------
    def mission_in_start_frame(self) -> np.ndarray:
        """The mission's targets (waypoint 1, 2, ..., then 0) in the robot's start frame (m).

        This is what a real robot is given: waypoints picked on its own map, whose origin is where it started.
        """
        return np.array([self._in_start_frame(t) for t in self.task.targets])

    def occupancy_grid(self, resolution: float = 0.05) -> Any:
        """Occupancy grid of the current static scene (see :mod:`agri_envs.sim2d.gridmap`)."""
        assert self.layout is not None
        return rasterize(self.layout.geometry, resolution)

    # -- rendering ---------------------------------------------------------------------------------------
    def render(self) -> np.ndarray | None:
        """Top-down frame with rays, sonar cones, waypoints and the path (``rgb_array``) or a window (``human``)."""
        return self.view.render(None if self.world is None or self.layout is None else self.layout.geometry, self._draw)

    def _draw(self, rd: TopDownRenderer) -> list[str]:
        assert self.world is not None and self.layout is not None
        rd.path(np.array(self._trail))
        mission = self.layout.mission
        rd.waypoints(self.layout.waypoints, -1 if self.task.done else int(mission[self.task.index % len(mission)]))
        rd.rays(
            self.lidar.pose_in_world(self.robot.pose),
            self.lidar.spec.beam_angles,
            self._last_scan,
            self.lidar.spec.max_range,
        )
        rd.cones(self.sonars.poses_in_world(self.robot.pose), self._last_sonar, self.sonars.spec.aperture)
        rd.circles(self.world.mover_circles[: self.crowd.n], Kind.PERSON)
        rd.robot(self.robot.pose, self.robot_spec.length, self.robot_spec.width)
        t = self._steps * self.config.control_period
        clearance = self.world.clearance(self.robot)
        return [f"t = {t:5.1f} s   waypoint {self.task.index}/{len(self.task.targets)}   clearance {clearance:.2f} m"]


class SyncTimeLimit(
    gym.Wrapper[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray], np.ndarray], gym.utils.RecordConstructorArgs
):
    """Tell the env about an explicit ``gym.make(..., max_episode_steps=N)``, so that N wins over its own limit.

    ``gym.make`` applies this wrapper (the registration's ``additional_wrappers``) outside the ``TimeLimit``
    wrapper it adds for an explicit ``max_episode_steps``. The env then truncates at N itself, says why in
    ``info``, and sizes its crash penalty to N (see the env's Rewards section). Without an explicit limit the
    env keeps the one it computes from the mission.
    """

    def __init__(self, env: gym.Env[dict[str, np.ndarray], np.ndarray]) -> None:
        # Recording the (no) arguments lets gym.make(env.spec) and check_env re-create the wrapper stack.
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)
        limit: int | None = None
        inner: gym.Env[Any, Any] = env
        while isinstance(inner, gym.Wrapper):
            if isinstance(inner, gym.wrappers.TimeLimit):
                limit = int(inner._max_episode_steps)
            inner = inner.env
        if isinstance(inner, GreenhouseNavEnv):
            inner.explicit_max_episode_steps = limit
