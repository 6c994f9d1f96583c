"""GreenhouseCoverage-v2 as a native Gymnasium ``VectorEnv``: N greenhouses covered together in one compiled loop.

``gym.make_vec("agri_envs/GreenhouseCoverage-v2", num_envs=N, **kwargs)`` builds
:class:`GreenhouseCoverageVectorEnv`. Each sub-env is a
:class:`~agri_envs.coverage.greenhouse_coverage.GreenhouseCoverageEnv` whose own ``reset`` sets every episode
up (a greenhouse drawn from ``scene_distribution`` too); :func:`_step_worlds` then steps all the worlds
(drive with exact contact, crop or other contact, compass, track encoders, coverage bins, progress along the
serpentine and the reward, sonars with their foliage echoes and noise, the memory and the observation) in
one numba call, drawing each world's noise from its sub-env's generator. For the same seeds and actions it gives
the single env's numbers bit for bit (``tests/envs/test_coverage_vector.py``), contacts aside as
:mod:`agri_envs.sim2d.batched` says.

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
from agri_envs.coverage import robot as fito
from agri_envs.coverage.greenhouse_coverage import GreenhouseCoverageEnv
from agri_envs.sim2d.batched import compass_read, drive_box, py_hypot, route_advance, sonar_scan, track_odometry
from agri_envs.sim2d.egomap import egocentric_view, mark_memory
from agri_envs.sim2d.raycast import footprint_clearance

__all__ = ["GreenhouseCoverageVectorEnv"]

#: ``info`` keys of a step, in the single env's order: (key, dtype, column of the array of that dtype).
_INFO: tuple[InfoKey, ...] = (
    ("reward_coverage", float, 0),
    ("reward_progress", float, 1),
    ("reward_success", float, 2),
    ("reward_contact", float, 3),
    ("reward_cross_track", float, 4),
    ("reward_time", float, 5),
    ("is_success", bool, 0),
    ("corridor", int, 0),
    ("cross_track", float, 6),
    ("max_cross_track", float, 7),
    ("coverage", float, 8),
    ("corridors_covered", int, 1),
    ("subgoal_index", int, 2),
    ("n_corridors", int, 3),
    ("mean_cross_track", float, 9),
    ("crop_contacts", int, 4),
    ("other_contacts", int, 5),
    ("collision", bool, 1),
    ("clearance", float, 10),
    ("min_clearance", float, 11),
    ("x", float, 12),
    ("y", float, 13),
    ("yaw", float, 14),
    ("est_x", float, 15),
    ("est_y", float, 16),
    ("compass", float, 17),
    ("v", float, 18),
    ("w", float, 19),
    ("path_length", float, 20),
    ("episode_time", float, 21),
    *((f"sonar_{name}", float, 22 + k) for k, name in enumerate(fito.SONAR_NAMES)),
)


class _Constants(NamedTuple):
    """What every world of the batch shares: the config, the robot and its sensors' layout."""

    dt: float
    limits: np.ndarray  # max_speed, max_reverse_speed, max_turn_rate, max_accel, max_angular_accel
    half_length: float
    half_width: float
    circumradius: float
    ground_truth: bool
    terminate_on_contact: bool
    weights: np.ndarray  # coverage, progress, success, contact, cross_track, time
    gauge: float
    pose_scale: np.ndarray  # (2,) m
    sonar_mounts: np.ndarray
    sonar_half_aperture: float
    sonar_min: float
    sonar_max: float
    sonar_noise: float
    memory_cell: float  # the memory grid's cell size (m)


class _State(NamedTuple):
    """Each world's episode state, padded to the largest greenhouse and mission met so far."""

    pose: np.ndarray  # (n, 3)
    vel: np.ndarray  # (n, 2)
    estimate: np.ndarray  # (n, 2) the encoders' position estimate
    encoder: np.ndarray  # (n, 2) the measured v, w
    scale: np.ndarray  # (n, 2) the encoders' scale errors
    compass: np.ndarray  # (n,) the last compass reading (rad)
    # the episode's sensor arguments (a scene distribution may draw them)
    compass_bias: np.ndarray  # (n,) rad
    compass_noise: np.ndarray  # (n,) rad
    encoder_noise: np.ndarray  # (n,)
    slip_prob: np.ndarray  # (n,) the sonars' foliage slip probability
    path_length: np.ndarray
    min_clearance: np.ndarray
    cross_sum: np.ndarray
    max_cross_track: np.ndarray
    max_substep: np.ndarray
    steps: np.ndarray
    max_steps: np.ndarray
    crop_contacts: np.ndarray
    other_contacts: np.ndarray
    cross_n: np.ndarray
    counts: np.ndarray  # (n, 6): circles, capsules, crop circles, crop capsules, solid circles, solid capsules
    circles: np.ndarray  # (n, C, 3)
    capsules: np.ndarray  # (n, S, 5)
    crop_circles: np.ndarray
    crop_capsules: np.ndarray
    solid_circles: np.ndarray
    solid_capsules: np.ndarray
    n_corridors: np.ndarray  # (n,)
    lines: np.ndarray  # (n, K, P, 2) corridor centre lines
    n_points: np.ndarray  # (n, K)
    n_bins: np.ndarray  # (n, K)
    first_bin: np.ndarray  # (n, K) index of each corridor's first bin in ``covered``
    covered: np.ndarray  # (n, B) bool
    covered_count: np.ndarray  # (n, K)
    subgoals: np.ndarray  # (n, G, 2) the covering serpentine's subgoals
    n_subgoals: np.ndarray  # (n,)
    subgoal_index: np.ndarray  # (n,) the current subgoal
    last_to_go: np.ndarray  # (n,) its distance to go at the last step (m)
    subgoal_radius: np.ndarray  # (n,) m
    turn_distance: np.ndarray  # (n,) m/rad
    memory: np.ndarray  # (n, 2, NY, NX) each robot's memory grid (EgoMap.grid)
    memory_size: np.ndarray  # (n, 2) its rows and columns
    memory_origin: np.ndarray  # (n, 2) its origin (m)


class _Output(NamedTuple):
    """What a step writes: observations, rewards, flags, info values and the sonar readings in metres."""

    sonar: np.ndarray
    compass: np.ndarray
    velocity: np.ndarray
    pose_obs: np.ndarray
    memory: np.ndarray
    sonar_m: np.ndarray
    hard: np.ndarray  # scratch for the sonars' echoes off solid obstacles
    sensor_poses: np.ndarray  # scratch: the sonars' estimated poses
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    info_f: np.ndarray
    info_i: np.ndarray
    info_b: np.ndarray
    trail: np.ndarray


@numba.njit(cache=True)
def _locate(lines: np.ndarray, n_points: np.ndarray, n_corridors: int, x: float, y: float) -> tuple[int, float]:
    """``CoverageTask.locate``: the corridor ``(x, y)`` is in (-1 in the headlands) and its cross-track error."""
    best = -1
    best_d = math.inf
    for k in range(n_corridors):
        m = n_points[k]
        if not lines[k, 0, 0] <= x <= lines[k, m - 1, 0]:
            continue
        below = 0  # np.searchsorted(xs, x): the number of points left of x
        while below < m and lines[k, below, 0] < x:
            below += 1
        seg = min(max(below - 1, 0), m - 2)
        ax, ay = lines[k, seg, 0], lines[k, seg, 1]
        bx, by = lines[k, seg + 1, 0], lines[k, seg + 1, 1]
        t = (x - ax) / (bx - ax) if bx != ax else 0.0
        dy = y - (ay + t * (by - ay))
        d = abs(dy) * math.cos(math.atan2(by - ay, bx - ax))  # perpendicular distance to the segment
        if d < best_d:
            best = k
            best_d = d
    return best, (best_d if best >= 0 else 0.0)


@numba.njit(cache=True)
def _step_worlds(rngs: Any, actions: np.ndarray, active: np.ndarray, c: _Constants, s: _State, o: _Output) -> None:
    """``GreenhouseCoverageEnv.step`` for every ``active`` world.

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
        n = s.counts[i]
        circles, capsules = s.circles[i, : n[0]], s.capsules[i, : n[1]]
        u, r = actions[i, 0], actions[i, 1]  # DiffDriveSpec.command
        v_cmd = u * (c.limits[0] if u >= 0 else c.limits[1])
        w_cmd = r * c.limits[2]
        bx, by = pose[0], pose[1]
        contact = drive_box(
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
        s.path_length[i] += py_hypot(pose[0] - bx, pose[1] - by)
        crop_contact = False
        other_contact = False
        if contact:  # which obstacle stopped the robot: the nearer of the crop and the rest
            hl, hw = c.half_length, c.half_width
            crop = footprint_clearance(
                pose[0], pose[1], pose[2], hl, hw, s.crop_circles[i, : n[2]], s.crop_capsules[i, : n[3]], -1
            )
            solid = footprint_clearance(
                pose[0], pose[1], pose[2], hl, hw, s.solid_circles[i, : n[4]], s.solid_capsules[i, : n[5]], -1
            )
            crop_contact = crop <= solid
            other_contact = not crop_contact
        s.crop_contacts[i] += crop_contact
        s.other_contacts[i] += other_contact
        s.steps[i] += 1
        h = compass_read(rng, pose[2], s.compass_bias[i], s.compass_noise[i])
        s.compass[i] = h
        enc_v, enc_w = track_odometry(
            rng, vel[0], vel[1], h, c.dt, c.gauge, s.scale[i], s.encoder_noise[i], s.estimate[i]
        )
        s.encoder[i, 0], s.encoder[i, 1] = enc_v, enc_w
        o.trail[i, 0, 0], o.trail[i, 0, 1] = pose[0], pose[1]
        # CoverageTask.evaluate
        x, y = pose[0], pose[1]
        n_corridors = s.n_corridors[i]
        total = s.first_bin[i, n_corridors]
        k, cross = _locate(s.lines[i], s.n_points[i], n_corridors, x, y)
        gained = 0
        if k >= 0:
            x0 = s.lines[i, k, 0, 0]
            x1 = s.lines[i, k, s.n_points[i, k] - 1, 0]
            b = min(s.n_bins[i, k] - 1, int((x - x0) / (x1 - x0) * s.n_bins[i, k]))
            if not s.covered[i, s.first_bin[i, k] + b]:
                s.covered[i, s.first_bin[i, k] + b] = True
                s.covered_count[i, k] += 1
                gained = 1
            s.max_cross_track[i] = max(s.max_cross_track[i], cross)
        progress, s.subgoal_index[i], s.last_to_go[i], _, _ = route_advance(
            s.subgoals[i],
            s.n_subgoals[i],
            s.subgoal_index[i],
            s.last_to_go[i],
            s.subgoal_radius[i],
            s.turn_distance[i],
            pose,
        )
        covered = np.sum(s.covered_count[i, :n_corridors])
        coverage = covered / total
        success = covered == total
        terms = (
            w[0] * (gained / total) * n_corridors,
            w[1] * progress,
            w[2] * (1.0 if success else 0.0),
            -w[3] * (1.0 if (crop_contact or other_contact) else 0.0),
            -w[4] * cross,
            -w[5],
        )
        reward = 0.0
        for term in terms:
            reward += term
        # GreenhouseCoverageEnv._track
        clearance = footprint_clearance(pose[0], pose[1], pose[2], c.half_length, c.half_width, circles, capsules, -1)
        s.min_clearance[i] = min(s.min_clearance[i], clearance)
        if k >= 0:
            s.cross_sum[i] += cross
            s.cross_n[i] += 1
        terminated = success or (contact and c.terminate_on_contact)
        o.reward[i] = reward
        o.terminated[i] = terminated
        o.truncated[i] = not terminated and s.steps[i] >= s.max_steps[i]
        # GreenhouseCoverageEnv._observe
        sonar = o.sonar_m[i]
        sonar_scan(
            rng,
            pose,
            c.sonar_mounts,
            c.sonar_half_aperture,
            c.sonar_min,
            c.sonar_max,
            c.sonar_noise,
            s.slip_prob[i],
            circles,
            capsules,
            s.solid_circles[i, : n[4]],
            s.solid_capsules[i, : n[5]],
            sonar,
            o.hard[i],
        )
        for j in range(sonar.shape[0]):
            o.sonar[i, j] = np.float32(sonar[j] / c.sonar_max)
        o.compass[i, 0] = np.float32(0.5 + 0.5 * math.sin(h))
        o.compass[i, 1] = np.float32(0.5 + 0.5 * math.cos(h))
        half = np.float32(0.5)
        zero, one = np.float32(0.0), np.float32(1.0)
        o.velocity[i, 0] = min(max(half + half * np.float32(enc_v / c.limits[0]), zero), one)
        o.velocity[i, 1] = min(max(half + half * np.float32(enc_w / c.limits[2]), zero), one)
        if c.ground_truth:
            px, py, ph = pose[0], pose[1], pose[2]
        else:
            px, py, ph = s.estimate[i, 0], s.estimate[i, 1], h
        # EgoMap.update with the sonars' poses_in_world, then EgoMap.view: the memory in the estimate's frame
        cs, sn = math.cos(ph), math.sin(ph)
        m, poses = c.sonar_mounts, o.sensor_poses[i]
        for j in range(m.shape[0]):
            poses[j, 0] = px + cs * m[j, 0] - sn * m[j, 1]
            poses[j, 1] = py + sn * m[j, 0] + cs * m[j, 1]
            poses[j, 2] = ph + m[j, 2]
        grid = s.memory[i, :, : s.memory_size[i, 0], : s.memory_size[i, 1]]
        x0, y0 = s.memory_origin[i, 0], s.memory_origin[i, 1]
        mark_memory(grid, x0, y0, c.memory_cell, px, py, poses, sonar, c.sonar_max)
        egocentric_view(grid, x0, y0, c.memory_cell, px, py, ph, o.memory[i])
        for j, value in enumerate(
            (px / c.pose_scale[0], py / c.pose_scale[1], 0.5 + 0.5 * math.sin(ph), 0.5 + 0.5 * math.cos(ph))
        ):
            o.pose_obs[i, j] = min(max(np.float32(value), zero), one)
        # GreenhouseCoverageEnv._info
        f = o.info_f[i]
        for j in range(6):
            f[j] = terms[j]
        f[6], f[7], f[8] = cross, s.max_cross_track[i], coverage
        f[9] = s.cross_sum[i] / s.cross_n[i] if s.cross_n[i] else 0.0
        f[10], f[11] = clearance, s.min_clearance[i]
        f[12], f[13], f[14] = pose[0], pose[1], pose[2]
        f[15], f[16], f[17] = s.estimate[i, 0], s.estimate[i, 1], h
        f[18], f[19], f[20], f[21] = vel[0], vel[1], s.path_length[i], s.steps[i] * c.dt
        for j in range(sonar.shape[0]):
            f[22 + j] = sonar[j]
        done = 0
        for j in range(n_corridors):
            done += s.covered_count[i, j] == s.n_bins[i, j]
        o.info_i[i, 0] = k
        o.info_i[i, 1] = done
        o.info_i[i, 2] = s.subgoal_index[i]
        o.info_i[i, 3] = n_corridors
        o.info_i[i, 4] = s.crop_contacts[i]
        o.info_i[i, 5] = s.other_contacts[i]
        o.info_b[i, 0] = success
        o.info_b[i, 1] = s.crop_contacts[i] > 0 or s.other_contacts[i] > 0


class GreenhouseCoverageVectorEnv(BatchedEnv):
    """``num_envs`` GreenhouseCoverage-v2 worlds stepped together: the native vector form of the env.

    Made by ``gym.make_vec("agri_envs/GreenhouseCoverage-v2", num_envs=N, **kwargs)`` (or directly), with every
    argument of the single env (see :class:`~agri_envs.coverage.greenhouse_coverage.GreenhouseCoverageEnv`), the
    same spaces per sub-env and the same episodes: sub-env ``i`` gives what ``gym.make(id, **kwargs)`` gives for
    the same seed and actions, bit for bit. Episodes are set up by the single env's own ``reset``; the steps
    run in one compiled loop over all sub-envs. Gymnasium's vector API as
    :class:`~agri_envs._vector.BatchedEnv` describes it.

    ``envs`` holds the sub-envs. Their greenhouse and corridors are the episode's; their robot, coverage,
    route, memory and counters are the vector env's copy from the episode's start (the steps run on the
    vector env's arrays).

    Example::

        envs = gym.make_vec("agri_envs/GreenhouseCoverage-v2", num_envs=64, n_rows=6)
        obs, info = envs.reset(seed=0)
        obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())

    Args:
        num_envs: Number of sub-envs, >= 1.
        autoreset_mode: A :class:`gymnasium.vector.AutoresetMode` or its value (``"NextStep"``, ...).
        max_episode_steps: Step limit of every episode, as ``gym.make(..., max_episode_steps=N)`` sets it
            (None: the env's own ``time_limit``).
        render_mode: None or ``"rgb_array"``.
        **kwargs: The single env's arguments.

    Raises:
        ValueError: For a bad ``num_envs``, ``autoreset_mode``, ``max_episode_steps`` or ``render_mode``, or a
            bad env argument (named as the single env names it).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10, "autoreset_mode": AutoresetMode.NEXT_STEP}
    INFO_KEYS = _INFO

    @classmethod
    def refusal(cls, kwargs: dict[str, Any]) -> str | None:
        """The privileged ``route`` observation: the kernel does not compute it."""
        if not kwargs.get("route_observation", False):
            return None
        return (
            "GreenhouseCoverage's batched form has no route observation (route_observation=True): use single envs "
            "(gym.make, or gym.make_vec(..., vectorization_mode='sync'))."
        )

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
        super().__init__(GreenhouseCoverageEnv, num_envs, autoreset_mode, max_episode_steps, render_mode, kwargs)
        self.envs: list[GreenhouseCoverageEnv] = self.envs  # type: ignore[assignment]
        first = self.envs[0]
        self.config = cfg = first.config
        spec = first.robot_spec
        sonar = first.sonars.spec
        weights = cfg.weights()
        self._constants = _Constants(
            dt=float(cfg.control_period),
            limits=np.array(
                [spec.max_speed, spec.max_reverse_speed, spec.max_turn_rate, spec.max_accel, spec.max_angular_accel]
            ),
            half_length=0.5 * spec.length,
            half_width=0.5 * spec.width,
            circumradius=spec.circumradius,
            ground_truth=cfg.localization == "ground_truth",
            terminate_on_contact=bool(cfg.terminate_on_contact),
            weights=np.array(
                [
                    weights.coverage,
                    weights.progress,
                    weights.success,
                    weights.contact,
                    weights.cross_track,
                    weights.time,
                ]
            ),
            gauge=float(first.encoders.gauge),
            pose_scale=np.array(first.pose_scale, dtype=np.float64),
            sonar_mounts=np.ascontiguousarray(first.sonars.mounts),
            sonar_half_aperture=0.5 * sonar.aperture,
            sonar_min=float(sonar.min_range),
            sonar_max=float(sonar.max_range),
            sonar_noise=float(sonar.noise_std),
            memory_cell=float(first.memory.spec.cell),
        )
        n = self.num_envs
        f = np.zeros
        self._state = _State(
            pose=f((n, 3)),
            vel=f((n, 2)),
            estimate=f((n, 2)),
            encoder=f((n, 2)),
            scale=f((n, 2)),
            compass=f(n),
            compass_bias=f(n),
            compass_noise=f(n),
            encoder_noise=f(n),
            slip_prob=f(n),
            path_length=f(n),
            min_clearance=f(n),
            cross_sum=f(n),
            max_cross_track=f(n),
            max_substep=f(n),
            steps=f(n, np.int64),
            max_steps=f(n, np.int64),
            crop_contacts=f(n, np.int64),
            other_contacts=f(n, np.int64),
            cross_n=f(n, np.int64),
            counts=f((n, 6), np.int64),
            circles=f((n, 0, 3)),
            capsules=f((n, 0, 5)),
            crop_circles=f((n, 0, 3)),
            crop_capsules=f((n, 0, 5)),
            solid_circles=f((n, 0, 3)),
            solid_capsules=f((n, 0, 5)),
            n_corridors=f(n, np.int64),
            lines=f((n, 0, 0, 2)),
            n_points=f((n, 0), np.int64),
            n_bins=f((n, 0), np.int64),
            first_bin=f((n, 1), np.int64),
            covered=f((n, 0), np.bool_),
            covered_count=f((n, 0), np.int64),
            subgoals=f((n, 0, 2)),
            n_subgoals=f(n, np.int64),
            subgoal_index=f(n, np.int64),
            last_to_go=f(n),
            subgoal_radius=f(n),
            turn_distance=f(n),
            memory=f((n, 2, 0, 0)),
            memory_size=f((n, 2), np.int64),
            memory_origin=f((n, 2)),
        )
        obs = self._obs
        self._out = _Output(
            sonar=obs["sonar"],
            compass=obs["compass"],
            velocity=obs["velocity"],
            pose_obs=obs["pose"],
            memory=obs["memory"].reshape(n, *first.memory.shape),  # a view: the kernel writes the flat key
            sonar_m=np.zeros((n, len(first.sonars))),
            hard=np.zeros((n, len(first.sonars))),
            sensor_poses=np.zeros((n, len(first.sonars), 3)),
            reward=self._reward,
            terminated=self._terminated,
            truncated=self._truncated,
            info_f=self._info[float],
            info_i=self._info[int],
            info_b=self._info[bool],
            trail=self._trail,
        )
        self._periods[:] = 1

    # -- BatchedEnv's hooks -------------------------------------------------------------------------------------
    def _load(self, i: int) -> None:
        """Copy sub-env ``i``'s freshly reset episode into the arrays."""
        env = self.envs[i]
        assert env.world is not None and env.layout is not None
        world, task = env.world, env.task
        crop, solid = env._crop, env._solid
        primitives = (world.circles, world.capsules, crop[0], crop[1], solid[0], solid[1])
        names = ("circles", "capsules", "crop_circles", "crop_capsules", "solid_circles", "solid_capsules")
        lines = task.corridors
        route, grid = task.route, env.memory.grid
        n_corridors = len(lines)
        n_points = max(len(line) for line in lines)
        n_bins = [int(b) for b in task.n_bins]
        s = self._state
        sizes = {
            **{name: (len(p), p.shape[1]) for name, p in zip(names, primitives, strict=True)},
            "lines": (n_corridors, n_points, 2),
            "n_points": (n_corridors,),
            "n_bins": (n_corridors,),
            "first_bin": (n_corridors + 1,),
            "covered": (sum(n_bins),),
            "covered_count": (n_corridors,),
            "subgoals": route.targets.shape,
            "memory": grid.shape,
        }
        grow = {
            name: grown(getattr(s, name), (self.num_envs, *shape))
            for name, shape in sizes.items()
            if any(want > have for want, have in zip(shape, getattr(s, name).shape[1:], strict=True))
        }
        if grow:  # a larger greenhouse or more corridors than any before
            s = self._state = s._replace(**grow)
        for k, (name, p) in enumerate(zip(names, primitives, strict=True)):
            getattr(s, name)[i, : len(p)] = p
            s.counts[i, k] = len(p)
        s.n_corridors[i] = n_corridors
        first = np.concatenate([[0], np.cumsum(n_bins)])
        s.first_bin[i, : n_corridors + 1] = first
        for k, line in enumerate(lines):
            s.lines[i, k, : len(line)] = line
            s.n_points[i, k] = len(line)
            s.n_bins[i, k] = n_bins[k]
            s.covered[i, first[k] : first[k + 1]] = task.covered[k]
            s.covered_count[i, k] = int(task.covered[k].sum())
        s.max_cross_track[i] = task.max_cross_track
        s.subgoals[i, : len(route.targets)] = route.targets
        s.n_subgoals[i] = len(route.targets)
        s.subgoal_index[i] = route.index
        s.last_to_go[i] = route._last_to_go
        s.subgoal_radius[i] = route.radius
        s.turn_distance[i] = route.turn_distance
        s.memory[i, :, : grid.shape[1], : grid.shape[2]] = grid
        s.memory_size[i] = grid.shape[1:]
        s.memory_origin[i] = env.memory.origin
        s.max_substep[i] = world.max_substep
        s.pose[i] = env.robot.pose
        s.vel[i] = (env.robot.v, env.robot.w)
        s.estimate[i] = env.encoders.estimate
        s.encoder[i] = (env.encoders.v, env.encoders.w)
        s.scale[i] = env.encoders.scale
        s.compass[i] = env._compass
        s.compass_bias[i] = env.compass.bias
        s.compass_noise[i] = env.compass.noise_std
        s.encoder_noise[i] = env.encoders.noise
        s.slip_prob[i] = env.sonars.spec.foliage_slip_prob
        s.path_length[i] = env._path_length
        s.min_clearance[i] = env._min_clearance
        s.cross_sum[i] = env._cross_sum
        s.cross_n[i] = env._cross_n
        s.crop_contacts[i] = env._crop_contacts
        s.other_contacts[i] = env._other_contacts
        s.steps[i] = env._steps
        s.max_steps[i] = env.max_steps
        self._out.sonar_m[i] = env._last_sonar
        if self.render_mode:
            self._trails[i] = list(env._trail)

    def _run(self, actions: np.ndarray, stepping: np.ndarray) -> None:
        _step_worlds(self._rngs, actions, stepping, self._constants, self._state, self._out)

    def _store(self, i: int) -> None:
        """Write world ``i``'s current state back into its sub-env (for drawing it)."""
        env, s = self.envs[i], self._state
        env.robot.pose = s.pose[i].copy()
        env.robot.v, env.robot.w = float(s.vel[i, 0]), float(s.vel[i, 1])
        for k, bins in enumerate(env.task.covered):
            bins[:] = s.covered[i, s.first_bin[i, k] : s.first_bin[i, k + 1]]
        env.task.route.index = int(s.subgoal_index[i])
        ny, nx = env.memory.grid.shape[1:]
        env.memory.grid[:] = s.memory[i, :, :ny, :nx]
        env._steps = int(s.steps[i])
        env._last_sonar = self._out.sonar_m[i].copy()
        env._trail = list(self._trails[i])
