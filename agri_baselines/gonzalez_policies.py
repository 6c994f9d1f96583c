"""SB3-style policies of González et al. (2009) for ``agri_envs/GreenhouseCoverage-v1``.

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
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from agri_baselines.gonzalez import PseudoReactiveController, PseudoReactiveParams, PurePursuit
from agri_baselines.gonzalez_planner import CoveragePlannerParams, plan_coverage


class _CoveragePolicyBase:
    """Observation decoding and action scaling shared by the three policies."""

    def __init__(self, env: Any) -> None:
        e = env.unwrapped
        self.env = env
        self.spec = e.robot_spec
        self.pose_scale = e.pose_scale
        self.max_range = e.sonars.spec.max_range
        self.mounts = e.sonars.mounts.copy()
        self.dt = e.config.control_period

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
    """A planned path and its Pure Pursuit tracker (the deliberative technique's on-line part)."""

    def __init__(self, path: np.ndarray, lookahead: float) -> None:
        self.path = path
        self.tracker = PurePursuit(path, lookahead=lookahead)

    def command(self, pose: np.ndarray, spec: Any) -> tuple[float, float]:
        return self.tracker.command(pose, spec.max_speed, spec.max_turn_rate, spec.max_accel)


class GonzalezDeliberativePolicy(_CoveragePolicyBase):
    """``gonzalez-deliberative`` (PRIVILEGED: the true map via ``env.unwrapped.true_map()``, the true pose).

    Args:
        env: A GreenhouseCoverage env made with ``localization="ground_truth"``.
        lookahead: Pure Pursuit look-ahead (m), the paper's 1 m.
        resolution: Map resolution (m/cell).
        planner: Planner parameters.
    """

    def __init__(
        self,
        env: Any,
        lookahead: float = 1.0,
        resolution: float = 0.05,
        planner: CoveragePlannerParams | None = None,
    ) -> None:
        super().__init__(env)
        if env.unwrapped.config.localization != "ground_truth":
            raise ValueError("gonzalez-deliberative needs gym.make(..., localization='ground_truth')")
        self.lookahead = lookahead
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
            self.follower = _Follower(plan.path + np.asarray(origin), self.lookahead)
        return self.to_action(*self.follower.command(pose, self.spec))

    def episode_metrics(self, index: int = 0) -> dict[str, Any]:
        """``plan_time_ms``, ``planned_length`` (m) and the ``planned_path`` (m, every 0.2 m) of the episode."""
        if self.follower is None:
            return {}
        path = self.follower.path
        return {
            "plan_time_ms": 1e3 * self.plan_time,
            "planned_length": self.follower.tracker.length,
            "planned_path": path[:: max(1, int(round(0.2 / 0.1)))].round(3).tolist(),
        }


class GonzalezPseudoReactivePolicy(_CoveragePolicyBase):
    """``gonzalez-pseudo-reactive``: sonars, compass and encoder odometry; no map, nothing privileged.

    Args:
        env: A GreenhouseCoverage env made with ``localization="odometry"``.
        params: Controller gains and thresholds.
    """

    def __init__(self, env: Any, params: PseudoReactiveParams | None = None) -> None:
        super().__init__(env)
        if env.unwrapped.config.localization != "odometry":
            raise ValueError("gonzalez-pseudo-reactive needs gym.make(..., localization='odometry')")
        self.params = params or PseudoReactiveParams()
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

    Args:
        env: A GreenhouseCoverage env made with ``localization="odometry"``; a fixed ``layout_seed`` makes
            every episode after the first a later run in the same greenhouse.
        params: Pseudo-reactive gains.
        lookahead: Pure Pursuit look-ahead (m).
        end_overshoot: The planned path is extended this far straight on past its end, where the map is free
            (m): the first run's map ends where that run's coverage did, and this run's odometry differs
            from the first run's by the encoders' scale errors.
    """

    def __init__(
        self, env: Any, params: PseudoReactiveParams | None = None, lookahead: float = 1.0, end_overshoot: float = 0.6
    ) -> None:
        super().__init__(env, params)
        self.lookahead = lookahead
        self.end_overshoot = end_overshoot
        self.known_map: tuple[np.ndarray, tuple[float, float]] | None = None
        self.follower: _Follower | None = None
        self.mode = "pseudo-reactive"
        self.runs = 0

    def act(self, obs: dict[str, np.ndarray], start: bool) -> np.ndarray:
        """First run: pseudo-reactive (building the map). Later runs: plan on the map and follow."""
        pose, sonar, heading = self.decode(obs)
        if start:
            same_greenhouse = self.env.unwrapped.config.layout_seed >= 0
            if self.runs > 0 and same_greenhouse and self.known_map is None and len(self.controller.map.points):
                self.known_map = self.controller.map.occupancy()
            if not same_greenhouse:
                self.known_map = None
            self.runs += 1
            self.follower = None
            self.mode = "pseudo-reactive"
            if self.known_map is not None:
                occ, origin = self.known_map
                try:
                    plan = plan_coverage(occ, 0.05, pose[:2] - np.asarray(origin))
                    path = _extend_end(plan.path, occ, 0.05, self.end_overshoot)
                    self.follower = _Follower(path + np.asarray(origin), self.lookahead)
                    self.mode = "deliberative"
                except ValueError:  # the map does not allow a plan: drive this run pseudo-reactively
                    self.known_map = None
            if self.follower is None:
                self.controller.reset()
        if self.follower is not None:
            return self.to_action(*self.follower.command(pose, self.spec))
        return self.to_action(*self.controller.command(sonar, heading, pose[0], pose[1], self.dt))

    def episode_metrics(self, index: int = 0) -> dict[str, Any]:
        """The run's mode (``hybrid_deliberative`` 1 or 0), plus the pseudo-reactive run's data or the plan."""
        if self.follower is None:
            return {"hybrid_deliberative": 0, **super().episode_metrics(index)}
        return {
            "hybrid_deliberative": 1,
            "planned_length": self.follower.tracker.length,
            "planned_path": self.follower.path[::2].round(3).tolist(),
        }


def _extend_end(path: np.ndarray, occ: np.ndarray, res: float, length: float) -> np.ndarray:
    """``path`` continued straight on past its last point, up to ``length`` metres over free cells."""
    seg = path[-1] - path[max(0, len(path) - 10)]
    norm = float(np.hypot(*seg))
    if length <= 0 or norm < 1e-9:
        return path
    u = seg / norm
    extra = []
    for t in np.arange(res, length + 1e-9, res):
        q = path[-1] + t * u
        i, j = int(q[1] // res), int(q[0] // res)
        if not (0 <= i < occ.shape[0] and 0 <= j < occ.shape[1]) or occ[i, j]:
            break
        extra.append(q)
    return np.vstack([path, *extra]) if extra else path


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
    """``gonzalez-hybrid``. Env: ``localization="odometry"`` (and a fixed ``layout_seed`` for later runs)."""
    return GonzalezHybridPolicy(env)
