"""Apoorva, Gautam & Kala 2018: a robot chain driven by A*, a ghost robot, sonar potential fields, a strip.

The pure parts (no Gymnasium, no PettingZoo):

The ghost robot (sec. 4.4) that runs along the A* path ahead of the leader belongs to the chain's task
(:mod:`agri_envs.chain.task`); the leader reads it in its observation.

* :func:`attractive_force` (eq. 2) and :func:`sonar_repulsion` (eq. 4 with the sonar form of Alg. 3);
* :func:`spacing_force` (Algs. 4b, 5a), :func:`strip_forces` (Alg. 6 as printed) and
  :func:`path_strip_forces` (the strip laid along the leader's trail, this project's departure from Alg. 6);
* :func:`force_to_command`: the proportional controller of Alg. 2; the policy adds the equipotential
  escape of sec. 6.1 (a small push along the robot's x axis once a robot stays put short of its target).

:class:`ApoorvaChainPolicy` puts them together as one multi-agent policy whose ``predict`` takes and
returns per-agent dicts (the central system of sec. 6.2 computes every robot's command).

Departure from Alg. 6 (``apoorva-chain``): Alg. 6 lays the strip on the straight line from the first to
the last robot. Once the chain bends round a corner, a door or the end of a crop row, that line runs
through the wall, the door frame or the row, and the strip pulls the middle robots into it: followers jam
at doors and squeeze through plant rows. ``apoorva-chain`` therefore lays the strip along the leader's
recorded trail between the leader and the last robot: the trail is where the leader's centre has been, so
free space, and each middle robot near it is pulled, with Alg. 6's ``Distance * Fix_force``, toward its
nearest point on it (:func:`path_strip_forces` says when it is not). On a straight stretch the trail is the
straight line from the first to the last robot and the two strips coincide. The printed strip is kept as
the ablation ``apoorva-chain-alg6``; ``apoorva-chain-no-strip`` has none. On the paper's task
(robot_chain_v1: every robot at the goal, no contact, no gap above Delta at any step), office, one dropped
obstacle, validation seeds 8000-8019 (``agri evaluate --env robot_chain_v1 --scenario office-chain --seed
8000 --episodes 20 --env-kwargs n_robots=N``): the strip along the trail 20/20 with 8, 12 and 16 robots
(greenhouse, 8 robots: 20/20), the printed strip 9/20, 4/20 and 1/20 (its failures are chain breaks and
chains jammed until the time limit), no strip 20/20 each. The held-out numbers are the leaderboard's
(suites ``chain-office``, ``-8``, ``-12``, ``-16``).

Env arguments :class:`ApoorvaChainPolicy` adapts to, and those it ignores (4 robots, default office, seeds
from 100000):

* ``spacing``, ``max_gap``, ``max_speed``, ``max_accel``, ``control_period``: ``d_s`` is the spacing and
  the stop threshold ``Delta`` the gap limit less the braking distance at ``max_speed``
  (:func:`default_params`); commands are scaled by the env's limits. ``max_speed`` 0.1 to 2.0: 3/3 each.
* ``max_turn_rate``: a robot that turns slower than the 2 rad/s the gains were tuned on
  (:data:`TUNED_TURN_RATE`) slows down in proportion when its turn rate saturates, so it drives the curves
  the tuned robot would (``max_turn_rate=0.2``: 2/4 before, chains broken or stuck in wide arcs; 4/4 now;
  0.5: 3/4, one chain stuck until the time limit; 1.0 and 6.0: all).
* The sonar layout and range, the map bounds, the robots' neighbours: read from the observation layout.
* Ignored, as the env's own limits: ``ghost_speed`` (the leader follows the env's ghost, whatever its
  pace) and ``max_cycles`` (the time limit is fixed steps, not sized to the speeds): with
  ``ghost_speed=0.01`` no chain arrives within the 1500 steps (0/3), with ``max_speed=0.05`` one of three
  does not (the mission needs more than 150 s at 0.05 m/s). ``max_angular_accel``: ignored.

With the default arguments the policy acts exactly as before (the chain entries verify unchanged).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from typing import Any

import numpy as np

from agri_envs.sim2d.polyline import Polyline

# ----------------------------------------------------------------------------------------------------
# Potential field (eqs. 1-4, Algs. 2-3)
# ----------------------------------------------------------------------------------------------------


def attractive_force(q: np.ndarray, goal: np.ndarray, epsilon: float, d_star: float) -> np.ndarray:
    """``-grad U_att`` of eq. 2: quadratic (``epsilon (g - q)``) within ``d_star``, conic (constant size) beyond.

    Args:
        q: Robot position ``(2,)``.
        goal: Goal position ``(2,)``.
        epsilon: Attraction gain.
        d_star: ``d*_goal``, where the potential switches from quadratic to conic (m).

    Returns:
        The force ``(2,)`` pointing at the goal.
    """
    diff = np.asarray(goal, dtype=np.float64) - np.asarray(q, dtype=np.float64)
    d = math.hypot(diff[0], diff[1])
    if d <= d_star:
        return epsilon * diff
    return d_star * epsilon * diff / d


def repulsive_magnitude(d: np.ndarray, eta: float, q_star: float) -> np.ndarray:
    """Size of eq. 4's repulsion for obstacle distances ``d``: ``eta (1/d - 1/Q*) / d^2`` within ``Q*``, else 0.

    (Eq. 4 gives the gradient ``eta (1/Q* - 1/D) / D^2 grad D``; the force is its negative, pointing away
    from the obstacle.)
    """
    d = np.maximum(np.asarray(d, dtype=np.float64), 1e-3)
    return np.where(d <= q_star, eta * (1.0 / d - 1.0 / q_star) / (d * d), 0.0)


def sonar_repulsion(
    ranges: np.ndarray, sonar_angles: np.ndarray, heading: float, eta: float, q_star: float, offset: float = 0.0
) -> np.ndarray:
    """Sum of the repulsive forces of every sonar echo (Alg. 3), in the world frame.

    Each sonar ``i`` with reading ``d_i`` at mount angle ``alpha_i`` pushes the robot along
    ``-u(alpha_i)``, rotated into the world by the robot's heading ``R(q_theta)``.

    Args:
        ranges: Sonar readings (m).
        sonar_angles: Mount angles in the robot frame (rad).
        heading: Robot heading (rad).
        eta: Repulsion gain.
        q_star: ``Q*``, echoes farther than this are ignored (m).
        offset: Distance from the robot centre to the sonar (added to each reading, m).

    Returns:
        The force ``(2,)``.
    """
    mag = repulsive_magnitude(np.asarray(ranges) + offset, eta, q_star + offset)
    a = np.asarray(sonar_angles) + heading
    return np.array([-(mag * np.cos(a)).sum(), -(mag * np.sin(a)).sum()])


def spacing_force(
    q: np.ndarray, other: np.ndarray, d_s: float, epsilon: float, eta: float, d_star: float = 0.6
) -> np.ndarray:
    """Force from a chain neighbour (Algs. 4b, 5a): attraction beyond ``d_s`` (eq. 2), repulsion within it.

    The attraction is eq. 2's toward ``other`` scaled by ``(d - d_s) / d``, and the repulsion eq. 4's with
    ``Q* = d_s``, so the force is continuous (zero) at ``d_s``.
    """
    diff = np.asarray(other, dtype=np.float64) - np.asarray(q, dtype=np.float64)
    d = math.hypot(diff[0], diff[1])
    if d < 1e-9:
        return np.zeros(2)
    if d > d_s:
        return attractive_force(q, other, epsilon, d_star) * (d - d_s) / d
    return -float(repulsive_magnitude(np.array([d]), eta, d_s)[0]) * diff / d


def strip_forces(positions: np.ndarray, gain: float, max_force: float) -> np.ndarray:
    """Elastic strip (Alg. 6): pull every robot toward the line from the first to the last robot.

    ``Force = Distance * Fix_force``, directed from the robot to its foot point on the strip (capped at
    ``max_force``: the strip must not overpower obstacle repulsion).

    Args:
        positions: ``(n, 2)`` robot positions, leader first.
        gain: ``Fix_force`` (1/s^2-like gain, force per metre).
        max_force: Cap on the size of each force.

    Returns:
        ``(n, 2)`` forces (zero for the first and the last robot, which define the strip).
    """
    p = np.asarray(positions, dtype=np.float64)
    out = np.zeros_like(p)
    if len(p) < 3:
        return out
    a, b = p[0], p[-1]
    e = b - a
    l2 = float(e @ e)
    t = np.clip(((p - a) @ e) / l2, 0.0, 1.0) if l2 > 1e-12 else np.zeros(len(p))
    foot = a + t[:, None] * e
    pull = gain * (foot - p)
    size = np.hypot(pull[:, 0], pull[:, 1])
    scale = np.minimum(1.0, max_force / np.maximum(size, 1e-12))
    out = pull * scale[:, None]
    out[0] = 0.0
    out[-1] = 0.0
    return out


def path_strip_forces(
    positions: np.ndarray,
    path: Polyline,
    s_from: np.ndarray,
    s_to: np.ndarray,
    gain: float,
    max_force: float,
    reach: float = math.inf,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The elastic strip laid along the leader's trail (this project's departure from Alg. 6).

    Each middle robot is pulled toward its foot point on ``path`` (its nearest point, searched between
    ``s_from[k]`` and ``s_to[k]`` so that it never jumps to a stretch of the trail behind a wall), with
    Alg. 6's ``Force = Distance * Fix_force`` capped at ``max_force``. The path is where the leader's centre
    has been, so the foot point lies in free space, unlike Alg. 6's straight line once the chain bends.
    The strip acts only where it pulls through free space and keeps the chain's order: the first and the
    last robot hold its ends (no force, as in Alg. 6), and a robot is not pulled when its foot is the
    trail's first point (it has not reached the leader's trail yet: the start formation), when it is
    farther than ``reach`` from its foot (only the trail's neighbourhood is known to be free: the straight
    pull from farther may cross a corner), or when its foot is not behind its predecessor's (robots of a
    start packed round the leader would all be pulled onto the same stretch of trail and jam).

    Args:
        positions: ``(n, 2)`` robot positions, leader first.
        path: The leader's trail, oldest point first.
        s_from: ``(n,)`` arc lengths from which each robot's foot point is searched.
        s_to: ``(n,)`` arc lengths up to which it is searched.
        gain: ``Fix_force`` (force per metre).
        max_force: Cap on the size of each force.
        reach: The strip pulls only robots within this distance of their foot point (m).

    Returns:
        ``(forces, feet, s)``: ``(n, 2)`` forces, ``(n, 2)`` foot points and ``(n,)`` their arc lengths
        (the ends' own feet are reported too, with zero force).
    """
    p = np.asarray(positions, dtype=np.float64)
    n = len(p)
    forces = np.zeros((n, 2))
    feet = p.copy()
    s = np.zeros(n)
    for k in range(n):
        lo = min(max(float(s_from[k]), 0.0), path.length)
        hi = min(max(float(s_to[k]), lo), path.length)
        s[k] = path.project(p[k], lo, hi) if path.length > 0 else 0.0
        feet[k] = path.at(float(s[k]))
    for k in range(1, n - 1):
        pull = feet[k] - p[k]
        distance = math.hypot(pull[0], pull[1])
        if s[k] <= 1e-9 or distance > reach or s[k] >= s[k - 1]:
            continue
        forces[k] = gain * pull * min(1.0, max_force / max(gain * distance, 1e-12))
    return forces, feet, s


def strip_distances(positions: np.ndarray) -> np.ndarray:
    """Distance (m) of every robot to the strip segment between the first and the last robot."""
    p = np.asarray(positions, dtype=np.float64)
    if len(p) < 3:
        return np.zeros(len(p))
    a, b = p[0], p[-1]
    e = b - a
    l2 = float(e @ e)
    t = np.clip(((p - a) @ e) / l2, 0.0, 1.0) if l2 > 1e-12 else np.zeros(len(p))
    foot = a + t[:, None] * e
    return np.hypot(*(p - foot).T)


@dataclasses.dataclass(frozen=True)
class ApoorvaParams:
    """Gains and thresholds of the chain controller (symbols of the paper).

    Attributes:
        epsilon: Attraction gain of eq. 2.
        d_star: ``d*_goal`` of eqs. 1-2 (m).
        eta_rep: Repulsion gain ``eta`` of eqs. 3-4.
        q_star: ``Q*``, sonar echoes beyond it are ignored (m).
        d_apf: ``d_APF``: with every echo farther than this the leader only follows the ghost (m).
        d_s: Desired spacing between neighbours (m).
        delta: ``Delta``: a robot stops while its follower is farther than this (m).
        spacing_gain: Attraction gain toward the predecessor (followers) / successor (leader).
        strip_gain: ``Fix_force`` of Alg. 6 (0: no strip).
        strip_max: Cap on the strip force.
        strip_window: How far (m) ahead of its last foot point on the leader's trail a robot's next one is
            searched (the strip along the trail; see :func:`path_strip_forces`).
        strip_reach: The strip along the trail pulls only robots within this distance of it (m).
        kp_v: ``k_p^1`` of Alg. 2 (1/s): speed per metre of ``d(q, q')``.
        kp_w: ``k_p^2`` of Alg. 2 (1/s): turn rate per radian of heading error.
        escape: Size of the push along the robot's x axis (its heading) that leaves an equipotential region
            (sec. 6.1).
        escape_below: Net force size under which the robot counts as stuck in an equipotential region.
        stuck_window: Control steps over which a robot that wants to move but moves less than
            ``stuck_distance`` counts as caught in an equipotential region (the forces cancel on average
            while the sonar cones swing with the heading, so the net force alone rarely drops to zero).
        stuck_distance: See ``stuck_window`` (m).
        escape_steps: Control steps the push lasts once triggered.
        escape_ghost_distance: The leader counts as wanting to move (and so as stuck when it does not)
            while its ghost is farther than this (m).
        lookahead: Followers aim this far ahead of themselves along their predecessor's trail (m).
        trail_window: A follower's place on its predecessor's trail is searched only this far (m) ahead of
            its last place, so it never jumps to a later stretch of the trail that runs past it on the far
            side of a wall (the trail through a door and back along the corridor).
        leader_wait: Relative gain of the follower's pull on the leader (Alg. 4b).
    """

    epsilon: float = 1.0
    d_star: float = 0.6
    eta_rep: float = 0.02
    q_star: float = 0.45
    d_apf: float = 0.45
    d_s: float = 0.55
    delta: float = 1.2
    spacing_gain: float = 1.0
    strip_gain: float = 0.8
    strip_max: float = 0.25
    strip_window: float = 1.0
    strip_reach: float = 0.4
    kp_v: float = 1.2
    kp_w: float = 2.5
    escape: float = 0.15
    escape_below: float = 0.05
    stuck_window: int = 20
    stuck_distance: float = 0.05
    escape_steps: int = 30
    escape_ghost_distance: float = 0.25
    lookahead: float = 0.45
    trail_window: float = 1.0
    leader_wait: float = 0.5

    def __post_init__(self) -> None:
        for name in (
            "epsilon",
            "d_star",
            "q_star",
            "d_s",
            "delta",
            "kp_v",
            "kp_w",
            "trail_window",
            "strip_window",
            "strip_reach",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"ApoorvaParams: {name} must be > 0, got {getattr(self, name)}")
        if self.delta <= self.d_s:
            raise ValueError(f"ApoorvaParams: delta ({self.delta}) must exceed d_s ({self.d_s})")
        if self.stuck_window < 1 or self.escape_steps < 0:
            raise ValueError(
                f"ApoorvaParams: stuck_window must be >= 1 and escape_steps >= 0, got {self.stuck_window} "
                f"and {self.escape_steps}"
            )
        for name in ("eta_rep", "d_apf", "strip_gain", "strip_max", "escape", "escape_below", "stuck_distance"):
            if getattr(self, name) < 0:
                raise ValueError(f"ApoorvaParams: {name} must be >= 0, got {getattr(self, name)}")


def default_params(config: Any) -> ApoorvaParams:
    """:class:`ApoorvaParams` for a ``robot_chain_v1`` config: ``d_s`` its spacing, ``Delta`` its max gap.

    The robots brake within their acceleration limit, so a robot that stops only once its follower is
    beyond the env's ``max_gap`` overshoots it (up to 1.24 m for 1.2 m seen, chain broken at the leader's
    arrival). The stop threshold is the env's ``max_gap`` less the braking distance ``v^2 / (2 a)`` and
    one control period of travel, so a gap never grows past ``max_gap`` after the stop.
    """
    v = config.max_speed
    margin = v * v / (2.0 * config.max_accel) + v * config.control_period
    delta = max(config.max_gap - margin, 0.5 * (config.spacing + config.max_gap))
    return ApoorvaParams(d_s=config.spacing, delta=delta)


#: The turn rate limit the gains were tuned on (robot_chain_v1's default ``max_turn_rate``, rad/s).
TUNED_TURN_RATE = 2.0


def force_to_command(
    force: np.ndarray,
    heading: float,
    kp_v: float,
    kp_w: float,
    max_v: float,
    max_w: float,
    tuned_w: float | None = None,
) -> tuple[float, float]:
    """Alg. 2's proportional controller: ``q' = q + F``, ``v = k_p^1 d(q, q')``, ``omega = k_p^2 theta_e``.

    The speed is scaled by ``cos theta_e`` (and is zero when the target lies behind), so a robot turns
    toward ``q'`` before it drives there instead of sweeping sideways into obstacles. On a robot that turns
    slower (``max_w``) than the one the gains were tuned on (``tuned_w``), a turn rate clipped to ``max_w``
    slows the robot in proportion, so that it drives the curve the tuned robot would have driven rather
    than a wider one (with ``max_w >= tuned_w``, as by default, or no ``tuned_w``, nothing changes).
    """
    size = math.hypot(force[0], force[1])
    if size < 1e-9:
        return 0.0, 0.0
    theta_e = math.atan2(force[1], force[0]) - heading
    theta_e = math.atan2(math.sin(theta_e), math.cos(theta_e))
    v = kp_v * size * max(0.0, math.cos(theta_e))
    w = kp_w * theta_e
    if tuned_w is not None and max_w < tuned_w and abs(w) > max_w:
        v *= max_w / min(abs(w), tuned_w)
    return min(v, max_v), max(-max_w, min(max_w, w))


class ApoorvaChainPolicy:
    """The whole chain controller as one multi-agent policy over ``robot_chain_v1`` observations.

    ``predict`` takes ``{agent: observation}`` and returns ``({agent: action}, state)``. It reads from each
    observation the robot's sonar, its pose, its neighbours' relative positions and (leader) the ghost;
    the env's fixed description (sonar mounts, scales, limits) comes from the env at construction. The
    followers aim at their predecessor's recent trail ("fetching its previous position", sec. 8), which
    the central system records from the observed poses.

    Args:
        env: The (unwrapped-able) ``robot_chain_v1`` env.
        params: Controller gains; default :class:`ApoorvaParams`.
        strip: The elastic strip: ``"trail"`` along the leader's trail (:func:`path_strip_forces`, the
            default, see the module's note on the departure from Alg. 6), ``"line"`` the printed Alg. 6
            (:func:`strip_forces`) or ``"none"``.
    """

    STRIPS = ("trail", "line", "none")

    def __init__(self, env: Any, params: ApoorvaParams | None = None, strip: str = "trail") -> None:
        if strip not in self.STRIPS:
            raise ValueError(f"ApoorvaChainPolicy: strip must be one of {self.STRIPS}, got {strip!r}")
        raw = env.unwrapped if hasattr(env, "unwrapped") else env
        self.env = raw
        self.spec = raw.observation_layout()
        self.params = params or default_params(raw.config)
        self.strip = strip
        self.strip_feet: np.ndarray | None = None  # the strip's target of every robot at the last step
        self._leader_trail: list[np.ndarray] = []
        self._leader_trail_s: list[float] = []
        self._strip_s: np.ndarray | None = None
        self.trails: dict[str, list[np.ndarray]] = {}
        self._trail_s: dict[str, list[float]] = {}
        self._progress: dict[str, float] = {}
        self._history: np.ndarray | None = None
        self._steps = 0
        self._escape_left = np.zeros(0, dtype=np.int64)

    def reset(self) -> None:
        """Forget the recorded trails and the escape state (a new episode)."""
        self.trails = {}
        self._trail_s = {}
        self._progress = {}
        self._history = None
        self._steps = 0
        self.strip_feet = None
        self._leader_trail = []
        self._leader_trail_s = []
        self._strip_s = None

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[dict[str, np.ndarray], Any]:
        """Commands for every agent in ``observation`` (actions in ``[-1, 1]^2``)."""
        if episode_start is not None and bool(np.asarray(episode_start).any()):
            self.reset()
        spec = self.spec
        p = self.params
        agents = sorted(observation, key=lambda a: int(a.rsplit("_", 1)[1]))
        n = len(agents)
        obs = np.stack([np.asarray(observation[a], dtype=np.float64) for a in agents])
        ranges = obs[:, spec["sonar"]] * spec["sonar_max_range"]
        bounds = self.env.map_bounds  # the map is known (sec. 4.1); observations 8-9 are scaled by it
        xy = obs[:, spec["xy"]] * (bounds[2:] - bounds[:2]) + bounds[:2]
        heading = np.arctan2(obs[:, spec["sin_yaw"]], obs[:, spec["cos_yaw"]])
        rel_pred = obs[:, spec["predecessor"]] * spec["rel_scale"]
        for k, a in enumerate(agents):
            trail = self.trails.setdefault(a, [])
            trail_s = self._trail_s.setdefault(a, [])
            step = math.hypot(*(trail[-1] - xy[k])) if trail else 0.0
            if not trail or step > 0.02:
                trail_s.append(trail_s[-1] + step if trail_s else 0.0)
                trail.append(xy[k].copy())
                if len(trail) > 400:
                    del trail[:200]
                    del trail_s[:200]
        moved = self._displacement(xy)
        strip = self._strip(xy)
        angles = spec["sonar_angles"]
        offset = spec["sonar_offset"]
        actions: dict[str, np.ndarray] = {}
        for k, a in enumerate(agents):
            c, s = math.cos(heading[k]), math.sin(heading[k])
            near = bool(np.any(ranges[k] < p.d_apf))
            rep = sonar_repulsion(ranges[k], angles, heading[k], p.eta_rep, p.q_star, offset) if near else np.zeros(2)
            waiting = k + 1 < n and math.hypot(*(xy[k + 1] - xy[k])) > p.delta
            if k == 0:
                # Alg. 4: the ghost (predecessor slot) attracts; the follower pulls or pushes.
                rx, ry = rel_pred[k]
                ghost = xy[k] + np.array([c * rx - s * ry, s * rx + c * ry])
                pull = attractive_force(xy[k], ghost, p.epsilon, p.d_star)
                force = pull + rep
                if n > 1:
                    force += spacing_force(xy[k], xy[k + 1], p.d_s, p.leader_wait * p.epsilon, p.eta_rep, p.d_star)
                wants = math.hypot(rx, ry) > p.escape_ghost_distance
            else:
                # Alg. 5 (attraction to q_{i-1}, the printed q_2 is a slip), along q_{i-1}'s own trail.
                target = self._trail_target(agents[k - 1], a, xy[k - 1], xy[k])
                force = spacing_force(xy[k], xy[k - 1], p.d_s, 0.0, p.eta_rep) + rep
                if target is not None:
                    pull = p.spacing_gain * attractive_force(xy[k], target, p.epsilon, p.d_star)
                else:
                    # Off the trail (its nearest point already within d_s of q_{i-1} along the trail): Alg. 5's
                    # own F_att(q_{i-1}), scaled to vanish at d_s.
                    pull = p.spacing_gain * spacing_force(xy[k], xy[k - 1], p.d_s, p.epsilon, 0.0, p.d_star)
                force += pull
                wants = math.hypot(*pull) > 1e-3
            force = force + strip[k]
            # Sec. 6.1: in an equipotential region (the forces cancel, so the robot stays put although its
            # target is not reached) "a small tangential force is applied in the positive x axis direction
            # of the robot", here for ``escape_steps`` steps once triggered. The robot x axis is its heading
            # (the paper's own reading, kept): the controller then drives on and turns with the residual
            # force, sliding round the obstacle. A push along the robot's y axis instead turns with the
            # robot and only spins it in place (11/20 on seeds 100000-100019 against 20/20).
            if (
                near
                and wants
                and not waiting
                and self._escape_left[k] == 0
                and (moved[k] < p.stuck_distance or math.hypot(*force) < p.escape_below)
            ):
                self._escape_left[k] = p.escape_steps
            if self._escape_left[k] > 0:
                self._escape_left[k] -= 1
                force = force + p.escape * np.array([c, s])
            v, w = force_to_command(
                force, float(heading[k]), p.kp_v, p.kp_w, spec["max_speed"], spec["max_turn_rate"], TUNED_TURN_RATE
            )
            # Stop while the follower is farther than Delta (Algs. 4-5).
            if waiting:
                v, w = 0.0, 0.0
            actions[a] = np.array([v / spec["max_speed"], w / spec["max_turn_rate"]], dtype=np.float32)
        return actions, state

    def _strip(self, xy: np.ndarray) -> np.ndarray:
        """The strip's force on every robot (zero without a strip or with fewer than three robots)."""
        p = self.params
        n = len(xy)
        if self.strip == "none" or n < 3:
            return np.zeros((n, 2))
        if self.strip == "line":
            self.strip_feet = None
            return strip_forces(xy, p.strip_gain, p.strip_max)
        # The leader's trail, kept long enough to reach the last robot (the followers' own trails are short).
        trail, trail_s = self._leader_trail, self._leader_trail_s
        step = math.hypot(*(trail[-1] - xy[0])) if trail else 0.0
        if not trail or step > 0.02:
            trail_s.append(trail_s[-1] + step if trail_s else 0.0)
            trail.append(xy[0].copy())
        keep = 2.0 * (n - 1) * p.delta + 2.0
        if trail_s[-1] - trail_s[0] > 2.0 * keep:
            cut = bisect.bisect_left(trail_s, trail_s[-1] - keep)
            del trail[:cut]
            del trail_s[:cut]
        line = Polyline(np.array(trail))
        s0 = trail_s[0]
        if self._strip_s is None or len(self._strip_s) != n:
            lo, hi = np.zeros(n), np.full(n, line.length)  # first step: anywhere on the (short) trail
        else:
            lo = np.maximum(self._strip_s - s0, 0.0)
            hi = lo + p.strip_window
        forces, feet, s = path_strip_forces(xy, line, lo, hi, p.strip_gain, p.strip_max, p.strip_reach)
        self._strip_s = s + s0
        self.strip_feet = feet
        return forces

    def _displacement(self, xy: np.ndarray) -> np.ndarray:
        """How far (m) every robot moved over the last ``stuck_window`` steps (inf until that many were seen)."""
        p = self.params
        n = len(xy)
        if self._history is None or self._history.shape[1] != n:
            self._history = np.repeat(xy[None], p.stuck_window, axis=0)
            self._steps = 0
            self._escape_left = np.zeros(n, dtype=np.int64)
        slot = self._steps % p.stuck_window
        old = self._history[slot]
        moved = np.hypot(*(xy - old).T) if self._steps >= p.stuck_window else np.full(n, np.inf)
        self._history[slot] = xy
        self._steps += 1
        return moved

    def _trail_target(self, agent: str, follower: str, position: np.ndarray, me: np.ndarray) -> np.ndarray | None:
        """Where a follower aims on its predecessor's recorded trail (sec. 8: "fetching its previous position").

        The follower's place on the trail (its nearest point, searched from its last place up to
        ``trail_window`` ahead), moved ``lookahead`` metres on along the trail but never closer than ``d_s``
        (along the trail) to the predecessor; None when the follower is already that close.

        Args:
            agent: The predecessor, whose trail is followed.
            follower: The follower (its place on the trail is remembered).
            position: The predecessor's position now.
            me: The follower's position.
        """
        p = self.params
        trail = self.trails.get(agent)
        if not trail:
            return None
        pts = np.vstack([np.array(trail), position[None, :]])
        s0 = self._trail_s[agent][0]
        line = Polyline(pts)
        last = self._progress.get(follower)
        lo, hi = (0.0, line.length) if last is None else (max(0.0, last - s0), last - s0 + p.trail_window)
        here = line.project(me, lo, min(hi, line.length)) if line.length > 0 else 0.0
        self._progress[follower] = s0 + here
        s_target = min(here + p.lookahead, line.length - p.d_s)
        if s_target <= here:
            return None
        return line.at(float(s_target))


def make_apoorva_chain(env: Any) -> ApoorvaChainPolicy:
    """``apoorva-chain``: the full controller (A* + ghost, potential fields, strip along the leader's trail)."""
    return ApoorvaChainPolicy(env, strip="trail")


def make_apoorva_chain_alg6(env: Any) -> ApoorvaChainPolicy:
    """``apoorva-chain-alg6``: the same with the printed Alg. 6 strip (the straight first-last line)."""
    return ApoorvaChainPolicy(env, strip="line")


def make_apoorva_chain_no_strip(env: Any) -> ApoorvaChainPolicy:
    """``apoorva-chain-no-strip``: the same without the elastic strip."""
    return ApoorvaChainPolicy(env, strip="none")
