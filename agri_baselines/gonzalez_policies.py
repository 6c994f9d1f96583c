"""SB3-style policies of González et al. (2009) for ``agri_envs/GreenhouseCoverage-v2``.

* ``gonzalez-deliberative`` (privileged): at each episode start it takes the greenhouse's map from the
  env's documented privileged accessor ``true_map()`` (the paper's digital map), plans the corridor-covering
  path on its Voronoi diagram (:func:`agri_baselines.coverage_path`) and follows it with Pure Pursuit
  (1 m look-ahead) on the ground-truth pose (the env is made with ``localization="ground_truth"``).
* ``gonzalez-pseudo-reactive``: no map; sonars, compass and encoder odometry only
  (:class:`~agri_baselines.gonzalez.PseudoReactiveController`). Its sensory map (eq. 2) is returned with
  the episode (``episode_metrics``) and by :meth:`GonzalezPseudoReactivePolicy.sensory_map`.
* ``gonzalez-hybrid`` (Fig. 2): the first run in a greenhouse is pseudo-reactive; its sensory map then
  feeds the deliberative planner on the next runs, followed with Pure Pursuit on the encoder/compass
  odometry. No true map, no true pose. "The same greenhouse" means the env has a fixed ``layout_seed``;
  with ``layout_seed=-1`` every episode is a new greenhouse and therefore a first run.

The policies drive one env at a time (the privileged map comes from that env); ``predict`` accepts a
batch of one, or a single observation.

Env arguments the policies adapt to, and those they ignore (measured on 4 episodes, seeds 100000-100003,
each argument at its bounds, ``max_speed`` 0.1 and 1.5, ``max_turn_rate`` 0.1 and 2.0, both at 1.5 and 2.0:
all three 4/4 on every one):

* ``max_speed``, ``max_turn_rate``: actions are scaled by the env's limits. Pure Pursuit (deliberative,
  hybrid's later runs) drives within the Fitorobot's limits the paper used (0.5 m/s, 0.6 rad/s:
  :data:`TRACKING_SPEED`, :data:`TRACKING_TURN_RATE`) or the env's where lower: allowed the env's 1.0 m/s
  it took the headland turns too fast for the acceleration limit and touched the crop (0/4). The
  pseudo-reactive controller (and the hybrid's first run) keeps its turn arcs' radius on a robot that turns
  slower than its 0.4 rad/s (at ``max_turn_rate=0.1`` the arc widened into the rows: 0/4), and speeds up
  when the env's speed limits shrink the time limit to less than half the default robot's (at 1.5 m/s and
  2 rad/s it timed out at 190.9 s: 0/4) (:func:`~agri_baselines.gonzalez.adapted_params`).
* ``time_limit`` and the mission-sized limit (``n_rows``, ``row_length``, ...): the pseudo-reactive speed-up
  above compares the env's limit with the default robot's.
* ``max_accel``: Pure Pursuit brakes within it. The pseudo-reactive controller plans its stops at its own
  0.2 m/s^2 (``brake_decel``) and ignores it (``max_accel=0.1``: still 4/4, in 223-234 s against 215-222 s).
  The hybrid's later runs at 1.5 m/s and 2 rad/s: 2 campaigns of 2 runs, all covered.
* ``control_period``, the sonar layout and range, ``pose_scale``: read from the env.
* Ignored: ``max_angular_accel`` (the turns assume the default 0.8 rad/s^2 or near it), the sensor noise
  arguments (the filters are the paper's, not tuned to them), ``localization`` (each policy requires its
  own: ground truth for the deliberative, odometry for the others).

With the default arguments every policy acts exactly as before these adaptations (the leaderboard's
coverage entries verify unchanged).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np

from agri_baselines.gonzalez import (
    LF,
    LM,
    LR,
    RF,
    RM,
    RR,
    PeakFilter,
    PseudoReactiveController,
    PseudoReactiveParams,
    PurePursuit,
    adapted_params,
    sonar_echo,
)
from agri_baselines.gonzalez_planner import (
    CORRIDOR,
    TURN,
    CoveragePlan,
    CoveragePlannerParams,
    anchor_corridors,
    plan_coverage,
    row_ends,
)

#: Shortest Pure Pursuit look-ahead before a bend (m): the 1 m of the paper on straight stretches, down to
#: this in the headland turns, where a fixed 1 m cut the planned turn by 0.27-0.30 m.
MIN_LOOKAHEAD = 0.4


#: The Fitorobot's limits as the paper drove it (GreenhouseCoverage's default ``max_speed`` (m/s) and
#: ``max_turn_rate`` (rad/s)): Pure Pursuit follows a plan within them, or within the env's where lower.
#: Allowed more, it took the headland turns too fast for the robot's acceleration limits and touched the
#: crop (``max_speed=1.0``: 4 of 4 episodes; ``max_turn_rate=2.0``: 1 of 4).
TRACKING_SPEED = 0.5
TRACKING_TURN_RATE = 0.6


class CoveragePolicyBase:
    """Observation decoding and action scaling shared by the coverage policies (the three of the paper, the teacher)."""

    def __init__(self, env: Any) -> None:
        e = env.unwrapped
        self.env = env
        self.spec = e.robot_spec
        self.pose_scale = e.pose_scale
        self.max_range = e.sonars.spec.max_range
        self.mounts = e.sonars.mounts.copy()
        self.dt = e.config.control_period
        #: ``(speed, turn rate, acceleration)`` limits Pure Pursuit follows a plan within.
        self.tracking = (
            min(self.spec.max_speed, TRACKING_SPEED),
            min(self.spec.max_turn_rate, TRACKING_TURN_RATE),
            self.spec.max_accel,
        )
        # The default robot's time limit over this env's (1 with the default speed limits and time_limit).
        cfg = e.config
        tuned = dataclasses.replace(cfg, max_speed=TRACKING_SPEED, max_turn_rate=TRACKING_TURN_RATE, time_limit=0.0)
        self.time_budget = tuned.mission_time() / cfg.mission_time()

    def decode(self, obs: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, float]:
        """``(pose (x, y, yaw), sonar ranges (m), compass heading (rad))`` from one observation."""
        pose = np.asarray(obs["pose"], dtype=np.float64)
        compass = np.asarray(obs["compass"], dtype=np.float64)
        yaw = math.atan2(2 * pose[2] - 1, 2 * pose[3] - 1)
        xy = np.array([pose[0] * self.pose_scale[0], pose[1] * self.pose_scale[1], yaw])
        heading = math.atan2(2 * compass[0] - 1, 2 * compass[1] - 1)
        return xy, np.asarray(obs["sonar"], dtype=np.float64) * self.max_range, heading

    def to_action(self, v: float, w: float) -> np.ndarray:
        """Velocities (m/s, rad/s) to the env's normalised action."""
        a0 = v / self.spec.max_speed if v >= 0 else v / max(self.spec.max_reverse_speed, 1e-9)
        return np.clip(np.array([a0, w / self.spec.max_turn_rate], dtype=np.float32), -1.0, 1.0)

    def act(self, obs: dict[str, np.ndarray], start: bool) -> np.ndarray:
        """One action for one observation (subclasses)."""
        raise NotImplementedError

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3's ``predict``: batched (a batch of one env) or single observations; ``state`` is passed through."""
        single = np.asarray(observation["sonar"]).ndim == 1
        batch = {k: np.asarray(v) for k, v in observation.items()}
        if single:
            batch = {k: v[None] for k, v in batch.items()}
        n = len(batch["sonar"])
        if n != 1:
            raise ValueError(f"{type(self).__name__} drives one env at a time (its map comes from it), got {n}")
        starts = np.zeros(1, bool) if episode_start is None else np.asarray(episode_start, bool).reshape(-1)
        action = self.act({k: v[0] for k, v in batch.items()}, bool(starts[0]))
        return (action if single else action[None]), state


class _Follower:
    """A planned path and its Pure Pursuit tracker (the deliberative technique's on-line part).

    The look-ahead is the paper's 1 m on straight stretches and shorter before bends (see
    :class:`~agri_baselines.gonzalez.PurePursuit`; ``min_lookahead`` None: fixed). Every command records the
    cross-track error of the pose it was given against the plan and the part of the plan it was on, for
    :meth:`tracking`.
    """

    def __init__(self, plan: CoveragePlan, origin: np.ndarray, lookahead: float, min_lookahead: float | None) -> None:
        self.path = plan.path + origin
        self.part = plan.part
        self.tracker = PurePursuit(self.path, lookahead=lookahead, min_lookahead=min_lookahead)
        self._s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(self.path, axis=0).T))])
        self.errors: dict[int, list[float]] = {CORRIDOR: [], TURN: []}

    def part_at(self, s: float) -> int:
        """The part of the plan (approach, corridor or turn) at arc length ``s``."""
        k = int(np.searchsorted(self._s, s, side="right")) - 1
        return int(self.part[min(len(self.part) - 1, max(0, k))])

    def command(self, pose: np.ndarray, limits: tuple[float, float, float]) -> tuple[float, float]:
        """Pure Pursuit's ``(v, w)`` for ``pose`` within ``(speed, turn rate, acceleration)`` limits.

        Records its cross-track error on the part of the plan it is on.
        """
        v, w = self.tracker.command(pose, *limits)
        part = self.part_at(self.tracker.progress)
        if not self.tracker.done and part in self.errors:
            self.errors[part].append(self.tracker.distance)
        return v, w

    def tracking(self) -> dict[str, float | None]:
        """Cross-track error against the plan (m), max and mean over the steps in the corridors and in the turns.

        Measured on the pose the tracker was given: the true pose of ``gonzalez-deliberative``, the (corrected)
        odometry of ``gonzalez-hybrid``. A turn is the stretch of the plan across a headland from one corridor
        to the next; the approach from the start to the first corridor is neither.
        """
        out: dict[str, float | None] = {}
        for name, part in (("corridors", CORRIDOR), ("turns", TURN)):
            e = self.errors[part]
            out[f"cross_track_{name}_max"] = float(max(e)) if e else None
            out[f"cross_track_{name}_mean"] = float(np.mean(e)) if e else None
        return out


#: The keys of :meth:`_Follower.tracking`, None in a run without a plan.
TRACKING_KEYS = tuple(f"cross_track_{n}_{s}" for n in ("corridors", "turns") for s in ("max", "mean"))


@dataclasses.dataclass
class _RowEnd:
    """Where a corridor's rows end on the first run's map, and the farthest a later run has seen them.

    Attributes:
        s_lo: Arc length of the plan where the corridor stretch begins (m).
        s_hi: ... and where it ends (m).
        origin: The stretch's first point (m); distances along the corridor are measured from it along ``u``.
        u: Unit vector of the driving direction along the corridor.
        ends: ``(2,)`` where the left and the right row end on the map (m along; NaN: not seen).
        seen: ``(2,)`` the farthest echo off each of those rows in this run (m along; -inf: none yet).
        done: The along-track correction of this corridor was made.
    """

    s_lo: float
    s_hi: float
    origin: np.ndarray
    u: np.ndarray
    ends: np.ndarray
    seen: np.ndarray = dataclasses.field(default_factory=lambda: np.full(2, -np.inf))
    done: bool = False


class GonzalezDeliberativePolicy(CoveragePolicyBase):
    """``gonzalez-deliberative`` (PRIVILEGED: the true map via ``env.unwrapped.true_map()``, the true pose).

    Args:
        env: A GreenhouseCoverage env made with ``localization="ground_truth"``.
        lookahead: Pure Pursuit look-ahead on straight stretches (m), the paper's 1 m.
        min_lookahead: Shortest look-ahead before a bend (m); None keeps ``lookahead`` everywhere (the
            paper's fixed look-ahead, which cuts the headland turns by about 0.3 m).
        resolution: Map resolution (m/cell).
        planner: Planner parameters.
    """

    def __init__(
        self,
        env: Any,
        lookahead: float = 1.0,
        min_lookahead: float | None = MIN_LOOKAHEAD,
        resolution: float = 0.05,
        planner: CoveragePlannerParams | None = None,
    ) -> None:
        super().__init__(env)
        if env.unwrapped.config.localization != "ground_truth":
            raise ValueError("gonzalez-deliberative needs gym.make(..., localization='ground_truth')")
        self.lookahead = lookahead
        self.min_lookahead = min_lookahead
        self.resolution = resolution
        self.planner = planner or CoveragePlannerParams()
        self.follower: _Follower | None = None
        self.plan_time = 0.0

    def act(self, obs: dict[str, np.ndarray], start: bool) -> np.ndarray:
        """Plan on the episode's first observation, then follow."""
        pose, _, _ = self.decode(obs)
        if start or self.follower is None:
            occ, res, origin = self.env.unwrapped.true_map(self.resolution)
            t0 = time.perf_counter()
            plan = plan_coverage(occ, res, pose[:2] - np.asarray(origin), self.planner)
            self.plan_time = time.perf_counter() - t0
            self.follower = _Follower(plan, np.asarray(origin), self.lookahead, self.min_lookahead)
        return self.to_action(*self.follower.command(pose, self.tracking))

    def episode_metrics(self, index: int = 0) -> dict[str, Any]:
        """The episode's plan: ``plan_time_ms``, ``planned_length`` (m), ``planned_path`` (m, every 0.2 m).

        Also the cross-track error against the plan in the corridors and turns (m, :meth:`_Follower.tracking`).
        """
        if self.follower is None:
            return {}
        path = self.follower.path
        return {
            "plan_time_ms": 1e3 * self.plan_time,
            "planned_length": self.follower.tracker.length,
            **self.follower.tracking(),
            "planned_path": path[:: max(1, int(round(0.2 / 0.1)))].round(3).tolist(),
        }


class GonzalezPseudoReactivePolicy(CoveragePolicyBase):
    """``gonzalez-pseudo-reactive``: sonars, compass and encoder odometry; no map, nothing privileged.

    Args:
        env: A GreenhouseCoverage env made with ``localization="odometry"``.
        params: Controller gains and thresholds.
    """

    def __init__(self, env: Any, params: PseudoReactiveParams | None = None) -> None:
        super().__init__(env)
        if env.unwrapped.config.localization != "odometry":
            raise ValueError("gonzalez-pseudo-reactive needs gym.make(..., localization='odometry')")
        spec = self.spec
        self.params = params or adapted_params(
            PseudoReactiveParams(), spec.max_speed, spec.max_turn_rate, self.time_budget
        )
        self.controller = PseudoReactiveController(self.params, self.mounts, self.max_range)

    def act(self, obs: dict[str, np.ndarray], start: bool) -> np.ndarray:
        """One pseudo-reactive step."""
        if start:
            self.controller.reset()
        pose, sonar, heading = self.decode(obs)
        return self.to_action(*self.controller.command(sonar, heading, pose[0], pose[1], self.dt))

    def sensory_map(self, index: int = 0) -> np.ndarray:
        """The episode's sensory map (eq. 2): ``(n, 2)`` echo positions in the odometry frame (m)."""
        return self.controller.map.as_array()

    def episode_metrics(self, index: int = 0) -> dict[str, Any]:
        """The final phase, the number of turns, the sensory map (eq. 2) and the driven odometry.

        The map keeps one echo per 10 cm square and the odometry every fifth step (small result files).
        """
        c = self.controller
        return {
            "final_phase": c.phase,
            "turns": c.turns,
            "sensory_map": _thin(self.sensory_map(), 0.1).round(3).tolist(),
            "odometry_path": np.array(c.map.trajectory)[::5].round(3).tolist(),
        }


class GonzalezHybridPolicy(GonzalezPseudoReactivePolicy):
    """``gonzalez-hybrid`` (Fig. 2): pseudo-reactive first, then deliberative on the sensory map, no true map.

    The first run in a greenhouse is pseudo-reactive and builds the sensory map (eq. 2) in its odometry frame.
    Later runs plan on that map (:func:`~agri_baselines.gonzalez_planner.plan_coverage`) and follow the plan
    with Pure Pursuit on the odometry, which starts at the robot's pose as the first run's did. Beyond the
    paper, this project adds three corrections, all from the robot's own sonars (the paper tracks on the
    odometry alone and names a Kalman filter as future work):

    * **Corridors re-anchored on the rows** (``anchor_rows``): the Voronoi mid-line of a sensory map wavers
      with every leaf and every echo slipped through a row, and beside a wall it leans toward the row (the
      sonars see into the row between the plants). Each corridor of the plan is moved onto a smooth mid-line
      fitted to the faces of its two rows in the first run's echoes
      (:func:`~agri_baselines.gonzalez_planner.anchor_corridors`). In eight validation campaigns of four
      runs on the default greenhouse (seeds 5000-5031) it took the later runs' mean max cross-track to the
      true centre lines from 0.103 m to 0.044 m.
    * **Odometry corrected sideways**: the two runs' odometry drifts differently (each encoder's scale error
      is the run's own), so the plan's corridors lie some centimetres beside the corridors this run's
      odometry sees. Along the corridors of the plan the robot corrects its odometry sideways by what its
      lateral sonars measure: the offset from the corridor's middle that each lateral pair of sonars reads
      (eq. 1-filtered, both seeing a row) against the offset from the plan's corridor line that the
      corrected odometry predicts, blended in with gain ``lateral_gain`` per step.
    * **Odometry re-scaled at the rows' ends** (``anchor_ends``): where the lateral sonars stop seeing a
      corridor's row, this run's odometry is compared with where the row ends on the map
      (:func:`~agri_baselines.gonzalez_planner.row_ends`), and the difference corrects the scale between the
      two runs' encoders (or, near the start, shifts the odometry along the corridor). Without it a later
      run whose encoders read a few per cent short of the first run's overshoots the first corridor's end
      and its turn runs into the end wall, and the scale difference moves each further corridor sideways.

    Args:
        env: A GreenhouseCoverage env made with ``localization="odometry"``; a fixed ``layout_seed`` makes
            every episode after the first a later run in the same greenhouse (a campaign).
        params: Pseudo-reactive gains (``side_valid`` also gates the lateral correction).
        lookahead: Pure Pursuit look-ahead on straight stretches (m).
        end_overshoot: The planned path is extended this far straight on past its end, where the map is free
            (m): the first run's map ends where that run's coverage did, and this run's odometry differs
            from the first run's by the encoders' scale errors.
        lateral_gain: Share of the sonar-measured lateral error corrected per step (0: odometry alone).
        lateral_gate: Larger disagreements between the sonars and the odometry are ignored (m): a leaf or an
            echo slipping into the foliage, not drift.
        anchor_rows: Re-anchor the plan's corridors on the rows of the sensory map (False: the Voronoi
            mid-line as planned).
        face_quantile: Share of a row's echoes nearer the corridor than its fitted face.
        depth: Echoes deeper than this behind a row's face are not used to fit it (m).
        anchor_ends: Correct the odometry at the rows' ends (False: sideways only).
        end_gap: The rows have ended once the middle lateral sonars are this far past their last echo (m).
        end_window: A larger disagreement with the map about where a row ends is a gap, not its end (m).
        scale_distance: Nearer the start along the corridor (m), a row end's disagreement shifts the odometry
            instead of scaling it.
    """

    def __init__(
        self,
        env: Any,
        params: PseudoReactiveParams | None = None,
        lookahead: float = 1.0,
        end_overshoot: float = 0.6,
        lateral_gain: float = 0.05,
        lateral_gate: float = 0.3,
        anchor_rows: bool = True,
        face_quantile: float = 0.25,
        depth: float = 0.4,
        anchor_ends: bool = True,
        end_gap: float = 0.3,
        end_window: float = 1.0,
        scale_distance: float = 3.0,
    ) -> None:
        super().__init__(env, params)
        self.anchor_rows = anchor_rows
        self.face_quantile = face_quantile
        self.depth = depth
        self.anchor_ends = anchor_ends
        self.end_gap = end_gap
        self.end_window = end_window
        self.scale_distance = scale_distance
        self.row_ends: list[_RowEnd] = []
        self.lookahead = lookahead
        self.end_overshoot = end_overshoot
        self.lateral_gain = lateral_gain
        self.lateral_gate = lateral_gate
        self.known_map: tuple[np.ndarray, tuple[float, float]] | None = None
        self.echoes = np.zeros((0, 2))  # the first run's sensory map (m, odometry frame)
        self.follower: _Follower | None = None
        self.mode = "pseudo-reactive"
        self.runs = 0
        self.correction = np.zeros(2)  # added to the odometry position on a later run (m)
        self.scale = 1.0  # the first run's distances over this run's, as the rows' ends measured it
        self.odometry_start = np.zeros(2)  # where this run's odometry started (m)
        self.filters = [PeakFilter(self.params.filter_n, self.params.filter_eps) for _ in range(len(self.mounts))]

    def act(self, obs: dict[str, np.ndarray], start: bool) -> np.ndarray:
        """First run: pseudo-reactive (building the map). Later runs: plan on the map and follow."""
        pose, sonar, heading = self.decode(obs)
        if start:
            self._start_run(pose)
        if self.follower is None:
            return self.to_action(*self.controller.command(sonar, heading, pose[0], pose[1], self.dt))
        filtered = [f(v) for f, v in zip(self.filters, sonar, strict=True)]
        corrected = pose.copy()
        corrected[:2] = self._corrected(pose[:2])
        self._correct_sideways(corrected, np.array(filtered))
        corrected[:2] = self._corrected(pose[:2])
        if self.anchor_ends:
            self._correct_along(corrected, pose[:2], np.array(filtered))
            corrected[:2] = self._corrected(pose[:2])
        return self.to_action(*self.follower.command(corrected, self.tracking))

    def _start_run(self, pose: np.ndarray) -> None:
        same_greenhouse = self.env.unwrapped.config.layout_seed >= 0
        if self.runs > 0 and same_greenhouse and self.known_map is None and len(self.controller.map.points):
            self.known_map = self.controller.map.occupancy()
            self.echoes = self.controller.map.as_array()
        if not same_greenhouse:
            self.known_map = None
        self.runs += 1
        self.follower = None
        self.row_ends = []
        self.mode = "pseudo-reactive"
        self.correction = np.zeros(2)
        self.scale = 1.0
        self.odometry_start = pose[:2].copy()
        for f in self.filters:
            f.reset()
        if self.known_map is not None:
            occ, origin = self.known_map
            try:
                plan = plan_coverage(occ, 0.05, pose[:2] - np.asarray(origin))
                if self.anchor_rows:
                    echoes = self.echoes - np.asarray(origin)
                    plan = anchor_corridors(plan, echoes, depth=self.depth, face_quantile=self.face_quantile)
                plan = _extend_end(plan, occ, 0.05, self.end_overshoot)
                self.follower = _Follower(plan, np.asarray(origin), self.lookahead, MIN_LOOKAHEAD)
                self.row_ends = [
                    _RowEnd(
                        float(self.follower._s[lo]),
                        float(self.follower._s[hi - 1]),
                        self.follower.path[lo],
                        _unit(self.follower.path[hi - 1] - self.follower.path[lo]),
                        ends,
                    )
                    for lo, hi, ends in row_ends(plan, self.echoes - np.asarray(origin), depth=self.depth)
                ]
                self.mode = "deliberative"
            except ValueError:  # the map does not allow a plan: drive this run pseudo-reactively
                self.known_map = None
        if self.follower is None:
            self.controller.reset()

    def _correct_sideways(self, pose: np.ndarray, filtered: np.ndarray) -> None:
        """Along a corridor of the plan: pull the odometry sideways toward what the lateral sonars measure.

        Each lateral pair (front, middle, rear) whose two sonars both see a row (eq. 1-filtered, no peak)
        measures the offset of its own position from the corridor's middle; the plan's corridor line there
        predicts it from the corrected odometry. The mean disagreement is blended into the correction.
        """
        assert self.follower is not None
        tracker = self.follower.tracker
        errors = []
        c, s = math.cos(pose[2]), math.sin(pose[2])
        for left, right in ((LF, RF), (LM, RM), (LR, RR)):
            if not (self._sees_row(left, filtered) and self._sees_row(right, filtered)):
                continue
            along = float(self.mounts[left, 0])  # the pair's position ahead of the robot's centre (m)
            at = pose[:2] + along * np.array([c, s])
            arc = tracker.progress + along
            if self.follower.part_at(arc) != CORRIDOR:
                continue
            here, ahead = tracker.point_at(arc), tracker.point_at(arc + 0.2)
            tangent = (ahead - here) / max(float(np.hypot(*(ahead - here))), 1e-9)
            normal = np.array([-tangent[1], tangent[0]])  # to the left of the plan
            predicted = float(np.dot(at - here, normal))
            # the left sonar reading short: the pair is left of the middle (the mounts are symmetric)
            tilt = math.cos(pose[2] - math.atan2(tangent[1], tangent[0]))
            measured = 0.5 * (filtered[right] - filtered[left]) * tilt
            if abs(measured - predicted) <= self.lateral_gate:
                errors.append((measured - predicted) * normal)
        if errors:
            self.correction += self.lateral_gain * np.mean(errors, axis=0)

    def _corrected(self, xy: np.ndarray) -> np.ndarray:
        """The odometry position ``xy`` in the first run's frame: scaled about this run's start, then shifted."""
        return self.odometry_start + self.scale * (xy - self.odometry_start) + self.correction

    def _sees_row(self, k: int, filtered: np.ndarray) -> bool:
        """Sonar ``k``'s eq. 1-filtered reading is a row or a wall beside the robot (a full window, no peak)."""
        f = self.filters[k]
        return len(f.window) == f.n and not f.last_was_peak and filtered[k] < self.params.side_valid

    def _correct_along(self, pose: np.ndarray, odometry: np.ndarray, filtered: np.ndarray) -> None:
        """At the end of a corridor of the plan: shift the odometry along it to where the sonars saw its rows end.

        While the robot drives a corridor stretch, every lateral echo off a row (:meth:`_sees_row`) is placed
        with the corrected odometry, and the farthest one along the corridor is kept per side. Once the middle
        lateral sonars have passed ``end_gap`` metres beyond it (neither they nor the front ones have seen the
        row for 0.6 m plus that: more than a gap between plants) on every side whose row ends first on the map
        (a wall beside the first and last corridors runs on), the odometry is shifted along the corridor by
        the mean difference between where the map's rows end and where this run saw them end, provided it is
        within ``end_window`` metres (a gap in the row, not its end, otherwise).

        The two runs' encoders differ in scale, so that difference grows with the distance driven: where the
        odometry (``odometry``, uncorrected) lies ``scale_distance`` metres or more along the corridor from
        where it started, the difference corrects the scale between the two runs' odometry instead of
        shifting it, and the sideways shift is kept as the lateral sonars left it here. The new scale then
        also moves the next corridors sideways by what the encoders' scales disagree over the headland turns.
        """
        s = self.follower.tracker.progress if self.follower is not None else 0.0
        for end in self.row_ends:
            if end.done or not end.s_lo <= s <= end.s_hi + 2.0:
                continue
            for side, sonars in ((0, (LF, LM, LR)), (1, (RF, RM, RR))):
                for k in sonars:
                    if self._sees_row(k, filtered):
                        echo = np.array(sonar_echo(pose[0], pose[1], pose[2], self.mounts[k], float(filtered[k])))
                        end.seen[side] = max(end.seen[side], float(np.dot(echo - end.origin, end.u)))
            if np.isnan(end.ends).all():
                continue
            rows = [k for k in (0, 1) if end.ends[k] <= np.nanmin(end.ends) + 0.5]
            at_lm = np.array(sonar_echo(pose[0], pose[1], pose[2], self.mounts[LM], 0.0))  # the sonar itself
            middle = float(np.dot(at_lm - end.origin, end.u))
            if all(np.isfinite(end.seen[k]) and middle > end.seen[k] + self.end_gap for k in rows):
                errors = [end.ends[k] - end.seen[k] for k in rows]
                if all(abs(e) <= self.end_window for e in errors):
                    self._shift_along(float(np.mean(errors)), end.u, odometry)
                    end.done = True

    def _shift_along(self, error: float, u: np.ndarray, odometry: np.ndarray) -> None:
        """Correct the odometry by ``error`` metres along ``u``: in scale when far enough from its start (see above)."""
        driven = float(np.dot(odometry - self.odometry_start, u))
        if abs(driven) < self.scale_distance:
            self.correction += error * u
            return
        d_scale = float(np.clip(error / driven, -0.2, 0.2))
        normal = np.array([-u[1], u[0]])
        self.scale += d_scale
        self.correction -= d_scale * float(np.dot(odometry - self.odometry_start, normal)) * normal

    def episode_metrics(self, index: int = 0) -> dict[str, Any]:
        """The run's mode (``hybrid_deliberative`` 1 or 0), plus the pseudo-reactive run's data or the plan.

        A later run adds the cross-track error against its plan (on the corrected odometry, m),
        ``lateral_correction``, the odometry's shift at the end of the run (m), and ``odometry_scale``, the
        scale between the first run's odometry and this run's that the rows' ends measured (1: none).
        """
        if self.follower is None:
            return {"hybrid_deliberative": 0, **dict.fromkeys(TRACKING_KEYS), **super().episode_metrics(index)}
        return {
            "hybrid_deliberative": 1,
            "planned_length": self.follower.tracker.length,
            **self.follower.tracking(),
            "lateral_correction": float(np.hypot(*self.correction)),
            "odometry_scale": self.scale,
            "planned_path": self.follower.path[::2].round(3).tolist(),
        }


def _extend_end(plan: CoveragePlan, occ: np.ndarray, res: float, length: float) -> CoveragePlan:
    """The plan continued straight on past its last point, up to ``length`` metres over free cells."""
    path = plan.path
    seg = path[-1] - path[max(0, len(path) - 10)]
    norm = float(np.hypot(*seg))
    if length <= 0 or norm < 1e-9:
        return plan
    u = seg / norm
    extra = []
    for t in np.arange(res, length + 1e-9, res):
        q = path[-1] + t * u
        i, j = int(q[1] // res), int(q[0] // res)
        if not (0 <= i < occ.shape[0] and 0 <= j < occ.shape[1]) or occ[i, j]:
            break
        extra.append(q)
    if not extra:
        return plan
    part = np.concatenate([plan.part, np.full(len(extra), plan.part[-1])])
    return dataclasses.replace(plan, path=np.vstack([path, *extra]), part=part)


def _unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to length 1 (a zero vector stays zero)."""
    norm = float(np.hypot(*v))
    return v / norm if norm > 0 else v


def _thin(points: np.ndarray, cell: float) -> np.ndarray:
    """One point per ``cell``-sized square (keeps the result files small)."""
    if len(points) == 0:
        return points
    _, first = np.unique(np.floor(points / cell).astype(np.int64), axis=0, return_index=True)
    return points[np.sort(first)]


def make_gonzalez_deliberative(env: Any) -> GonzalezDeliberativePolicy:
    """``gonzalez-deliberative``. Env: ``localization="ground_truth"`` (privileged: true map and pose)."""
    return GonzalezDeliberativePolicy(env)


def make_gonzalez_pseudo_reactive(env: Any) -> GonzalezPseudoReactivePolicy:
    """``gonzalez-pseudo-reactive``. Env: ``localization="odometry"``."""
    return GonzalezPseudoReactivePolicy(env)


def make_gonzalez_hybrid(env: Any) -> GonzalezHybridPolicy:
    """``gonzalez-hybrid``. Env: ``localization="odometry"``; its later runs need a campaign in one world.

    ``agri evaluate --campaign-runs R`` (or a suite's ``campaign``) drives R runs in one greenhouse with one
    policy; evaluated episode by episode, every run is a first run.
    """
    return GonzalezHybridPolicy(env)
