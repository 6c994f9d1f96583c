"""Several episodes of one policy stepped together in an env's batched form, each recorded as the reference loop does.

An env with a native vector form (``gym.make_vec``: GreenhouseNav-v2's :class:`~agri_envs.rover.vector.
GreenhouseNavVectorEnv`, whose sub-envs give the single env's episodes bit for bit) steps a batch of episodes
in one compiled call, at about a third of the cost per episode-step of the single env (``benchmarks/
bench_batched_eval.py``). :func:`run_batch` runs the episodes of consecutive seeds that way: sub-env ``i`` is
reset with seed ``seeds[i]``, driven by a policy of its own built afresh for the episode (as every episode of
the reference loop gets one), and recorded by an :class:`~agri_training.evaluation.episode.EpisodeBook`, the
bookkeeping of :func:`~agri_training.evaluation.episode.run_episode`. The records and traces are therefore
the reference loop's; only ``wall_time_s`` differs (each vector step's time is shared among the episodes it
advanced, plus each episode's own policy calls). ``tests/training/test_batched_eval.py`` checks them against
the reference loop on committed leaderboard entries.

Only policies that act on their observations alone may run this way (:func:`batchable`): a learned policy,
or a baseline registered with ``observation_only=True``. A policy that read the env during an episode would
see a sub-env whose robot and people the vector env does not update.

A finished sub-env's slot idles (the vector env resets it and steps it with the batch; nothing of it is
recorded). When few episodes are left, their slots cost more than single envs would, so the batch decides as
in ski rental: once the idle work it has paid beyond that point exceeds what re-running the unfinished episodes
from their start on single envs would cost, it hands them to the reference loop (``rerun``). Episodes are
deterministic given their seed, so a re-run episode's record is the one it would have had in the batch.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator

import agri_envs
from agri_training.core.documents import EpisodeOutput
from agri_training.evaluation.episode import EpisodeBook
from agri_training.evaluation.reference import PolicyRef

#: Most episodes one batch steps together (16 GreenhouseNav-v2 worlds cost 86 us each a step, 32 cost 83 us).
BATCH_SIZE = 16
#: What one single-env step costs in batched world-steps (GreenhouseNav-v2 with its full scan: about 260 us
#: against 86 us at 16 sub-envs); the batch hands its last episodes to single envs by this ratio.
SINGLE_STEP_COST = 3.0


def has_batched_form(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> bool:
    """Whether ``gym.make_vec(env_id, **env_kwargs)`` builds the env's own vector env (a ``vector_entry_point``).

    False also where that vector env refuses these arguments (its ``refusal``: GreenhouseNav's for a scene
    distribution that draws the robot per episode).
    """
    if agri_envs.is_parallel_id(env_id) or env_id not in gym.registry:
        return False
    entry_point = gym.registry[env_id].vector_entry_point
    if entry_point is None:
        return False
    vector_class = load_env_creator(entry_point) if isinstance(entry_point, str) else entry_point
    refusal = getattr(vector_class, "refusal", None)
    return refusal is None or refusal(dict(env_kwargs or {})) is None


def batchable(env_id: str, policy: PolicyRef, env_kwargs: Mapping[str, Any] | None = None) -> bool:
    """Whether ``policy``'s episodes on ``env_id`` (made with ``env_kwargs``) may be stepped together in batches.

    True when the env has a batched form for these arguments and the policy acts on its observations alone: a
    network (a zoo name, an ``agri train`` run folder, an ONNX or SB3 file) or a baseline registered with
    ``observation_only=True``.
    """
    return has_batched_form(env_id, env_kwargs) and policy.observation_only


class _InfoRow(Mapping[str, Any]):
    """Sub-env ``i``'s row of a vector env's ``info`` dict of arrays, as the single env's ``info`` (Python scalars)."""

    __slots__ = ("_infos", "_i")

    def __init__(self, infos: Mapping[str, Any], i: int) -> None:
        self._infos = infos
        self._i = i

    def __getitem__(self, key: str) -> Any:
        mask = self._infos.get("_" + key)
        if key.startswith("_") or mask is None or not mask[self._i]:
            raise KeyError(key)
        value = self._infos[key][self._i]
        return value.item() if isinstance(value, np.generic) else value

    def __iter__(self) -> Iterator[str]:
        return (k for k in self._infos if not k.startswith("_") and k in self)

    def __len__(self) -> int:
        return sum(1 for _ in self)


class _SubEnv:
    """What the episode loop sees of one sub-env after a reset or a step (a driver, as ``episode._SingleAgent``)."""

    __slots__ = ("info", "done", "truncated")

    def __init__(self, infos: Mapping[str, Any], i: int, done: bool = False, truncated: bool = False) -> None:
        self.info = _InfoRow(infos, i)
        self.done = done
        self.truncated = truncated

    def trace_step(self, trace: dict[str, list[Any]]) -> None:
        for k in trace:
            trace[k].append(self.info.get(k))

    def finish(self, record: dict[str, Any], trace: dict[str, Any]) -> None:
        """Nothing beyond the shared keys."""


def _row(observations: Any, i: int) -> Any:
    if isinstance(observations, Mapping):
        return {key: value[i] for key, value in observations.items()}
    return observations[i]


def run_batch(
    envs: gym.vector.VectorEnv[Any, Any, Any],
    policies: Sequence[Any],
    seeds: Sequence[int],
    trace_keys: tuple[str, ...] | None,
    rerun: Callable[[int], EpisodeOutput],
) -> list[EpisodeOutput]:
    """Episode ``i`` on seed ``seeds[i]`` in sub-env ``i`` of ``envs``, driven by ``policies[i]``; their outputs.

    Args:
        envs: A vector env of ``len(seeds)`` sub-envs in ``NEXT_STEP`` autoreset mode (``gym.make_vec``'s
            default), made with the env arguments of the episodes.
        policies: One fresh policy per episode, built on its sub-env (``envs.envs[i]``).
        seeds: The episodes' reset seeds.
        trace_keys: ``info`` keys every episode records at every step, or None.
        rerun: Runs episode ``i`` alone from its start with the reference loop (for the batch's last episodes).

    Returns:
        Each episode's output, as :func:`~agri_training.evaluation.episode.run_episode` returns it.
    """
    n = len(seeds)
    if envs.num_envs != n or len(policies) != n:
        raise ValueError(f"a batch of {n} seeds needs {n} sub-envs and policies, got {envs.num_envs}, {len(policies)}")
    metric_keys = _metric_keys(envs)
    books = [EpisodeBook(p, seed, trace_keys, metric_keys, True) for p, seed in zip(policies, seeds, strict=True)]
    # one seed per sub-env (Gymnasium's vector API allows a list; its stubs say int)
    observations, infos = envs.reset(seed=[int(s) for s in seeds])  # type: ignore[arg-type]
    latest: list[Mapping[str, Any]] = []
    for i, book in enumerate(books):
        driver = _SubEnv(infos, i)
        book.started(driver)
        latest.append(driver.info)
    outs: list[EpisodeOutput | None] = [None] * n
    wall = np.zeros(n)
    active = np.ones(n, dtype=np.bool_)
    actions = np.zeros((n, *(envs.single_action_space.shape or ())), dtype=np.float64)
    idle_work = 0.0
    while active.any():
        live = np.flatnonzero(active).tolist()
        for i in live:
            t0 = time.perf_counter()
            actions[i] = np.asarray(books[i].act(_row(observations, i), latest[i]), dtype=np.float64)
            wall[i] += time.perf_counter() - t0
        t0 = time.perf_counter()
        observations, rewards, terminated, truncated, infos = envs.step(actions)
        wall[live] += (time.perf_counter() - t0) / len(live)
        for i in live:
            done = bool(terminated[i] or truncated[i])
            driver = _SubEnv(infos, i, done, bool(truncated[i]))
            books[i].stepped(float(rewards[i]), driver)
            latest[i] = driver.info
            if done:
                outs[i] = books[i].output(driver, float(wall[i]))
                active[i] = False
                actions[i] = 0.0  # its slot idles: standing still, it ends (and is reset) seldom
        left = int(active.sum())
        if left and n > SINGLE_STEP_COST * left:  # the idle slots cost more than single envs for the rest would
            idle_work += n - SINGLE_STEP_COST * left
            restart = SINGLE_STEP_COST * sum(books[i].steps for i in np.flatnonzero(active).tolist())
            if idle_work > restart:
                for i in np.flatnonzero(active).tolist():
                    outs[i] = rerun(i)
                break
    return [out for out in outs if out is not None]


def _metric_keys(envs: gym.vector.VectorEnv[Any, Any, Any]) -> tuple[str, ...]:
    """The single env's ``episode_metric_keys`` (its sub-envs' metadata; the vector env's own has none)."""
    return tuple(envs.envs[0].unwrapped.metadata.get("episode_metric_keys", ()))  # type: ignore[attr-defined]
