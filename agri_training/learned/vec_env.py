"""An SB3 ``VecEnv`` over a Gymnasium ``VectorEnv``: how ``agri train`` drives batched envs.

SB3 trains on its own ``VecEnv`` interface, not on a Gymnasium ``VectorEnv``. :class:`VectorVecEnv` is the
bridge. Under it sits a vector env in ``AutoresetMode.DISABLED`` (the contract of
:mod:`agri_training.learned.vector`): the adapter resets the sub-envs whose episode ended in the same step
(``reset(options={"reset_mask": done})``), as SB3 expects, and hands SB3 the final observation as
``info["terminal_observation"]`` and ``info["TimeLimit.truncated"]`` for the time-limit bootstrap. The
vector env's info (one dict of arrays with ``_key`` masks) becomes SB3's list of per-env dicts. Episode
statistics are SB3's ``VecMonitor`` on top, normalisation its ``VecNormalize``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import VectorEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn

from agri_training.learned.vector import check_disabled_autoreset, split_info


class VectorVecEnv(VecEnv):  # type: ignore[misc]
    """An SB3 ``VecEnv`` over a Gymnasium ``VectorEnv`` in ``DISABLED`` autoreset (see the module docstring).

    It behaves as SB3's ``DummyVecEnv`` of the same single envs: the same observations, rewards and dones for
    the same seeds (``seed(s)``: sub-env i resets from ``s + i``) and actions; a finished sub-env is reset in
    the same step, its final observation in ``info["terminal_observation"]``; every info carries
    ``TimeLimit.truncated``. Observations are copied once per step (SB3 keeps references to them).

    ``get_attr`` / ``set_attr`` / ``env_method`` reach an attribute of the vector env or of one of its
    wrappers (one value for every sub-env: a curriculum's state, the render mode), else the sub-envs' own
    (``SyncVectorEnv``).

    Args:
        env: The vector env (wrapped as the training declares).
    """

    def __init__(self, env: VectorEnv[Any, Any, Any]) -> None:
        check_disabled_autoreset(env, "VectorVecEnv")
        self.venv = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self._dict_obs = isinstance(env.single_observation_space, gym.spaces.Dict)
        self._actions: np.ndarray | None = None
        self.metadata = {**env.metadata, **self.metadata}

    def reset(self) -> VecEnvObs:
        """Reset every sub-env (with the seeds of :meth:`seed` and the options of :meth:`set_options`, once)."""
        seeds: Any = None if all(s is None for s in self._seeds) else list(self._seeds)
        observations, infos = self.venv.reset(seed=seeds, options=self._merged_options())
        self.reset_infos = split_info(infos, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return self._copy(observations)

    def _merged_options(self) -> dict[str, Any] | None:
        """SB3's per-env option dicts as one vector option dict (per-sub-env arrays where they differ)."""
        if not any(self._options):
            return None
        keys = {k for options in self._options for k in options}
        merged: dict[str, Any] = {}
        for key in sorted(keys):
            if not all(key in options for options in self._options):
                raise ValueError(f"reset option {key!r} must be given for every sub-env or none")
            values = [options[key] for options in self._options]
            merged[key] = values[0] if all(v == values[0] for v in values) else np.asarray(values)
        return merged

    def step_async(self, actions: np.ndarray) -> None:
        """Remember the actions for :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every sub-env; reset those whose episode ended, handing SB3 their final observations."""
        observations, rewards, terminations, truncations, info = self.venv.step(self._actions)
        terminations = np.asarray(terminations, dtype=bool)
        truncations = np.asarray(truncations, dtype=bool)
        dones = terminations | truncations
        observations = self._copy(observations)
        infos = split_info(info, self.num_envs)
        for entry, truncated in zip(infos, (truncations & ~terminations).tolist(), strict=True):
            entry["TimeLimit.truncated"] = truncated
        if dones.any():
            rows = np.flatnonzero(dones)
            for i in rows:
                infos[i]["terminal_observation"] = (
                    {k: v[i].copy() for k, v in observations.items()} if self._dict_obs else observations[i].copy()
                )
            reset_observations, reset_info = self.venv.reset(options={"reset_mask": dones})
            if self._dict_obs:
                for key, value in observations.items():
                    value[rows] = np.asarray(reset_observations[key])[rows]
            else:
                observations[rows] = np.asarray(reset_observations)[rows]
            reset_infos = split_info(reset_info, self.num_envs, rows)
            for i in rows:
                self.reset_infos[i] = reset_infos[i]
        return observations, np.array(rewards, dtype=np.float32), dones, infos

    def _copy(self, observations: Any) -> Any:
        if self._dict_obs:
            return {key: np.array(value) for key, value in observations.items()}
        return np.array(observations)

    def close(self) -> None:
        """Close the vector env."""
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The sub-envs' frames (``rgb_array`` render mode)."""
        frames: Any = self.venv.render()
        return [None] * self.num_envs if frames is None else list(frames)

    def _layer_with(self, name: str) -> Any:
        """The outermost vector wrapper (or the vector env) that has ``name``, or None."""
        layer: Any = self.venv
        while layer is not None:
            if name in vars(layer) or hasattr(type(layer), name):
                return layer
            layer = getattr(layer, "env", None)
        return None

    def _sub_envs(self, indices: VecEnvIndices) -> list[gym.Env[Any, Any]]:
        envs = getattr(self.venv.unwrapped, "envs", None)
        if envs is None:
            return []
        return [envs[i] for i in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute per sub-env: the vector env's (the same for each), else each sub-env's own."""
        n = len(list(self._get_indices(indices)))
        layer = self._layer_with(attr_name)
        if layer is not None:
            return [getattr(layer, attr_name)] * n
        envs = self._sub_envs(indices)
        if not envs:
            raise AttributeError(f"the vector env has no attribute {attr_name!r}")
        return [env.get_wrapper_attr(attr_name) for env in envs]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute where :meth:`get_attr` finds it (a vector-level one only for every sub-env at once)."""
        layer = self._layer_with(attr_name)
        if layer is not None:
            if sorted(self._get_indices(indices)) != list(range(self.num_envs)):
                raise ValueError(f"{attr_name!r} belongs to the vector env: set it for every sub-env (indices=None)")
            setattr(layer, attr_name, value)
            return
        for env in self._sub_envs(indices):
            env.set_wrapper_attr(attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call a method of the vector env (once; its result for every index), else of each sub-env."""
        layer = self._layer_with(method_name)
        if layer is not None:
            result = getattr(layer, method_name)(*method_args, **method_kwargs)
            return [result] * len(list(self._get_indices(indices)))
        envs = self._sub_envs(indices)
        if not envs:
            raise AttributeError(f"the vector env has no method {method_name!r}")
        return [env.get_wrapper_attr(method_name)(*method_args, **method_kwargs) for env in envs]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper[Any, Any, Any, Any]], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Whether each sub-env is wrapped in ``wrapper_class`` (a batched env has no single-env wrappers)."""
        from stable_baselines3.common.env_util import is_wrapped

        envs = self._sub_envs(indices)
        if not envs:
            return [False] * len(list(self._get_indices(indices)))
        return [is_wrapped(env, wrapper_class) for env in envs]
