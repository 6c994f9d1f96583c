"""Parameter-shared training and acting for the PettingZoo envs (the robot chain): one network drives every agent.

Training goes through SuperSuit: ``pettingzoo_env_to_vec_env_v1`` turns one parallel env of ``n`` agents
into a vector env of ``n`` slots (one per agent), and ``concat_vec_envs_v1(..., base_class=
"stable_baselines3")`` concatenates ``n_envs`` copies into one SB3 ``VecEnv`` of ``n_envs * n`` slots. PPO
then sees every agent's step as one transition of the same policy (parameter sharing), with the
cooperative reward each agent receives.

Agents leaving: SuperSuit's Markov vector env needs the same agents throughout an episode (its
``black_death`` option would feed zero observations to agents that left). ``robot_chain_v1`` never
removes a single agent: every agent terminates or truncates at the same step (the leader's arrival, any
contact, or ``max_cycles``), so the plain conversion applies and no black-death wrapper is used; the
vector env resets the whole chain when the episode ends. (SuperSuit's conversion refuses, by an assertion,
an env that removes agents one by one.)

The wrapper :func:`make_shared_vec_env` returns repairs two things of SuperSuit's SB3 wrapper (3.11):
SB3's ``seed()`` (called by every algorithm with a seed) is forwarded to the next ``reset`` (copy ``i``
resets from ``seed + i`` and then continues its own random stream), and truncations are reported as
``TimeLimit.truncated``, so that PPO bootstraps from the value of the final observation instead of
treating ``max_cycles`` as a terminal state.

Acting: :func:`predict_shared` stacks the per-agent observation dict into one batch, runs the network once
and returns a per-agent action dict, the interface of the chain baselines (``apoorva-chain``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np


def make_shared_vec_env(make_parallel_env: Callable[[], Any], n_envs: int) -> Any:
    """An SB3 ``VecEnv`` with one slot per agent of ``n_envs`` copies of a PettingZoo parallel env.

    Args:
        make_parallel_env: Builds one parallel env (every agent with the same spaces).
        n_envs: Copies of the env; the vector env has ``n_envs * len(possible_agents)`` slots.

    Raises:
        ValueError: For ``n_envs < 1``, or agents with different spaces.
    """
    if n_envs < 1:
        raise ValueError(f"n_envs must be >= 1, got {n_envs}")
    import supersuit as ss

    env = make_parallel_env()
    agents = list(env.possible_agents)
    spaces = {(repr(env.observation_space(a)), repr(env.action_space(a))) for a in agents}
    if len(spaces) != 1:
        raise ValueError("parameter sharing needs one observation and one action space for every agent")
    markov = ss.pettingzoo_env_to_vec_env_v1(env)
    concat = ss.concat_vec_envs_v1(markov, n_envs, num_cpus=0, base_class="gymnasium")
    return _agent_vec_env_class()(concat)


def _agent_vec_env_class() -> type:
    """SuperSuit's SB3 wrapper with SB3 seeding and ``TimeLimit.truncated`` (see the module docstring).

    Built on first use, so that acting with a trained policy does not import SuperSuit.
    """
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class SB3AgentVecEnv(SB3VecEnvWrapper):  # type: ignore[misc]
        def __init__(self, venv: Any) -> None:
            super().__init__(venv)
            self._next_seed: int | None = None

        def seed(self, seed: int | None = None) -> list[int | None]:
            """Seed the next reset: copy ``i`` resets from ``seed + i``."""
            self._next_seed = None if seed is None else int(seed)
            return [self._next_seed] * self.num_envs

        def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> np.ndarray:
            """Reset every copy (from the pending seed, if any) and return the stacked observations."""
            if seed is None:
                seed, self._next_seed = self._next_seed, None
            observations, self.reset_infos = self.venv.reset(seed=seed, options=options)
            return observations  # type: ignore[no-any-return]

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            """``render_mode`` per slot (SB3 asks for it when a wrapper is added); other attributes: SuperSuit's."""
            if attr_name == "render_mode":
                return [self.render_mode] * self.num_envs
            return super().get_attr(attr_name, indices)  # type: ignore[no-any-return]

        def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
            """Step every slot; a slot whose episode was truncated (not terminated) says so like SB3's envs."""
            observations, rewards, terminations, truncations, infos = self.venv.step_wait()
            terminations = np.asarray(terminations, dtype=bool)
            truncations = np.asarray(truncations, dtype=bool)
            dones = terminations | truncations
            for i in np.flatnonzero(dones):
                infos[i]["TimeLimit.truncated"] = bool(truncations[i] and not terminations[i])
            return observations, np.asarray(rewards, dtype=np.float32), dones, infos

    return SB3AgentVecEnv


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
