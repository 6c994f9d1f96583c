"""The training's vector envs: the contract the SB3 adapter drives, the sync fallback, the observation wrappers.

:class:`agri_training.learned.vec_env.VectorVecEnv` trains SB3 on a Gymnasium ``VectorEnv`` that follows
this contract (the batched GreenhouseNav, or :class:`OptionsSyncVectorEnv` of single envs for an env
without a batched form):

- ``metadata["autoreset_mode"]`` is ``AutoresetMode.DISABLED``;
- ``reset(seed=[s_0, ..., s_n-1])`` seeds sub-env i with ``s_i``; ``reset(options={"reset_mask": m})``
  resets only the sub-envs where ``m`` is true (the other rows of the returned observation are theirs,
  unchanged);
- a reset option given as a 1-D array of length ``num_envs`` holds one value per sub-env
  (``{"start_waypoint": array}``); any other value goes to every sub-env.

The observation wrappers a training config declares have vector forms here (:data:`VECTOR_WRAPPERS`:
the same names, the same observations bit for bit), and so do the curricula
(:data:`agri_training.learned.curricula.VECTOR_TRAIN_WRAPPERS`). Wrappers with a memory clear it per
sub-env at the masked resets: :class:`VectorObservationHistory` starts a new episode's history from its
first observation, exactly as the single-env :class:`~agri_training.learned.policy.ObservationHistory`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, SyncVectorEnv, VectorEnv, VectorWrapper
from gymnasium.vector.utils import concatenate

from agri_training.learned.policy import add_proximity, proximity_space, wrap_by_name
from agri_training.learned.range_features import (
    Pair,
    RampSpec,
    add_differences,
    add_ramps,
    differences_space,
    ramp_bounds,
    ramp_space,
)


def per_env_seeds(seed: int | Sequence[int | None] | None, num_envs: int) -> list[int | None]:
    """Gymnasium's vector seeding spelled out: None, an int ``s`` (sub-env i gets ``s + i``) or one seed per sub-env.

    Raises:
        ValueError: For a list whose length is not ``num_envs``.
    """
    if seed is None:
        return [None] * num_envs
    if isinstance(seed, (int, np.integer)):
        return [int(seed) + i for i in range(num_envs)]
    seeds = list(seed)
    if len(seeds) != num_envs:
        raise ValueError(f"seed: one per sub-env ({num_envs}) expected, got {len(seeds)}")
    return seeds


def reset_rows(options: Mapping[str, Any] | None, num_envs: int) -> np.ndarray:
    """Indices of the sub-envs a ``reset(options=...)`` resets: those of ``reset_mask``, else all."""
    mask = None if options is None else options.get("reset_mask")
    return np.arange(num_envs) if mask is None else np.flatnonzero(mask)


def is_per_env(value: Any, num_envs: int) -> bool:
    """True for a reset option that holds one value per sub-env (a 1-D array of length ``num_envs``)."""
    return isinstance(value, np.ndarray) and value.shape == (num_envs,)


class OptionsSyncVectorEnv(SyncVectorEnv):
    """Gymnasium's ``SyncVectorEnv`` whose reset options may hold one value per sub-env, like the batched envs'.

    A reset option that is a 1-D array of length ``num_envs`` gives sub-env i its element i (as a Python
    scalar, or the object an object array holds); other options go to every sub-env unchanged, and
    ``reset_mask`` works as in ``SyncVectorEnv``. This is how the vector curricula choose, say, each
    sub-env's start waypoint. Everything else is ``SyncVectorEnv``'s.
    """

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Reset the sub-envs (all, or those of ``options["reset_mask"]``), each with its own options."""
        options = dict(options or {})
        per_env = {k: v for k, v in options.items() if k != "reset_mask" and is_per_env(v, self.num_envs)}
        if not per_env:
            return super().reset(seed=seed, options=options or None)
        seeds = per_env_seeds(seed, self.num_envs)
        shared = {k: v for k, v in options.items() if k != "reset_mask" and k not in per_env}
        rows = reset_rows(options, self.num_envs)
        if not len(rows):
            raise ValueError("options['reset_mask'] must select at least one sub-env")
        infos: dict[str, Any] = {}
        values = {k: v.tolist() for k, v in per_env.items()}  # Python scalars (or the objects of an object array)
        for i in rows:
            env_options = {**shared, **{k: v[i] for k, v in values.items()}}
            self._env_obs[i], env_info = self.envs[i].reset(seed=seeds[i], options=env_options)
            infos = self._add_info(infos, env_info, i)
        self._terminations[rows] = False
        self._truncations[rows] = False
        self._autoreset_envs[rows] = False
        self._observations = concatenate(self.single_observation_space, self._env_obs, self._observations)
        return (np.copy(self._observations) if self.copy else self._observations), infos


def make_sync_vector_env(env_fns: Sequence[Callable[[], gym.Env[Any, Any]]]) -> OptionsSyncVectorEnv:
    """Single envs stepped one after another as one vector env, in the adapter's contract (``DISABLED`` autoreset).

    Observations are not copied here: :class:`VectorVecEnv` copies once, at its output.
    """
    return OptionsSyncVectorEnv(list(env_fns), copy=False, autoreset_mode=AutoresetMode.DISABLED)


def check_disabled_autoreset(env: VectorEnv[Any, Any, Any], who: str) -> None:
    """Raise ``ValueError`` (naming ``who``) unless ``env`` leaves resets to its caller (``DISABLED`` autoreset)."""
    mode = env.metadata.get("autoreset_mode")
    if mode != AutoresetMode.DISABLED:
        raise ValueError(
            f"{who} needs a vector env in AutoresetMode.DISABLED (it resets finished sub-envs itself, "
            f"reset(options={{'reset_mask': done}})), got {mode}; make it with autoreset_mode=AutoresetMode.DISABLED"
        )


class VectorFlattenObservation(gym.vector.VectorObservationWrapper[Any, Any, Any, Any]):
    """``FlattenObservation`` for a whole batch: a Box or a Dict of Boxes becomes one ``(num_envs, n)`` array.

    The columns are the single-env wrapper's (the Dict's keys in the space's order, each flattened), so each
    row equals ``gym.wrappers.FlattenObservation`` on that sub-env's observation, bit for bit. Other spaces
    go through Gymnasium's per-sub-env vector ``FlattenObservation``.
    """

    def __init__(self, env: VectorEnv[Any, Any, Any]) -> None:
        super().__init__(env)
        single = env.single_observation_space
        parts = single.spaces if isinstance(single, gym.spaces.Dict) else {None: single}
        if not all(isinstance(s, gym.spaces.Box) for s in parts.values()):
            raise ValueError(f"VectorFlattenObservation needs a Box or a Dict of Boxes, got {single}")
        self._parts = [(key, np.dtype(space.dtype)) for key, space in parts.items()]
        self.single_observation_space = gym.spaces.flatten_space(single)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self._dtype = self.single_observation_space.dtype

    def observations(self, observations: Any) -> np.ndarray:
        """The batch flattened row by row."""
        n = self.num_envs
        columns = [
            np.asarray(observations if key is None else observations[key], dtype=dtype).reshape(n, -1)
            for key, dtype in self._parts
        ]
        return np.concatenate(columns, axis=1).astype(self._dtype, copy=False)


def vector_flatten(env: VectorEnv[Any, Any, Any]) -> VectorEnv[Any, Any, Any]:
    """The batched :class:`VectorFlattenObservation` where it applies, else Gymnasium's per-sub-env one."""
    single = env.single_observation_space
    parts = single.spaces.values() if isinstance(single, gym.spaces.Dict) else [single]
    if all(isinstance(s, gym.spaces.Box) for s in parts):
        return VectorFlattenObservation(env)
    return gym.wrappers.vector.FlattenObservation(env)


class VectorObservationHistory(VectorWrapper[Any, Any, Any, Any, Any]):
    """:class:`~agri_training.learned.policy.ObservationHistory` for every sub-env at once.

    Each row holds that sub-env's last ``frames`` flat observations side by side, oldest first. A sub-env
    reset (the adapter's masked reset after its episode ended, or a full reset) fills that sub-env's
    frames with its new first observation; the other sub-envs keep their history. Needs ``DISABLED``
    autoreset, in which a reset is the only way an episode starts.
    """

    def __init__(self, env: VectorEnv[Any, Any, Any], frames: int = 2) -> None:
        super().__init__(env)
        space = env.single_observation_space
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ValueError(f"ObservationHistory needs a flat Box observation (FlattenObservation first), got {space}")
        if int(frames) < 1:
            raise ValueError(f"ObservationHistory frames must be >= 1, got {frames}")
        check_disabled_autoreset(env, "ObservationHistory")
        self.frames = int(frames)
        self.single_observation_space = gym.spaces.Box(
            np.tile(space.low, self.frames), np.tile(space.high, self.frames), dtype=space.dtype
        )
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)
        self._history = np.zeros((self.num_envs, self.frames, space.shape[0]), dtype=space.dtype)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the sub-envs and fill their histories with their first observations."""
        rows = reset_rows(options, self.num_envs)
        observations, infos = self.env.reset(seed=seed, options=None if options is None else dict(options))
        self._history[rows] = np.asarray(observations)[rows, None, :]
        return self._stacked(), infos

    def step(self, actions: Any) -> tuple[np.ndarray, Any, Any, Any, dict[str, Any]]:
        """Step the sub-envs and push their observations."""
        observations, rewards, terminations, truncations, infos = self.env.step(actions)
        self._history[:, :-1] = self._history[:, 1:]
        self._history[:, -1] = observations
        return self._stacked(), rewards, terminations, truncations, infos

    def _stacked(self) -> np.ndarray:
        return self._history.reshape(self.num_envs, -1).copy()


class VectorProximity(gym.vector.VectorObservationWrapper[Any, Any, Any, Any]):
    """:class:`~agri_training.learned.policy.Proximity` for a whole batch: the same keys, the same bits."""

    def __init__(self, env: VectorEnv[Any, Any, Any], **lengths: float) -> None:
        single = proximity_space(env.single_observation_space, lengths)  # type: ignore[arg-type]
        super().__init__(env)
        self.lengths = {key: float(length) for key, length in lengths.items()}
        self.single_observation_space = single
        self.observation_space = gym.vector.utils.batch_space(single, self.num_envs)

    def observations(self, observations: Any) -> dict[str, Any]:
        """The batch with its proximity keys."""
        return add_proximity(observations, self.lengths)


class VectorDifferences(gym.vector.VectorObservationWrapper[Any, Any, Any, Any]):
    """:class:`~agri_training.learned.range_features.Differences` for a whole batch: the same keys, the same bits."""

    def __init__(self, env: VectorEnv[Any, Any, Any], **pairs: Sequence[Pair]) -> None:
        single = differences_space(env.single_observation_space, pairs)  # type: ignore[arg-type]
        super().__init__(env)
        self.pairs = dict(pairs)
        self.single_observation_space = single
        self.observation_space = gym.vector.utils.batch_space(single, self.num_envs)

    def observations(self, observations: Any) -> dict[str, Any]:
        """The batch with its difference keys."""
        return add_differences(observations, self.pairs)


class VectorRamp(gym.vector.VectorObservationWrapper[Any, Any, Any, Any]):
    """:class:`~agri_training.learned.range_features.Ramp` for a whole batch: the same keys, the same bits."""

    def __init__(self, env: VectorEnv[Any, Any, Any], **bounds: RampSpec) -> None:
        self.bounds = ramp_bounds(env.single_observation_space, bounds)  # type: ignore[arg-type]
        super().__init__(env)
        self.single_observation_space = ramp_space(env.single_observation_space, self.bounds)  # type: ignore[arg-type]
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, self.num_envs)

    def observations(self, observations: Any) -> dict[str, Any]:
        """The batch with its ramp keys."""
        return add_ramps(observations, self.bounds)


#: Vector forms of :data:`agri_training.learned.policy.WRAPPERS`, by the same names.
VECTOR_WRAPPERS: dict[str, Callable[..., VectorEnv[Any, Any, Any]]] = {
    "FlattenObservation": vector_flatten,
    "FilterObservation": gym.wrappers.vector.FilterObservation,
    "ObservationHistory": VectorObservationHistory,
    "Proximity": VectorProximity,
    "Differences": VectorDifferences,
    "Ramp": VectorRamp,
}


def apply_vector_wrappers(
    env: VectorEnv[Any, Any, Any], wrappers: Sequence[str | Mapping[str, Any]]
) -> VectorEnv[Any, Any, Any]:
    """Wrap a vector env in the declared observation wrappers' vector forms, innermost first.

    Raises:
        ValueError: For a wrapper without a vector form, or a malformed entry.
    """
    return wrap_by_name(env, wrappers, VECTOR_WRAPPERS, kind="vector observation wrapper")


def split_info(info: Mapping[str, Any], num_envs: int, rows: Iterable[int] | None = None) -> list[dict[str, Any]]:
    """A vector env's info (arrays with ``_key`` masks) as one dict per sub-env, with Python scalars.

    Args:
        info: The vector env's info.
        num_envs: Sub-envs.
        rows: Only these sub-envs get their entries (the others an empty dict); None: all.
    """
    wanted = np.ones(num_envs, bool) if rows is None else np.isin(np.arange(num_envs), list(rows))
    everywhere: list[tuple[str, Any]] = []  # entries every wanted sub-env has: one dict per sub-env at once
    somewhere: list[tuple[str, Any, np.ndarray]] = []
    for key, value in info.items():
        if key.startswith("_"):
            continue
        mask = info.get("_" + key)
        if mask is None:
            present = wanted
        else:
            present = np.asarray(mask, bool) if rows is None else wanted & np.asarray(mask, bool)
        if isinstance(value, Mapping):
            values: Any = split_info(value, num_envs, np.flatnonzero(present))
        elif isinstance(value, np.ndarray) and value.ndim == 1 and value.dtype != object:
            values = value.tolist()  # Python scalars, as a single env reports them
        else:
            values = value
        if rows is None and present.all():
            everywhere.append((key, values))
        else:
            somewhere.append((key, values, np.flatnonzero(present)))
    keys = [key for key, _ in everywhere]
    out = [dict(zip(keys, entries, strict=True)) for entries in zip(*(v for _, v in everywhere), strict=True)]
    if not everywhere:
        out = [{} for _ in range(num_envs)]
    for key, values, where in somewhere:
        for i in where:
            out[i][key] = values[i]
    return out
