"""GreenhouseNav-v2 as a native Gymnasium ``VectorEnv``: N greenhouses stepped together in one compiled loop.

``gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=N, **kwargs)`` builds :class:`GreenhouseNavVectorEnv`.
Each sub-env is a :class:`~agri_envs.rover.greenhouse_nav.GreenhouseNavEnv`: its own ``reset`` sets every
episode up (scene, people, mission, time limit, start), with its own generator; the vector env then copies
the episode's state into padded arrays, and :func:`_step_worlds` steps all the worlds (people, drive, odometry,
task and reward, LIDAR and sonars, observation) in one numba call, drawing each world's noise from its sub-env's
generator. The single env is the reference: for the same seeds and actions both give the same numbers bit
for bit (``tests/envs/test_nav_vector.py`` checks it), contacts aside as :mod:`agri_envs.sim2d.batched` says.

This module is the single env's twin and lives beside it: it reads and writes the sub-envs' episode state
(their private attributes) when it loads an episode and before it draws one.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np
from gymnasium.vector import AutoresetMode

from agri_envs._vector import BatchedEnv, InfoKey, grown
from agri_envs.rover.distribution import DISTRIBUTIONS, ROBOT_ARGUMENTS
from agri_envs.rover.greenhouse_nav import GreenhouseNavEnv
from agri_envs.sim2d.batched import (
    drive_box,
    lidar_scan,
    pooled,
    py_hypot,
    route_advance,
    sonar_scan,
    step_people,
    wheel_odometry,
)
from agri_envs.sim2d.raycast import footprint_clearance

__all__ = ["GreenhouseNavVectorEnv"]

_GROUND_TRUTH, _ODOMETRY, _NONE = 0, 1, 2

#: ``info`` keys of a step, in the single env's order: (key, dtype, column of the array of that dtype).
_INFO: tuple[InfoKey, ...] = (
    ("reward_progress", float, 0),
    ("reward_waypoint", float, 1),
    ("reward_success", float, 2),
    ("reward_collision", float, 3),
    ("reward_clearance", float, 4),
    ("reward_time", float, 5),
    ("is_success", bool, 0),
    ("collision", bool, 1),
    ("waypoint_reached", bool, 2),
    ("waypoint_index", int, 0),
    ("distance_to_waypoint", float, 6),
    ("bearing_to_waypoint", float, 7),
    ("clearance", float, 8),
    ("min_clearance", float, 9),
    ("waypoints_reached", int, 1),
    ("n_waypoints", int, 2),
    ("x", float, 10),
    ("y", float, 11),
    ("yaw", float, 12),
    ("v", float, 13),
    ("w", float, 14),
    ("path_length", float, 15),
    ("episode_time", float, 16),
    ("max_episode_steps", int, 3),
    ("truncated", bool, 3),
    ("est_x", float, 17),
    ("est_y", float, 18),
    ("est_yaw", float, 19),
)


class _Constants(NamedTuple):
    """What every world of the batch shares: the config, the robot and its sensors."""

    dt: float
    frame_skip: int
    limits: np.ndarray  # max_speed, max_reverse_speed, max_turn_rate, max_accel, max_angular_accel
    half_length: float
    half_width: float
    circumradius: float
    localization: int
    odometry_noise: float
    terminate_on_collision: bool
    waypoint_radius: float
    safety_margin: float
    turn_distance: float
    weights: np.ndarray  # progress, waypoint, success, collision, clearance, time
    full_scan: bool
    lidar_mount: np.ndarray
    beam_ux: np.ndarray
    beam_uy: np.ndarray
    angle0: float
    dangle: float
    lidar_min: float
    lidar_max: float
    lidar_noise: float
    lidar_dropout: float
    pool_starts: np.ndarray
    sonar_mounts: np.ndarray
    sonar_half_aperture: float
    sonar_min: float
    sonar_max: float
    sonar_noise: float


class _State(NamedTuple):
    """Each world's episode state, padded to the largest scene, route graph and mission met so far."""

    pose: np.ndarray  # (n, 3)
    vel: np.ndarray  # (n, 2)
    estimate: np.ndarray  # (n, 3)
    start: np.ndarray  # (n, 3)
    path_length: np.ndarray
    min_clearance: np.ndarray
    gyro_bias: np.ndarray
    last_to_go: np.ndarray
    max_substep: np.ndarray
    diagonal: np.ndarray  # the scene's diagonal (m): the scale of waypoint distances
    steps: np.ndarray
    max_steps: np.ndarray
    task_index: np.ndarray  # the waypoint being driven to
    n_targets: np.ndarray
    n_static: np.ndarray
    n_people: np.ndarray
    n_circles: np.ndarray
    n_capsules: np.ndarray
    circles: np.ndarray  # (n, C, 3): static circles, then the people
    capsules: np.ndarray  # (n, S, 5)
    targets: np.ndarray  # (n, T, 2)
    prev_node: np.ndarray  # (n, P)
    next_node: np.ndarray
    speed: np.ndarray
    mode: np.ndarray
    timer: np.ndarray
    reacted: np.ndarray
    nodes: np.ndarray  # (n, K, 2)
    adjacency: np.ndarray  # (n, K, D)
    degree: np.ndarray  # (n, K)
    crowd: np.ndarray  # (n, 4): notice distance, tease probability, shortest and longest standing time


class _Output(NamedTuple):
    """What a step writes: observations, rewards, flags, info values and the sensor readings in metres."""

    lidar: np.ndarray
    sonar: np.ndarray
    velocity: np.ndarray
    waypoint: np.ndarray
    next_waypoint: np.ndarray
    target: np.ndarray
    scan: np.ndarray
    scan_m: np.ndarray
    sonar_m: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    info_f: np.ndarray
    info_i: np.ndarray
    info_b: np.ndarray
    trail: np.ndarray  # (n, frame_skip, 2): the robot's position after each control period
    periods: np.ndarray  # control periods each world ran


@numba.njit(cache=True)
def _polar(px: float, py: float, pose: np.ndarray, diagonal: float, out: np.ndarray) -> None:
    """``GreenhouseNavEnv._polar``: ``[d / diagonal, sin(alpha), cos(alpha)]`` of a point from ``pose``."""
    d = py_hypot(px - pose[0], py - pose[1])
    alpha = math.atan2(py - pose[1], px - pose[0]) - pose[2]
    out[0] = np.float32(min(1.0, d / diagonal))
    out[1] = np.float32(math.sin(alpha))
    out[2] = np.float32(math.cos(alpha))


@numba.njit(cache=True)
def _step_worlds(rngs: Any, actions: np.ndarray, active: np.ndarray, c: _Constants, s: _State, o: _Output) -> None:
    """``GreenhouseNavEnv.step`` for every ``active`` world: ``frame_skip`` control periods, then the observation.

    Args:
        rngs: Each world's generator (its sub-env's ``np_random``), a typed list.
        actions: ``(n, 2)`` actions, already checked and clipped to [-1, 1] (float64).
        active: ``(n,)`` which worlds step (the others are left as they are).
        c: The shared constants.
        s: The worlds' state, updated.
        o: Where the results go.
    """
    w = c.weights
    for i in range(actions.shape[0]):
        if not active[i]:
            continue
        rng = rngs[i]
        pose = s.pose[i]
        vel = s.vel[i]
        est = s.estimate[i]
        circles = s.circles[i, : s.n_circles[i]]
        capsules = s.capsules[i, : s.n_capsules[i]]
        people = s.circles[i, s.n_static[i] : s.n_static[i] + s.n_people[i]]
        targets = s.targets[i]
        n_targets = s.n_targets[i]
        u, r = actions[i, 0], actions[i, 1]  # DiffDriveSpec.command
        v_cmd = u * (c.limits[0] if u >= 0 else c.limits[1])
        w_cmd = r * c.limits[2]
        sums = np.zeros(7)  # the reward terms, then the reward, summed over the periods
        reached_any = False
        terminated = False
        truncated = False
        collided = False
        clearance = 0.0
        d = 0.0
        alpha = 0.0
        periods = 0
        for _ in range(c.frame_skip):  # GreenhouseNavEnv._advance
            step_people(
                rng,
                people,
                s.prev_node[i],
                s.next_node[i],
                s.speed[i],
                s.mode[i],
                s.timer[i],
                s.reacted[i],
                s.nodes[i],
                s.adjacency[i],
                s.degree[i],
                pose[0],
                pose[1],
                c.circumradius,
                c.dt,
                s.crowd[i, 0],
                s.crowd[i, 1],
                s.crowd[i, 2],
                s.crowd[i, 3],
            )
            bx, by = pose[0], pose[1]
            collided = drive_box(
                pose,
                vel,
                v_cmd,
                w_cmd,
                c.limits,
                c.half_length,
                c.half_width,
                c.circumradius,
                circles,
                capsules,
                c.dt,
                s.max_substep[i],
            )
            travelled = py_hypot(pose[0] - bx, pose[1] - by)
            s.path_length[i] += travelled
            if c.localization == _GROUND_TRUTH:
                est[0], est[1], est[2] = pose[0], pose[1], pose[2]
            elif c.localization == _ODOMETRY:
                wheel_odometry(rng, est, vel[0], vel[1], c.dt, c.odometry_noise, s.gyro_bias[i])
            s.steps[i] += 1
            clearance = footprint_clearance(
                pose[0], pose[1], pose[2], c.half_length, c.half_width, circles, capsules, -1
            )
            s.min_clearance[i] = min(s.min_clearance[i], clearance)
            o.trail[i, periods, 0] = pose[0]
            o.trail[i, periods, 1] = pose[1]
            periods += 1
            # WaypointTask.evaluate
            before = s.task_index[i]
            progress, index, s.last_to_go[i], d, alpha = route_advance(
                targets, n_targets, before, s.last_to_go[i], c.waypoint_radius, c.turn_distance, pose
            )
            s.task_index[i] = index
            reached = index != before
            success = index >= n_targets
            if c.safety_margin > 0:
                shortfall = max(0.0, c.safety_margin - clearance) / c.safety_margin
            else:
                shortfall = 0.0
            steps_left = max(0, s.max_steps[i] - s.steps[i])
            terms = (
                w[0] * progress,
                w[1] * (1.0 if reached else 0.0),
                w[2] * (1.0 if success else 0.0),
                -(w[3] + steps_left * w[5]) * (1.0 if collided else 0.0),
                -w[4] * min(1.0, shortfall) * travelled,
                -w[5] * 1.0,
            )
            reward = 0.0
            for k in range(6):
                reward += terms[k]
                sums[k] = sums[k] + terms[k]
            sums[6] = sums[6] + reward
            reached_any = reached_any or reached
            terminated = success or (collided and c.terminate_on_collision)
            truncated = not terminated and s.steps[i] >= s.max_steps[i]
            if terminated or truncated:
                break
        o.periods[i] = periods
        # GreenhouseNavEnv._observe
        scan = o.scan_m[i]
        lidar_scan(
            rng,
            pose,
            c.lidar_mount,
            c.beam_ux,
            c.beam_uy,
            c.angle0,
            c.dangle,
            c.lidar_min,
            c.lidar_max,
            c.lidar_noise,
            c.lidar_dropout,
            circles,
            capsules,
            scan,
        )
        sonar = o.sonar_m[i]
        sonar_scan(
            rng,
            pose,
            c.sonar_mounts,
            c.sonar_half_aperture,
            c.sonar_min,
            c.sonar_max,
            c.sonar_noise,
            0.0,
            circles,
            capsules,
            circles,
            capsules,
            sonar,
            sonar,
        )
        pooled(scan, c.pool_starts, c.lidar_max, o.lidar[i])
        for k in range(sonar.shape[0]):
            o.sonar[i, k] = np.float32(sonar[k] / c.sonar_max)
        o.velocity[i, 0] = np.float32(vel[0] / c.limits[0])
        o.velocity[i, 1] = np.float32(vel[1] / c.limits[2])
        index = s.task_index[i]
        current = min(index, n_targets - 1)
        following = min(index + 1, n_targets - 1)
        if c.localization == _NONE:  # the current target in the start frame
            dx = targets[current, 0] - s.start[i, 0]
            dy = targets[current, 1] - s.start[i, 1]
            cs, sn = math.cos(s.start[i, 2]), math.sin(s.start[i, 2])
            o.target[i, 0] = np.float32(min(max((cs * dx + sn * dy) / s.diagonal[i], -1.0), 1.0))
            o.target[i, 1] = np.float32(min(max((-sn * dx + cs * dy) / s.diagonal[i], -1.0), 1.0))
        else:
            _polar(targets[current, 0], targets[current, 1], est, s.diagonal[i], o.waypoint[i])
            _polar(targets[following, 0], targets[following, 1], est, s.diagonal[i], o.next_waypoint[i])
        if c.full_scan:
            for k in range(scan.shape[0]):
                o.scan[i, k] = np.float32(scan[k] / c.lidar_max)
        # GreenhouseNavEnv._info
        o.reward[i] = sums[6]
        o.terminated[i] = terminated
        o.truncated[i] = truncated
        f = o.info_f[i]
        for k in range(6):
            f[k] = sums[k]
        f[6], f[7], f[8], f[9] = d, alpha, clearance, s.min_clearance[i]
        f[10], f[11], f[12], f[13], f[14] = pose[0], pose[1], pose[2], vel[0], vel[1]
        f[15], f[16] = s.path_length[i], s.steps[i] * c.dt
        f[17], f[18], f[19] = est[0], est[1], est[2]
        o.info_i[i, 0] = index
        o.info_i[i, 1] = index
        o.info_i[i, 2] = n_targets
        o.info_i[i, 3] = s.max_steps[i]
        o.info_b[i, 0] = index >= n_targets
        o.info_b[i, 1] = collided
        o.info_b[i, 2] = reached_any
        o.info_b[i, 3] = truncated


class GreenhouseNavVectorEnv(BatchedEnv):
    """``num_envs`` GreenhouseNav-v2 worlds stepped together: the native vector form of the env.

    Made by ``gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=N, **kwargs)`` (or directly), with every
    argument of the single env (see :class:`~agri_envs.rover.greenhouse_nav.GreenhouseNavEnv`), the same
    spaces per sub-env, and the same episodes: sub-env ``i`` gives what ``gym.make(id, **kwargs)`` gives for the
    same seed and actions, bit for bit. Episodes are set up by the single env's own ``reset`` (so every reset
    option and scene argument works batched too); the steps run in one compiled loop over all sub-envs.
    Gymnasium's vector API as :class:`~agri_envs._vector.BatchedEnv` describes it: per-sub-env seeds and
    reset options (``{"start_waypoint": np.array([0, 3, 1, ...])}``), reset masks, the three autoreset modes,
    ``max_episode_steps``, ``info`` as a dict of arrays with ``_key`` masks (``truncation_reason`` only on the
    sub-envs the env truncated), ``rgb_array`` frames.

    ``envs`` holds the sub-envs. Their scene, layout and mission are the episode's; their robot, people and
    counters are the vector env's copy from the episode's start (the steps run on the vector env's arrays).

    Example::

        envs = gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=64, n_people=3, growth=0.5)
        obs, info = envs.reset(seed=0)
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())

    Args:
        num_envs: Number of sub-envs, >= 1.
        autoreset_mode: A :class:`gymnasium.vector.AutoresetMode` or its value (``"NextStep"``, ...).
        max_episode_steps: Explicit step limit of every episode (None: the mission-sized one), as
            ``gym.make(..., max_episode_steps=N)`` sets it (the crash penalty and ``info`` follow it).
        render_mode: None or ``"rgb_array"``.
        **kwargs: The single env's arguments.

    Raises:
        ValueError: For a bad ``num_envs``, ``autoreset_mode``, ``max_episode_steps`` or ``render_mode``, or a
            bad env argument (named as the single env names it).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15, "autoreset_mode": AutoresetMode.NEXT_STEP}
    INFO_KEYS = _INFO

    def __init__(
        self,
        num_envs: int = 1,
        *,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        refused = self.refusal(kwargs)
        if refused:
            raise ValueError(refused)
        super().__init__(GreenhouseNavEnv, num_envs, autoreset_mode, max_episode_steps, render_mode, kwargs)
        self.envs: list[GreenhouseNavEnv] = self.envs  # type: ignore[assignment]
        for env in self.envs:  # what SyncTimeLimit tells a single env made with an explicit limit
            env.explicit_max_episode_steps = self.max_episode_steps
        first = self.envs[0]
        self.config = first.config
        self._constants = self._shared_constants(first)
        self._state = self._empty_state()
        n = self.num_envs
        self._trail = np.zeros((n, self.config.frame_skip, 2))  # a position per control period of a step
        obs = self._obs

        def key(name: str) -> np.ndarray:
            return obs[name] if name in obs else np.zeros((n, 0), np.float32)

        self._out = _Output(
            lidar=key("lidar"),
            sonar=key("sonar"),
            velocity=key("velocity"),
            waypoint=key("waypoint"),
            next_waypoint=key("next_waypoint"),
            target=key("target"),
            scan=key("scan"),
            scan_m=np.zeros((n, first.lidar.spec.n_beams)),
            sonar_m=np.zeros((n, len(first.sonars))),
            reward=self._reward,
            terminated=self._terminated,
            truncated=self._truncated,
            info_f=self._info[float],
            info_i=self._info[int],
            info_b=self._info[bool],
            trail=self._trail,
            periods=self._periods,
        )

    @classmethod
    def refusal(cls, kwargs: dict[str, Any]) -> str | None:
        """A scene distribution that draws the robot's limits per episode: the kernel keeps one robot for all."""
        distribution = DISTRIBUTIONS.get(kwargs.get("scene_distribution", "off"))
        drawn = sorted(ROBOT_ARGUMENTS & distribution.arguments) if distribution is not None else []
        if not drawn:
            return None
        return (
            f"GreenhouseNav's batched form keeps one robot for every sub-env; scene_distribution="
            f"{kwargs['scene_distribution']!r} draws {drawn} per episode: use single envs (gym.make, or "
            "gym.make_vec(..., vectorization_mode='sync'))."
        )

    @staticmethod
    def _shared_constants(env: GreenhouseNavEnv) -> _Constants:
        cfg = env.config
        spec = env.robot_spec
        lidar = env.lidar.spec
        sonar = env.sonars.spec
        weights = cfg.reward_weights()
        return _Constants(
            dt=float(cfg.control_period),
            frame_skip=int(cfg.frame_skip),
            limits=np.array(
                [spec.max_speed, spec.max_reverse_speed, spec.max_turn_rate, spec.max_accel, spec.max_angular_accel]
            ),
            half_length=0.5 * spec.length,
            half_width=0.5 * spec.width,
            circumradius=spec.circumradius,
            localization={"ground_truth": _GROUND_TRUTH, "odometry": _ODOMETRY, "none": _NONE}[cfg.localization],
            odometry_noise=float(env.odometry.noise),
            terminate_on_collision=bool(cfg.terminate_on_collision),
            waypoint_radius=float(cfg.waypoint_radius),
            safety_margin=float(cfg.safety_margin),
            turn_distance=cfg.max_speed / cfg.max_turn_rate,
            weights=np.array(
                [
                    weights.progress,
                    weights.waypoint,
                    weights.success,
                    weights.collision,
                    weights.clearance,
                    weights.time,
                ]
            ),
            full_scan=bool(cfg.full_scan),
            lidar_mount=np.array(lidar.mount, dtype=np.float64),
            beam_ux=np.cos(lidar.beam_angles),
            beam_uy=np.sin(lidar.beam_angles),
            angle0=float(lidar.beam_angles[0]),
            dangle=float(lidar.angle_step),
            lidar_min=float(lidar.min_range),
            lidar_max=float(lidar.max_range),
            lidar_noise=float(lidar.noise_std),
            lidar_dropout=float(lidar.dropout_prob),
            pool_starts=np.ascontiguousarray(env._pool_edges, dtype=np.int64),
            sonar_mounts=np.ascontiguousarray(env.sonars.mounts),
            sonar_half_aperture=0.5 * sonar.aperture,
            sonar_min=float(sonar.min_range),
            sonar_max=float(sonar.max_range),
            sonar_noise=float(sonar.noise_std),
        )

    def _empty_state(self) -> _State:
        """Arrays for no world yet; :meth:`_load` grows them to what the episodes need."""
        n = self.num_envs
        f = np.zeros
        return _State(
            pose=f((n, 3)),
            vel=f((n, 2)),
            estimate=f((n, 3)),
            start=f((n, 3)),
            path_length=f(n),
            min_clearance=f(n),
            gyro_bias=f(n),
            last_to_go=f(n),
            max_substep=f(n),
            diagonal=f(n),
            steps=f(n, np.int64),
            max_steps=f(n, np.int64),
            task_index=f(n, np.int64),
            n_targets=f(n, np.int64),
            n_static=f(n, np.int64),
            n_people=f(n, np.int64),
            n_circles=f(n, np.int64),
            n_capsules=f(n, np.int64),
            circles=f((n, 0, 3)),
            capsules=f((n, 0, 5)),
            targets=f((n, 0, 2)),
            prev_node=f((n, 0), np.int64),
            next_node=f((n, 0), np.int64),
            speed=f((n, 0)),
            mode=f((n, 0), np.int64),
            timer=f((n, 0)),
            reacted=f((n, 0), np.bool_),
            nodes=f((n, 0, 2)),
            adjacency=f((n, 0, 0), np.int64),
            degree=f((n, 0), np.int64),
            crowd=f((n, 4)),
        )

    # -- BatchedEnv's hooks -------------------------------------------------------------------------------------
    def _load(self, i: int) -> None:
        """Copy sub-env ``i``'s freshly reset episode into the arrays."""
        env = self.envs[i]
        assert env.world is not None
        world, crowd, task = env.world, env.crowd, env.task
        graph = crowd.graph
        n_circles, n_capsules, n_targets = len(world.circles), len(world.capsules), len(task.targets)
        n_nodes, p = len(graph.nodes), crowd.n
        degree = max(1, max((len(a) for a in graph.adjacency), default=1))
        s = self._state
        sizes = {  # the padded arrays and the shape this episode needs of them
            "circles": (n_circles, 3),
            "capsules": (n_capsules, 5),
            "targets": (n_targets, 2),
            "nodes": (n_nodes, 2),
            "adjacency": (n_nodes, degree),
            "degree": (n_nodes,),
            **{name: (p,) for name in ("prev_node", "next_node", "speed", "mode", "timer", "reacted")},
        }
        grow = {
            name: grown(getattr(s, name), (self.num_envs, *shape))
            for name, shape in sizes.items()
            if any(want > have for want, have in zip(shape, getattr(s, name).shape[1:], strict=True))
        }
        if grow:  # a larger scene, route graph, mission or crowd than any before
            s = self._state = s._replace(**grow)
        s.circles[i, :n_circles] = world.circles
        s.capsules[i, :n_capsules] = world.capsules
        s.n_circles[i], s.n_capsules[i] = n_circles, n_capsules
        s.n_static[i] = len(world.geometry.circles) if world.geometry is not None else 0
        s.n_people[i] = p
        s.diagonal[i] = env.diagonal
        s.max_substep[i] = world.max_substep
        s.pose[i] = env.robot.pose
        s.vel[i] = (env.robot.v, env.robot.w)
        s.estimate[i] = env._estimate
        s.start[i] = env._start_pose
        s.path_length[i] = env._path_length
        s.min_clearance[i] = env._min_clearance
        s.gyro_bias[i] = env.odometry.gyro_bias
        s.steps[i] = env._steps
        s.max_steps[i] = env.max_episode_steps
        s.targets[i, :n_targets] = task.targets
        s.n_targets[i] = n_targets
        s.task_index[i] = task.index
        s.last_to_go[i] = task._last_to_go
        s.prev_node[i, :p] = crowd.prev_node
        s.next_node[i, :p] = crowd.next_node
        s.speed[i, :p] = crowd.speed
        s.mode[i, :p] = crowd.mode
        s.timer[i, :p] = crowd.timer
        s.reacted[i, :p] = crowd.reacted
        spec = crowd.spec
        s.crowd[i] = (spec.notice_distance, spec.tease_prob, spec.stand_range[0], spec.stand_range[1])
        s.nodes[i, :n_nodes] = graph.nodes
        for k, neighbours in enumerate(graph.adjacency):
            s.degree[i, k] = len(neighbours)
            s.adjacency[i, k, : len(neighbours)] = neighbours
        self._out.scan_m[i] = env._last_scan
        self._out.sonar_m[i] = env._last_sonar
        if self.render_mode:
            self._trails[i] = list(env._trail)

    def _run(self, actions: np.ndarray, stepping: np.ndarray) -> None:
        _step_worlds(self._rngs, actions, stepping, self._constants, self._state, self._out)

    def _truncation_reasons(self, truncated: np.ndarray) -> dict[int, str]:
        s = self._state
        reasons = {}
        for i in np.flatnonzero(truncated).tolist():
            limit = int(s.max_steps[i])
            reasons[i] = (
                f"time limit: {limit} steps ({limit * self.config.control_period:.1f} s, "
                f"{self.envs[i].time_limit_source}) reached at waypoint {int(s.task_index[i])}/{int(s.n_targets[i])}"
            )
        return reasons

    def _has(self, key: str) -> bool:
        return not (key.startswith("est_") and self.config.localization == "none")

    def _store(self, i: int) -> None:
        """Write world ``i``'s current state back into its sub-env (for drawing it)."""
        env, s, o = self.envs[i], self._state, self._out
        assert env.world is not None
        env.robot.pose = s.pose[i].copy()
        env.robot.v, env.robot.w = float(s.vel[i, 0]), float(s.vel[i, 1])
        env.world.circles[:] = s.circles[i, : s.n_circles[i]]
        env.crowd.sync_from_world()
        env.task.index = int(s.task_index[i])
        env._steps = int(s.steps[i])
        env._estimate = s.estimate[i].copy()
        env._last_scan = o.scan_m[i].copy()
        env._last_sonar = o.sonar_m[i].copy()
        env._trail = list(self._trails[i])
