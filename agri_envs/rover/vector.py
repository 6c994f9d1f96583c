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
from collections.abc import Sequence
from typing import Any, NamedTuple

import numba
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numba.typed import List as TypedList

from agri_envs.rover.greenhouse_nav import GreenhouseNavEnv
from agri_envs.sim2d.batched import (
    drive_box,
    lidar_scan,
    pooled,
    py_hypot,
    sonar_scan,
    step_people,
)
from agri_envs.sim2d.raycast import footprint_clearance

__all__ = ["GreenhouseNavVectorEnv"]

_GROUND_TRUTH, _ODOMETRY, _NONE = 0, 1, 2

#: ``info`` keys of a step, in the single env's order: (key, dtype, column of the array of that dtype).
_INFO: tuple[tuple[str, type, int], ...] = (
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
_N_INFO = {float: 20, int: 4, bool: 4}


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
def _distance_bearing(targets: np.ndarray, index: int, n: int, pose: np.ndarray) -> tuple[float, float]:
    """``WaypointTask.distance`` and ``bearing`` of the current target (the last once done)."""
    t = min(index, n - 1)
    tx, ty = targets[t, 0], targets[t, 1]
    d = py_hypot(tx - pose[0], ty - pose[1])
    a = math.atan2(ty - pose[1], tx - pose[0]) - pose[2]
    return d, math.atan2(math.sin(a), math.cos(a))


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
            elif c.localization == _ODOMETRY:  # WheelOdometry.integrate
                v_meas = vel[0] * (1.0 + c.odometry_noise * rng.standard_normal())
                w_meas = vel[1] * (1.0 + c.odometry_noise * rng.standard_normal()) + s.gyro_bias[i]
                th_mid = est[2] + 0.5 * w_meas * c.dt
                th_new = est[2] + w_meas * c.dt
                est[0] = est[0] + v_meas * c.dt * math.cos(th_mid)
                est[1] = est[1] + v_meas * c.dt * math.sin(th_mid)
                est[2] = math.atan2(math.sin(th_new), math.cos(th_new))
            s.steps[i] += 1
            clearance = footprint_clearance(
                pose[0], pose[1], pose[2], c.half_length, c.half_width, circles, capsules, -1
            )
            s.min_clearance[i] = min(s.min_clearance[i], clearance)
            o.trail[i, periods, 0] = pose[0]
            o.trail[i, periods, 1] = pose[1]
            periods += 1
            # WaypointTask.evaluate
            index = s.task_index[i]
            d, alpha = _distance_bearing(targets, index, n_targets, pose)
            progress = s.last_to_go[i] - (d + c.turn_distance * abs(alpha))
            reached = False
            if index < n_targets and d < c.waypoint_radius:
                index += 1
                s.task_index[i] = index
                reached = True
                d, alpha = _distance_bearing(targets, index, n_targets, pose)
            s.last_to_go[i] = d + c.turn_distance * abs(alpha)
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
            circles,
            capsules,
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


def _grown(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` copied into a zero array at least ``shape`` large (room to spare along the grown axes)."""
    new = tuple(want + (want - old) // 2 if want > old else old for old, want in zip(a.shape, shape, strict=True))
    if new == a.shape:
        return a
    b = np.zeros(new, dtype=a.dtype)
    b[tuple(slice(0, n) for n in a.shape)] = a
    return b


class GreenhouseNavVectorEnv(VectorEnv[dict[str, np.ndarray], np.ndarray, np.ndarray]):
    """``num_envs`` GreenhouseNav-v2 worlds stepped together: the native vector form of the env.

    Made by ``gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=N, **kwargs)`` (or directly), with every
    argument of the single env (see :class:`~agri_envs.rover.greenhouse_nav.GreenhouseNavEnv`), the same
    spaces per sub-env, and the same episodes: sub-env ``i`` gives what ``gym.make(id, **kwargs)`` gives for the
    same seed and actions, bit for bit. Episodes are set up by the single env's own ``reset`` (so every reset
    option and scene argument works batched too); the steps run in one compiled loop over all sub-envs.

    Contract (Gymnasium's vector API):

    * ``reset(seed=S)`` seeds sub-env ``i`` with ``S + i`` (as ``SyncVectorEnv``); ``seed=[s0, s1, ...]`` gives one
      seed (or None) per sub-env. ``options`` are the single env's reset options; a value that is a sequence
      of ``num_envs`` items gives one per sub-env (``{"start_waypoint": np.array([0, 3, 1, ...])}``), any other
      value goes to every sub-env. ``options={"reset_mask": mask}`` (a bool array) resets only those sub-envs,
      leaving the others' observations as they are.
    * ``step(actions)`` takes ``(num_envs, 2)`` actions (clipped to [-1, 1]; NaN or inf raises ``ValueError``
      naming the sub-env) and returns observations as a dict of ``(num_envs, ...)`` float32 arrays, rewards
      (float64), terminations and truncations (bool), and ``info`` as a dict of arrays with a ``_key`` bool
      mask telling which sub-envs have the key (``truncation_reason`` only on truncated ones).
    * ``autoreset_mode`` (``gym.make_vec(..., autoreset_mode=...)``): ``NEXT_STEP`` (default) resets a finished
      sub-env on the next ``step``, which then returns its first observation with reward 0 and ignores its
      action; ``SAME_STEP`` resets it in the step that finishes it and returns the new episode's first
      observation and ``info``, with the last observation and info of the finished episode in
      ``info["final_obs"]`` and ``info["final_info"]``; ``DISABLED`` never resets by itself: reset finished
      sub-envs with ``reset(options={"reset_mask": mask})`` before stepping them again.
    * ``max_episode_steps=N`` limits every episode to N steps as ``gym.make(..., max_episode_steps=N)`` does.
    * ``render_mode="rgb_array"``: ``render()`` returns one frame per sub-env, drawn as the single env draws.
    * ``envs``: the sub-envs. Their scene, layout and mission are the episode's; their robot, people and
      counters are the vector env's copy from the episode's start (the steps run on the vector env's arrays).

    Example::

        envs = gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=64, n_people=3, growth=0.5)
        obs, info = envs.reset(seed=0)
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())

    Args:
        num_envs: Number of sub-envs, >= 1.
        autoreset_mode: A :class:`gymnasium.vector.AutoresetMode` or its value (``"NextStep"``, ...).
        max_episode_steps: Explicit step limit of every episode (None: the mission-sized one).
        render_mode: None or ``"rgb_array"``.
        **kwargs: The single env's arguments.

    Raises:
        ValueError: For a bad ``num_envs``, ``autoreset_mode``, ``max_episode_steps`` or ``render_mode``, or a
            bad env argument (named as the single env names it).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        *,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            valid = [m.value for m in AutoresetMode]
            raise ValueError(
                f"autoreset_mode must be an AutoresetMode or one of {valid}, got {autoreset_mode!r}"
            ) from None
        if max_episode_steps is not None and (
            isinstance(max_episode_steps, bool)
            or not isinstance(max_episode_steps, (int, np.integer))
            or max_episode_steps < 1
        ):
            raise ValueError(f"max_episode_steps must be an integer >= 1 or None, got {max_episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array' for the vector env, got {render_mode!r}")
        self.num_envs = int(num_envs)
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        self.render_mode = render_mode
        self.envs = [GreenhouseNavEnv(render_mode=render_mode, **kwargs) for _ in range(self.num_envs)]
        for env in self.envs:
            env.explicit_max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        first = self.envs[0]
        self.config = first.config
        self.single_observation_space: spaces.Dict = first.observation_space  # type: ignore[assignment]
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._constants = self._shared_constants(first)
        self._state = self._empty_state()
        self._out = self._empty_output()
        self._rngs: Any = None  # the sub-envs' generators, as a numba typed list (after the first reset)
        self._rng_objects: list[Any] = [None] * self.num_envs
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)
        self._max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self._elapsed = np.zeros(self.num_envs, dtype=np.int64)  # steps since each sub-env's reset
        self._trails: list[list[tuple[float, float]]] = [[] for _ in range(self.num_envs)]  # with render_mode only
        self._started = False
        self.closed = False

    # -- set-up -----------------------------------------------------------------------------------------------
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
        """Arrays for one world of each kind of thing; :meth:`_load` grows them to what the episodes need."""
        n, p, n_circles, n_capsules, n_targets, n_nodes, degree = self.num_envs, 0, 0, 0, 0, 0, 0
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
            circles=f((n, n_circles, 3)),
            capsules=f((n, n_capsules, 5)),
            targets=f((n, n_targets, 2)),
            prev_node=f((n, p), np.int64),
            next_node=f((n, p), np.int64),
            speed=f((n, p)),
            mode=f((n, p), np.int64),
            timer=f((n, p)),
            reacted=f((n, p), np.bool_),
            nodes=f((n, n_nodes, 2)),
            adjacency=f((n, n_nodes, degree), np.int64),
            degree=f((n, n_nodes), np.int64),
            crowd=f((n, 4)),
        )

    def _empty_output(self) -> _Output:
        n = self.num_envs
        space = self.single_observation_space

        def obs(key: str) -> np.ndarray:
            shape: tuple[int, ...] = space[key].shape or () if key in space.spaces else (0,)
            return np.zeros((n, *shape), np.float32)

        n_beams = self.envs[0].lidar.spec.n_beams
        return _Output(
            lidar=obs("lidar"),
            sonar=obs("sonar"),
            velocity=obs("velocity"),
            waypoint=obs("waypoint"),
            next_waypoint=obs("next_waypoint"),
            target=obs("target"),
            scan=obs("scan"),
            scan_m=np.zeros((n, n_beams)),
            sonar_m=np.zeros((n, len(self.envs[0].sonars))),
            reward=np.zeros(n),
            terminated=np.zeros(n, np.bool_),
            truncated=np.zeros(n, np.bool_),
            info_f=np.zeros((n, _N_INFO[float])),
            info_i=np.zeros((n, _N_INFO[int]), np.int64),
            info_b=np.zeros((n, _N_INFO[bool]), np.bool_),
            trail=np.zeros((n, self.config.frame_skip, 2)),
            periods=np.zeros(n, np.int64),
        )

    def _load(self, i: int, obs: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        """Copy sub-env ``i``'s freshly reset episode (and its first observation and info) into the arrays."""
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
            name: _grown(getattr(s, name), (self.num_envs, *shape))
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
        s.nodes[i, : len(graph.nodes)] = graph.nodes
        for k, neighbours in enumerate(graph.adjacency):
            s.degree[i, k] = len(neighbours)
            s.adjacency[i, k, : len(neighbours)] = neighbours
        o = self._out
        for key, value in obs.items():
            getattr(o, key)[i] = value
        o.scan_m[i] = env._last_scan
        o.sonar_m[i] = env._last_sonar
        self._write_info(i, info)
        self._elapsed[i] = 0
        if env.np_random is not self._rng_objects[i]:  # a seeded reset made a new generator
            self._rng_objects[i] = env.np_random
            if self._rngs is not None:
                self._rngs[i] = env.np_random
        self._trails[i] = [(float(env.robot.pose[0]), float(env.robot.pose[1]))] if self.render_mode else []

    def _write_info(self, i: int, info: dict[str, Any]) -> None:
        """Put one sub-env's ``info`` dict into the info arrays' row ``i``."""
        arrays = {float: self._out.info_f, int: self._out.info_i, bool: self._out.info_b}
        for key, kind, col in _INFO:
            if key in info:
                arrays[kind][i, col] = info[key]

    # -- the vector API ---------------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset every sub-env (or those of ``options["reset_mask"]``); see the class docstring."""
        if self.closed:
            raise RuntimeError("the vector env is closed")
        seeds = self._seeds(seed)
        opts = dict(options or {})
        mask = self._reset_mask(opts.pop("reset_mask", None))
        per_env = self._per_env_options(opts)
        if mask is None or not self._started:  # the first reset sets every sub-env up
            mask = np.ones(self.num_envs, dtype=np.bool_)
        for i in np.flatnonzero(mask).tolist():
            obs, info = self.envs[i].reset(seed=seeds[i], options=per_env[i])
            self._load(i, obs, info)
        if self._rngs is None:
            self._rngs = TypedList(self._rng_objects)
        self._started = True
        self._autoreset[mask] = False
        self._out.terminated[mask] = False
        self._out.truncated[mask] = False
        return self._observations(), self._infos(mask, {})

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-env (see the class docstring for what happens to finished ones)."""
        if self.closed or not self._started:
            raise RuntimeError("call reset() before step()" if not self.closed else "the vector env is closed")
        a = self._checked_actions(actions)
        o = self._out
        if self.autoreset_mode == AutoresetMode.DISABLED and self._autoreset.any():
            done = np.flatnonzero(self._autoreset).tolist()
            raise RuntimeError(
                f"sub-envs {done} finished their episodes: reset them with reset(options={{'reset_mask': mask}}) "
                "before stepping them again (autoreset_mode=DISABLED)"
            )
        stepping = ~self._autoreset if self.autoreset_mode == AutoresetMode.NEXT_STEP else np.ones_like(self._autoreset)
        _step_worlds(self._rngs, a, stepping, self._constants, self._state, o)
        # the env's own truncations say why in info; TimeLimit's below do not
        reasons = {int(i): self._truncation_reason(int(i)) for i in np.flatnonzero(stepping & o.truncated)}
        self._elapsed[stepping] += 1
        if self._max_episode_steps is not None:  # gym.make's TimeLimit: truncated at N steps even when terminated
            o.truncated[stepping & (self._elapsed >= self._max_episode_steps)] = True
        if self.render_mode:
            for k in np.flatnonzero(stepping).tolist():
                self._trails[k].extend(map(tuple, o.trail[k, : o.periods[k]].tolist()))
        final: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            for i in np.flatnonzero(self._autoreset).tolist():
                obs, info = self.envs[i].reset()
                self._load(i, obs, info)
                o.reward[i] = 0.0
                o.terminated[i] = o.truncated[i] = False
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            for i in np.flatnonzero(o.terminated | o.truncated).tolist():
                final = self._add_info(
                    final,
                    {"final_obs": self._observation(i), "final_info": self._info(i, reasons.pop(i, None))},
                    i,
                )
                obs, info = self.envs[i].reset()
                self._load(i, obs, info)
        self._autoreset = o.terminated | o.truncated
        infos = self._infos(np.ones(self.num_envs, dtype=np.bool_), reasons)
        infos.update(final)
        return self._observations(), o.reward.copy(), o.terminated.copy(), o.truncated.copy(), infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``rgb_array`` frame per sub-env, as the single env draws it (None without a render mode)."""
        if self.render_mode is None:
            return None
        if not self._started:
            raise RuntimeError("call reset() before render()")
        frames = []
        for i, env in enumerate(self.envs):
            self._store(i)
            frame = env.render()
            assert frame is not None
            frames.append(frame)
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        """Close every sub-env (their renderers and pymunk worlds)."""
        for env in self.envs:
            env.close()

    # -- helpers ----------------------------------------------------------------------------------------------
    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(self.num_envs)]
        if isinstance(seed, bool):
            raise ValueError(f"reset: seed must be an int, None or one seed per sub-env, got {seed!r}")
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(
                f"reset: seed must be an int, None or {self.num_envs} seeds (one per sub-env), got {len(seeds)}"
            )
        return seeds

    def _reset_mask(self, mask: Any) -> np.ndarray | None:
        if mask is None:
            return None
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (self.num_envs,):
            raise ValueError(f"reset option reset_mask must be a bool array of shape ({self.num_envs},), got {mask!r}")
        if not mask.any():
            raise ValueError("reset option reset_mask must select at least one sub-env")
        return mask

    def _per_env_options(self, options: dict[str, Any]) -> list[dict[str, Any] | None]:
        """One options dict per sub-env: sequences of ``num_envs`` values are split, others shared."""
        if not options:
            return [None] * self.num_envs
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for key, value in options.items():
            if isinstance(value, (list, tuple, np.ndarray)):
                if len(value) != self.num_envs:
                    raise ValueError(
                        f"reset option {key!r}: give one value for every sub-env ({self.num_envs}) or a single value, "
                        f"got {len(value)}"
                    )
                values = value.tolist() if isinstance(value, np.ndarray) else list(value)
            else:
                values = [value] * self.num_envs
            for opts, v in zip(out, values, strict=True):
                opts[key] = v
        return list(out)

    def _checked_actions(self, actions: Any) -> np.ndarray:
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (self.num_envs, 2):
            raise ValueError(f"actions must have shape ({self.num_envs}, 2), got {a.shape}")
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(f"actions of sub-envs {np.flatnonzero(bad).tolist()} contain NaN or inf")
        return np.minimum(np.maximum(a, -1.0), 1.0)

    def _truncation_reason(self, i: int) -> str:
        env, s = self.envs[i], self._state
        limit = int(s.max_steps[i])
        return (
            f"time limit: {limit} steps ({limit * self.config.control_period:.1f} s, {env.time_limit_source})"
            f" reached at waypoint {int(s.task_index[i])}/{int(s.n_targets[i])}"
        )

    def _observations(self) -> dict[str, np.ndarray]:
        o = self._out
        return {key: getattr(o, key).copy() for key in self.single_observation_space.spaces}

    def _observation(self, i: int) -> dict[str, np.ndarray]:
        o = self._out
        return {key: getattr(o, key)[i].copy() for key in self.single_observation_space.spaces}

    def _info(self, i: int, reason: str | None) -> dict[str, Any]:
        """Sub-env ``i``'s info as the single env returns it (Python scalars)."""
        arrays = {float: self._out.info_f, int: self._out.info_i, bool: self._out.info_b}
        info = {key: kind(arrays[kind][i, col]) for key, kind, col in _INFO if self._has(key)}
        if reason is not None:
            info["truncation_reason"] = reason
        return info

    def _has(self, key: str) -> bool:
        return not (key.startswith("est_") and self.config.localization == "none")

    def _infos(self, mask: np.ndarray, reasons: dict[int, str]) -> dict[str, Any]:
        """The info dict of arrays for the sub-envs of ``mask`` (as ``VectorEnv._add_info`` lays it out)."""
        arrays = {float: self._out.info_f, int: self._out.info_i, bool: self._out.info_b}
        full = bool(mask.all())
        infos: dict[str, Any] = {}
        for key, kind, col in _INFO:
            if not self._has(key):
                continue
            values = arrays[kind][:, col].copy()
            if not full:
                values[~mask] = 0
            infos[key] = values
            infos[f"_{key}"] = mask.copy()
        if reasons:
            text = np.full(self.num_envs, None, dtype=object)
            has = np.zeros(self.num_envs, dtype=np.bool_)
            for i, reason in reasons.items():
                text[i], has[i] = reason, True
            infos["truncation_reason"], infos["_truncation_reason"] = text, has
        return infos

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
