"""The vector-env side of a batched 2D env, written once: Gymnasium's ``VectorEnv`` API over compiled steps.

A batched env (:class:`~agri_envs.rover.vector.GreenhouseNavVectorEnv`, ...) keeps one single env per sub-env:
its own ``reset`` sets each episode up, with its own generator, and the batched env copies the episode into
padded arrays (:meth:`BatchedEnv._load`); a compiled kernel then steps every sub-env's world in one call
(:meth:`BatchedEnv._run`), writing observations, rewards, flags and ``info`` values into preallocated arrays.
:class:`BatchedEnv` does the rest the way Gymnasium's ``SyncVectorEnv`` over ``gym.make`` envs does it:
seeds, reset options and masks, the three autoreset modes, ``max_episode_steps`` (``TimeLimit``'s rule),
the ``info`` dict of arrays with ``_key`` masks (and ``final_obs`` / ``final_info``), and frames.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numba.typed import List as TypedList

#: How an ``info`` key is stored: its name, its Python type (float, int or bool: the dtype of its array, as
#: ``VectorEnv._add_info`` chooses it) and its column in the info array of that type.
InfoKey = tuple[str, type, int]


class BatchedEnv(VectorEnv[dict[str, np.ndarray], np.ndarray, np.ndarray]):
    """Gymnasium's vector API for ``num_envs`` single envs whose steps a compiled kernel runs together.

    The contract, the same as Gymnasium's ``SyncVectorEnv`` over ``gym.make`` envs:

    * ``reset(seed=S)`` seeds sub-env ``i`` with ``S + i``; ``seed=[s0, s1, ...]`` gives one seed (or None) per
      sub-env. ``options`` are the single env's reset options; a value that is a sequence of ``num_envs``
      items gives one per sub-env, any other value goes to every sub-env. ``options={"reset_mask": mask}``
      (a bool array) resets only those sub-envs, leaving the others' observations as they are.
    * ``step(actions)`` takes ``(num_envs, *action_shape)`` actions (clipped to [-1, 1]; NaN or inf raises
      ``ValueError`` naming the sub-env) and returns observations as a dict of ``(num_envs, ...)`` float32
      arrays, rewards (float64), terminations and truncations (bool), and ``info`` as a dict of arrays with a
      ``_key`` bool mask telling which sub-envs have the key.
    * ``autoreset_mode``: ``NEXT_STEP`` (default) resets a finished sub-env on the next ``step``, which returns
      its first observation with reward 0 and ignores its action; ``SAME_STEP`` resets it in the step that
      finishes it and returns the new episode's first observation and ``info``, with the last observation
      and info of the finished episode in ``info["final_obs"]`` and ``info["final_info"]``; ``DISABLED`` never
      resets by itself: reset finished sub-envs with ``reset(options={"reset_mask": mask})`` before
      stepping them again.
    * ``max_episode_steps=N`` truncates every episode at N steps, as ``gym.make(..., max_episode_steps=N)``'s
      ``TimeLimit`` does (a terminating step is then truncated too).
    * ``render_mode="rgb_array"``: ``render()`` returns one frame per sub-env, drawn as the single env draws.

    Subclasses set :attr:`INFO_KEYS` and implement :meth:`_load` (an episode's state into the kernel's
    arrays), :meth:`_run` (the kernel) and :meth:`_store` (the state back into a sub-env, to draw it).

    Args:
        make_env: Makes one single env from the keyword arguments (``render_mode`` and the env's own).
        num_envs: Number of sub-envs, >= 1.
        autoreset_mode: A :class:`gymnasium.vector.AutoresetMode` or its value (``"NextStep"``, ...).
        max_episode_steps: Step limit of every episode, as ``gym.make(..., max_episode_steps=N)``'s ``TimeLimit``
            sets it (None: the env's own).
        render_mode: None or ``"rgb_array"``.
        kwargs: The single env's arguments.

    Raises:
        ValueError: For a bad ``num_envs``, ``autoreset_mode``, ``max_episode_steps`` or ``render_mode``, or a
            bad env argument (named as the single env names it).
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}
    #: The info keys of a step, in the single env's order.
    INFO_KEYS: tuple[InfoKey, ...] = ()

    @classmethod
    def refusal(cls, kwargs: dict[str, Any]) -> str | None:
        """Why this batched form cannot run envs made with ``kwargs`` (valid single-env arguments); None: it can."""
        return None

    def __init__(
        self,
        make_env: Callable[..., gym.Env[Any, Any]],
        num_envs: int,
        autoreset_mode: AutoresetMode | str,
        max_episode_steps: int | None,
        render_mode: str | None,
        kwargs: dict[str, Any],
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            valid = [m.value for m in AutoresetMode]
            raise ValueError(
                f"autoreset_mode must be an AutoresetMode or one of {valid}, got {autoreset_mode!r}"
            ) from None
        if max_episode_steps is not None and (
            isinstance(max_episode_steps, bool)
            or not isinstance(max_episode_steps, (int, np.integer))
            or max_episode_steps < 1
        ):
            raise ValueError(f"max_episode_steps must be an integer >= 1 or None, got {max_episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array' for the vector env, got {render_mode!r}")
        self.num_envs = n = int(num_envs)
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        self.render_mode = render_mode
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        #: The sub-envs (see the subclass's docstring for what they hold between resets).
        self.envs = [make_env(render_mode=render_mode, **kwargs) for _ in range(n)]
        self.single_observation_space: spaces.Dict = self.envs[0].observation_space  # type: ignore[assignment]
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, n)
        self.action_space = batch_space(self.single_action_space, n)
        #: Observations, rewards, flags and info values of the last step or reset, one row per sub-env.
        self._obs = {
            key: np.zeros((n, *(box.shape or ())), np.float32) for key, box in self.single_observation_space.items()
        }
        self._reward = np.zeros(n)
        self._terminated = np.zeros(n, np.bool_)
        self._truncated = np.zeros(n, np.bool_)
        self._info: dict[type, np.ndarray] = {
            kind: np.zeros((n, sum(k == kind for _, k, _ in self.INFO_KEYS)), kind) for kind in (float, int, bool)
        }
        # The robot's position after each control period of the last step (subclasses with several periods a
        # step make it longer).
        self._trail = np.zeros((n, 1, 2))
        self._periods = np.zeros(n, np.int64)  # control periods each sub-env ran in the last step
        self._rngs: Any = None  # the sub-envs' generators, as a numba typed list (after the first reset)
        self._rng_objects: list[Any] = [None] * n
        self._autoreset = np.zeros(n, dtype=np.bool_)
        self._elapsed = np.zeros(n, dtype=np.int64)  # steps since each sub-env's reset (TimeLimit's count)
        self._trails: list[list[tuple[float, float]]] = [[] for _ in range(n)]  # with a render mode only
        self._started = False
        self.closed = False

    # -- what a subclass provides -----------------------------------------------------------------------------
    def _load(self, i: int) -> None:
        """Copy sub-env ``i``'s freshly reset episode into the kernel's arrays (and its start into its trail)."""
        raise NotImplementedError

    def _run(self, actions: np.ndarray, stepping: np.ndarray) -> None:
        """Step the sub-envs of ``stepping`` (actions checked and clipped, float64), writing the output arrays."""
        raise NotImplementedError

    def _store(self, i: int) -> None:
        """Write sub-env ``i``'s current state (and its trail, :attr:`_trails`) back into it, for drawing."""
        raise NotImplementedError

    def _truncation_reasons(self, truncated: np.ndarray) -> dict[int, str]:
        """``info["truncation_reason"]`` of the sub-envs the env itself truncated (none by default)."""
        return {}

    def _has(self, key: str) -> bool:
        """Whether this env's ``info`` holds ``key`` (every key of :attr:`INFO_KEYS` by default)."""
        return True

    # -- the vector API ---------------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset every sub-env, or those of ``options["reset_mask"]`` (see the subclass's docstring)."""
        if self.closed:
            raise RuntimeError("the vector env is closed")
        seeds = self._seeds(seed)
        opts = dict(options or {})
        mask = self._reset_mask(opts.pop("reset_mask", None))
        per_env = self._per_env_options(opts)
        if mask is None or not self._started:  # the first reset sets every sub-env up
            mask = np.ones(self.num_envs, dtype=np.bool_)
        for i in np.flatnonzero(mask).tolist():
            self._reset_one(i, seeds[i], per_env[i])
        if self._rngs is None:
            self._rngs = TypedList(self._rng_objects)
        self._started = True
        self._autoreset[mask] = False
        self._terminated[mask] = False
        self._truncated[mask] = False
        return self._observations(), self._infos(mask, {})

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-env (see the subclass's docstring for what happens to finished ones)."""
        if self.closed or not self._started:
            raise RuntimeError("the vector env is closed" if self.closed else "call reset() before step()")
        a = self._checked_actions(actions)
        if self.autoreset_mode == AutoresetMode.DISABLED and self._autoreset.any():
            done = np.flatnonzero(self._autoreset).tolist()
            raise RuntimeError(
                f"sub-envs {done} finished their episodes: reset them with reset(options={{'reset_mask': mask}}) "
                "before stepping them again (autoreset_mode=DISABLED)"
            )
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            stepping = ~self._autoreset
        else:
            stepping = np.ones(self.num_envs, dtype=np.bool_)
        self._run(a, stepping)
        reasons = self._truncation_reasons(stepping & self._truncated)  # the env's own truncations say why
        self._elapsed[stepping] += 1
        if self.max_episode_steps is not None:  # TimeLimit truncates at N steps, even a terminated episode
            self._truncated[stepping & (self._elapsed >= self.max_episode_steps)] = True
        if self.render_mode:
            for k in np.flatnonzero(stepping).tolist():
                self._trails[k].extend(map(tuple, self._trail[k, : self._periods[k]].tolist()))
        final: dict[str, Any] = {}
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            for i in np.flatnonzero(self._autoreset).tolist():
                self._reset_one(i, None, None)
                self._reward[i] = 0.0
                self._terminated[i] = self._truncated[i] = False
        elif self.autoreset_mode == AutoresetMode.SAME_STEP:
            for i in np.flatnonzero(self._terminated | self._truncated).tolist():
                last = {"final_obs": self._observation(i), "final_info": self._info_of(i, reasons.pop(i, None))}
                final = self._add_info(final, last, i)
                self._reset_one(i, None, None)
        self._autoreset = self._terminated | self._truncated
        infos = self._infos(np.ones(self.num_envs, dtype=np.bool_), reasons)
        infos.update(final)
        return (
            self._observations(),
            self._reward.copy(),
            self._terminated.copy(),
            self._truncated.copy(),
            infos,
        )

    # Typed as SyncVectorEnv types them (a tuple per sub-env), which VectorEnv's annotations do not foresee.
    @property
    def np_random_seed(self) -> tuple[int, ...]:  # type: ignore[override]
        """The sub-envs' seeds, as ``SyncVectorEnv`` reports them: ``(42, 43, ...)`` after ``reset(seed=42)``.

        A sub-env not yet seeded draws a random seed on the first access (Gymnasium's ``Env.np_random_seed``).
        """
        return tuple(env.np_random_seed for env in self.envs)

    @property  # type: ignore[misc]
    def np_random(self) -> tuple[np.random.Generator, ...]:  # type: ignore[override]
        """The sub-envs' generators (the ones the batched loop draws from), as ``SyncVectorEnv`` gives them."""
        return tuple(env.np_random for env in self.envs)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``rgb_array`` frame per sub-env, as the single env draws it (None without a render mode)."""
        if self.render_mode is None:
            return None
        if not self._started:
            raise RuntimeError("call reset() before render()")
        frames = []
        for i, env in enumerate(self.envs):
            self._store(i)
            frame = env.render()
            assert isinstance(frame, np.ndarray)
            frames.append(frame)
        return tuple(frames)

    def close_extras(self, **kwargs: Any) -> None:
        """Close every sub-env (their renderers and pymunk worlds)."""
        for env in self.envs:
            env.close()

    # -- resets -----------------------------------------------------------------------------------------------
    def _reset_one(self, i: int, seed: int | None, options: dict[str, Any] | None) -> None:
        """Reset sub-env ``i`` with the single env's own ``reset`` and load the episode."""
        env = self.envs[i]
        obs, info = env.reset(seed=seed, options=options)
        self._load(i)
        for key, value in obs.items():
            self._obs[key][i] = value
        for key, kind, col in self.INFO_KEYS:
            if key in info:
                self._info[kind][i, col] = info[key]
        self._elapsed[i] = 0
        if env.np_random is not self._rng_objects[i]:  # a seeded reset made a new generator
            self._rng_objects[i] = env.np_random
            if self._rngs is not None:
                self._rngs[i] = env.np_random

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(self.num_envs)]
        if isinstance(seed, bool):
            raise ValueError(f"reset: seed must be an int, None or one seed per sub-env, got {seed!r}")
        seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(
                f"reset: seed must be an int, None or {self.num_envs} seeds (one per sub-env), got {len(seeds)}"
            )
        return seeds

    def _reset_mask(self, mask: Any) -> np.ndarray | None:
        if mask is None:
            return None
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (self.num_envs,):
            raise ValueError(f"reset option reset_mask must be a bool array of shape ({self.num_envs},), got {mask!r}")
        if not mask.any():
            raise ValueError("reset option reset_mask must select at least one sub-env")
        return mask

    def _per_env_options(self, options: dict[str, Any]) -> list[dict[str, Any] | None]:
        """One options dict per sub-env: sequences of ``num_envs`` values are split, others shared."""
        if not options:
            return [None] * self.num_envs
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for key, value in options.items():
            if isinstance(value, (list, tuple, np.ndarray)):
                if len(value) != self.num_envs:
                    raise ValueError(
                        f"reset option {key!r}: give one value for every sub-env ({self.num_envs}) or a single value, "
                        f"got {len(value)}"
                    )
                values = value.tolist() if isinstance(value, np.ndarray) else list(value)
            else:
                values = [value] * self.num_envs
            for opts, v in zip(out, values, strict=True):
                opts[key] = v
        return list(out)

    # -- steps ------------------------------------------------------------------------------------------------
    def _checked_actions(self, actions: Any) -> np.ndarray:
        """The actions as float64, clipped to the action box, as the single env's ``checked_action`` does."""
        shape = self.action_space.shape
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != shape:
            raise ValueError(f"actions must have shape {shape}, got {a.shape}")
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(f"actions of sub-envs {np.flatnonzero(bad).tolist()} contain NaN or inf")
        return np.minimum(np.maximum(a, -1.0), 1.0)

    def _observations(self) -> dict[str, np.ndarray]:
        return {key: array.copy() for key, array in self._obs.items()}

    def _observation(self, i: int) -> dict[str, np.ndarray]:
        return {key: array[i].copy() for key, array in self._obs.items()}

    def _info_of(self, i: int, reason: str | None) -> dict[str, Any]:
        """Sub-env ``i``'s info as the single env returns it (Python scalars)."""
        info = {key: kind(self._info[kind][i, col]) for key, kind, col in self.INFO_KEYS if self._has(key)}
        if reason is not None:
            info["truncation_reason"] = reason
        return info

    def _infos(self, mask: np.ndarray, reasons: dict[int, str]) -> dict[str, Any]:
        """The info dict of arrays for the sub-envs of ``mask`` (as ``VectorEnv._add_info`` lays it out)."""
        full = bool(mask.all())
        infos: dict[str, Any] = {}
        for key, kind, col in self.INFO_KEYS:
            if not self._has(key):
                continue
            values = self._info[kind][:, col].copy()
            if not full:
                values[~mask] = 0
            infos[key] = values
            infos[f"_{key}"] = mask.copy()
        if reasons:
            text = np.full(self.num_envs, None, dtype=object)
            has = np.zeros(self.num_envs, dtype=np.bool_)
            for i, reason in reasons.items():
                text[i], has[i] = reason, True
            infos["truncation_reason"], infos["_truncation_reason"] = text, has
        return infos


def grown(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` copied into a zero array at least ``shape`` large (room to spare along the grown axes)."""
    new = tuple(want + (want - old) // 2 if want > old else old for old, want in zip(a.shape, shape, strict=True))
    if new == a.shape:
        return a
    b = np.zeros(new, dtype=a.dtype)
    b[tuple(slice(0, n) for n in a.shape)] = a
    return b
