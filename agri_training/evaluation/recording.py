"""An env as :func:`~agri_training.evaluation.episode.run_episode` drives it, every step kept for a dataset.

:class:`StepRecorder` stands between the episode loop and the env (of either kind) and passes everything
through; what ``reset`` and ``step`` return, and the action each step was given, it keeps. The episode is run
by the one loop that evaluation runs, so a dataset's episodes are the evaluated ones.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

import agri_envs
from agri_training.core.datasets import EpisodeSteps, recorded_info_keys, stack_observations


class _Track:
    """One trajectory being recorded."""

    def __init__(self, observation: Any, info: Mapping[str, Any], keys: tuple[str, ...]) -> None:
        self.keys = keys
        self.observations = [_copy(observation)]
        self.infos: dict[str, list[Any]] = {k: [info[k]] for k in keys}
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []
        self.terminations: list[bool] = []
        self.truncations: list[bool] = []

    def step(self, action: Any, observation: Any, reward: Any, terminated: Any, truncated: Any, info: Any) -> None:
        self.actions.append(np.array(action, dtype=np.float64))
        self.observations.append(_copy(observation))
        self.rewards.append(float(reward))
        self.terminations.append(bool(terminated))
        self.truncations.append(bool(truncated))
        missing = [k for k in self.keys if k not in info]
        if missing:
            raise ValueError(f"the env's step info lacks {missing}, which its reset info had")
        for k in self.keys:
            self.infos[k].append(info[k])

    def done(self, seed: int, agent: str | None) -> EpisodeSteps:
        return EpisodeSteps(
            seed=seed,
            observations=stack_observations(self.observations),
            actions=np.stack(self.actions) if self.actions else np.zeros((0,), np.float64),
            rewards=np.asarray(self.rewards, dtype=np.float64),
            terminations=np.asarray(self.terminations, dtype=bool),
            truncations=np.asarray(self.truncations, dtype=bool),
            infos={k: np.asarray(v) for k, v in self.infos.items()},
            agent=agent,
        )


def _copy(observation: Any) -> Any:
    if isinstance(observation, Mapping):
        return {k: np.array(v) for k, v in observation.items()}
    return np.array(observation)


class StepRecorder:
    """Passes an env through (attributes included) and records each episode's steps.

    On a PettingZoo parallel env every agent's trajectory is recorded apart (from the reset to the step that
    ends it for that agent).

    Args:
        env: A Gymnasium env or a PettingZoo parallel env.
    """

    def __init__(self, env: Any) -> None:
        self.env = env
        self.parallel = agri_envs.is_parallel_env(env)
        self.seed: int | None = None
        self._tracks: dict[str | None, _Track] = {}

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        """``env.reset``; starts the record of a new episode.

        Raises:
            ValueError: Without a seed (a dataset's episode is replayed from its seed).
        """
        if seed is None:
            raise ValueError("a recorded episode needs a reset seed")
        obs, info = self.env.reset(seed=seed, options=options)
        self.seed = int(seed)
        if self.parallel:
            self._tracks = {a: _Track(obs[a], info[a], recorded_info_keys(info[a])) for a in obs}
        else:
            self._tracks = {None: _Track(obs, info, recorded_info_keys(info))}
        return obs, info

    def step(self, action: Any) -> Any:
        """``env.step``, recorded."""
        out = self.env.step(action)
        obs, reward, terminated, truncated, info = out
        if self.parallel:
            for agent, act in action.items():
                self._tracks[agent].step(
                    act, obs[agent], reward[agent], terminated[agent], truncated[agent], info[agent]
                )
        else:
            self._tracks[None].step(action, obs, reward, terminated, truncated, info)
        return out

    def episodes(self) -> list[EpisodeSteps]:
        """The recorded episode: one trajectory, or one per agent (in the env's agent order)."""
        assert self.seed is not None, "no episode recorded"
        return [track.done(self.seed, agent) for agent, track in self._tracks.items()]
