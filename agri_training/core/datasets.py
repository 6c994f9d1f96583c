"""Demonstration datasets in Minari's format (the Farama standard for offline RL): what one holds, written and read.

:func:`agri_training.datasets.make_dataset` runs the episodes; this module knows the format only.
A dataset of ours is a Minari dataset (``minari.load_dataset(dataset_id)``, stored in HDF5 under
``MINARI_DATASETS_PATH``, default ``~/.minari/datasets``) whose

- ``env_spec`` is the Gymnasium spec the episodes ran with (its ``kwargs`` the resolved env arguments, the
  policy's own needs included), so ``dataset.recover_environment()`` rebuilds the env; the PettingZoo chain has
  no Gymnasium spec, and every dataset also names its env in the metadata key ``agri`` (:func:`describe`,
  :func:`recover_env` build either kind);
- episodes each hold the reset ``seed`` (Minari's episode metadata), the observations (one more than the
  steps: the reset's first), the actions exactly as the policy passed them to ``step`` (as float64: the envs
  read actions as float64 themselves, so replay is exact whatever dtype a policy returns; an action outside
  the box is stored as given and clipped by the env, as in the run), rewards, terminations, truncations and the
  ``info`` keys a learner needs (:data:`LEARNER_INFO_KEYS` and the named ``reward_*`` terms);
- on a PettingZoo env, every robot's trajectory is one Minari episode, its metadata naming the ``agent`` and
  the run (``run``: the index of the reset, ``seed``: its seed). The agents share one observation and action
  space (the chain's parameter sharing), so Minari's single pair of spaces describes them all, any number of
  robots fits one layout, and a learner reads each robot's decisions as the trajectory it was.

A dataset is written to a hidden folder beside its final place and moved there whole at the end
(:class:`DatasetWriter`): an interrupted run leaves nothing under its id.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import uuid
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec

import agri_envs

#: ``pip install`` of the optional dependency that writes and reads datasets.
MINARI_EXTRA_HINT = 'pip install -e ".[datasets]"'
#: ``info`` keys recorded at every step where the env has them (success and contacts, for learners' filters).
LEARNER_INFO_KEYS = ("is_success", "collision", "collisions", "chain_intact")
#: Prefix of the named reward terms, recorded too (a learner may re-weigh them).
REWARD_TERM_PREFIX = "reward_"
#: Minari's storage format for our datasets.
DATA_FORMAT = "hdf5"
#: The metadata key under which a dataset names its env, policy and seeds.
METADATA_KEY = "agri"


def require_minari() -> Any:
    """The ``minari`` module.

    Raises:
        ValueError: When Minari (or its HDF5 backend) is not installed, naming the extra to install.
    """
    try:
        import h5py  # noqa: F401  (Minari's HDF5 storage)
        import minari
    except ImportError as exc:
        raise ValueError(f"datasets need Minari with its HDF5 storage ({exc}): {MINARI_EXTRA_HINT}") from None
    return minari


def datasets_root() -> Path:
    """Where Minari keeps datasets: ``MINARI_DATASETS_PATH``, else ``~/.minari/datasets``."""
    root = os.environ.get("MINARI_DATASETS_PATH")
    return Path(root) if root else Path.home() / ".minari" / "datasets"


def dataset_path(dataset_id: str) -> Path:
    """The folder of a dataset id (it holds ``data/``)."""
    return datasets_root() / dataset_id


def check_dataset_id(dataset_id: str) -> None:
    """Refuse an id Minari cannot parse (``namespace/name-vN``, e.g. ``agri/GreenhouseNav-v2/harik-apf-gt-v0``).

    Raises:
        ValueError: Naming the expected form.
    """
    require_minari()
    from minari.dataset.minari_dataset import parse_dataset_id

    try:
        parse_dataset_id(dataset_id)
    except (ValueError, TypeError):
        raise ValueError(
            f"dataset id {dataset_id!r} is not of Minari's form NAMESPACE/NAME-vVERSION, "
            "e.g. agri/GreenhouseNav-v2/harik-apf-gt-v0"
        ) from None
    if dataset_id.startswith("/") or ".." in dataset_id.split("/"):
        raise ValueError(f"dataset id {dataset_id!r} must be relative, without '..'")


@dataclasses.dataclass
class EpisodeSteps:
    """One recorded trajectory: a Gymnasium episode, or one agent's part of a PettingZoo one.

    Attributes:
        seed: The reset seed.
        observations: ``steps + 1`` observations (an array, or a dict of arrays), the reset's first.
        actions: ``(steps, ...)`` float64, as passed to ``step``.
        rewards: ``(steps,)``.
        terminations: ``(steps,)`` bool.
        truncations: ``(steps,)`` bool.
        infos: ``info`` key -> ``steps + 1`` values (the reset's first).
        agent: The agent of a PettingZoo env, else None.
    """

    seed: int
    observations: Any
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    infos: dict[str, np.ndarray]
    agent: str | None = None

    @property
    def steps(self) -> int:
        """Steps of the trajectory."""
        return len(self.rewards)


def recorded_info_keys(info: Mapping[str, Any]) -> tuple[str, ...]:
    """The keys of ``info`` a dataset records: :data:`LEARNER_INFO_KEYS` and the reward terms it carries."""
    return tuple(k for k in info if k in LEARNER_INFO_KEYS or k.startswith(REWARD_TERM_PREFIX))


def stack_observations(frames: list[Any]) -> Any:
    """Observations one per step -> one array per key (a dict observation) or one array."""
    if isinstance(frames[0], Mapping):
        return {k: np.stack([np.asarray(f[k]) for f in frames]) for k in frames[0]}
    return np.stack([np.asarray(f) for f in frames])


def action_space_of(space: gym.Space[Any]) -> gym.spaces.Box:
    """The dataset's action space: the env's box in float64 (the dtype the envs read actions in).

    Raises:
        ValueError: For an action space that is not a Box.
    """
    if not isinstance(space, gym.spaces.Box):
        raise ValueError(f"datasets record Box actions, the env's are {space}")
    return gym.spaces.Box(space.low.astype(np.float64), space.high.astype(np.float64), space.shape, np.float64)


@dataclasses.dataclass(frozen=True)
class DatasetEnv:
    """The env a dataset's episodes ran in.

    Attributes:
        env_id: The package's env id (Gymnasium or PettingZoo).
        env_kwargs: The arguments it was built with (the policy's own needs included).
        parallel: A PettingZoo env: one Minari episode per agent and run.
    """

    env_id: str
    env_kwargs: Mapping[str, Any]
    parallel: bool

    def make(self) -> Any:
        """A fresh env like the dataset's (``agri_envs.make``)."""
        return agri_envs.make(self.env_id, **dict(self.env_kwargs))


class DatasetWriter:
    """Writes one dataset into a hidden folder and moves it under its id at :meth:`commit`, never half.

    Use as a context manager: leaving it without :meth:`commit` (an error, Ctrl-C) removes the partial folder.

    Args:
        dataset_id: Minari id.
        env: The env the episodes run in (describes the spaces and, for a Gymnasium env, the spec).
        described: Its id and arguments.
        overwrite: Replace a dataset already under the id (it stays until the new one is complete).

    Raises:
        ValueError: For a malformed id, an existing one without ``overwrite``, or an env whose spec Minari cannot
            store.
    """

    def __init__(self, dataset_id: str, env: Any, described: DatasetEnv, overwrite: bool = False) -> None:
        require_minari()
        from minari.dataset.minari_storage import MinariStorage

        check_dataset_id(dataset_id)
        self.dataset_id = dataset_id
        self.final = dataset_path(dataset_id)
        if self.final.exists() and not overwrite:
            raise ValueError(f"dataset {dataset_id} exists at {self.final}; add --overwrite to replace it")
        self.described = described
        if described.parallel:
            agent = env.possible_agents[0]
            obs_space, act_space, spec = env.observation_space(agent), env.action_space(agent), None
        else:
            obs_space, act_space, spec = env.observation_space, env.action_space, env.spec
            try:
                stored = spec is not None and EnvSpec.from_json(spec.to_json()) == spec
            except (TypeError, ValueError):
                stored = False
            if not stored:
                raise ValueError(f"{described.env_id}: the env's spec cannot be stored, so no dataset can describe it")
        self.obs_space = obs_space
        datasets_root().mkdir(parents=True, exist_ok=True)
        self.partial = datasets_root() / f".partial-{uuid.uuid4().hex}"
        self.partial.mkdir()
        self.storage = MinariStorage.new(
            self.partial / "data", obs_space, action_space_of(act_space), env_spec=spec, data_format=DATA_FORMAT
        )
        self.episode_metadata: list[dict[str, Any]] = []
        self.done = False

    def __enter__(self) -> DatasetWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        if not self.done:
            shutil.rmtree(self.partial, ignore_errors=True)

    def add(self, episode: EpisodeSteps, run: int) -> None:
        """Append one trajectory (``run``: the index of its reset among the dataset's)."""
        require_minari()
        from minari.data_collector.episode_buffer import EpisodeBuffer

        buffer = EpisodeBuffer(
            seed=int(episode.seed),
            observations=episode.observations,
            actions=episode.actions,
            rewards=episode.rewards,
            terminations=episode.terminations,
            truncations=episode.truncations,
            infos=episode.infos,
        )
        self.storage.update_episodes([buffer])
        meta: dict[str, Any] = {"run": run}
        if episode.agent is not None:
            meta["agent"] = episode.agent
        self.episode_metadata.append(meta)

    def commit(self, policy: str, description: str, extra: Mapping[str, Any]) -> Path:
        """Write the metadata and move the dataset under its id (replacing an old one); its folder.

        Args:
            policy: The policy that drove (Minari's ``algorithm_name``).
            description: One paragraph for Minari's ``description``.
            extra: What else the ``agri`` metadata key holds (seeds, command, commit, versions).
        """
        minari = require_minari()
        self.storage.update_episode_metadata(self.episode_metadata, range(len(self.episode_metadata)))
        agri = {
            "env_id": self.described.env_id,
            "env_kwargs": dict(self.described.env_kwargs),
            "parallel": self.described.parallel,
            "policy": policy,
            **extra,
        }
        self.storage.update_metadata(
            {
                "dataset_id": self.dataset_id,
                "algorithm_name": policy,
                "author": {"agri_envs"},
                "code_permalink": "agri_training.datasets (agri dataset)",
                "description": description,
                "minari_version": minari.__version__,
                "requirements": [f"agri-envs=={agri_envs.__version__}"],
                METADATA_KEY: agri,
            }
        )
        self.final.parent.mkdir(parents=True, exist_ok=True)
        old = None
        if self.final.exists():  # --overwrite: the old one leaves only now that the new one is whole
            old = self.final.parent / f".replaced-{uuid.uuid4().hex}"
            self.final.rename(old)
        self.partial.rename(self.final)
        self.done = True
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.final


def load(dataset_id: str) -> Any:
    """The Minari dataset of an id (``minari.load_dataset``), local only.

    Raises:
        ValueError: When there is none under ``MINARI_DATASETS_PATH``.
    """
    minari = require_minari()
    try:
        return minari.load_dataset(dataset_id)
    except FileNotFoundError:
        raise ValueError(f"no dataset {dataset_id} under {datasets_root()} (make it with `agri dataset`)") from None


def describe(dataset: Any) -> DatasetEnv:
    """The env a dataset of ours ran in.

    Raises:
        ValueError: For a dataset ``agri dataset`` did not write.
    """
    meta = dataset.storage.metadata.get(METADATA_KEY)
    if not isinstance(meta, Mapping):
        raise ValueError(f"dataset {dataset.spec.dataset_id} was not written by `agri dataset` (no {METADATA_KEY!r})")
    return DatasetEnv(str(meta["env_id"]), dict(meta["env_kwargs"]), bool(meta["parallel"]))


def recover_env(dataset: Any) -> Any:
    """A fresh env like the one a dataset's episodes ran in (Gymnasium or PettingZoo)."""
    return describe(dataset).make()


def episodes(dataset: Any, seeds: Sequence[int] | None = None) -> Iterator[tuple[dict[str, Any], Any]]:
    """``(metadata, episode)`` of the episodes in order: Minari's metadata (``seed``, ``run``, ``agent``) and data.

    Args:
        dataset: A Minari dataset.
        seeds: Only the episodes reset with these seeds (every one must be there), in the dataset's order.

    Raises:
        ValueError: When a seed has no episode.
    """
    ids = list(dataset.episode_indices)
    metas = list(dataset.storage.get_episode_metadata(ids))
    if seeds is not None:
        wanted = {int(s) for s in seeds}
        missing = sorted(wanted - {int(m["seed"]) for m in metas})
        if missing:
            held = sorted({int(m["seed"]) for m in metas})
            raise ValueError(
                f"dataset {dataset.spec.dataset_id} holds no episode of seeds {_span(missing)} (it holds seeds "
                f"{_span(held)}): ask for seeds it holds"
            )
        picked = [k for k, m in enumerate(metas) if int(m["seed"]) in wanted]
        ids, metas = [ids[k] for k in picked], [metas[k] for k in picked]
    yield from zip(metas, dataset.iterate_episodes(ids), strict=True)


def _span(seeds: list[int]) -> str:
    """``3..7`` for a run of consecutive seeds, else the list (shortened)."""
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}..{seeds[-1]}" if len(seeds) > 1 else str(seeds[0])
    return str(seeds[:8])[:-1] + (", ...]" if len(seeds) > 8 else "]")
