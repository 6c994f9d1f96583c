"""Training-time curricula: wrappers that change where training episodes start or what a crash costs early on.

Evaluation never sees them.

They are declared in a hyperparameter block's ``train_wrappers`` (by name, like ``wrappers``) and wrap
only the training envs: periodic evaluation, ``agri evaluate`` and the leaderboard run the plain env.
Gymnasium envs take the names of :data:`TRAIN_WRAPPERS`, PettingZoo parallel envs (the robot chain) those of
:data:`PARALLEL_TRAIN_WRAPPERS`. Each Gymnasium curriculum has a vector form (:data:`VECTOR_TRAIN_WRAPPERS`,
the same names) for the vector envs ``agri train`` drives through
:class:`~agri_training.learned.vec_env.VectorVecEnv`: it acts per sub-env and draws the same numbers as the
single-env wrapper on each sub-env would.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv, VectorWrapper
from pettingzoo.utils.wrappers import BaseParallelWrapper

from agri_training.learned.harvest import HarvestLegs
from agri_training.learned.policy import wrap_by_name
from agri_training.learned.vector import per_env_seeds, reset_rows


class RandomStartWaypoint(gym.Wrapper[Any, Any, Any, Any]):
    """Start a share of GreenhouseNav's training episodes at a random waypoint of the mission.

    A long waypoint mission shows a learner its later legs (and the turns between them) only once it masters
    the earlier ones; starting some episodes on the way (``reset(options={"start_waypoint": k})``, the
    robot standing on waypoint k - 1 as if it had just reached it) shows every leg from the start.

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
        self._n_targets = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset, at a random waypoint with probability ``prob`` (once the mission's length is known)."""
        if seed is not None:
            self._rng = np.random.default_rng([seed, 1])
        options = dict(options or {})
        if "start_waypoint" not in options and self._n_targets > 1 and self._rng.random() < self.prob:
            options["start_waypoint"] = int(self._rng.integers(1, self._n_targets))
        obs, info = self.env.reset(seed=seed, options=options or None)
        self._n_targets = int(info["n_waypoints"])
        return obs, info


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
    the env's reward is unchanged. It reads the penalty from ``info["reward_collision"]`` (GreenhouseNav).

    Args:
        env: The training env.
        start: Share of the crash penalty charged at first, in [0, 1].
        ramp_steps: Steps of this env copy over which the share reaches 1, >= 1 (with ``action_repeat`` a
            step is one action, held for that many control periods).
    """

    def __init__(self, env: gym.Env[Any, Any], start: float = 0.1, ramp_steps: int = 100_000) -> None:
        super().__init__(env)
        self.start_ramp(start, ramp_steps)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Step the env; refund ``1 - share`` of a crash's penalty."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        penalty = -float(info.get("reward_collision", 0.0))
        return obs, float(reward) + (1.0 - self.share) * penalty, terminated, truncated, info


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
    "HarvestLegs": HarvestLegs,
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
    The vector env must take ``start_waypoint`` as an array with one value per sub-env (0: the mission's start).

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
        self._n_targets = np.zeros(self.num_envs, dtype=np.int64)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Reset the sub-envs (all, or those of ``reset_mask``), each at a random waypoint with probability ``prob``."""
        rows = reset_rows(options, self.num_envs)
        seeds = per_env_seeds(seed, self.num_envs)
        options = dict(options or {})
        for i in rows:
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng([seeds[i], 1])
        if "start_waypoint" not in options:
            start = np.zeros(self.num_envs, dtype=np.int64)
            for i in rows:
                rng, n = self._rngs[i], int(self._n_targets[i])
                if n > 1 and rng.random() < self.prob:
                    start[i] = int(rng.integers(1, n))
            if start.any():
                options["start_waypoint"] = start
        observations, infos = self.env.reset(seed=seed, options=options or None)
        self._n_targets[rows] = np.asarray(infos["n_waypoints"])[rows]
        return observations, infos


class VectorCrashCostRamp(CrashShare, VectorWrapper[Any, Any, Any, Any, Any]):
    """:class:`CrashCostRamp` for every sub-env of a vector env at once.

    The sub-envs step together, so they share one step count and one share: after ``k`` vector steps each
    sub-env has taken ``k`` steps, as each copy of the single-env wrapper would have.

    Args:
        env: The training vector env (its info carries ``reward_collision``).
        start: Share of the crash penalty charged at first, in [0, 1].
        ramp_steps: Steps of each sub-env over which the share reaches 1, >= 1.
    """

    def __init__(self, env: VectorEnv[Any, Any, Any], start: float = 0.1, ramp_steps: int = 100_000) -> None:
        super().__init__(env)
        self.start_ramp(start, ramp_steps)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, Any, Any, dict[str, Any]]:
        """Step the sub-envs; refund ``1 - share`` of each crash's penalty."""
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        self.steps += 1
        penalty = np.zeros(self.num_envs)
        if "reward_collision" in infos:
            present = np.asarray(infos.get("_reward_collision", np.ones(self.num_envs, bool)), bool)
            penalty[present] = -np.asarray(infos["reward_collision"], dtype=np.float64)[present]
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
