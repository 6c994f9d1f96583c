"""Behaviour cloning from a scripted baseline: a policy's first weights, before reinforcement learning.

A hyperparameter block may declare ``pretrain`` (``agri train`` reads it)::

    pretrain: {policy: harik-apf-gt, episodes: 200, epochs: 10, seed: 50000}

Before PPO's first rollout, :func:`pretrain_from_baseline`

1. runs the baseline ``episodes`` times on the training env (``env_kwargs`` and ``train_env_kwargs``, plus
   what the baseline itself needs, e.g. the full scan) at seeds ``seed ..``: the baseline acts every
   control period, as it was written to; every ``action_repeat``-th period is a decision of the learner,
   which records the learner's observation (through the run's observation wrappers, without the keys only
   the baseline reads), the baseline's action and the reward until the next decision;
2. sets ``VecNormalize``'s observation and return statistics from these decisions;
3. fits the policy's mean action to the baseline's actions (mean squared error) and its value function to
   the demonstrations' discounted, normalised returns, ``epochs`` passes with Adam. The action noise (the
   log standard deviation) keeps its configured value, so PPO still explores from there.

PPO then fine-tunes on the env's reward. The policy stays a learned one: what it may observe is the run's
observation, never the baseline's extra inputs (the baseline's privileges show only in the actions it
demonstrated, and the policy's registration says which baseline that was).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from agri_baselines import make_policy, policy_spec
from agri_training.learned.policy import ObservationReplay, observation_chain


@dataclasses.dataclass(frozen=True)
class PretrainSpec:
    """The ``pretrain`` block of a hyperparameter file.

    Attributes:
        policy: Registered baseline of the env whose actions are cloned.
        episodes: Demonstration episodes, >= 1.
        epochs: Passes over the demonstrations, >= 1.
        seed: First demonstration seed (``seed .. seed + episodes - 1``), below 100000.
        learning_rate: Adam's step size.
        batch_size: Decisions per gradient step.
    """

    policy: str
    episodes: int = 100
    epochs: int = 10
    seed: int = 50_000
    learning_rate: float = 1e-3
    batch_size: int = 256

    def __post_init__(self) -> None:
        if self.episodes < 1 or self.epochs < 1 or self.batch_size < 1:
            raise ValueError(f"pretrain: episodes, epochs and batch_size must be >= 1, got {self}")
        if not 0 <= self.seed or self.seed + self.episodes > 100_000:
            raise ValueError(f"pretrain: seeds {self.seed}..{self.seed + self.episodes - 1} must lie below 100000")

    @classmethod
    def from_config(cls, block: Mapping[str, Any]) -> PretrainSpec:
        """The spec of a ``pretrain`` mapping (unknown keys are refused, naming the valid ones).

        Raises:
            ValueError: For an unknown key or a bad value.
        """
        names = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(block) - set(names))
        if unknown:
            raise ValueError(f"pretrain: unknown keys {unknown}; valid: {', '.join(names)}")
        return cls(**dict(block))


@dataclasses.dataclass
class Demonstrations:
    """Decisions of a demonstrated run, as the learner sees them.

    Attributes:
        observations: Learner observations (wrapped, not normalised): an array, or a dict of arrays.
        actions: ``(n, action_dim)`` the baseline's actions, in the env's action box.
        rewards: ``(n,)`` reward from each decision to the next.
        episode_ends: ``(n,)`` True at an episode's last decision.
        successes: Episodes the baseline finished with ``info["is_success"]``.
        episodes: Episodes run.
    """

    observations: Any
    actions: np.ndarray
    rewards: np.ndarray
    episode_ends: np.ndarray
    successes: int
    episodes: int


def _stack(frames: list[Any]) -> Any:
    if isinstance(frames[0], Mapping):
        return {k: np.stack([f[k] for f in frames]).astype(np.float32) for k in frames[0]}
    return np.stack(frames).astype(np.float32)


def demonstrate(spec: PretrainSpec, config: Mapping[str, Any]) -> Demonstrations:
    """Run the baseline on the training env and record the learner's decisions (step 1 of the module doc).

    Raises:
        ValueError: When the baseline drives another env or needs arguments the training env contradicts.
    """
    baseline = policy_spec(spec.policy)
    env_id = config["env_id"]
    if baseline.env_id != env_id:
        raise ValueError(f"pretrain: {spec.policy} drives {baseline.env_id}, not {env_id}")
    learner_kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
    for key, value in baseline.env_kwargs.items():
        if key in learner_kwargs and learner_kwargs[key] != value:
            raise ValueError(
                f"pretrain: {spec.policy} needs {key}={value!r}, the training env has {learner_kwargs[key]!r}"
            )
    learner_env = gym.make(env_id, **learner_kwargs)
    space = learner_env.observation_space
    keys = list(space.spaces) if isinstance(space, gym.spaces.Dict) else None
    _, chain = observation_chain(learner_env, config.get("wrappers", []))
    replay = ObservationReplay(chain)
    env = gym.make(env_id, **{**learner_kwargs, **baseline.env_kwargs})
    expert = make_policy(spec.policy, env)
    repeat = int(config.get("action_repeat", 1))
    observations, actions, rewards, ends = [], [], [], []
    successes = 0
    for episode in range(spec.episodes):
        obs, info = env.reset(seed=spec.seed + episode)
        step, done = 0, False
        while not done:
            action, _ = expert.predict(obs, episode_start=np.array([step == 0]), deterministic=True)
            if step % repeat == 0:  # a decision of the learner: what it sees, what the baseline does
                seen = {k: obs[k] for k in keys} if keys is not None else obs
                observations.append(replay(seen, new_episode=step == 0))
                actions.append(np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0))
                rewards.append(0.0)
                ends.append(False)
            obs, reward, terminated, truncated, info = env.step(action)
            rewards[-1] += float(reward)
            step += 1
            done = terminated or truncated
        ends[-1] = True
        successes += int(bool(info.get("is_success", False)))
    env.close()
    learner_env.close()
    return Demonstrations(
        _stack(observations), np.stack(actions), np.array(rewards), np.array(ends), successes, spec.episodes
    )


def _set_statistics(venv: Any, demos: Demonstrations, gamma: float) -> None:
    """Step 2: ``VecNormalize``'s observation and return statistics from the demonstrations."""
    n = len(demos.actions)
    if venv.norm_obs:
        if isinstance(venv.obs_rms, dict):
            for key in venv.norm_obs_keys:
                x = demos.observations[key].reshape(n, -1).astype(np.float64)
                venv.obs_rms[key].mean = x.mean(axis=0).reshape(venv.obs_rms[key].mean.shape)
                venv.obs_rms[key].var = x.var(axis=0).reshape(venv.obs_rms[key].var.shape)
                venv.obs_rms[key].count = float(n)
        else:
            x = demos.observations.reshape(n, -1).astype(np.float64)
            venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = x.mean(axis=0), x.var(axis=0), float(n)
    if venv.norm_reward:  # the running discounted return VecNormalize scales rewards by, as it computes it
        running, seen = 0.0, []
        for r, end in zip(demos.rewards, demos.episode_ends, strict=True):
            running = running * gamma + float(r)
            seen.append(running)
            if end:
                running = 0.0
        venv.ret_rms.mean, venv.ret_rms.var, venv.ret_rms.count = float(np.mean(seen)), float(np.var(seen)), float(n)


def _discounted(rewards: np.ndarray, ends: np.ndarray, gamma: float) -> np.ndarray:
    """The discounted return from each decision to its episode's end."""
    returns = np.zeros(len(rewards))
    running = 0.0
    for i in range(len(rewards) - 1, -1, -1):
        running = float(rewards[i]) + (0.0 if ends[i] else gamma * running)
        returns[i] = running
    return returns


def _targets(venv: Any, demos: Demonstrations, gamma: float) -> tuple[Any, np.ndarray]:
    """Observations and discounted returns as PPO will see them: normalised when the run normalises."""
    if venv is None:
        return demos.observations, _discounted(demos.rewards, demos.episode_ends, gamma)
    obs = venv.normalize_obs(demos.observations)
    obs = {k: v.astype(np.float32) for k, v in obs.items()} if isinstance(obs, dict) else obs.astype(np.float32)
    rewards = venv.normalize_reward(demos.rewards) if venv.norm_reward else demos.rewards
    return obs, _discounted(rewards, demos.episode_ends, gamma)


def pretrain_from_baseline(model: Any, venv: Any, config: Mapping[str, Any]) -> dict[str, Any]:
    """Clone the declared baseline into ``model`` before it trains (see the module doc).

    Args:
        model: The SB3 on-policy model (PPO) about to learn.
        venv: Its ``VecNormalize`` env, or None when the run does not normalise.
        config: The resolved training config (its ``pretrain`` block).

    Returns:
        A summary for ``meta.json``: decisions, the baseline's success on its demonstrations, losses.
    """
    import torch

    spec = PretrainSpec.from_config(config["pretrain"])
    gamma = float(config["algo_kwargs"].get("gamma", 0.99))
    demos = demonstrate(spec, config)
    if venv is not None:
        _set_statistics(venv, demos, gamma)
    obs, returns = _targets(venv, demos, gamma)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=spec.learning_rate)  # no loss term reaches log_std
    n = len(demos.actions)
    rng = np.random.default_rng(int(config["seed"]))
    actions = torch.as_tensor(demos.actions)
    targets = torch.as_tensor(returns, dtype=torch.float32)
    first = last = None
    for _ in range(spec.epochs):
        order = rng.permutation(n)
        for start in range(0, n, spec.batch_size):
            batch = order[start : start + spec.batch_size]
            x = {k: torch.as_tensor(v[batch]) for k, v in obs.items()} if isinstance(obs, dict) else obs[batch]
            x = torch.as_tensor(x) if not isinstance(x, dict) else x
            mean = policy.get_distribution(x).distribution.mean
            action_loss = torch.mean((mean - actions[batch]) ** 2)
            value_loss = torch.mean((policy.predict_values(x).flatten() - targets[batch]) ** 2)
            loss = action_loss + 0.5 * value_loss
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            last = (float(action_loss), float(value_loss))
            first = first or last
    assert first is not None and last is not None
    return {
        "policy": spec.policy,
        "episodes": spec.episodes,
        "seeds": [spec.seed, spec.seed + spec.episodes - 1],
        "baseline_success_rate": demos.successes / demos.episodes,
        "decisions": n,
        "epochs": spec.epochs,
        "action_mse_first_last": [first[0], last[0]],
        "value_mse_first_last": [first[1], last[1]],
    }

