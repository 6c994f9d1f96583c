"""GreenhouseCoverage-v2: the tracked Fitorobot drives every corridor of a Mediterranean greenhouse (González 2009)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agri_envs.coverage import robot as fito
from agri_envs.coverage.config import GreenhouseCoverageConfig
from agri_envs.coverage.task import CoverageTask, serpentine_path
from agri_envs.scenes.distribution import largest_scenes
from agri_envs.scenes.greenhouse import generate_layout
from agri_envs.scenes.layout import Layout, LayoutCache
from agri_envs.sim2d.egomap import EgoMap
from agri_envs.sim2d.geometry import Kind, enclosing_bounds
from agri_envs.sim2d.gridmap import rasterize
from agri_envs.sim2d.odometry import Compass, TrackOdometry
from agri_envs.sim2d.polyline import PathProgress, Polyline
from agri_envs.sim2d.raycast import footprint_clearance
from agri_envs.sim2d.render import TopDownRenderer
from agri_envs.sim2d.sensors import SonarArray, SonarSpec
from agri_envs.sim2d.view import SceneView
from agri_envs.sim2d.world import World2D

__all__ = ["GreenhouseCoverageConfig", "GreenhouseCoverageEnv"]
_CROP = (int(Kind.PLANT), int(Kind.LEAF), int(Kind.TREE))
#: Where the ``route`` observation samples the serpentine: metres beyond the robot's point on it.
ROUTE_AHEAD = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
#: The ``route`` observation's points are normalised by this distance (m) and clipped.
ROUTE_RANGE = 4.0


class GreenhouseCoverageEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """Drive the tracked Fitorobot through every corridor of a Mediterranean greenhouse without touching the crop.

    ## Description

    The robot of González et al. (2009), the Fitorobot (a 0.7 x 1.5 m, 756 kg rubber-tracked vehicle with
    differential steering), must traverse every corridor of a greenhouse end to end, as a spraying robot
    does. The greenhouse has ``n_rows`` rows of plants; the corridors are the ``n_rows + 1`` spaces between
    them and between the outer rows and the walls. As in Almería's greenhouses the corridors are neither
    straight nor equally wide (``row_incline``, ``row_bend``, ``corridor_width_jitter``), and sonar echoes
    off the foliage sometimes slip between the leaves and read long (``vegetation_echo_prob``: the peaks of
    the paper's Fig. 9). The world is a top-view pymunk space shared with GreenhouseNav.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``: ``[u, r]``, the commanded linear and angular velocity, scaled by
    ``max_speed`` (forward; half of it backward) and ``max_turn_rate``. The achieved velocities follow
    within the (low) acceleration limits. Actions outside the box are clipped; NaN or inf raises ``ValueError``.

    ## Observation Space

    A ``Dict`` of float32 boxes, every value normalised to [0, 1]:

    | key | shape | meaning |
    |---|---|---|
    | ``sonar`` | (7,) | ranges / 4 m: front; left front, middle, rear; right front, middle, rear |
    | ``compass`` | (2,) | ``(1 + sin h) / 2, (1 + cos h) / 2`` of the compass heading h (noise and bias) |
    | ``velocity`` | (2,) | ``(1 + v / max_speed) / 2, (1 + w / max_turn_rate) / 2`` measured by the track encoders |
    | ``pose`` | (4,) | ``x / pose_scale[0], y / pose_scale[1], (1 + sin), (1 + cos) / 2`` of the pose estimate (1) |
    | ``memory`` | (512,) | the robot's own map around it (2), flat: cells it drove over; cells its sonars echoed from |
    | ``route`` | (16,) | PRIVILEGED, only with ``route_observation=True`` (3): the covering serpentine ahead |

    (1) ``localization="odometry"``: the encoders' distance integrated along the compass heading (it
    drifts, and it is rotated by the compass bias); ``"ground_truth"``: the true pose (privileged).
    ``pose_scale`` is an attribute of the env (m), the largest greenhouse size the arguments allow.
    (2) A grid of 0.5 m cells in the frame of the pose estimate (:mod:`agri_envs.sim2d.egomap`): every
    control period the cell under the estimated centre is marked visited (channel 0) and the cell of each
    sonar echo on the sonar's axis is marked (channel 1: the sensory map of González's eq. 2). The
    observation is the 8 x 8 m window centred on the robot and turned with its estimated heading: row
    ``a`` lies ``(a - 7.5) * 0.5`` m ahead, column ``b`` as far to the left. The key holds that
    ``(channel, a, b)`` grid flattened in C order: ``obs["memory"].reshape(2, 16, 16)`` gives it back. It is
    built from the robot's own readings only, so it drifts with the odometry, as a real robot's would.
    (3) What a robot that knew the greenhouse's map and its own pose would know of its route; no sensor gives
    it. The serpentine is the corridors' centre lines in covering order, each extended ``headland / 2`` past
    its ends and joined across the headland (:func:`~agri_envs.coverage.task.serpentine_path`: the polyline
    through the reward's subgoals). The robot's point on it follows the true pose (the nearest point within
    0.5 m back and 3 m ahead of the last one, :class:`~agri_envs.sim2d.polyline.PathProgress`); the key holds
    the points 0, 0.5, 1, 1.5, 2, 3 and 4 m beyond it as ``(ahead, left)`` of the true robot pose, each
    ``(1 + d / 4 m) / 2`` clipped to [0, 1], then the true ``(1 + v / max_speed) / 2, (1 + w / max_turn_rate) /
    2``. It only adds the key: every other key, the dynamics and the random draws are those of the env without it.

    ## Sensors

    Seven ultrasonic range finders (three per side at 0.6 m ahead of, at, and 0.6 m behind the centre, one
    at the front; 0.1-4 m, 20 deg cone; nearest echo in the cone, Gaussian noise ``sonar_noise_std``; an
    echo off plants or leaves slips long with probability ``vegetation_echo_prob``, uniformly up to the
    nearest solid echo behind or 4 m). A magnetic compass (Gaussian noise ``compass_noise_std``, constant
    ``compass_bias``). One incremental encoder per track (per-episode scale error ``encoder_scale_std`` and
    relative noise ``encoder_noise``). Control period 100 ms, as the paper's programs.

    ## Rewards

    ``reward = coverage + progress + success + contact + cross_track + time`` with

    | term | formula |
    |---|---|
    | ``reward_coverage`` | ``reward_coverage * (n_rows + 1) * (coverage gained this step)``: 1 per corridor |
    | ``reward_progress`` | ``reward_progress * (g_prev - g)``, g = d + (max_speed / max_turn_rate) * abs(alpha) (1) |
    | ``reward_success`` | ``+reward_success`` when every corridor is covered |
    | ``reward_contact`` | ``-reward_contact`` on contact with the crop or anything else |
    | ``reward_cross_track`` | ``-reward_cross_track * cross_track`` (0 by default) |
    | ``reward_time`` | ``-reward_time`` every step |

    (1) d and alpha are the true distance and bearing of the current subgoal of the covering serpentine
    (González's Fig. 5): through corridor 0 to the middle of the headland past its far end (``headland / 2``
    past the row ends, room for the 1.5 m robot's turn on either side), across the headland to the
    mouth of corridor 1 on the same side, through it, and so on; a subgoal counts as passed within 0.3 m
    and the next one starts from its own distance to go. Turning toward the subgoal is progress, so the
    U-turn through the headland into the next corridor pays as it is driven. The robot is not told the
    subgoals. Each term is reported in ``info`` under its name. Why the weights are what they are:

    * **Corridors pay when they are driven, turns when they are turned.** In v0 only the covered bins
      paid (1 per corridor, 0.1 per metre): the U-turns in the headlands (15-25 s near walls and row ends)
      paid nothing until the next corridor's first bin, and PPO drove the first corridor and parked in
      the headland in every run. With 0.3 per metre of progress a well-driven default mission returns
      about 40, of which about 3.5 per U-turn.
    * **Touching the crop ends the mission.** 10 on contact, and what the rest of the mission would
      have paid is lost with it.

    ## Starting State

    The robot stands in the headland before the first corridor (the one at the lowest y, between the wall
    and the first row), 1 m before the row ends, facing along it, with a uniform jitter of +-3 cm and
    +-0.02 rad. The odometry starts at the true pose. With ``layout_seed=-1`` the greenhouse (corridor
    widths, row inclines and bends, plants and leaves) is drawn anew from the episode seed; otherwise it
    comes from ``layout_seed``. ``reset(options={"layout_seed": s, "growth": g})`` overrides these for one
    episode. The memory starts empty.

    With ``scene_distribution="training"`` (default ``"off"``) each episode first draws its greenhouse
    from the env's training distribution (:data:`agri_envs.coverage.distribution.TRAINING`), with the
    episode's own Generator: ``n_rows`` 1..4, ``row_length`` [4, 12] m, ``corridor_width`` [1.4, 1.6] m,
    ``corridor_width_jitter`` [0, 0.1] m, ``row_incline`` [0, 0.012] rad, ``row_bend`` [0, 0.05] m,
    ``growth`` [0.2, 1] and ``vegetation_echo_prob`` [0, 0.3]. The drawn arguments replace the config's for
    that episode (``env.unwrapped.episode_config``; reset options still apply on top), and so do the time
    limit and ``info["n_corridors"]``; ``pose_scale`` is the largest greenhouse the distribution draws. The
    arguments it draws cannot also be given to ``gym.make``. Training uses seeds below 100000; held-out
    suites (100000 and up) run the plain env, and ``coverage-generalization`` lies outside every range.

    ``scene_distribution="robust"`` (:data:`agri_envs.coverage.distribution.ROBUST`) widens it along the
    stress suites' axes, each suite keeping a level outside: ``n_rows`` 1..6, ``row_length`` [4, 16] m,
    ``corridor_width`` [1.3, 2.5] m (below 1.5 m with ``growth`` up to 0.7, or, at 1.4-1.5 m in rows of up to
    12 m, up to 1), ``vegetation_echo_prob`` [0, 0.7], and the dead reckoning: ``encoder_noise`` [0, 0.2],
    ``encoder_scale_std`` [0, 0.05], ``compass_noise_std`` [0, 0.2] rad, ``compass_bias`` [-0.2, 0.2] rad;
    jitter, incline, bend and growth as in training. Every training scene is one of its scenes, and so is
    ``coverage-generalization``'s. The sensors take each episode's drawn arguments (the sonars' slip
    probability, the compass, the encoders).

    ## Episode End

    Terminated when every corridor is covered end to end (success) or, with ``terminate_on_contact``, when
    the robot touches the crop, a post or a wall. Truncated at ``time_limit`` seconds (0: three times the
    serpentine's length at full speed plus the turns, plus 30 s).

    ## Info

    ``is_success``, ``coverage`` (covered fraction of all corridor bins), ``corridors_covered``,
    ``n_corridors``, ``corridor`` (index of the corridor the robot is in, -1 in the headlands),
    ``cross_track`` (m, distance from the robot's centre to that corridor's centre line, 0 in the
    headlands), ``max_cross_track`` (m, over the episode), ``mean_cross_track`` (m, over the steps inside
    corridors), ``crop_contacts`` (steps that touched plants, leaves or trees), ``other_contacts``
    (walls, posts), ``collision`` (any contact so far), ``clearance`` and ``min_clearance`` (m, footprint to
    the nearest obstacle, now and over the episode), true pose ``x``, ``y``, ``yaw``, odometry
    ``est_x``, ``est_y``, compass ``compass`` (rad), ``v``, ``w``, ``path_length`` (m), ``episode_time``
    (s), the seven ``sonar_<name>`` readings (m) and the reward terms.

    ## Arguments

    Every argument is a field of :class:`GreenhouseCoverageConfig`; unknown names and values out of range
    raise ``ValueError`` naming the argument and its valid range.

    | argument | default | unit | valid | meaning |
    |---|---|---|---|---|
    | ``n_rows`` | 4 |  | in [1, 12] | rows of plants (the corridors are the n_rows + 1 spaces beside them) |
    | ``row_length`` | 10 | m | in [3.0, 50.0] | length of each row |
    | ``corridor_width`` | 1.4 | m | in [1.0, 3.0] | mean free width of a corridor |
    | ``corridor_width_jitter`` | 0.1 | m | in [0.0, 0.4] | each corridor is corridor_width + U(-jitter, jitter) wide |
    | ``row_incline`` | 0.01 | rad | in [0.0, 0.05] | each row is tilted by U(-incline, incline) |
    | ``row_bend`` | 0.05 | m | in [0.0, 0.3] | each row bows sideways by U(-bend, bend) at mid-length |
    | ``row_width`` | 0.6 | m | in [0.2, 1.5] | width of a row bed |
    | ``headland`` | 2.6 | m | in [2.2, 6.0] | free space between row ends and the end walls |
    | ``plant_spacing`` | 0.4 | m | in [0.15, 2.0] | distance between plants along a row |
    | ``plant_jitter`` | 0.03 | m | in [0.0, 0.1] | uniform jitter of plant positions |
    | ``growth`` | 0.6 |  | in [0.0, 1.0] | season: plant size and leaves reaching into corridors |
    | ``post_spacing`` | 4 | m | in [1.0, 20.0] | distance between structural posts along rows and walls |
    | ``layout_seed`` | -1 |  | in [-1, 2147483647] | layout seed; -1: a new greenhouse every episode |
    | ``scene_distribution`` | 'off' |  | one of 'off', 'training', 'robust' | per-episode scenes (see Starting State) |
    | ``max_speed`` | 0.5 | m/s | in [0.1, 1.5] | forward speed limit (reverse: half of it) |
    | ``max_turn_rate`` | 0.6 | rad/s | in [0.1, 2.0] | angular speed limit |
    | ``max_accel`` | 0.3 | m/s^2 | in [0.05, 2.0] | linear acceleration limit |
    | ``max_angular_accel`` | 0.8 | rad/s^2 | in [0.05, 5.0] | angular acceleration limit |
    | ``control_period`` | 0.1 | s | in [0.02, 0.5] | time between actions (the paper's 100 ms) |
    | ``sonar_noise_std`` | 0.01 | m | in [0.0, 0.5] | sonar Gaussian range noise |
    | ``vegetation_echo_prob`` | 0.15 |  | in [0.0, 1.0] | chance that an echo off foliage slips through (reads long) |
    | ``compass_noise_std`` | 0.01 | rad | in [0.0, 0.5] | compass Gaussian heading noise |
    | ``compass_bias`` | 0.03 | rad | in [-0.5, 0.5] | constant compass heading bias |
    | ``encoder_noise`` | 0.02 |  | in [0.0, 0.5] | relative std of each track-speed measurement |
    | ``encoder_scale_std`` | 0.01 |  | in [0.0, 0.1] | per-episode scale error std of each track encoder (drift) |
    | ``localization`` | 'odometry' |  | one of 'odometry', 'ground_truth' | source of the 'pose' observation |
    | ``bin_length`` | 0.25 | m | in [0.05, 2.0] | length of a coverage bin along a corridor |
    | ``terminate_on_contact`` | True |  | True or False | end the episode on touching the crop or anything else |
    | ``time_limit`` | 0 | s | in [0.0, 36000.0] | episode time limit; 0 sizes it to the mission |
    | ``reward_coverage`` | 1 |  | in [0.0, 100.0] | reward per corridor covered (paid per bin) |
    | ``reward_progress`` | 0.3 |  | in [0.0, 100.0] | reward per metre along the covering serpentine (see Rewards) |
    | ``reward_success`` | 10 |  | in [0.0, 1000.0] | bonus when every corridor is covered |
    | ``reward_contact`` | 10 |  | in [0.0, 1000.0] | penalty on contact |
    | ``reward_cross_track`` | 0 |  | in [0.0, 100.0] | penalty per step per metre of cross-track error |
    | ``reward_time`` | 0.001 |  | in [0.0, 10.0] | penalty per step |
    | ``render_width`` | 800 | px | in [100, 4000] | width of rendered frames |

    Example::

        env = gym.make("agri_envs/GreenhouseCoverage-v2", n_rows=6, row_bend=0.1, vegetation_echo_prob=0.3)

    Batched: ``gym.make_vec("agri_envs/GreenhouseCoverage-v2", num_envs=64, **kwargs)`` steps 64 of these worlds
    in one compiled loop (:class:`~agri_envs.coverage.vector.GreenhouseCoverageVectorEnv`), each sub-env's
    episodes bit for bit this env's for the same seed and actions (its memory and progress reward included).

    ## Baselines

    ``gonzalez-deliberative`` (Voronoi diagram, corridor-covering search, Pure Pursuit; privileged: the true
    map and pose), ``gonzalez-pseudo-reactive`` (behaviours, turn rule, centering, peak filter, sensory map;
    no map) and ``gonzalez-hybrid`` (first run pseudo-reactive, later runs deliberative on its sensory map).

    ## Version History

    * v0: initial release. Later, without a version change: the batched form (``gym.make_vec``) and resets
      that reuse the pymunk world.
    * v1: a covering policy can be learned from what the robot has. New observation ``memory`` (the robot's
      own map of where it drove and where its sonars echoed, around it, from its odometry); the
      ``coverage`` observation (each corridor's covered fraction, which the robot cannot measure and whose
      size followed ``n_rows``) is gone. New reward term ``reward_progress`` (0.3 per metre along the
      covering serpentine, turns included); with v0's reward PPO parked after the first corridor. New
      argument ``scene_distribution``; ``info["subgoal_index"]``. Dynamics, sensors, the other reward terms,
      termination and time limits are unchanged. Later, without a version change: the batched form again.
    * v2: the ``memory`` observation is a flat ``(512,)`` vector (the same values, the ``(2, 16, 16)`` grid in
      C order), so that learners take it as it is: SB3 reads a float box of image shape as an image that
      should be uint8 and warns. Everything else is unchanged; a policy that flattened v1's ``memory``
      (SB3's ``MultiInputPolicy`` does) sees the same input. Later, without a version change (the defaults
      are unchanged): the sensors take the episode's drawn arguments (sonar slip probability, compass noise and
      bias, encoder noise and scale error); before, the sonars kept the config's ``vegetation_echo_prob``, so
      ``scene_distribution="training"`` episodes change (their drawn echoes now apply; ``"off"`` gives the same
      episodes). New value ``scene_distribution="robust"``. The privileged argument ``route_observation``
      (default off: the ``route`` key, for learners that may read the true pose, as ``localization=
      "ground_truth"`` lets them).

    ## References

    R. González Sánchez, F. Rodríguez Díaz, J. Sánchez-Hermosilla López, J. García Donaire, "Navigation
    techniques for mobile robots in greenhouses", Applied Engineering in Agriculture 25(2), 2009.
    """

    metadata = {
        "render_modes": ["rgb_array", "human"],
        "render_fps": 10,
        "episode_metric_keys": (
            "collision",
            "coverage",
            "corridors_covered",
            "n_corridors",
            "max_cross_track",
            "mean_cross_track",
            "crop_contacts",
            "other_contacts",
            "min_clearance",
            "path_length",
            "episode_time",
        ),
        "trace_keys": (
            "x",
            "y",
            "yaw",
            "est_x",
            "est_y",
            "compass",
            "corridor",
            "cross_track",
            "clearance",
            "coverage",
            *(f"sonar_{n}" for n in fito.SONAR_NAMES),
        ),
    }

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        self.render_mode = render_mode
        self.config = cfg = GreenhouseCoverageConfig.from_kwargs(kwargs)
        #: The training distribution each episode's greenhouse is drawn from (None: the arguments' own).
        self.distribution = cfg.distribution()
        if self.distribution is not None:
            self.distribution.refuse_given(kwargs, f"GreenhouseCoverage: scene_distribution={cfg.scene_distribution!r}")
        largest = largest_scenes(self.distribution, cfg)
        canvas = enclosing_bounds(c.layout_params().max_bounds() for c in largest)
        self.view = SceneView(render_mode, canvas, cfg.render_width, self.metadata["render_fps"])
        self.robot_spec = fito.fitorobot_spec(cfg.max_speed, cfg.max_turn_rate, cfg.max_accel, cfg.max_angular_accel)
        self.sonars = SonarArray(
            SonarSpec(
                aperture=fito.SONAR_APERTURE,
                min_range=fito.SONAR_MIN_RANGE,
                max_range=fito.SONAR_MAX_RANGE,
                noise_std=cfg.sonar_noise_std,
                foliage_slip_prob=cfg.vegetation_echo_prob,
            ),
            fito.SONAR_MOUNTS,
        )
        self.compass = Compass(cfg.compass_noise_std, cfg.compass_bias)
        self.encoders = TrackOdometry(fito.TRACK_GAUGE, cfg.encoder_noise, cfg.encoder_scale_std)
        #: Normalisation of the ``pose`` observation (m): the largest greenhouse the arguments allow.
        scales = [c.largest_size() for c in largest]
        self.pose_scale = (max(w for w, _ in scales), max(h for _, h in scales))
        #: The robot's own map (the ``memory`` observation).
        self.memory = EgoMap()
        #: The arguments of the current episode: the config, with the greenhouse drawn from the distribution if any.
        self.episode_config = cfg
        self.n_corridors = cfg.n_rows + 1
        self.max_steps = int(math.ceil(cfg.mission_time() / cfg.control_period))
        box = spaces.Box
        keys: dict[str, spaces.Space[Any]] = {
            "sonar": box(0.0, 1.0, (len(self.sonars),), np.float32),
            "compass": box(0.0, 1.0, (2,), np.float32),
            "velocity": box(0.0, 1.0, (2,), np.float32),
            "pose": box(0.0, 1.0, (4,), np.float32),
            # Flat (the (2, 16, 16) view in C order): a float image would make SB3 want uint8 (v2).
            "memory": box(0.0, 1.0, (math.prod(self.memory.shape),), np.float32),
        }
        if cfg.route_observation:  # privileged: the serpentine from the true pose, and the true velocity
            keys["route"] = box(0.0, 1.0, (2 * len(ROUTE_AHEAD) + 2,), np.float32)
        self.observation_space = spaces.Dict(keys)  # type: ignore[assignment]
        self._route: PathProgress | None = None
        self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.layout: Layout | None = None
        self.world: World2D | None = None
        self._scenes = LayoutCache()  # greenhouses of fixed layout seeds
        self._trail: list[tuple[float, float]] = []

    # -- episode set-up --------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Build a new greenhouse and place the robot before the first corridor (see Starting State)."""
        # Checked before anything of the env changes, so a bad option leaves the env as it was.
        allowed = ("growth", "layout_seed")
        cfg = self.config.with_options(options, allowed)
        super().reset(seed=seed)
        rng = self.np_random
        if self.distribution is not None:  # the greenhouse of this episode, from the episode's own Generator
            _, drawn = self.distribution.sample(rng)
            cfg = self.config.replace(**drawn).with_options(options, allowed)
        self.episode_config = cfg
        self._apply_sensor_arguments(cfg)
        self.n_corridors = cfg.n_rows + 1
        self.max_steps = int(math.ceil(cfg.mission_time() / cfg.control_period))
        params = cfg.layout_params()
        if cfg.layout_seed < 0:
            self.layout = generate_layout(params, rng)
        else:  # the same greenhouse every time: built once
            seed = cfg.layout_seed
            self.layout = self._scenes.get((params, seed), lambda: generate_layout(params, np.random.default_rng(seed)))
        geo = self.layout.geometry
        crop_c = np.isin(geo.circle_kinds, _CROP)
        crop_s = np.isin(geo.capsule_kinds, _CROP)
        self._solid = (np.ascontiguousarray(geo.circles[~crop_c]), np.ascontiguousarray(geo.capsules[~crop_s]))
        self._crop = (np.ascontiguousarray(geo.circles[crop_c]), np.ascontiguousarray(geo.capsules[crop_s]))
        first = self.layout.corridors[0]
        start = np.array([first[0, 0] - 1.0, first[0, 1], 0.0]) + rng.uniform([-0.03, -0.03, -0.02], [0.03, 0.03, 0.02])
        if self.world is None:  # the first episode (or the first after close()) builds the world ...
            self.world = World2D(geo, n_movers=0)
            self.robot = self.world.add_robot(self.robot_spec, start)
        else:  # ... later ones move what is in it
            self.world.set_scene(geo)
            self.world.place_robot(self.robot, start)
        self.task = CoverageTask(
            self.layout.corridors,
            cfg.bin_length,
            cfg.weights(),
            turn_distance=cfg.max_speed / cfg.max_turn_rate,
            subgoal_offset=0.5 * cfg.headland,
            subgoal_radius=0.3,
        )
        self.task.reset(start)
        if cfg.route_observation:
            self._route = PathProgress(Polyline(serpentine_path(self.layout.corridors, 0.5 * cfg.headland)))
            self._route.reset(self.robot.pose)
        self.memory.reset(geo.bounds)
        self.encoders.draw_scale(rng)
        self.encoders.reset(start)
        self._steps = 0
        self._path_length = 0.0
        self._crop_contacts = 0
        self._other_contacts = 0
        self._cross_sum = 0.0
        self._cross_n = 0
        self._trail = [(float(start[0]), float(start[1]))]
        self._compass = self.compass.read(self.robot.pose[2], self.np_random)
        self._min_clearance = math.inf
        outcome = self.task.evaluate(self.robot.pose, False, False)
        self._track(outcome)
        obs = self._observe()
        info = self._info(outcome)
        if self.render_mode == "human":
            self.render()
        return obs, info

    def _apply_sensor_arguments(self, cfg: GreenhouseCoverageConfig) -> None:
        """Give the sonars, compass and encoders the episode's arguments (a distribution may draw them).

        Updated in place: without a distribution they are the config's, and every draw stays as it was.
        """
        self.sonars.spec = dataclasses.replace(self.sonars.spec, foliage_slip_prob=cfg.vegetation_echo_prob)
        self.compass.noise_std, self.compass.bias = cfg.compass_noise_std, cfg.compass_bias
        self.encoders.noise, self.encoders.scale_std = cfg.encoder_noise, cfg.encoder_scale_std

    # -- stepping --------------------------------------------------------------------------------------
    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Apply ``[u, r]`` for one control period and return the Gymnasium 5-tuple."""
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        v_cmd, w_cmd = self.robot_spec.command(action)
        dt = self.config.control_period
        robot = self.robot
        before = robot.pose
        contact = self.world.drive(robot, v_cmd, w_cmd, dt)
        self._path_length += math.hypot(robot.pose[0] - before[0], robot.pose[1] - before[1])
        crop_contact = other_contact = False
        if contact:  # which obstacle stopped the robot: the nearer of the crop and the rest
            crop_contact = self._clearance(self._crop) <= self._clearance(self._solid)
            other_contact = not crop_contact
        self._crop_contacts += int(crop_contact)
        self._other_contacts += int(other_contact)
        self._steps += 1
        self._compass = self.compass.read(self.robot.pose[2], self.np_random)
        self.encoders.update(robot.v, robot.w, self._compass, dt, self.np_random)
        self._trail.append((float(robot.pose[0]), float(robot.pose[1])))
        outcome = self.task.evaluate(robot.pose, crop_contact, other_contact)
        self._track(outcome)
        terminated = bool(outcome["is_success"]) or (contact and self.config.terminate_on_contact)
        truncated = not terminated and self._steps >= self.max_steps
        obs = self._observe()
        info = self._info(outcome)
        if self.render_mode == "human":
            self.render()
        return obs, float(outcome["reward"]), terminated, truncated, info

    def _clearance(self, arrays: tuple[np.ndarray, np.ndarray]) -> float:
        p = self.robot.pose
        s = self.robot_spec
        return float(footprint_clearance(p[0], p[1], p[2], 0.5 * s.length, 0.5 * s.width, arrays[0], arrays[1]))

    def _track(self, outcome: dict[str, Any]) -> None:
        assert self.world is not None
        self._clearance_now = self.world.clearance(self.robot)
        self._min_clearance = min(self._min_clearance, self._clearance_now)
        if outcome["corridor"] >= 0:
            self._cross_sum += float(outcome["cross_track"])
            self._cross_n += 1

    # -- observation and info ---------------------------------------------------------------------------
    def _observe(self) -> dict[str, np.ndarray]:
        assert self.world is not None
        self._last_sonar = self.sonars.ranges(
            self.robot.pose, self.world.circles, self.world.capsules, self.np_random, solid=self._solid
        )
        spec = self.robot_spec
        enc = self.encoders
        h = self._compass
        if self.config.localization == "ground_truth":
            px, py, ph = (float(v) for v in self.robot.pose)
        else:
            px, py, ph = float(enc.estimate[0]), float(enc.estimate[1]), h
        estimate = np.array([px, py, ph])
        self.memory.update(estimate, self.sonars.poses_in_world(estimate), self._last_sonar, self.sonars.spec.max_range)
        half = np.float32(0.5)
        obs = {
            "sonar": (self._last_sonar / self.sonars.spec.max_range).astype(np.float32),
            "compass": np.array([0.5 + 0.5 * math.sin(h), 0.5 + 0.5 * math.cos(h)], np.float32),
            "velocity": np.clip(
                half + half * np.array([enc.v / spec.max_speed, enc.w / spec.max_turn_rate], np.float32),
                0.0,
                1.0,
            ),
            "pose": np.clip(
                np.array(
                    [
                        px / self.pose_scale[0],
                        py / self.pose_scale[1],
                        0.5 + 0.5 * math.sin(ph),
                        0.5 + 0.5 * math.cos(ph),
                    ],
                    np.float32,
                ),
                0.0,
                1.0,
            ),
            "memory": self.memory.view(estimate).reshape(-1),
        }
        if self._route is not None:
            obs["route"] = self._route_observation()
        return obs

    def _route_observation(self) -> np.ndarray:
        """PRIVILEGED: the serpentine's points ahead in the true robot frame, and the true velocity (``route``)."""
        assert self._route is not None
        pose = self.robot.pose
        self._route.update(pose)
        points = self._route.ahead(pose, ROUTE_AHEAD).reshape(-1) / ROUTE_RANGE
        spec = self.robot_spec
        velocity = np.array([self.robot.v / spec.max_speed, self.robot.w / spec.max_turn_rate])
        return np.clip(0.5 + 0.5 * np.concatenate([points, velocity]), 0.0, 1.0).astype(np.float32)

    def _info(self, outcome: dict[str, Any]) -> dict[str, Any]:
        pose = self.robot.pose
        info = dict(outcome)
        info.pop("reward")
        info.update(
            is_success=bool(outcome["is_success"]),
            n_corridors=self.n_corridors,
            mean_cross_track=self._cross_sum / self._cross_n if self._cross_n else 0.0,
            crop_contacts=self._crop_contacts,
            other_contacts=self._other_contacts,
            collision=bool(self._crop_contacts or self._other_contacts),
            clearance=float(self._clearance_now),
            min_clearance=float(self._min_clearance),
            x=float(pose[0]),
            y=float(pose[1]),
            yaw=float(pose[2]),
            est_x=float(self.encoders.estimate[0]),
            est_y=float(self.encoders.estimate[1]),
            compass=self._compass,
            v=float(self.robot.v),
            w=float(self.robot.w),
            path_length=float(self._path_length),
            episode_time=self._steps * self.config.control_period,
        )
        for name, value in zip(fito.SONAR_NAMES, self._last_sonar, strict=True):
            info[f"sonar_{name}"] = float(value)
        return info

    # -- privileged accessors (labelled so: a real robot has neither) ----------------------------------
    def true_map(self, resolution: float = 0.05) -> tuple[np.ndarray, float, tuple[float, float]]:
        """PRIVILEGED: the current greenhouse as an occupancy grid, for the deliberative baseline.

        González's deliberative technique is given the greenhouse's digital map (sec. 3.1); this accessor
        plays that map. Results that use it are labelled privileged.

        Args:
            resolution: Cell size (m).

        Returns:
            ``(occupancy, resolution, origin)``: a boolean grid (True = blocked) whose cell ``[i, j]``
            covers x in ``origin[0] + [j*res, (j+1)*res)`` and y in ``origin[1] + [i*res, (i+1)*res)``.
        """
        if self.layout is None:
            raise RuntimeError("call reset() before true_map()")
        grid = rasterize(self.layout.geometry, resolution)
        return grid.data > 0, grid.resolution, (float(grid.origin[0]), float(grid.origin[1]))

    def corridor_lines(self) -> tuple[np.ndarray, ...]:
        """PRIVILEGED: the centre line of every corridor (m), as the task measures cross-track error."""
        if self.layout is None:
            raise RuntimeError("call reset() before corridor_lines()")
        return self.layout.corridors

    # -- rendering ---------------------------------------------------------------------------------------
    def render(self) -> np.ndarray | None:
        """Top-down frame with sonar cones, corridor centre lines and the driven path."""
        return self.view.render(None if self.world is None or self.layout is None else self.layout.geometry, self._draw)

    def _draw(self, rd: TopDownRenderer) -> list[str]:
        rd.path(np.array(self._trail))
        rd.cones(self.sonars.poses_in_world(self.robot.pose), self._last_sonar, self.sonars.spec.aperture)
        rd.robot(self.robot.pose, self.robot_spec.length, self.robot_spec.width)
        done = sum(bool(c.all()) for c in self.task.covered)
        t = self._steps * self.config.control_period
        return [f"t = {t:5.1f} s   coverage {self.task.coverage:4.0%}   corridors {done}/{self.n_corridors}"]

    def close(self) -> None:
        """Release the renderer and the pymunk world (idempotent; ``reset()`` builds a new world)."""
        self.view.close(self.world)
        self.world = None
