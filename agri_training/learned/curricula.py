"""Training-time curricula: wrappers that change where training episodes start or what a crash costs early on.

Evaluation never sees them.

They are declared in a hyperparameter block's ``train_wrappers`` (by name, like ``wrappers``) and wrap
only the training envs: periodic evaluation, ``agri evaluate`` and the leaderboard run the plain env.
Gymnasium envs take the names of :data:`TRAIN_WRAPPERS`, PettingZoo parallel envs (the robot chain) those of
:data:`PARALLEL_TRAIN_WRAPPERS`. Each Gymnasium curriculum but :class:`ExpertStart` and the arm's
(:class:`HarvestLegs`, :class:`RobustVines`: the arm has no batched form) has a vector form
(:data:`VECTOR_TRAIN_WRAPPERS`, the same names) for the vector envs ``agri train`` drives through
:class:`~agri_training.learned.vec_env.VectorVecEnv`: it acts per sub-env and draws the same numbers as the
single-env wrapper on each sub-env would. ExpertStart lets a baseline drive one env alone before the
learner's episode starts, which a batched env (its sub-envs stepped together) cannot do.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv, VectorWrapper
from pettingzoo.utils.wrappers import BaseParallelWrapper

from agri_baselines import make_policy
from agri_envs.arm.scene import sample_scene_and_configurations
from agri_training.learned.harvest import HarvestLegs
from agri_training.learned.policy import wrap_by_name
from agri_training.learned.vector import per_env_seeds, reset_rows


class RandomStartWaypoint(gym.Wrapper[Any, Any, Any, Any]):
    """Start a share of GreenhouseNav's training episodes at a random waypoint of the mission.

    A long waypoint mission shows a learner its later legs (and the turns between them) only once it masters
    the earlier ones; starting some episodes on the way (``reset(options={"start_waypoint": "random"})``:
    the env draws k from 1 .. n - 1 once it knows the episode's mission, and the robot stands on waypoint
    k - 1 as if it had just reached it) shows every leg from the start, also when every episode draws
    another scene and mission (``scene_distribution``).

    Args:
        env: A GreenhouseNav env (anything whose reset takes the ``start_waypoint`` option).
        prob: Share of the episodes that start at a waypoint drawn uniformly from 1 .. n - 1, in [0, 1].
    """

    def __init__(self, env: gym.Env[Any, Any], prob: float = 0.5) -> None:
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"RandomStartWaypoint: prob must be in [0, 1], got {prob}")
        super().__init__(env)
        self.prob = prob
        self._rng = np.random.default_rng(0)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset, at a random waypoint with probability ``prob``."""
        if seed is not None:
            self._rng = np.random.default_rng([seed, 1])
        options = dict(options or {})
        if "start_waypoint" not in options and self._rng.random() < self.prob:
            options["start_waypoint"] = "random"
        return self.env.reset(seed=seed, options=options or None)


class CrashShare:
    """The crash penalty's share that :class:`CrashCostRamp` and its vector form charge: ``start`` rising to 1.

    Attributes:
        start: Share charged at first, in [0, 1].
        ramp_steps: Steps over which the share reaches 1, >= 1.
        steps: Steps taken so far.
    """

    start: float
    ramp_steps: int
    steps: int

    def start_ramp(self, start: float, ramp_steps: int) -> None:
        """Set the ramp and count from 0.

        Raises:
            ValueError: For a ``start`` outside [0, 1] or ``ramp_steps`` below 1.
        """
        if not 0.0 <= start <= 1.0:
            raise ValueError(f"CrashCostRamp: start must be in [0, 1], got {start}")
        if ramp_steps < 1:
            raise ValueError(f"CrashCostRamp: ramp_steps must be >= 1, got {ramp_steps}")
        self.start, self.ramp_steps, self.steps = start, ramp_steps, 0

    @property
    def share(self) -> float:
        """The share of the crash penalty charged now."""
        return self.start + (1.0 - self.start) * min(1.0, self.steps / self.ramp_steps)


class CrashCostRamp(CrashShare, gym.Wrapper[Any, Any, Any, Any]):
    """Phase a crash's penalty in over the first part of training: cheap crashes first, the env's cost later.

    A learner whose first random drives end in a crash that costs more than idling to the time limit learns
    to stand still before it learns to steer. This wrapper gives back part of each crash's penalty: the
    share charged grows linearly from ``start`` to 1 over this env's first ``ramp_steps`` steps, after which
    the env's reward is unchanged. It reads the penalty from ``info[term]``: ``reward_collision``
    (GreenhouseNav) or ``reward_contact`` (GreenhouseCoverage).

    Args:
        env: The training env.
        start: Share of the crash penalty charged at first, in [0, 1].
        ramp_steps: Steps of this env copy over which the share reaches 1, >= 1 (with ``action_repeat`` a
            step is one action, held for that many control periods).
        term: The ``info`` key of the env's crash penalty (a reward term, <= 0).
    """

    def __init__(
        self, env: gym.Env[Any, Any], start: float = 0.1, ramp_steps: int = 100_000, term: str = "reward_collision"
    ) -> None:
        super().__init__(env)
        self.start_ramp(start, ramp_steps)
        self.term = term

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Step the env; refund ``1 - share`` of a crash's penalty."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        penalty = -float(info.get(self.term, 0.0))
        return obs, float(reward) + (1.0 - self.share) * penalty, terminated, truncated, info


class ExpertStart(gym.Wrapper[Any, Any, Any, Any]):
    """Start a share of training episodes where a scripted baseline left off, part way through the mission.

    On such a reset the baseline drives the env (in the env's own control periods) until ``info[progress]``
    reaches a ``k`` drawn from 1 .. ``info[total]`` - 1, and then for up to ``extra_steps`` more periods; the
    learner's episode starts there, in a state it reached by real driving (its memory, odometry and
    coverage included). For GreenhouseCoverage with ``progress="corridors_covered"`` the learner starts at
    the end of a corridor or in the turn into the next: the skill a learner meets last when every episode
    starts at the first corridor, and the one it parks in front of. The baseline's periods are not part of
    the learner's episode (its return and length count from the handover). A backward curriculum from
    demonstrations (Salimans and Chen 2018), with the paper's own controller as the demonstrator.

    Args:
        env: The training env.
        policy: A registered baseline of the env (``agri list``), built on the unwrapped env.
        prob: Share of the episodes that start where the baseline left off, in [0, 1].
        progress: ``info`` key counting the mission's completed parts.
        total: ``info`` key holding their number.
        extra_steps: The baseline drives up to this many control periods past the completed part, >= 0.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        policy: str,
        prob: float = 0.5,
        progress: str = "corridors_covered",
        total: str = "n_corridors",
        extra_steps: int = 120,
    ) -> None:
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"ExpertStart: prob must be in [0, 1], got {prob}")
        if extra_steps < 0:
            raise ValueError(f"ExpertStart: extra_steps must be >= 0, got {extra_steps}")
        super().__init__(env)
        self.expert = make_policy(policy, env.unwrapped)
        self.prob = prob
        self.progress = progress
        self.total = total
        self.extra_steps = extra_steps
        self._rng = np.random.default_rng(0)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset; with probability ``prob``, let the baseline drive first (a fresh reset if its drive ends)."""
        if seed is not None:
            self._rng = np.random.default_rng([seed, 2])
        obs, info = self.env.reset(seed=seed, options=options)
        if self._rng.random() >= self.prob or int(info[self.total]) < 2:
            return obs, info
        goal = int(self._rng.integers(1, int(info[self.total])))
        extra = int(self._rng.integers(0, self.extra_steps + 1))
        base = self.env.unwrapped
        start = True
        while extra >= 0:
            action, _ = self.expert.predict(obs, episode_start=np.array([start]), deterministic=True)
            start = False
            obs, _, terminated, truncated, info = base.step(action)
            if terminated or truncated:  # the baseline's drive ended the episode: start afresh instead
                return self.env.reset(options=options)
            if int(info[self.progress]) >= goal:
                extra -= 1
        return obs, info


class RobustVines(gym.Wrapper[Any, Any, Any, Any]):
    """Draw each GrapeHarvest training vine from wider ranges than the env's arguments (a training distribution).

    On each reset the episode's Generator draws the largest lean of the clusters' hanging axes from
    ``cluster_tilt`` (a uniform range, rad) and the fewest clusters from ``min_clusters`` (an integer range, both
    ends included; the count is then drawn up to the env's ``max_clusters`` as the env draws it), and the env
    places a vine drawn with them (``reset(options={"scene": ...})``); its other scene arguments (leaves, canes,
    ``feasible_scenes``) stay the env's. A reset that places a scene of its own is left alone. The observation
    does not change (the lean is not observed; the cluster slots are ``max_clusters``'). Evaluation runs the plain
    env, so the suites' levels beyond the ranges stay outside training.

    Args:
        env: A GrapeHarvest env.
        cluster_tilt: ``[low, high]`` of the largest lean (rad), within the env's range [0, 0.5].
        min_clusters: ``[low, high]`` of the fewest clusters, within 1 .. the env's ``max_clusters``.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        cluster_tilt: Sequence[float] = (0.17, 0.4),
        min_clusters: Sequence[int] = (2, 5),
    ) -> None:
        raw: Any = env.unwrapped
        if not hasattr(raw, "config") or not hasattr(raw.config, "scene_params"):
            raise ValueError("RobustVines needs a GrapeHarvest env")
        tilt = tuple(float(t) for t in cluster_tilt)
        if len(tilt) != 2 or not 0.0 <= tilt[0] <= tilt[1] <= 0.5:
            raise ValueError(f"RobustVines: cluster_tilt must be [low, high] within [0, 0.5] rad, got {cluster_tilt!r}")
        fewest = tuple(int(n) for n in min_clusters)
        most = int(raw.config.max_clusters)
        if len(fewest) != 2 or not 1 <= fewest[0] <= fewest[1] <= most:
            raise ValueError(
                f"RobustVines: min_clusters must be [low, high] within 1 .. max_clusters={most}, got {min_clusters!r}"
            )
        super().__init__(env)
        self.cluster_tilt, self.min_clusters = tilt, fewest

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset, then place a vine drawn from the ranges with the episode's Generator."""
        obs, info = self.env.reset(seed=seed, options=options)
        if options and options.get("scene") is not None:
            return obs, info
        raw: Any = self.env.unwrapped
        rng = raw.np_random
        params = dataclasses.replace(
            raw.config.scene_params(),
            cluster_tilt=float(rng.uniform(*self.cluster_tilt)),
            min_clusters=int(rng.integers(self.min_clusters[0], self.min_clusters[1] + 1)),
        )
        scene, _ = sample_scene_and_configurations(rng, params)
        return self.env.reset(options={"scene": scene})


class ShortMissions(BaseParallelWrapper):  # type: ignore[misc]
    """Start a share of robot_chain's training episodes near the goal; the share shrinks as training goes on.

    A chain that has never arrived cannot learn what arriving pays. Early on, most episodes start with the
    leader ``goal_distance`` metres from the goal along the free floor (the env's ``reset`` option of that
    name); the share of such episodes falls linearly from ``start`` to ``end`` over this env copy's first
    ``ramp_steps`` steps, and the rest of the episodes are the env's own (at least ``min_goal_distance``).

    Args:
        env: A robot_chain parallel env.
        goal_distance: ``(lo, hi)`` metres of a short mission.
        start: Share of short missions at first, in [0, 1].
        end: Share after ``ramp_steps``, in [0, 1].
        ramp_steps: Steps of this env copy (parallel steps, every robot once) over which the share goes from
            ``start`` to ``end``, >= 1.
    """

    def __init__(
        self,
        env: Any,
        goal_distance: Sequence[float] = (1.0, 3.0),
        start: float = 1.0,
        end: float = 0.2,
        ramp_steps: int = 100_000,
    ) -> None:
        lo, hi = (float(v) for v in goal_distance)
        if not 0.0 <= lo <= hi:
            raise ValueError(f"ShortMissions: goal_distance must be (lo, hi) with 0 <= lo <= hi, got {goal_distance}")
        for name, value in (("start", start), ("end", end)):
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"ShortMissions: {name} must be in [0, 1], got {value}")
        if ramp_steps < 1:
            raise ValueError(f"ShortMissions: ramp_steps must be >= 1, got {ramp_steps}")
        super().__init__(env)
        self.goal_distance = (lo, hi)
        self.start, self.end, self.ramp_steps = float(start), float(end), int(ramp_steps)
        self.steps = 0
        self._rng = np.random.default_rng(0)

    @property
    def share(self) -> float:
        """The share of short missions now."""
        return self.start + (self.end - self.start) * min(1.0, self.steps / self.ramp_steps)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset, as a short mission with probability :attr:`share`."""
        if seed is not None:
            self._rng = np.random.default_rng([seed, 2])
        options = dict(options or {})
        if "goal_distance" not in options and self._rng.random() < self.share:
            options["goal_distance"] = self.goal_distance
        result: tuple[dict[str, Any], dict[str, Any]] = self.env.reset(seed=seed, options=options or None)
        return result

    def step(self, actions: dict[str, Any]) -> tuple[Any, Any, Any, Any, Any]:
        """Step the env and count the step."""
        self.steps += 1
        result: tuple[Any, Any, Any, Any, Any] = self.env.step(actions)
        return result


#: Training wrappers a config may declare (by name; nothing is imported from a string).
TRAIN_WRAPPERS: dict[str, type[gym.Wrapper[Any, Any, Any, Any]]] = {
    "RandomStartWaypoint": RandomStartWaypoint,
    "CrashCostRamp": CrashCostRamp,
    "ExpertStart": ExpertStart,
    "HarvestLegs": HarvestLegs,
    "RobustVines": RobustVines,
}


#: Training wrappers of PettingZoo parallel envs (the robot chain), likewise by name.
PARALLEL_TRAIN_WRAPPERS: dict[str, type[Any]] = {"ShortMissions": ShortMissions}


def check_wrapper_names(wrappers: Sequence[str | Mapping[str, Any]], allowed: Mapping[str, Any], kind: str) -> None:
    """Refuse declared wrappers whose names are not in ``allowed`` (before any env is made).

    Raises:
        ValueError: Naming the wrapper and the allowed names.
    """
    for item in wrappers:
        name = item if isinstance(item, str) else next(iter(item), None) if isinstance(item, Mapping) else None
        if name not in allowed:
            raise ValueError(f"{kind} {name!r} is not allowed; allowed: {', '.join(allowed)}")


def apply_parallel_train_wrappers(env: Any, wrappers: Sequence[str | Mapping[str, Any]]) -> Any:
    """Wrap a parallel env in the declared training wrappers, innermost first (:data:`PARALLEL_TRAIN_WRAPPERS`).

    Raises:
        ValueError: For a wrapper that is not in :data:`PARALLEL_TRAIN_WRAPPERS`, or a malformed entry.
    """
    return wrap_by_name(env, wrappers, PARALLEL_TRAIN_WRAPPERS, kind="training wrapper")


def apply_train_wrappers(env: gym.Env[Any, Any], wrappers: Sequence[str | Mapping[str, Any]]) -> gym.Env[Any, Any]:
    """Wrap ``env`` in the declared training wrappers, innermost first (names from :data:`TRAIN_WRAPPERS`).

    Raises:
        ValueError: For a wrapper that is not in :data:`TRAIN_WRAPPERS`, or a malformed entry.
    """
    wrapped: gym.Env[Any, Any] = wrap_by_name(env, wrappers, TRAIN_WRAPPERS, kind="training wrapper")
    return wrapped


class VectorRandomStartWaypoint(VectorWrapper[Any, Any, Any, Any, Any]):
    """:class:`RandomStartWaypoint` for each sub-env of a vector env (reset option ``start_waypoint`` per sub-env).

    Each sub-env has its own generator, seeded like the single-env wrapper's (``[seed_i, 1]`` at a seeded
    reset), so sub-env i starts where ``RandomStartWaypoint`` around a single env seeded ``seed_i`` would.
    The vector env must take ``start_waypoint`` as an array with one value per sub-env (0: the mission's
    start; ``"random"``: a waypoint the sub-env draws once it knows its episode's mission).

    Args:
        env: A vector GreenhouseNav env.
        prob: Share of the episodes that start at a waypoint drawn uniformly from 1 .. n - 1, in [0, 1].
    """

    def __init__(self, env: VectorEnv[Any, Any, Any], prob: float = 0.5) -> None:
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"RandomStartWaypoint: prob must be in [0, 1], got {prob}")
        super().__init__(env)
        self.prob = prob
        self._rngs = [np.random.default_rng(0) for _ in range(self.num_envs)]

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset the sub-envs (all, or those of ``reset_mask``), each at a random waypoint with probability ``prob``."""
        rows = reset_rows(options, self.num_envs)
        seeds = per_env_seeds(seed, self.num_envs)
        options = dict(options or {})
        for i in rows:
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng([seeds[i], 1])
        if "start_waypoint" not in options:
            start = np.zeros(self.num_envs, dtype=object)
            for i in rows:
                if self._rngs[i].random() < self.prob:
                    start[i] = "random"
            if any(s == "random" for s in start):
                options["start_waypoint"] = start
        return self.env.reset(seed=seed, options=options or None)


class VectorCrashCostRamp(CrashShare, VectorWrapper[Any, Any, Any, Any, Any]):
    """:class:`CrashCostRamp` for every sub-env of a vector env at once.

    The sub-envs step together, so they share one step count and one share: after ``k`` vector steps each
    sub-env has taken ``k`` steps, as each copy of the single-env wrapper would have.

    Args:
        env: The training vector env (its info carries ``term``).
        start: Share of the crash penalty charged at first, in [0, 1].
        ramp_steps: Steps of each sub-env over which the share reaches 1, >= 1.
        term: The ``info`` key of the env's crash penalty (a reward term, <= 0).
    """

    def __init__(
        self,
        env: VectorEnv[Any, Any, Any],
        start: float = 0.1,
        ramp_steps: int = 100_000,
        term: str = "reward_collision",
    ) -> None:
        super().__init__(env)
        self.start_ramp(start, ramp_steps)
        self.term = term

    def step(self, actions: Any) -> tuple[Any, np.ndarray, Any, Any, dict[str, Any]]:
        """Step the sub-envs; refund ``1 - share`` of each crash's penalty."""
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        self.steps += 1
        penalty = np.zeros(self.num_envs)
        if self.term in infos:
            present = np.asarray(infos.get("_" + self.term, np.ones(self.num_envs, bool)), bool)
            penalty[present] = -np.asarray(infos[self.term], dtype=np.float64)[present]
        rewards = np.asarray(rewards, dtype=np.float64) + (1.0 - self.share) * penalty
        return observations, rewards, terminations, truncations, infos


#: Vector forms of :data:`TRAIN_WRAPPERS`, by the same names.
VECTOR_TRAIN_WRAPPERS: dict[str, type[VectorWrapper[Any, Any, Any, Any, Any]]] = {
    "RandomStartWaypoint": VectorRandomStartWaypoint,
    "CrashCostRamp": VectorCrashCostRamp,
}


def apply_vector_train_wrappers(
    env: VectorEnv[Any, Any, Any], wrappers: Sequence[str | Mapping[str, Any]]
) -> VectorEnv[Any, Any, Any]:
    """Wrap a vector env in the declared training wrappers' vector forms, innermost first.

    Raises:
        ValueError: For a wrapper that is not in :data:`VECTOR_TRAIN_WRAPPERS`, or a malformed entry.
    """
    wrapped: VectorEnv[Any, Any, Any] = wrap_by_name(env, wrappers, VECTOR_TRAIN_WRAPPERS, kind="training wrapper")
    return wrapped
