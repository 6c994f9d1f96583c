"""Parameter-shared training and acting for the PettingZoo envs (the robot chain): one network drives every agent.

Training: :class:`SharedAgentVecEnv` turns ``n_envs`` copies of a parallel env of ``n`` agents into one SB3
``VecEnv`` of ``n_envs * n`` slots (one per agent; copy ``i``'s agents fill slots ``i * n`` to
``i * n + n - 1`` in ``possible_agents`` order). PPO then sees every agent's step as one transition of the
same policy (parameter sharing), with the cooperative reward each agent receives. It does what SuperSuit's
``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1`` do for this case, in one layer and with fewer
copies (measured on the chain: SuperSuit's two layers cost about 13 % of a training step), plus what SB3
needs and SuperSuit's SB3 wrapper lacks: ``seed()`` is forwarded to the next ``reset`` (copy ``i`` resets
from ``seed + i`` and then continues its own random stream), and a truncated episode is reported as
``TimeLimit.truncated``, so that PPO bootstraps from the value of the final observation instead of treating
``max_cycles`` as a terminal state.

Agents leaving: a slot per agent needs the same agents throughout an episode. ``robot_chain_v1`` never
removes a single agent: every agent terminates or truncates at the same step (success, any contact or
break, or ``max_cycles``), and the copy then resets whole. An env that removes agents one by one is refused
(``ValueError``), as SuperSuit refuses it (it would need its ``black_death`` option, which feeds zero
observations to agents that left).

Acting: :func:`predict_shared` stacks the per-agent observation dict into one batch, runs the network once
and returns a per-agent action dict, the interface of the chain baselines (``apoorva-chain``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np


def make_shared_vec_env(make_parallel_env: Callable[[], Any], n_envs: int) -> Any:
    """An SB3 ``VecEnv`` with one slot per agent of ``n_envs`` copies of a PettingZoo parallel env.

    Args:
        make_parallel_env: Builds one parallel env (every agent with the same spaces); called ``n_envs`` times.
        n_envs: Copies of the env; the vector env has ``n_envs * len(possible_agents)`` slots.

    Raises:
        ValueError: For ``n_envs < 1``, or agents with different spaces.
    """
    if n_envs < 1:
        raise ValueError(f"n_envs must be >= 1, got {n_envs}")
    return _vec_env_class()([make_parallel_env() for _ in range(n_envs)])


def _vec_env_class() -> type:
    """:class:`SharedAgentVecEnv`, built on first use so that acting with a trained policy needs no SB3 VecEnv."""
    global SharedAgentVecEnv
    if SharedAgentVecEnv is not None:
        return SharedAgentVecEnv
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv

    class _SharedAgentVecEnv(VecEnv):  # type: ignore[misc]
        """Copies of a parallel env, one slot per agent (see the module docstring)."""

        def __init__(self, envs: Sequence[Any]) -> None:
            self.envs = list(envs)
            first = self.envs[0]
            self.agents = list(first.possible_agents)
            agent = self.agents[0]
            observation_space, action_space = first.observation_space(agent), first.action_space(agent)
            for env in self.envs:
                for a in env.possible_agents:
                    if (repr(env.observation_space(a)), repr(env.action_space(a))) != (
                        repr(observation_space),
                        repr(action_space),
                    ):
                        raise ValueError("parameter sharing needs one observation and one action space for every agent")
                if list(env.possible_agents) != self.agents:
                    raise ValueError("every copy must have the same agents")
            self.n_agents = len(self.agents)
            self.render_mode = None
            super().__init__(len(self.envs) * self.n_agents, observation_space, action_space)
            shape = (self.num_envs, *observation_space.shape)
            self._obs = np.zeros(shape, dtype=observation_space.dtype)
            self._next_seed: int | None = None
            self._actions: np.ndarray | None = None

        def _store(self, i: int, observations: Mapping[str, Any]) -> None:
            rows = self._obs[i * self.n_agents : (i + 1) * self.n_agents]
            for k, a in enumerate(self.agents):
                rows[k] = observations[a]

        def seed(self, seed: int | None = None) -> list[int | None]:
            """Seed the next reset: copy ``i`` resets from ``seed + i``."""
            self._next_seed = None if seed is None else int(seed)
            return [self._next_seed] * self.num_envs

        def reset(self) -> np.ndarray:
            """Reset every copy (from the pending seed, if any) and return the stacked observations."""
            seed, self._next_seed = self._next_seed, None
            self.reset_infos = []
            for i, env in enumerate(self.envs):
                observations, infos = env.reset(seed=None if seed is None else seed + i)
                self._store(i, observations)
                self.reset_infos += [infos[a] for a in self.agents]
            return self._obs.copy()

        def step_async(self, actions: np.ndarray) -> None:
            self._actions = np.asarray(actions)

        def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
            """Step every copy; a copy whose episode ended returns its final observation and resets whole."""
            assert self._actions is not None, "step_async first"
            n = self.n_agents
            rewards = np.zeros(self.num_envs, dtype=np.float32)
            dones = np.zeros(self.num_envs, dtype=bool)
            infos: list[dict[str, Any]] = []
            for i, env in enumerate(self.envs):
                acts = dict(zip(self.agents, self._actions[i * n : (i + 1) * n], strict=True))
                observations, rew, terms, truncs, env_infos = env.step(acts)
                ended = not env.agents
                if not ended and len(env.agents) != n:
                    raise ValueError("parameter sharing needs every agent to stay until the episode ends")
                for k, a in enumerate(self.agents):
                    rewards[i * n + k] = rew[a]
                    info = env_infos[a]  # a fresh dict every step: the env keeps no reference to it
                    if ended:
                        info["terminal_observation"] = np.asarray(observations[a], dtype=self._obs.dtype)
                        info["TimeLimit.truncated"] = bool(truncs[a] and not terms[a])
                    infos.append(info)
                if ended:
                    dones[i * n : (i + 1) * n] = True
                    observations, _ = env.reset()
                self._store(i, observations)
            return self._obs.copy(), rewards, dones, infos

        def close(self) -> None:
            for env in self.envs:
                env.close()

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            """An attribute of the copy behind each slot (``render_mode``: None, the training envs draw nothing)."""
            slots = self._slots(indices)
            if attr_name == "render_mode":
                return [None] * len(slots)
            return [getattr(self.envs[s // self.n_agents], attr_name) for s in slots]

        def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
            for i in sorted({s // self.n_agents for s in self._slots(indices)}):
                setattr(self.envs[i], attr_name, value)

        def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
            return [getattr(self.envs[s // self.n_agents], method_name)(*args, **kwargs) for s in self._slots(indices)]

        def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
            return [False] * len(self._slots(indices))

        def _slots(self, indices: Any) -> list[int]:
            if indices is None:
                return list(range(self.num_envs))
            if isinstance(indices, int):
                return [indices]
            return list(indices)

    SharedAgentVecEnv = _SharedAgentVecEnv
    return SharedAgentVecEnv


#: The vector env class of :func:`make_shared_vec_env` (an SB3 ``VecEnv``), made on first use.
SharedAgentVecEnv: Any = None


def predict_shared(
    model: Any,
    observations: Mapping[str, Any],
    transform: Callable[[np.ndarray], np.ndarray],
    deterministic: bool = True,
) -> dict[str, np.ndarray]:
    """Every agent's action from one batched pass of the shared network.

    Args:
        model: The shared network: SB3's ``predict`` on a batch of observations
            (:class:`~agri_training.inference.PolicyNetwork`).
        observations: Per-agent observations of one step of a parallel env.
        transform: Maps the ``(n_agents, obs_dim)`` batch to what the network saw in training
            (observation normalisation).
        deterministic: The network's mean action instead of a sample.

    Returns:
        Per-agent actions, keyed like ``observations``.
    """
    agents = list(observations)
    if not agents:
        return {}
    batch = np.stack([np.asarray(observations[a], dtype=np.float32) for a in agents])
    actions, _ = model.predict(transform(batch), deterministic=deterministic)
    return {a: np.asarray(actions[i], dtype=np.float32) for i, a in enumerate(agents)}
