"""Behaviour cloning from a scripted baseline: a policy's first weights, before reinforcement learning.

A hyperparameter block may declare ``pretrain`` (``agri train`` reads it)::

    pretrain: {policy: harik-apf-gt, episodes: 200, epochs: 10, seed: 50000}

Before PPO's first rollout, :func:`pretrain_from_baseline`

1. runs the baseline ``episodes`` times on the training env (``env_kwargs`` and ``train_env_kwargs``, plus
   what the baseline itself needs, e.g. the full scan) at seeds ``seed ..``: the baseline acts every
   control period, as it was written to; every ``action_repeat``-th period is a decision of the learner,
   which records the learner's observation (through the run's observation wrappers), the baseline's action
   and the reward until the next decision. Where the baseline needs env arguments that change more than
   extra observation keys (the true pose, not a full scan: ``StrictConfig.differences``), the training env
   runs beside the baseline's on the same seed and actions, and the learner's observation is the training
   env's: a learner trained with odometry sees its odometry, not the baseline's true pose. The two must
   agree on every reward and episode end, or the arguments changed the dynamics and the run stops;
2. sets ``VecNormalize``'s observation and return statistics from these decisions;
3. fits the policy's mean action to the baseline's actions (mean squared error) and its value function to
   the demonstrations' discounted, normalised returns, ``epochs`` passes with Adam. The action noise (the
   log standard deviation) keeps its configured value, so PPO still explores from there;
4. with ``dagger_rounds: R`` (DAgger, Ross, Gordon & Bagnell 2011), R times: the policy's mean action
   (plus ``dagger_noise``) drives ``dagger_episodes`` episodes while the baseline, run beside it, says
   what it would have done; these decisions join the demonstrations and the fit is repeated
   (``dagger_epochs`` passes over all of them). Cloning alone trains only on the states the baseline
   visits, and a small error then leads the clone where it has never been shown what to do; DAgger
   shows it. The baseline keeps the memory it builds from what it is shown (a chain's recorded trails, a
   state machine's phase), so its labels answer the learner's run, as the baseline would go on from there.

The demonstrations may come from a Minari dataset that ``agri dataset`` wrote instead of a live run::

    pretrain: {dataset: agri/GreenhouseNav-v2/harik-apf-gt-v0, epochs: 10}

Its episodes are read as step 1 would have recorded them: the dataset's env must be the training env (its id,
and its arguments up to what the baseline adds). Where those arguments change more than extra observation keys,
the training env replays each episode's recorded actions from its seed in lockstep, exactly as beside a live
baseline, and must agree on every reward and end. ``seed`` and ``episodes`` keep their meaning: the dataset's
episodes of seeds ``seed .. seed + episodes - 1`` are the demonstrations (the dataset must hold them all), and
DAgger's seeds follow; ``policy`` (the labeller of DAgger rounds) defaults to the dataset's and must be it. Cloned
from a dataset, the demonstrations (and so the weights) equal those of the same baseline driven live on the
same seeds.

A PettingZoo env (the robot chain) is cloned the same way into the parameter-shared policy: every agent's
decision is one sample, each agent's decisions one trajectory for the returns, and the baseline is the
multi-agent policy that commands every agent at once (``apoorva-chain``).

PPO then fine-tunes on the env's reward. The policy stays a learned one: what it may observe is the run's
observation, never the baseline's extra inputs (the baseline's privileges show only in the actions it
demonstrated, and the policy's registration says which baseline that was).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

import agri_envs
from agri_baselines import make_policy, policy_spec
from agri_training.core import datasets
from agri_training.learned.policy import ObservationReplay, observation_chain


@dataclasses.dataclass(frozen=True)
class PretrainSpec:
    """The ``pretrain`` block of a hyperparameter file.

    Attributes:
        policy: Registered baseline of the env whose actions are cloned (with ``dataset``: the dataset's policy,
            the default; DAgger rounds need it registered).
        episodes: Demonstration episodes, >= 1.
        epochs: Passes over the demonstrations, >= 1.
        seed: First demonstration seed (``seed .. seed + episodes - 1``), below 100000.
        learning_rate: Adam's step size.
        batch_size: Decisions per gradient step.
        dagger_rounds: DAgger rounds after the first fit (0: cloning alone).
        dagger_episodes: Episodes the policy drives in each round; round ``r`` (from 0) runs seeds
            ``seed + episodes + r * dagger_episodes ..``.
        dagger_epochs: Passes over all decisions after each round.
        dagger_noise: Standard deviation of Gaussian noise added to the policy's action while it drives a
            DAgger round (clipped to [-1, 1]): the rounds then also visit the states just off its own path. The
            labels stay the baseline's. 0: the mean action, as is.
        emphasize: Optional ``{action: i, below: x, weight: w}``: the decisions in which the baseline's action
            component ``i`` is below ``x`` count ``w`` times in the action loss. A rare, decisive action (a
            safety stop's step back: about 1 % of harik-apf-gt's decisions) is otherwise smoothed away by the
            mean-squared fit.
        dataset: Minari id of an ``agri dataset`` dataset to clone from instead of driving the baseline.
        fit_clipped: Where the baseline's action lies on a bound of the action space, a mean action past that
            bound costs nothing in the action loss: the env clips it to the same action. Without it such labels
            pull the mean back to the bound from both sides and about half the means fall short of it: cloned
            without it, ``dagger-greenhouse-coverage-route`` asked for its full speed in 44 % of its control
            periods of one greenhouse, where its teacher did in 90 %.
    """

    policy: str = ""
    episodes: int = 100
    epochs: int = 10
    seed: int = 50_000
    learning_rate: float = 1e-3
    batch_size: int = 256
    dagger_rounds: int = 0
    dagger_episodes: int = 50
    dagger_epochs: int = 10
    dagger_noise: float = 0.0
    emphasize: Mapping[str, float] | None = None
    dataset: str | None = None
    fit_clipped: bool = False

    def __post_init__(self) -> None:
        if not self.policy and not self.dataset:
            raise ValueError("pretrain: give policy (a baseline to drive) or dataset (a Minari id of its episodes)")
        if self.emphasize is not None:
            given = dict(self.emphasize)
            if sorted(given) != ["action", "below", "weight"]:
                raise ValueError(f"pretrain: emphasize needs exactly the keys action, below, weight; got {given}")
            if int(given["action"]) != given["action"] or int(given["action"]) < 0 or not float(given["weight"]) > 0:
                raise ValueError(f"pretrain: emphasize needs an action index >= 0 and a weight > 0; got {given}")
        if self.episodes < 1 or self.epochs < 1 or self.batch_size < 1:
            raise ValueError(f"pretrain: episodes, epochs and batch_size must be >= 1, got {self}")
        if not self.dagger_noise >= 0:
            raise ValueError(f"pretrain: dagger_noise must be >= 0, got {self.dagger_noise}")
        if self.dagger_rounds < 0 or self.dagger_episodes < 1 or self.dagger_epochs < 1:
            raise ValueError(f"pretrain: dagger_rounds must be >= 0, dagger_episodes and dagger_epochs >= 1: {self}")
        if not 0 <= self.seed or self.last_seed >= 100_000:
            raise ValueError(f"pretrain: seeds {self.seed}..{self.last_seed} must lie below 100000")

    def loss_weights(self, actions: np.ndarray) -> np.ndarray | None:
        """Each decision's weight in the action loss (``emphasize``), or None when all weigh the same.

        Raises:
            ValueError: When the action index lies outside the actions.
        """
        if self.emphasize is None:
            return None
        index = int(self.emphasize["action"])
        if index >= actions.shape[1]:
            raise ValueError(f"pretrain: emphasize action {index}, but the actions have {actions.shape[1]} components")
        rare = actions[:, index] < float(self.emphasize["below"])
        return np.where(rare, float(self.emphasize["weight"]), 1.0).astype(np.float32)

    @property
    def last_seed(self) -> int:
        """The last seed the demonstrations and every DAgger round run."""
        return self.seed + self.episodes + self.dagger_rounds * self.dagger_episodes - 1

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
        episodes: Episodes run (skipped ones included).
        skipped: Episodes left out because the baseline could not act in them (a planner that finds no plan
            raises ``ValueError``); their decisions are not recorded.
    """

    observations: Any
    actions: np.ndarray
    rewards: np.ndarray
    episode_ends: np.ndarray
    successes: int
    episodes: int
    skipped: int = 0


#: A learner acting: a batch of learner observations (wrapped, not normalised) -> its actions, one row each.
Learner = Callable[[Any], np.ndarray]


def _stack(frames: list[Any]) -> Any:
    if isinstance(frames[0], Mapping):
        return {k: np.stack([f[k] for f in frames]).astype(np.float32) for k in frames[0]}
    return np.stack(frames).astype(np.float32)


def _join(first: Demonstrations, second: Demonstrations) -> Demonstrations:
    """The decisions of both, first's before second's."""
    if isinstance(first.observations, Mapping):
        observations: Any = {k: np.concatenate([v, second.observations[k]]) for k, v in first.observations.items()}
    else:
        observations = np.concatenate([first.observations, second.observations])
    return Demonstrations(
        observations,
        np.concatenate([first.actions, second.actions]),
        np.concatenate([first.rewards, second.rewards]),
        np.concatenate([first.episode_ends, second.episode_ends]),
        first.successes + second.successes,
        first.episodes + second.episodes,
        first.skipped + second.skipped,
    )


class _Decisions:
    """The learner's decisions over demonstration episodes: what it sees, the label, the reward until the next.

    One bookkeeping for both sources of step 1 (a baseline driven live, a dataset's recorded episodes), so that
    the same episodes give the same demonstrations bit for bit whichever way they come.

    Args:
        learner_env: The training env (its observation keys; ``config``'s wrappers replay on them).
        config: The resolved training config (``wrappers``, ``action_repeat``).
    """

    def __init__(self, learner_env: Any, config: Mapping[str, Any]) -> None:
        space = learner_env.observation_space
        self.keys = list(space.spaces) if isinstance(space, gym.spaces.Dict) else None
        _, chain = observation_chain(learner_env, config.get("wrappers", []))
        self.replay = ObservationReplay(chain)
        self.repeat = int(config.get("action_repeat", 1))
        self.observations: list[Any] = []
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []
        self.ends: list[bool] = []

    def decide(self, step: int, shown: Any, action: Any) -> bool:
        """Record a decision at ``step`` (one every ``action_repeat`` steps): True when it is one.

        On the other steps the wrappers that read every scan see the observation (``SlamWaypoint``'s
        ``every_scan``), as they do where the weights act (:func:`~agri_training.learned.policy.decide_held`).
        """
        seen = {k: shown[k] for k in self.keys} if self.keys is not None else shown
        if step % self.repeat:
            self.replay.see(seen)
            return False
        self.observations.append(self.replay(seen, new_episode=step == 0))
        self.actions.append(np.clip(np.asarray(action, dtype=np.float32), -1.0, 1.0))
        self.rewards.append(0.0)
        self.ends.append(False)
        return True

    def paid(self, reward: SupportsFloat) -> None:
        """Add a step's reward to the current decision's."""
        self.rewards[-1] += float(reward)

    def end_episode(self) -> None:
        """The current decision ends its episode."""
        self.ends[-1] = True

    def drop_from(self, kept: int) -> None:
        """Forget the decisions from index ``kept`` on (an episode left out)."""
        del self.observations[kept:], self.actions[kept:], self.rewards[kept:], self.ends[kept:]

    def demonstrations(self, successes: int, episodes: int, skipped: int = 0) -> Demonstrations:
        """The decisions recorded, stacked."""
        return Demonstrations(
            _stack(self.observations),
            np.stack(self.actions),
            np.array(self.rewards),
            np.array(self.ends),
            successes,
            episodes,
            skipped,
        )


def _lockstep(own: Any, action: Any, ends: tuple[Any, ...], source: str, env_id: str, seed: int, step: int) -> Any:
    """Step the learner's own env beside the source's and return what it shows; it must agree on reward and ends.

    Raises:
        ValueError: When the source's arguments (``source`` names them) change the env's dynamics.
    """
    shown, own_reward, *own_ends, _ = own.step(action)
    if (own_reward, *own_ends) != ends:
        raise ValueError(
            f"pretrain: {source} change {env_id}'s dynamics (seed {seed}, step {step}: reward {ends[0]} against "
            f"the training env's {own_reward})"
        )
    return shown


def demonstrate(
    spec: PretrainSpec, config: Mapping[str, Any], seeds: Sequence[int] | None = None, learner: Learner | None = None
) -> Demonstrations:
    """Run the baseline on the training env and record the learner's decisions (step 1 of the module doc).

    Args:
        spec: The ``pretrain`` block.
        config: The resolved training config.
        seeds: Episode seeds; default ``spec.seed .. spec.seed + spec.episodes - 1``.
        learner: When given, the learner drives and the baseline only labels each decision (a DAgger round).

    Raises:
        ValueError: When the baseline drives another env, or its arguments change the training env's dynamics.
    """
    baseline = policy_spec(spec.policy)
    env_id = config["env_id"]
    if baseline.env_id != env_id:
        raise ValueError(f"pretrain: {spec.policy} drives {baseline.env_id}, not {env_id}")
    learner_kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
    seeds = range(spec.seed, spec.seed + spec.episodes) if seeds is None else seeds
    if agri_envs.is_parallel_id(env_id):
        for key, value in baseline.env_kwargs.items():
            if key in learner_kwargs and learner_kwargs[key] != value:
                raise ValueError(
                    f"pretrain: {spec.policy} needs {key}={value!r}, the training env has {learner_kwargs[key]!r}"
                )
        # One env serves baseline and learner (no observation wrappers), so the baseline may add no argument.
        extra = sorted(set(baseline.env_kwargs) - set(learner_kwargs))
        if extra:
            raise ValueError(
                f"pretrain: {spec.policy} needs {extra} set on {env_id}; add them to the training env_kwargs"
            )
        return _demonstrate_agents(spec, env_id, learner_kwargs, seeds, learner)
    learner_env = gym.make(env_id, **learner_kwargs)
    decisions = _Decisions(learner_env, config)
    env = gym.make(env_id, **{**learner_kwargs, **baseline.env_kwargs})
    # Where the baseline's arguments change more than extra observation keys (a true pose for the baseline,
    # not a scan only it reads), the learner's own env runs beside it in lockstep and the learner sees what
    # that env shows: a learner without localization can learn from a teacher on the true pose. An argument
    # of the baseline's that changes the dynamics is refused there (_lockstep), on the first step it shows.
    unwrapped: Any = learner_env.unwrapped
    own = learner_env if unwrapped.config.differences(baseline.env_kwargs) else None
    expert = make_policy(spec.policy, env)
    source = f"{spec.policy}'s arguments {baseline.env_kwargs}"
    successes = skipped = 0
    for seed in seeds:
        obs, info = env.reset(seed=int(seed))
        shown = own.reset(seed=int(seed))[0] if own is not None else obs
        step, done, kept = 0, False, len(decisions.actions)
        while not done:
            try:
                action, _ = expert.predict(obs, episode_start=np.array([step == 0]), deterministic=True)
            except ValueError:  # the baseline cannot act here (no plan): the episode is left out
                decisions.drop_from(kept)
                skipped += 1
                break
            # a decision of the learner: what it sees, what the baseline does
            if decisions.decide(step, shown, action) and learner is not None:
                # the learner drives, its action held for the action_repeat periods until its next decision
                driven = learner(_stack(decisions.observations[-1:]))[0]
            acted = action if learner is None else driven
            obs, reward, terminated, truncated, info = env.step(acted)
            shown = obs
            if own is not None:
                shown = _lockstep(own, acted, (reward, terminated, truncated), source, env_id, int(seed), step)
            decisions.paid(reward)
            step += 1
            done = terminated or truncated
        if done:
            decisions.end_episode()
            successes += int(bool(info.get("is_success", False)))
    env.close()
    learner_env.close()
    if not decisions.actions:
        raise ValueError(f"pretrain: {spec.policy} could not act in any of the {len(seeds)} episodes")
    return decisions.demonstrations(successes, len(seeds), skipped)


def demonstrate_dataset(spec: PretrainSpec, config: Mapping[str, Any]) -> tuple[PretrainSpec, Demonstrations]:
    """Step 1 from a dataset's episodes instead of a live baseline (see the module doc).

    Args:
        spec: The ``pretrain`` block, with ``dataset``.
        config: The resolved training config.

    Returns:
        The spec with the dataset's policy; the demonstrations of its episodes on seeds ``spec.seed ..``.

    Raises:
        ValueError: When the dataset is missing, lacks one of the seeds, ran another env or another policy than
            ``spec.policy``, or its arguments change the training env's dynamics.
    """
    assert spec.dataset is not None
    dataset = datasets.load(spec.dataset)
    described = datasets.describe(dataset)
    meta = dataset.storage.metadata[datasets.METADATA_KEY]
    if spec.policy and spec.policy != meta["policy"]:
        raise ValueError(f"pretrain: dataset {spec.dataset} was driven by {meta['policy']}, not {spec.policy}")
    spec = dataclasses.replace(spec, policy=str(meta["policy"]))
    seeds = range(spec.seed, spec.seed + spec.episodes)
    env_id = config["env_id"]
    if described.env_id != env_id:
        raise ValueError(f"pretrain: dataset {spec.dataset} ran {described.env_id}, not {env_id}")
    learner_kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
    recorded = described.make()
    learner_env = agri_envs.make(env_id, **learner_kwargs)
    # What the dataset's arguments change beyond extra observation keys (and the time limit, which gym.make holds).
    unwrapped: Any = learner_env.unwrapped
    changed = unwrapped.config.differences(recorded.unwrapped.config.to_dict())
    if not described.parallel and learner_env.spec.max_episode_steps != recorded.spec.max_episode_steps:
        changed.append("max_episode_steps")
    recorded.close()
    if described.parallel:
        learner_env.close()
        if changed:
            raise ValueError(f"pretrain: dataset {spec.dataset}'s {env_id} differs from the training env in {changed}")
        return spec, _dataset_agents(dataset, seeds)
    decisions = _Decisions(learner_env, config)
    own = learner_env if changed else None
    source = f"dataset {spec.dataset}'s arguments {dict(described.env_kwargs)}"
    successes = runs = 0
    for meta_ep, episode in datasets.episodes(dataset, seeds):
        seed = int(meta_ep["seed"])
        runs += 1

        def recorded_obs(t: int, ep: Any = episode) -> Any:
            if isinstance(ep.observations, Mapping):
                return {k: v[t] for k, v in ep.observations.items()}
            return ep.observations[t]

        shown = own.reset(seed=seed)[0] if own is not None else recorded_obs(0)
        for step, action in enumerate(episode.actions):
            decisions.decide(step, shown, action)  # a decision of the learner, as in demonstrate()
            reward = float(episode.rewards[step])
            if own is not None:
                ends = (reward, episode.terminations[step], episode.truncations[step])
                shown = _lockstep(own, action, ends, source, env_id, seed, step)
            else:
                shown = recorded_obs(step + 1)
            decisions.paid(reward)
        if len(episode.actions) and (episode.terminations[-1] or episode.truncations[-1]):
            decisions.end_episode()
            successes += int(bool(episode.infos["is_success"][-1]))
    learner_env.close()
    if not decisions.actions:
        raise ValueError(f"pretrain: dataset {spec.dataset} holds no steps")
    return spec, decisions.demonstrations(successes, runs)


def _dataset_agents(dataset: Any, seeds: Sequence[int]) -> Demonstrations:
    """:func:`demonstrate_dataset` on a PettingZoo env: every agent's episode one trajectory, as live."""
    observations, actions, rewards, ends = [], [], [], []
    successes, runs, first_agent = 0, set(), None
    for meta, episode in datasets.episodes(dataset, seeds):
        first_agent = first_agent or meta["agent"]
        runs.add(int(meta["run"]))
        steps = len(episode.actions)
        observations.append(np.asarray(episode.observations[:steps], dtype=np.float32))
        actions.append(np.clip(np.asarray(episode.actions, dtype=np.float32), -1.0, 1.0))
        rewards.append(np.asarray(episode.rewards, dtype=np.float64))
        agent_ends = np.zeros(steps, dtype=bool)
        agent_ends[-1] = True
        ends.append(agent_ends)
        if meta["agent"] == first_agent:  # the first agent's info speaks for the team
            successes += int(bool(episode.infos["is_success"][-1]))
    return Demonstrations(
        np.concatenate(observations),
        np.concatenate(actions),
        np.concatenate(rewards),
        np.concatenate(ends),
        successes,
        len(runs),
    )


def _demonstrate_agents(
    spec: PretrainSpec, env_id: str, env_kwargs: Mapping[str, Any], seeds: Sequence[int], learner: Learner | None
) -> Demonstrations:
    """:func:`demonstrate` on a PettingZoo env: one sample per agent and decision, agent by agent per episode.

    Raises:
        ValueError: When an agent leaves before its episode ends (parameter sharing needs every agent).
    """
    env = agri_envs.make(env_id, **env_kwargs)
    expert = make_policy(spec.policy, env)
    agents = list(env.possible_agents)
    observations, actions, rewards, ends = [], [], [], []
    successes = 0
    for seed in seeds:
        obs, infos = env.reset(seed=int(seed))
        seen: list[np.ndarray] = []
        advised: list[np.ndarray] = []
        paid: list[list[float]] = []
        while env.agents:
            if sorted(obs) != sorted(agents):
                raise ValueError("pretrain: every agent must stay until the episode ends")
            advice, _ = expert.predict(obs, episode_start=np.array([not seen]), deterministic=True)
            batch = np.stack([obs[a] for a in agents]).astype(np.float32)
            label = np.clip(np.stack([np.asarray(advice[a], dtype=np.float32) for a in agents]), -1.0, 1.0)
            acting = label if learner is None else learner(batch)
            obs, reward, _, _, infos = env.step({a: acting[k] for k, a in enumerate(agents)})
            seen.append(batch)
            advised.append(label)
            paid.append([float(reward[a]) for a in agents])
        steps = len(seen)
        # (agents, steps, ...): each agent's decisions one trajectory, its last one ending the episode.
        observations.append(np.swapaxes(np.stack(seen), 0, 1).reshape(len(agents) * steps, -1))
        actions.append(np.swapaxes(np.stack(advised), 0, 1).reshape(len(agents) * steps, -1))
        rewards.append(np.array(paid).T.ravel())
        episode_ends = np.zeros((len(agents), steps), dtype=bool)
        episode_ends[:, -1] = True
        ends.append(episode_ends.ravel())
        successes += int(bool(infos[agents[0]].get("is_success", False)))
    env.close()
    return Demonstrations(
        np.concatenate(observations),
        np.concatenate(actions),
        np.concatenate(rewards),
        np.concatenate(ends),
        successes,
        len(seeds),
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


def _mean_action(model: Any, venv: Any, noise: float = 0.0, rng: np.random.Generator | None = None) -> Learner:
    """The policy's mean action on a batch of learner observations (normalised as PPO will see them).

    With ``noise`` > 0, Gaussian noise of that standard deviation from ``rng`` is added, clipped to [-1, 1].
    """

    def act(batch: Any) -> np.ndarray:
        obs = venv.normalize_obs(batch) if venv is not None else batch
        actions, _ = model.predict(obs, deterministic=True)
        actions = np.asarray(actions, dtype=np.float32)
        if noise > 0:
            assert rng is not None
            actions = np.clip(actions + rng.normal(0.0, noise, actions.shape), -1.0, 1.0).astype(np.float32)
        return actions

    return act


def pretrain_from_baseline(model: Any, venv: Any, config: Mapping[str, Any]) -> dict[str, Any]:
    """Clone the declared baseline into ``model`` before it trains (see the module doc).

    Args:
        model: The SB3 on-policy model (PPO) about to learn.
        venv: Its ``VecNormalize`` env, or None when the run does not normalise.
        config: The resolved training config (its ``pretrain`` block).

    Returns:
        A summary for ``meta.json``: decisions, the baseline's success on its demonstrations, losses, and
        per DAgger round the policy's own success on the episodes it drove.
    """
    import torch

    spec = PretrainSpec.from_config(config["pretrain"])
    gamma = float(config["algo_kwargs"].get("gamma", 0.99))
    if spec.dataset:
        spec, demos = demonstrate_dataset(spec, config)
    else:
        demos = demonstrate(spec, config)
    baseline_success, first_skipped = demos.successes / demos.episodes, demos.skipped
    if venv is not None:
        _set_statistics(venv, demos, gamma)
    policy = model.policy
    optimizer = torch.optim.Adam(policy.parameters(), lr=spec.learning_rate)  # no loss term reaches log_std
    rng = np.random.default_rng(int(config["seed"]))
    weights = spec.loss_weights(demos.actions)
    clipped = spec.fit_clipped
    losses = [_fit(policy, optimizer, venv, demos, gamma, spec.epochs, spec.batch_size, rng, weights, clipped)]
    rounds = []
    for r in range(spec.dagger_rounds):
        first = spec.seed + spec.episodes + r * spec.dagger_episodes
        seeds = range(first, first + spec.dagger_episodes)
        driven = demonstrate(spec, config, seeds, learner=_mean_action(model, venv, spec.dagger_noise, rng))
        rounds.append(
            {
                "seeds": [seeds[0], seeds[-1]],
                "policy_success_rate": driven.successes / driven.episodes,
                "skipped": driven.skipped,
            }
        )
        demos = _join(demos, driven)
        weights = spec.loss_weights(demos.actions)
        losses.append(
            _fit(policy, optimizer, venv, demos, gamma, spec.dagger_epochs, spec.batch_size, rng, weights, clipped)
        )
    (first_action, first_value), _ = losses[0]  # the first batch of the first fit
    _, (last_action, last_value) = losses[-1]  # the last batch of the last fit
    return {
        "policy": spec.policy,
        **({"dataset": spec.dataset} if spec.dataset else {}),
        "episodes": spec.episodes,
        "seeds": [spec.seed, spec.seed + spec.episodes - 1],
        "baseline_success_rate": baseline_success,
        "baseline_skipped": first_skipped,
        "decisions": len(demos.actions),
        "epochs": spec.epochs,
        "action_mse_first_last": [first_action, last_action],
        "value_mse_first_last": [first_value, last_value],
        "dagger_rounds": rounds,
        **({} if weights is None else {"emphasized_share": float(np.mean(weights != 1.0))}),
    }


def action_loss_of(mean: Any, target: Any, weights: Any = None, bounds: tuple[Any, Any] | None = None) -> Any:
    """The mean squared error of ``mean`` against ``target`` (torch tensors, one row per decision).

    With ``weights`` (one per row) a row of weight w counts as w copies of it would. With ``bounds`` (the action
    space's ``low, high``, one per component) a mean past the bound its target lies on counts as that bound: the
    env would clip it to the target (``PretrainSpec.fit_clipped``).
    """
    import torch

    if bounds is not None:
        low, high = bounds
        mean = torch.where(target >= high, torch.minimum(mean, high), mean)
        mean = torch.where(target <= low, torch.maximum(mean, low), mean)
    squared = (mean - target) ** 2
    if weights is None:
        return torch.mean(squared)
    return torch.sum(weights[:, None] * squared) / (torch.sum(weights) * squared.shape[1])


def _fit(
    policy: Any,
    optimizer: Any,
    venv: Any,
    demos: Demonstrations,
    gamma: float,
    epochs: int,
    batch_size: int,
    rng: np.random.Generator,
    loss_weights: np.ndarray | None = None,
    clipped: bool = False,
) -> tuple[tuple[float, float], tuple[float, float]]:
    """``epochs`` passes of step 3 over ``demos``; the (action, value) losses of the first and last batch.

    ``loss_weights`` (one per decision, :meth:`PretrainSpec.loss_weights`) weigh the action loss; ``clipped``
    fits the action the env executes where the label lies on a bound (:attr:`PretrainSpec.fit_clipped`).
    """
    import torch

    obs, returns = _targets(venv, demos, gamma)
    n = len(demos.actions)
    actions = torch.as_tensor(demos.actions)
    weights = None if loss_weights is None else torch.as_tensor(loss_weights)
    targets = torch.as_tensor(returns, dtype=torch.float32)
    space = policy.action_space
    bounds = (torch.as_tensor(space.low), torch.as_tensor(space.high)) if clipped else None
    first = last = None
    for _ in range(epochs):
        order = rng.permutation(n)
        for start in range(0, n, batch_size):
            batch = order[start : start + batch_size]
            x = {k: torch.as_tensor(v[batch]) for k, v in obs.items()} if isinstance(obs, dict) else obs[batch]
            x = torch.as_tensor(x) if not isinstance(x, dict) else x
            mean = policy.get_distribution(x).distribution.mean
            action_loss = action_loss_of(mean, actions[batch], None if weights is None else weights[batch], bounds)
            value_loss = torch.mean((policy.predict_values(x).flatten() - targets[batch]) ** 2)
            loss = action_loss + 0.5 * value_loss
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            last = (action_loss.item(), value_loss.item())
            first = first or last
    assert first is not None and last is not None
    return first, last
