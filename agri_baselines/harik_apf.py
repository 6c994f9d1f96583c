"""Harik & Korsæth (2018) artificial potential field controller, with its passive safety behaviour.

The controller maps the waypoint error (distance d, eq. 2; angle alpha, eqs. 3-4) and the obstacles on
the robot's sides straight into the unicycle's velocities (eq. 12):

    u = 1/2 k_att d^2                  r = K_a alpha + k_rep / d_obs

with the saturations of eq. 13 (u = 0 once d < d_min, u = u_max beyond d_max) and eq. 14 (r = +-r_max
and u = 0 when |alpha| > alpha_max). Reading of the printed slips (papers/README.md): the first case of
eq. 13 is d < d_min, and the saturated cases of eq. 14 are |alpha| > alpha_max. Repulsion comes only from
obstacles beside the robot closer than d_obs_threshold (eq. 11); with obstacles on both sides the two
repulsions oppose each other (an obstacle on the left turns the robot right). Anything entering the area
in front of the robot triggers the passive motion safety (sec. 3.1): stop, step back a few centimetres,
and wait (no forward motion) until the front is free, still turning toward the waypoint as in the
corridor experiment (sec. 3.4).

:class:`HarikApfController` is the pure algorithm (no Gymnasium); :class:`HarikApfPolicy` adapts it to
SB3's ``predict`` on GreenhouseNav-v2 observations.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any, cast

import numba
import numpy as np

from agri_envs.rover.config import GreenhouseNavConfig


@dataclasses.dataclass(frozen=True)
class HarikApfParams:
    """Gains and thresholds of the controller ("defined experimentally" in the paper; ours, documented).

    Attributes:
        u_max: Linear speed saturation (m/s), reached at ``d_max``.
        d_max: Distance beyond which ``u = u_max`` (m); ``k_att = 2 u_max / d_max^2`` keeps eq. 13 continuous.
        d_min: Waypoint radius (m): ``u = 0`` below it (the paper's 30 cm).
        k_a: Angular gain K_a (1/s).
        r_max: Angular speed saturation (rad/s).
        alpha_max: Above this |alpha| the robot turns on the spot at ``r_max`` (rad).
        k_rep: Repulsive gain (rad m / s).
        d_obs_threshold: Side obstacles farther than this from the robot's side are ignored (m, eq. 11).
        side_lookahead: The side zone extends this far ahead of the front edge (m).
        front_stop_distance: An obstacle closer than this ahead of the front edge triggers the safety stop (m).
        front_margin: The front zone is this much wider than the robot on each side (m).
        step_back_distance: How far the robot backs off when the safety stop triggers (m).
        step_back_speed: Backing speed (m/s).
        rear_clearance: No stepping back when the rear sonar sees something closer than this (m).
        braking_accel: The robot's deceleration (m/s^2), for the speed cap before obstacles (:meth:`governed_speed`).
        reaction_time: Time between two commands (s), travelled before braking starts.
    """

    u_max: float = 0.5
    d_max: float = 1.0
    d_min: float = 0.3
    k_a: float = 1.2
    r_max: float = 0.8
    alpha_max: float = 0.6
    k_rep: float = 0.02
    d_obs_threshold: float = 0.35
    side_lookahead: float = 0.3
    front_stop_distance: float = 0.35
    front_margin: float = 0.05
    step_back_distance: float = 0.05
    step_back_speed: float = 0.1
    rear_clearance: float = 0.3
    braking_accel: float = 1.0
    reaction_time: float = 1.0 / 15.0

    @property
    def k_att(self) -> float:
        """Attractive gain of eq. 12, chosen so that eq. 13 is continuous at ``d_max``."""
        return 2.0 * self.u_max / self.d_max**2

    def governed_speed(self, u: float, front: float) -> float:
        """``u`` capped so that the robot stops short of the paper's stop distance from what is ``front`` m ahead.

        Not in the paper, and never binding at its speeds: there the stop distance is the fixed 0.35 m, and the
        safety stop acts below it. A faster robot slows as the gap closes instead of running into the stop
        from full speed (a stop distance grown with the speed instead blocked it in front of every post).
        """
        budget = _PAPER_BRAKING_DISTANCE + (front - self.front_stop_distance)
        if u <= 0.0 or budget <= 0.0 or _braking(u, self.braking_accel, self.reaction_time) <= budget:
            return u
        a, t = self.braking_accel, self.reaction_time
        return a * (math.sqrt(t * t + 2.0 * budget / a) - t)  # the speed whose braking distance is the budget

    def for_corridor(self, free: float) -> HarikApfParams:
        """These gains in corridors leaving ``free`` metres (corridor width minus the body's) across the robot.

        The paper's front zone is the body plus 5 cm on each side, set for corridors wide enough that the rows'
        plants stay outside it while the robot drives within a few centimetres of the centre line. Where the
        corridor is narrower, the margin shrinks so that the zone still clears the plants with the robot up to
        :data:`CENTRING_TOLERANCE` off the centre line (down to no margin at 0.8 m for this 0.5 m robot); with a
        5 cm margin it stopped and stepped back 30-50 times an episode there and timed out in 5 of 20 held-out
        episodes. From 0.9 m up the margin is the paper's, bit for bit.
        """
        return dataclasses.replace(self, front_margin=_fitted_margin(free, self.front_margin))

    def for_robot(
        self, max_speed: float, max_turn_rate: float, max_accel: float, control_period: float
    ) -> HarikApfParams:
        """These gains adapted to a robot with other limits than the env's default one (0.6 m/s, 1.2 rad/s, 1 m/s^2).

        The paper's saturations are fractions of its robot's limits: ``u_max`` is 5/6 of the speed limit and
        ``r_max`` 2/3 of the turn-rate limit. An env with another ``max_speed`` or ``max_turn_rate`` gets the
        same fractions, so the controller drives as fast, relative to the robot, as the time limit (which scales
        with the limits) assumes; it slows before obstacles ahead as its braking needs (:meth:`governed_speed`,
        from ``max_accel``). With the default limits every value is the paper's, bit for bit (a ratio of
        equal floats is exactly 1).
        """
        return dataclasses.replace(
            self,
            u_max=self.u_max * (max_speed / DEFAULT_LIMITS["max_speed"]),
            r_max=self.r_max * (max_turn_rate / DEFAULT_LIMITS["max_turn_rate"]),
            braking_accel=max_accel,
            reaction_time=control_period,
        )


def _fitted_margin(free: float, default: float) -> float:
    """The front zone's side margin (m) that a corridor leaving ``free`` metres beside the body can hold."""
    fitted = 0.5 * free - CENTRING_TOLERANCE
    return default if fitted >= default else max(0.0, fitted)


#: How far off the centre line (m) the controller keeps the robot while it drives along a corridor: the front
#: zone's margin must leave this much room to the rows' plants (:meth:`HarikApfParams.for_corridor`).
CENTRING_TOLERANCE = 0.15


def _braking(u: float, accel: float, reaction_time: float) -> float:
    """Distance (m) to stop from ``u`` (m/s): one reaction time of travel, then braking at ``accel``."""
    return u * u / (2.0 * accel) + u * reaction_time


#: Distance (m) the paper's robot needs to stop from its 0.5 m/s at 1 m/s^2 after one 1/15 s period: the paper's
#: front stop distance covers it, so only a robot that needs more slows down (:meth:`HarikApfParams.governed_speed`).
_PAPER_BRAKING_DISTANCE = _braking(0.5, 1.0, 1.0 / 15.0)

#: The limits of GreenhouseNav's default robot, for which the paper's gains (:class:`HarikApfParams`) are set.
DEFAULT_LIMITS: dict[str, float] = {
    f.name: float(cast(float, f.default))
    for f in dataclasses.fields(GreenhouseNavConfig)
    if f.name in ("max_speed", "max_turn_rate", "max_accel")
}


@dataclasses.dataclass(frozen=True)
class RobotGeometry:
    """What the controller knows of its own robot: footprint, sensor mounts, scan geometry."""

    length: float
    width: float
    lidar_mount: tuple[float, float, float]
    beam_angles: np.ndarray
    lidar_max_range: float
    sonar_mounts: np.ndarray
    sonar_max_range: float
    control_period: float


def scan_zones_reference(
    ranges: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    mount_x: float,
    mount_y: float,
    no_echo: float,
    half_length: float,
    half_width: float,
    front_margin: float,
    side_lookahead: float,
) -> tuple[float, float, float]:
    """:func:`scan_zones` in numpy: the statement of what it computes (and the reference its test compares with)."""
    valid = ranges < no_echo
    px = mount_x + ranges * cos
    py = mount_y + ranges * sin
    front_zone = valid & (px > half_length) & (np.abs(py) < half_width + front_margin)
    front = float(np.min(px[front_zone] - half_length)) if np.any(front_zone) else math.inf
    side_zone = valid & (px > -half_length) & (px < half_length + side_lookahead)
    left_pts = py[side_zone & (py > half_width)]
    right_pts = py[side_zone & (py < -half_width)]
    left = float(np.min(left_pts) - half_width) if left_pts.size else math.inf
    right = float(np.min(-right_pts) - half_width) if right_pts.size else math.inf
    return front, left, right


@numba.njit(cache=True)
def scan_zones(
    ranges: np.ndarray,
    cos: np.ndarray,
    sin: np.ndarray,
    mount_x: float,
    mount_y: float,
    no_echo: float,
    half_length: float,
    half_width: float,
    front_margin: float,
    side_lookahead: float,
) -> tuple[float, float, float]:
    """The LIDAR's gaps ahead of and beside the footprint: ``(front, left, right)`` in metres, ``inf`` for none.

    Beam ``k`` ends at ``(mount_x + r cos_k, mount_y + r sin_k)`` in the robot frame (beams at ``no_echo`` or
    beyond saw nothing). Front: ahead of the front edge, within ``front_margin`` of the sides; left and right:
    beside the body, from its rear edge to ``side_lookahead`` ahead of its front edge. The same operations as
    :func:`scan_zones_reference` (numpy), compiled; minima are exact whatever their order.
    """
    front = math.inf
    left = math.inf
    right = math.inf
    front_width = half_width + front_margin
    side_end = half_length + side_lookahead
    for k in range(ranges.shape[0]):
        r = ranges[k]
        if not r < no_echo:
            continue
        px = mount_x + r * cos[k]
        py = mount_y + r * sin[k]
        if px > half_length and abs(py) < front_width:
            front = min(front, px - half_length)
        if px > -half_length and px < side_end:
            if py > half_width:
                left = min(left, py)
            elif py < -half_width:
                right = min(right, -py)
    return front, left - half_width, right - half_width


class HarikApfController:
    """Eqs. 12-14 plus the passive safety stop, for one robot (keeps the safety state between calls)."""

    def __init__(self, params: HarikApfParams, robot: RobotGeometry) -> None:
        self.p = params
        self.robot = robot
        mx, my, myaw = robot.lidar_mount
        ang = myaw + robot.beam_angles
        self._cos = np.cos(ang)
        self._sin = np.sin(ang)
        self._mount = (mx, my)
        self._back_sonars = [i for i, m in enumerate(robot.sonar_mounts) if abs(abs(m[2]) - math.pi) < 1e-6]
        self._left_sonars = [i for i, m in enumerate(robot.sonar_mounts) if abs(m[2] - math.pi / 2) < 1e-6]
        self._right_sonars = [i for i, m in enumerate(robot.sonar_mounts) if abs(m[2] + math.pi / 2) < 1e-6]
        self._front_sonars = [i for i, m in enumerate(robot.sonar_mounts) if abs(m[2]) < 1e-6]
        self.reset()

    def reset(self) -> None:
        """Forget the safety state (new episode)."""
        self.backing_left = 0.0  # metres still to back off
        self.blocked = False
        self.stops = 0
        self.turn_stops = 0  # stops triggered while turning on the spot (|alpha| > alpha_max)
        self.blocked_steps = 0

    def obstacle_zones(self, ranges: np.ndarray, sonar: np.ndarray) -> tuple[float, float, float]:
        """Distances (m) to the nearest obstacle in front of, left of and right of the footprint.

        Args:
            ranges: Full LIDAR scan (m).
            sonar: Sonar ranges (m), mounts as in :class:`RobotGeometry`.

        Returns:
            ``(front, left, right)``: gap ahead of the front edge within the front zone, and lateral gaps
            between each side and obstacles alongside the robot (``inf`` when none).
        """
        rb = self.robot
        front, left, right = scan_zones(
            np.asarray(ranges, dtype=np.float64),
            self._cos,
            self._sin,
            float(self._mount[0]),
            float(self._mount[1]),
            rb.lidar_max_range - 1e-6,
            0.5 * rb.length,
            0.5 * rb.width,
            self.p.front_margin,
            self.p.side_lookahead,
        )
        for i in self._left_sonars:
            left = min(left, float(sonar[i]) if sonar[i] < rb.sonar_max_range - 1e-6 else math.inf)
        for i in self._right_sonars:
            right = min(right, float(sonar[i]) if sonar[i] < rb.sonar_max_range - 1e-6 else math.inf)
        for i in self._front_sonars:
            if sonar[i] < rb.sonar_max_range - 1e-6:
                front = min(front, float(sonar[i]))
        return front, left, right

    def attractive(self, d: float, alpha: float) -> tuple[float, float]:
        """Eqs. 13-14 without repulsion: ``(u, r)`` for waypoint distance d (m) and angle alpha (rad)."""
        p = self.p
        if d < p.d_min:
            u = 0.0
        elif d < p.d_max:
            u = 0.5 * p.k_att * d * d
        else:
            u = p.u_max
        if abs(alpha) > p.alpha_max:
            return 0.0, math.copysign(p.r_max, alpha)
        return u, p.k_a * alpha

    def command(self, d: float, alpha: float, ranges: np.ndarray, sonar: np.ndarray) -> tuple[float, float]:
        """One control step: ``(u, r)`` in m/s and rad/s.

        Args:
            d: Distance to the current waypoint (m).
            alpha: Angle of the waypoint in the robot frame (rad).
            ranges: Full LIDAR scan (m).
            sonar: Sonar ranges (m).
        """
        p = self.p
        front, left, right = self.obstacle_zones(ranges, sonar)
        u, r = self.attractive(d, alpha)
        if abs(alpha) <= p.alpha_max:
            # Eq. 12 with eq. 11: each side within the threshold pushes the robot away from it.
            #
            # Reading of d_obs (eq. 10). The paper writes d_obs as the Euclidean distance between the robot
            # and the obstacle, the robot taken as a point. We use the sideways gap between the body's
            # side and the obstacle (``left``/``right`` from obstacle_zones). For this robot the two
            # readings differ where it matters: the body is 0.5 m wide in 1.2-1.6 m corridors, so the centre
            # distance of a side obstacle never falls below the half-width (0.25 m) even at contact, and
            # k_rep / d_obs would grow only 1.4 times between a 10 cm gap and a touch; the gap reading
            # grows without bound as the side closes in, which is what a repulsion that "keeps a safe
            # distance" (sec. 3.1) must do. It is also what the paper's robot measures for its sides:
            # the HC-SR04 sonars sit on the body's sides (sec. 2.1) and read the gap from the edge. The
            # repulsion is restricted to obstacles alongside the body (the sides, sec. 3.1): what lies
            # ahead is the front zone's, handled by the passive safety stop below.
            if right < p.d_obs_threshold:
                r += p.k_rep / max(right, 1e-3)
            if left < p.d_obs_threshold:
                r -= p.k_rep / max(left, 1e-3)
            # Clamp not in eq. 14: the paper saturates r only for |alpha| > alpha_max, but k_rep / d_obs is
            # unbounded as d_obs -> 0, so inside the band r could exceed r_max, the rate the paper
            # introduced the saturation for ("high ... angular velocities ... may damage its actuators",
            # sec. 3.1). Clamping at r_max applies that same limit to the repulsive term; it changes r only
            # when a side is closer than k_rep / (r_max - K_a |alpha|), i.e. 2.5 cm at alpha = 0.
            r = min(p.r_max, max(-p.r_max, r))
        return self.passive_safety(u, front, sonar, turning=abs(alpha) > p.alpha_max), r

    def passive_safety(self, u: float, front: float, sonar: np.ndarray, turning: bool = False) -> float:
        """The linear speed ``u`` (m/s) after the passive motion safety of sec. 3.1, for a gap ``front`` m ahead.

        Something in the front zone closer than the stop distance: stop, step back a few centimetres (while the
        rear sonars leave room), and wait with no forward motion until the front is free. Before that the
        speed is capped so the robot can still stop short of it (:meth:`HarikApfParams.governed_speed`). The
        detection acts whatever ``u`` is, also in a turn on the spot (``turning``, u = 0 by eq. 14): in a
        corridor the robot faces the wall halfway through a 180 deg turn, steps back and keeps turning until the
        front is free (sec. 3.4, Figs. 14-15: d stays almost constant while alpha decreases). The angular
        speed is never changed. Counts stops and blocked steps (:meth:`reset` clears them).
        """
        p = self.p
        u = p.governed_speed(u, front)
        if front < p.front_stop_distance:
            if not self.blocked:
                self.blocked = True
                self.stops += 1
                self.turn_stops += int(turning)
                self.backing_left = p.step_back_distance
            self.blocked_steps += 1
            u = 0.0
        else:
            self.blocked = False
        if self.backing_left > 0.0:
            rear = min((float(sonar[i]) for i in self._back_sonars), default=math.inf)
            if rear > p.rear_clearance:
                u = -p.step_back_speed
                self.backing_left -= p.step_back_speed * self.robot.control_period
            else:
                self.backing_left = 0.0
        return u


class HarikApfPolicy:
    """SB3-style ``predict`` adapter of :class:`HarikApfController` for GreenhouseNav-v2.

    Reads the ``waypoint`` (d, alpha from the env's localization), ``scan`` and ``sonar`` observation keys,
    so the env must be made with ``full_scan=True`` and a localization other than ``"none"``. One
    controller is kept per env of a vectorised batch; ``episode_start`` resets it. ``diagonal`` scales the
    observation's distances back to metres: the env's ``diagonal``, or a function that reads it, for an env
    whose scene (and with it the scale) is drawn per episode (``scene_distribution``).
    """

    #: Observation keys the policy reads, and the env arguments that provide them.
    required_keys: tuple[str, ...] = ("scan", "sonar", "waypoint")
    requirement = "full_scan=True and localization != 'none'"

    def __init__(
        self,
        robot: RobotGeometry,
        diagonal: float | Callable[[], float],
        max_speed: float,
        max_reverse_speed: float,
        max_turn_rate: float,
        params: HarikApfParams | None = None,
        episode_setup: Callable[[], tuple[HarikApfParams, tuple[float, float, float]]] | None = None,
    ) -> None:
        self.params = params or HarikApfParams()
        self.robot = robot
        self.diagonal = diagonal
        self.max_speed = max_speed
        self.max_reverse_speed = max_reverse_speed
        self.max_turn_rate = max_turn_rate
        #: For one env whose robot or scene is drawn per episode: the gains and the robot's limits
        #: ``(max_speed, max_reverse_speed, max_turn_rate)`` of the episode that starts (None: fixed).
        self.episode_setup = episode_setup
        self.controllers: list[HarikApfController] = []

    def _controller(self, i: int) -> HarikApfController:
        while len(self.controllers) <= i:
            self.controllers.append(HarikApfController(self.params, self.robot))
        return self.controllers[i]

    def to_action(self, u: float, r: float) -> np.ndarray:
        """Velocities (m/s, rad/s) to the env's normalised action."""
        a0 = u / self.max_speed if u >= 0 else u / max(self.max_reverse_speed, 1e-9)
        return np.clip(np.array([a0, r / self.max_turn_rate], dtype=np.float32), -1.0, 1.0)

    def scale(self) -> float:
        """The observation's distance scale now (m): the env's diagonal (of the current episode's scene)."""
        return float(self.diagonal()) if callable(self.diagonal) else float(self.diagonal)

    def start_episode(self, i: int) -> None:
        """Clear the per-episode memory of env ``i`` (and take the episode's gains and limits, if drawn)."""
        controller = self._controller(i)
        if self.episode_setup is not None:
            controller.p, (self.max_speed, self.max_reverse_speed, self.max_turn_rate) = self.episode_setup()
        controller.reset()

    def waypoint_error(self, i: int, obs: dict[str, np.ndarray], scan: np.ndarray) -> tuple[float, float]:
        """Distance d (m) and angle alpha (rad) of the current waypoint for env ``i`` (eqs. 2-4)."""
        wp = obs["waypoint"]
        return float(wp[0]) * self.scale(), math.atan2(float(wp[1]), float(wp[2]))

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """Batched actions for batched observations (SB3's signature; ``state`` is passed through)."""
        missing = [k for k in self.required_keys if k not in observation]
        if missing:
            raise ValueError(f"observation lacks {missing}: make the env with {self.requirement}")
        single = np.asarray(observation["sonar"]).ndim == 1
        batch = {k: np.asarray(v, dtype=np.float64) for k, v in observation.items()}
        if single:
            batch = {k: v[None] for k, v in batch.items()}
        n = len(batch["sonar"])
        starts = np.zeros(n, bool) if episode_start is None else np.asarray(episode_start, bool).reshape(-1)
        actions = np.zeros((n, 2), dtype=np.float32)
        for i in range(n):
            if starts[i]:
                self.start_episode(i)
            obs_i = {k: v[i] for k, v in batch.items()}
            scan = obs_i["scan"] * self.robot.lidar_max_range
            d, alpha = self.waypoint_error(i, obs_i, scan)
            actions[i] = self.to_action(
                *self._controller(i).command(d, alpha, scan, obs_i["sonar"] * self.robot.sonar_max_range)
            )
        return (actions[0] if single else actions), state

    def episode_metrics(self, index: int = 0) -> dict[str, float]:
        """Per-episode statistics of env ``index``.

        Returns:
            ``safety_stops`` (how often the passive safety stop triggered), ``turn_safety_stops`` (those
            that triggered while turning on the spot, |alpha| > alpha_max: the corridor turns of sec. 3.4),
            ``blocked_time`` (s spent waiting for the front to clear) and ``blocked_at_end`` (1 when the
            episode ended while waiting).
        """
        c = self._controller(index)
        return {
            "safety_stops": float(c.stops),
            "turn_safety_stops": float(c.turn_stops),
            "blocked_time": c.blocked_steps * self.robot.control_period,
            "blocked_at_end": float(c.blocked),
        }


def robot_geometry(env: Any) -> RobotGeometry:
    """The public robot description of a GreenhouseNav env (footprint, mounts, scan geometry, period)."""
    e = env.unwrapped
    return RobotGeometry(
        length=e.robot_spec.length,
        width=e.robot_spec.width,
        lidar_mount=e.lidar.spec.mount,
        beam_angles=e.lidar.spec.beam_angles,
        lidar_max_range=e.lidar.spec.max_range,
        sonar_mounts=e.sonars.mounts,
        sonar_max_range=e.sonars.spec.max_range,
        control_period=e.config.control_period,
    )


def robot_params(env: Any, d_min: float, cfg: Any = None) -> HarikApfParams:
    """The paper's gains, waypoint radius ``d_min``, adapted to the env's robot (:meth:`HarikApfParams.for_robot`).

    ``cfg``: the arguments of the episode (``env.unwrapped.episode_config``); None takes the env's config.
    """
    cfg = env.unwrapped.config if cfg is None else cfg
    period = cfg.control_period * cfg.frame_skip  # the controller acts once per env step
    params = HarikApfParams(d_min=d_min).for_robot(cfg.max_speed, cfg.max_turn_rate, cfg.max_accel, period)
    if cfg.scene == "greenhouse":  # the rows' spacing is part of the map the robot is given
        free = cfg.corridor_width - env.unwrapped.robot_spec.width
        params = params.for_corridor(free)
    return params


def episode_setup(env: Any, d_min: float) -> Callable[[], tuple[HarikApfParams, tuple[float, float, float]]] | None:
    """For a single env that draws its scene (and robot) per episode: the gains and limits of the episode.

    None for an env with fixed arguments, whose gains :func:`robot_params` computes once.
    """
    e = env.unwrapped
    if getattr(e, "distribution", None) is None:
        return None

    def setup() -> tuple[HarikApfParams, tuple[float, float, float]]:
        spec = e.robot_spec
        return robot_params(env, d_min, e.episode_config), (spec.max_speed, spec.max_reverse_speed, spec.max_turn_rate)

    return setup


def make_harik_apf_gt(env: Any) -> HarikApfPolicy:
    """``harik-apf-gt``: the controller on the ground-truth pose (privileged). Env: ``full_scan=True``.

    The controller's ``d_min`` (eq. 13) is the env's waypoint radius (the paper's 30 cm by default).

    Env arguments it adapts to: ``waypoint_radius`` (its ``d_min``), ``max_speed``, ``max_turn_rate`` and
    ``max_accel`` (its saturations and speed cap before obstacles, :meth:`HarikApfParams.for_robot`),
    ``corridor_width`` of a greenhouse (its front zone's margin, :meth:`HarikApfParams.for_corridor`), each
    episode's own where ``scene_distribution`` draws them (:func:`episode_setup`), the scene
    and its scale (read from the observation). It ignores the reward weights and ``time_limit_*`` (it drives the
    same whatever the limit) and needs ``frame_skip=1`` to act at the paper's 15 Hz.
    """
    e = env.unwrapped
    cfg = e.config
    if not cfg.full_scan or cfg.localization != "ground_truth":
        raise ValueError("harik-apf-gt needs gym.make(..., full_scan=True, localization='ground_truth')")
    return HarikApfPolicy(
        robot_geometry(env),
        lambda: e.diagonal,
        e.robot_spec.max_speed,
        e.robot_spec.max_reverse_speed,
        e.robot_spec.max_turn_rate,
        params=robot_params(env, cfg.waypoint_radius),
        episode_setup=episode_setup(env, cfg.waypoint_radius),
    )


class HarikApfSlamPolicy(HarikApfPolicy):
    """``harik-apf``: the controller fed by Hector SLAM on the LIDAR alone, as on the paper's robot.

    The map frame is anchored at the start pose (the SLAM starts at the origin); the mission comes as the
    current target in that frame (observation key ``target``), so the env must be made with
    ``localization="none"`` and ``full_scan=True``. Nothing privileged is used. One SLAM instance per env of
    a batch, cleared on ``episode_start``.
    """

    required_keys = ("scan", "sonar", "target")
    requirement = "full_scan=True and localization='none'"

    def __init__(self, *args: Any, slam_config: Any = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        from agri_baselines.hector_slam import HectorSlamConfig

        self.slam_config = slam_config or HectorSlamConfig()
        self.slams: list[Any] = []

    def _slam(self, i: int) -> Any:
        from agri_baselines.hector_slam import HectorSlam

        while len(self.slams) <= i:
            self.slams.append(HectorSlam(self.slam_config, self.robot.beam_angles, self.robot.lidar_mount))
        return self.slams[i]

    def start_episode(self, i: int) -> None:
        """Clear the controller and the SLAM map of env ``i``; the new map frame is the start pose."""
        super().start_episode(i)
        self._slam(i).reset((0.0, 0.0, 0.0))

    def waypoint_error(self, i: int, obs: dict[str, np.ndarray], scan: np.ndarray) -> tuple[float, float]:
        """SLAM update on this scan, then d and alpha (eqs. 2-4) of the target in the map frame."""
        x, y, yaw = self._slam(i).update(scan)
        tx, ty = obs["target"] * self.scale()
        theta = math.atan2(ty - y, tx - x)
        return math.hypot(tx - x, ty - y), math.atan2(math.sin(theta - yaw), math.cos(theta - yaw))

    def pose_estimate(self, index: int = 0) -> np.ndarray:
        """Current SLAM pose ``(x, y, yaw)`` of env ``index`` in its start frame."""
        return np.asarray(self._slam(index).pose, dtype=np.float64)


def make_harik_apf_slam(env: Any, localization_margin: float = 0.1, slam_config: Any = None) -> HarikApfSlamPolicy:
    """``harik-apf``: the controller on the Hector SLAM pose. Env: ``full_scan=True, localization='none'``.

    Args:
        env: A GreenhouseNav env made with the arguments above.
        localization_margin: The controller's ``d_min`` is the env's waypoint radius minus this (m).
        slam_config: A :class:`baselines.hector_slam.HectorSlamConfig`; None takes its defaults.

    On the paper's robot the controller itself declared a waypoint reached (eq. 13, d < d_min) and moved
    on. Here the env counts a waypoint from the true position, so a controller that stops at d_min of
    its SLAM estimate would wait forever when the estimate is a centimetre off (it then stands at, say,
    0.306 m from the waypoint with u = 0). The controller therefore aims ``localization_margin`` inside
    the radius: the env's count, not the estimate, ends each leg. This is the one change from the
    ground-truth variant; it is reported with the results.
    """
    e = env.unwrapped
    cfg = e.config
    if not cfg.full_scan or cfg.localization != "none":
        raise ValueError("harik-apf needs gym.make(..., full_scan=True, localization='none')")
    spec = e.robot_spec
    d_min = max(0.05, cfg.waypoint_radius - localization_margin)
    return HarikApfSlamPolicy(
        robot_geometry(env),
        lambda: e.diagonal,
        spec.max_speed,
        spec.max_reverse_speed,
        spec.max_turn_rate,
        params=robot_params(env, d_min),
        episode_setup=episode_setup(env, d_min),
        slam_config=slam_config,
    )


def make_harik_apf_hector_plain(env: Any) -> HarikApfSlamPolicy:
    """``harik-apf-hector-plain``: ``harik-apf`` on plain Hector SLAM, without our three safeguards.

    No free-space guard against moving people, no cost check of Gauss-Newton steps and no constant-velocity
    prediction of the match's start, as in ROS ``hector_mapping`` (see :mod:`baselines.hector_slam`).
    """
    from agri_baselines.hector_slam import HectorSlamConfig

    plain = HectorSlamConfig(free_space_guard=None, max_step_halvings=0, constant_velocity=False)
    return make_harik_apf_slam(env, slam_config=plain)
