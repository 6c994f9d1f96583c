"""``agri train``: stable-baselines3 training with rl-zoo3-style YAML hyperparameters and weights-only runs.

Hyperparameters live in ``agri_training/hyperparams/<algo>.yml``, keyed by env id with a ``default``
block; an env block may hold ``scenarios: {name: {...}}`` for presets. Blocks merge
``default`` <- env <- scenario (nested mappings key by key). Every value is plain YAML: no string is
evaluated. The keys:

| key | meaning |
|---|---|
| ``n_timesteps`` | training steps when ``--timesteps`` is not given (0 with ``pretrain``: imitation only) |
| ``policy`` | SB3 policy name (``MlpPolicy``, ``MultiInputPolicy``) |
| ``n_envs`` | parallel envs |
| ``vec_env`` | ``dummy`` (one process), ``subproc`` (one process per env) or ``vector`` (one process: the |
| | env's batched form where it registers one, else its single envs; see :func:`make_vector_train_env`) |
| ``env_kwargs`` | ``gym.make`` arguments (after the scenario's) |
| ``train_env_kwargs`` | ``gym.make`` arguments of the training envs only, over ``env_kwargs`` |
| ``eval_env_kwargs`` | ``gym.make`` arguments of the periodic evaluation only, over ``env_kwargs`` |
| ``wrappers`` | observation wrappers by name, innermost first (see ``learned.WRAPPERS``) |
| ``action_repeat`` | env steps per action (1: every step); evaluation holds actions the same way |
| ``train_wrappers`` | training-only curricula by name, inside ``wrappers`` (see ``curricula.TRAIN_WRAPPERS``) |
| ``pretrain`` | PPO only: cloning a baseline (and DAgger) before the first rollout (see ``learned.pretrain``) |
| ``normalize`` | ``false`` or ``VecNormalize`` arguments (``norm_obs``, ``norm_reward``, ``clip_obs``, ...) |
| ``algo_kwargs`` | the algorithm's arguments (``learning_rate`` may be ``lin_3e-4``: linear decay) |
| ``policy_kwargs`` | ``net_arch``, ``activation_fn`` (a name), ... |
| ``her`` | ``HerReplayBuffer`` arguments, used with ``--her`` |
| ``eval_freq``, ``eval_episodes``, ``eval_seed`` | periodic evaluation every N steps on seeds S.. S+n-1 |
| ``checkpoint_freq`` | weights-only checkpoint every N steps (0: none) |
| ``torch_threads`` | torch CPU threads (1 beside env workers) |
| ``update_threads`` | torch CPU threads of the gradient updates, at most (null: ``torch_threads``); PPO's |
| | rollout and updates alternate, so each update uses up to this many of the cores idle when it starts |
| ``safety_layer`` | a fixed rule between the network and the robot wherever the weights act (evaluation, |
| | validation, leaderboard; not PPO's rollouts), its interventions counted (``learned.safety``); null: none |

A run directory holds ``policy.pt`` (the final weights: the acting layers' ``state_dict``), ``normalize.json`` (the
observation statistics), ``config.yaml`` (the resolved config), ``meta.json`` (exact command, package
versions, git commit, wall time, machine load), ``curve.csv`` (the learning curve of the periodic
evaluation), ``best/`` (the weights of the best periodic evaluation), ``checkpoints/step_N/`` and ``tb/``
(TensorBoard). Training and its evaluation use seeds below :data:`HELD_OUT_SEED` (held-out suites start there).
"""

from __future__ import annotations

import copy
import csv
import dataclasses
import functools
import json
import os
import platform
import shlex
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml
from gymnasium.vector import AutoresetMode

import agri_envs
from agri_envs.scenarios import scenario as get_scenario
from agri_training.core.documents import git_commit
from agri_training.core.yaml_values import load_yaml
from agri_training.evaluation.episode import run_episode
from agri_training.learned.curricula import (
    PARALLEL_TRAIN_WRAPPERS,
    TRAIN_WRAPPERS,
    VECTOR_TRAIN_WRAPPERS,
    apply_parallel_train_wrappers,
    apply_train_wrappers,
    apply_vector_train_wrappers,
    check_wrapper_names,
)
from agri_training.learned.inference import PolicyNetwork, acting_state
from agri_training.learned.parameter_sharing import make_shared_vec_env, predict_shared
from agri_training.learned.policy import (
    ALGORITHMS,
    CONFIG_FILE,
    NORMALIZE_FILE,
    WEIGHTS_FILE,
    WRAPPERS,
    ActionRepeat,
    HeldActions,
    ObservationReplay,
    ObsNormalization,
    algorithm_class,
    apply_wrappers,
    decide_held,
    guarded,
    observation_chain,
    resolve_algo_kwargs,
    resolve_policy_kwargs,
)
from agri_training.learned.pretrain import PretrainSpec, pretrain_from_baseline
from agri_training.learned.safety import check_safety_layer, make_safety_layer
from agri_training.learned.vector import VECTOR_WRAPPERS, apply_vector_wrappers, make_sync_vector_env

HYPERPARAMS_DIR = Path(__file__).parent / "hyperparams"
#: Seeds from here on are reserved for held-out evaluation suites; training never uses them.
HELD_OUT_SEED = 100_000
HYPERPARAM_KEYS = (
    "n_timesteps",
    "policy",
    "n_envs",
    "vec_env",
    "env_kwargs",
    "train_env_kwargs",
    "eval_env_kwargs",
    "wrappers",
    "train_wrappers",
    "action_repeat",
    "pretrain",
    "normalize",
    "algo_kwargs",
    "policy_kwargs",
    "her",
    "eval_freq",
    "eval_episodes",
    "eval_seed",
    "checkpoint_freq",
    "torch_threads",
    "update_threads",
    "safety_layer",
    "scenarios",
)
VEC_ENVS = ("dummy", "subproc", "vector")
_PACKAGES = ("agri-envs", "gymnasium", "stable-baselines3", "sb3-contrib", "torch", "numpy", "pymunk", "pybullet")


@dataclasses.dataclass(frozen=True)
class TrainRequest:
    """What to train.

    Attributes:
        env_id: Registered env id.
        algo: ``ppo``, ``sac``, ``td3`` or ``tqc``.
        out: Run directory to create (must not hold a run already).
        seed: Training seed; env ``i`` of ``n_envs`` resets from ``seed + i``. In [0, 100000 - n_envs).
        timesteps: Training steps (None: the YAML's ``n_timesteps``).
        scenario: Name of an env-argument preset (``agri list``), or None.
        her: Use ``HerReplayBuffer`` (off-policy algorithms on goal-conditioned Dict envs).
        overrides: Hyperparameters that replace the YAML's (same keys, merged like a block).
        hyperparams_file: YAML to read instead of ``hyperparams/<algo>.yml``.
        progress: Show the progress bar.
    """

    env_id: str
    algo: str
    out: Path
    seed: int = 0
    timesteps: int | None = None
    scenario: str | None = None
    her: bool = False
    overrides: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    hyperparams_file: Path | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        if self.algo not in ALGORITHMS:
            raise ValueError(f"algo must be one of {', '.join(ALGORITHMS)}, got {self.algo!r}")
        if not 0 <= self.seed < HELD_OUT_SEED:
            raise ValueError(f"seed must be in [0, {HELD_OUT_SEED}) (held-out suites start at {HELD_OUT_SEED})")
        if self.timesteps is not None and self.timesteps < 0:
            raise ValueError(f"timesteps must be >= 0 (0: imitation only, with a pretrain block), got {self.timesteps}")
        if self.her and self.algo == "ppo":
            raise ValueError("--her needs an off-policy algorithm (sac, td3, tqc), not ppo")


def _merge(base: dict[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = _merge(dict(out[key]), value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _check_keys(block: Mapping[str, Any], where: str) -> None:
    unknown = sorted(set(block) - set(HYPERPARAM_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown hyperparameter keys {unknown}; valid: {', '.join(HYPERPARAM_KEYS)}")


def load_hyperparams(
    env_id: str,
    algo: str,
    scenario: str | None = None,
    overrides: Mapping[str, Any] | None = None,
    path: Path | None = None,
) -> dict[str, Any]:
    """The resolved hyperparameters: ``default`` <- env block <- its scenario block <- overrides.

    Raises:
        ValueError: For unknown keys, or a file without a ``default`` block.
    """
    path = path or HYPERPARAMS_DIR / f"{algo}.yml"
    data = load_yaml(path.read_text()) or {}
    if "default" not in data:
        raise ValueError(f"{path} needs a 'default' block")
    for key, block in data.items():
        _check_keys(block, f"{path.name}[{key}]")
    hp = _merge({}, data["default"])
    env_block = dict(data.get(env_id, {}))
    scenarios = env_block.pop("scenarios", {}) or {}
    hp = _merge(hp, env_block)
    if scenario is not None and scenario in scenarios:
        _check_keys(scenarios[scenario], f"{path.name}[{env_id}].scenarios[{scenario}]")
        hp = _merge(hp, scenarios[scenario])
    if overrides:
        _check_keys(overrides, "overrides")
        hp = _merge(hp, overrides)
    hp.pop("scenarios", None)
    hp["hyperparams_source"] = f"{path.name}: default <- {env_id if env_id in data else '(no env block)'}" + (
        f" <- scenarios[{scenario}]" if scenario is not None and scenario in scenarios else ""
    )
    return hp


def resolve_config(request: TrainRequest) -> dict[str, Any]:
    """The full, resolved training config saved as ``config.yaml`` (and read back to load the policy).

    Raises:
        ValueError: For an env id that is not the package's (the message lists the known ones), bad
            hyperparameters, or a combination the env does not take.
    """
    agri_envs.env_version(request.env_id)  # a misspelled id fails here, before anything is written
    hp = load_hyperparams(request.env_id, request.algo, request.scenario, request.overrides, request.hyperparams_file)
    env_kwargs: dict[str, Any] = {}
    if request.scenario:
        env_kwargs.update(get_scenario(request.env_id, request.scenario).env_kwargs)
    env_kwargs.update(hp.get("env_kwargs", {}) or {})
    n_envs = int(hp.get("n_envs", 1))
    if request.seed + n_envs > HELD_OUT_SEED:
        raise ValueError(f"seed + n_envs must stay below {HELD_OUT_SEED}")
    eval_seed = int(hp.get("eval_seed", 10_000))
    eval_episodes = int(hp.get("eval_episodes", 10))
    if not 0 <= eval_seed or eval_seed + eval_episodes > HELD_OUT_SEED:
        raise ValueError(
            f"eval seeds must lie in [0, {HELD_OUT_SEED}), got {eval_seed}..{eval_seed + eval_episodes - 1}"
        )
    vec_env = hp.get("vec_env", "dummy")
    if vec_env not in VEC_ENVS:
        raise ValueError(f"vec_env must be one of {', '.join(VEC_ENVS)}, got {vec_env!r}")
    torch_threads = int(hp.get("torch_threads", 1))
    update_threads = int(hp["update_threads"]) if hp.get("update_threads") is not None else torch_threads
    if torch_threads < 1 or update_threads < 1:
        raise ValueError(f"torch_threads and update_threads must be >= 1, got {torch_threads} and {update_threads}")
    safety_layer = hp.get("safety_layer")
    check_safety_layer(safety_layer, request.env_id)
    algo_kwargs = dict(hp.get("algo_kwargs", {}) or {})
    her = dict(hp.get("her", {}) or {}) if request.her else None
    if vec_env == "vector":  # refused here, before anything is written
        forms = (("wrappers", WRAPPERS, VECTOR_WRAPPERS), ("train_wrappers", TRAIN_WRAPPERS, VECTOR_TRAIN_WRAPPERS))
        for key, single, vector in forms:
            for item in hp.get(key, []) or []:
                name = item if isinstance(item, str) else next(iter(item), None)
                if name in single and name not in vector:
                    raise ValueError(f"{key}: {name} has no vector form; train with vec_env: dummy or subproc")
        repeat = int(hp.get("action_repeat", 1))
        single_agent = not agri_envs.is_parallel_id(request.env_id)
        if repeat > 1 and single_agent and not batched_form_holds_actions(request.env_id):
            raise ValueError(
                f"{request.env_id}: action_repeat {repeat} on vec_env: vector needs the batched form to hold each "
                "action itself (a frame_skip argument), and this env has none; train with vec_env: dummy or subproc"
            )
    timesteps = int(request.timesteps if request.timesteps is not None else hp.get("n_timesteps", 100_000))
    if int(hp.get("action_repeat", 1)) > 1 and timesteps > 0:
        for item in hp.get("wrappers", []) or []:
            if isinstance(item, dict) and (item.get("SlamWaypoint") or {}).get("every_scan"):
                raise ValueError(
                    "SlamWaypoint every_scan with action_repeat > 1 needs an imitation-only run (n_timesteps 0): "
                    "PPO's rollouts hold actions inside the env (ActionRepeat), so its SLAM would see one scan per "
                    "decision there and every scan wherever the weights act"
                )
    if timesteps < 0 or (timesteps < 1 and not hp.get("pretrain")):
        raise ValueError(f"timesteps must be >= 1, or 0 with a pretrain block (imitation only), got {timesteps}")
    if hp.get("pretrain"):
        PretrainSpec.from_config(hp["pretrain"])  # refused here, before anything is written
        if request.algo != "ppo" or request.her:
            raise ValueError("pretrain clones a baseline into a PPO policy: --algo ppo, without --her")
    if agri_envs.is_parallel_id(request.env_id):  # one parameter-shared policy for every agent (see parameter_sharing)
        if request.algo != "ppo" or request.her:
            raise ValueError(f"{request.env_id} trains a parameter-shared PPO: --algo ppo, without --her")
        if hp.get("wrappers"):
            raise ValueError(f"{request.env_id}: wrappers apply to Gymnasium envs only; leave 'wrappers' empty")
        if hp.get("eval_env_kwargs"):  # the periodic evaluation of a parallel env runs env_kwargs alone
            raise ValueError(
                f"{request.env_id}: eval_env_kwargs apply to Gymnasium envs only; leave 'eval_env_kwargs' empty"
            )
        kind = f"{request.env_id}: training wrapper"
        check_wrapper_names(hp.get("train_wrappers") or [], PARALLEL_TRAIN_WRAPPERS, kind)
        if int(hp.get("action_repeat", 1)) != 1:
            raise ValueError(f"{request.env_id}: action_repeat applies to Gymnasium envs only; leave it at 1")
        if vec_env == "vector":
            raise ValueError(f"{request.env_id}: vec_env 'vector' applies to Gymnasium envs only; use dummy")
    return {
        "env_id": request.env_id,
        "scenario": request.scenario,
        "env_kwargs": env_kwargs,
        "train_env_kwargs": dict(hp.get("train_env_kwargs", {}) or {}),
        "eval_env_kwargs": dict(hp.get("eval_env_kwargs", {}) or {}),
        "algo": request.algo,
        "her": her,
        "seed": request.seed,
        "timesteps": timesteps,
        "policy": hp.get("policy", "MultiInputPolicy" if request.her else "MlpPolicy"),
        "n_envs": n_envs,
        "vec_env": vec_env,
        "wrappers": list(hp.get("wrappers", []) or []),
        "train_wrappers": list(hp.get("train_wrappers", []) or []),
        "action_repeat": int(hp.get("action_repeat", 1)),
        "pretrain": dict(hp["pretrain"]) if hp.get("pretrain") else None,
        "normalize": dict(hp["normalize"]) if hp.get("normalize") else None,
        "algo_kwargs": algo_kwargs,
        "policy_kwargs": dict(hp.get("policy_kwargs", {}) or {}),
        "eval_freq": int(hp.get("eval_freq", 50_000)),
        "eval_episodes": eval_episodes,
        "eval_seed": eval_seed,
        "checkpoint_freq": int(hp.get("checkpoint_freq", 0)),
        "torch_threads": torch_threads,
        "update_threads": update_threads,
        "safety_layer": safety_layer,
        "hyperparams_source": hp["hyperparams_source"],
        # Labelled like the baselines: a policy fed the ground-truth pose uses what a real robot lacks.
        "privileged": env_kwargs.get("localization") == "ground_truth",
    }


def _env_factory(config: Mapping[str, Any], rank: int) -> Callable[[], gym.Env[Any, Any]]:
    env_id, wrappers = config["env_id"], list(config["wrappers"])
    env_kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
    curricula = list(config.get("train_wrappers", []))
    repeat = int(config.get("action_repeat", 1))

    def make() -> gym.Env[Any, Any]:
        from stable_baselines3.common.monitor import Monitor

        env = apply_train_wrappers(make_repeating(env_id, env_kwargs, repeat), curricula)
        return Monitor(apply_wrappers(env, wrappers), info_keywords=("is_success",))

    return make


def check_same_spaces(config: Mapping[str, Any]) -> None:
    """Refuse ``train_env_kwargs`` or ``eval_env_kwargs`` that give their env other spaces than ``env_kwargs``'s.

    Raises:
        ValueError: When the observation or action spaces differ.
    """
    env_id = config["env_id"]

    def spaces(env: Any) -> tuple[Any, Any]:
        if agri_envs.is_parallel_env(env):
            agent = env.possible_agents[0]
            return env.observation_space(agent), env.action_space(agent)
        return env.observation_space, env.action_space

    evaluation = agri_envs.make(env_id, **config["env_kwargs"])
    reference = spaces(evaluation)
    evaluation.close()
    for key in ("train_env_kwargs", "eval_env_kwargs"):
        if not config.get(key):
            continue
        other = agri_envs.make(env_id, **{**config["env_kwargs"], **config[key]})
        same = spaces(other) == reference
        other.close()
        if not same:
            raise ValueError(
                f"{key} {config[key]} change the env's spaces; the policy must act in the evaluation env "
                "(env_kwargs) too"
            )


def make_eval_env(config: Mapping[str, Any]) -> Any:
    """The periodic evaluation's env: ``env_kwargs`` and ``eval_env_kwargs`` over them (multi-agent: the first)."""
    if agri_envs.is_parallel_id(config["env_id"]):
        return agri_envs.make(config["env_id"], **config["env_kwargs"])
    return gym.make(config["env_id"], **{**config["env_kwargs"], **(config.get("eval_env_kwargs") or {})})


def make_repeating(env_id: str, env_kwargs: Mapping[str, Any], repeat: int) -> gym.Env[Any, Any]:
    """The env stepping ``repeat`` periods per action: its own ``frame_skip`` if it has one, else :class:`ActionRepeat`.

    An env with ``frame_skip`` (GreenhouseNav) skips the observations of the held periods, which nobody
    reads; :class:`ActionRepeat` would have the env make each one. Either way a step sums the periods'
    rewards and ends at the period that ends the episode.

    Raises:
        ValueError: When ``env_kwargs`` sets ``frame_skip`` itself (``action_repeat`` is the one setting).
    """
    if repeat <= 1:
        return gym.make(env_id, **env_kwargs)
    if "frame_skip" in env_kwargs:
        raise ValueError("set action_repeat, not env_kwargs.frame_skip: evaluation holds actions by action_repeat")
    env = gym.make(env_id, **env_kwargs)
    if has_frame_skip(env):
        env.close()
        return gym.make(env_id, **env_kwargs, frame_skip=repeat)
    return ActionRepeat(env, repeat)


def has_frame_skip(env: gym.Env[Any, Any]) -> bool:
    """Whether the env takes a ``frame_skip`` argument (its own way to hold an action for several periods)."""
    return "frame_skip" in getattr(getattr(env.unwrapped, "config", None), "__dataclass_fields__", {})


def batched_form_holds_actions(env_id: str) -> bool:
    """Whether ``vec_env: vector`` can hold actions for ``action_repeat`` periods on ``env_id``.

    It can where the env has no batched form (the single envs repeat actions themselves) or where the env takes
    ``frame_skip``, which its batched form then implements (GreenhouseNav); GreenhouseCoverage's has none.
    """
    if gym.spec(env_id).vector_entry_point is None:
        return True
    env = gym.make(env_id)
    try:
        return has_frame_skip(env)
    finally:
        env.close()


def make_vector_train_env(config: Mapping[str, Any], batched: bool = True) -> Any:
    """The training envs as one Gymnasium vector env in the adapter's contract, wrapped as the config declares.

    The env's own batched form (``gym.make_vec`` through its ``vector_entry_point``, ``DISABLED`` autoreset,
    ``frame_skip`` for ``action_repeat``) where it registers one and ``batched`` is true; else its single envs
    (:func:`make_repeating`) in :func:`~agri_training.learned.vector.make_sync_vector_env`. Then the vector
    forms of the curricula and of the observation wrappers, innermost first, as around each single env.

    Raises:
        ValueError: When ``env_kwargs`` sets ``frame_skip`` (``action_repeat`` is the one setting).
    """
    env_id, n_envs, repeat = config["env_id"], int(config["n_envs"]), int(config.get("action_repeat", 1))
    env_kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
    if batched and gym.spec(env_id).vector_entry_point is not None:
        if "frame_skip" in env_kwargs:
            raise ValueError("set action_repeat, not env_kwargs.frame_skip: evaluation holds actions by action_repeat")
        kwargs: dict[str, Any] = {**env_kwargs, "autoreset_mode": AutoresetMode.DISABLED}
        if repeat > 1:
            kwargs["frame_skip"] = repeat
        venv = gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point", **kwargs)
    else:
        venv = make_sync_vector_env([functools.partial(make_repeating, env_id, env_kwargs, repeat)] * n_envs)
    venv = apply_vector_train_wrappers(venv, list(config.get("train_wrappers", [])))
    return apply_vector_wrappers(venv, list(config["wrappers"]))


def make_vec_env(config: Mapping[str, Any]) -> Any:
    """The training VecEnv: ``n_envs`` copies (Dummy, Subproc or one vector env), then ``VecNormalize`` if declared.

    ``vec_env: vector`` drives :func:`make_vector_train_env` through
    :class:`~agri_training.learned.vec_env.VectorVecEnv`, with ``VecMonitor`` for the episode statistics (the
    other two wrap each env in ``Monitor``). A multi-agent env (the robot chain) becomes one slot per agent
    of ``n_envs`` copies, all in this process (:func:`agri_training.parameter_sharing.make_shared_vec_env`),
    each copy in its declared training wrappers (``train_wrappers``), with ``VecMonitor``.
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor, VecNormalize

    from agri_training.learned.vec_env import VectorVecEnv

    venv: Any
    if agri_envs.is_parallel_id(config["env_id"]):
        env_id = config["env_id"]
        env_kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
        curricula = list(config.get("train_wrappers", []))
        venv = make_shared_vec_env(
            lambda: apply_parallel_train_wrappers(agri_envs.make(env_id, **env_kwargs), curricula), config["n_envs"]
        )
        venv = VecMonitor(venv, info_keywords=("is_success",))
    elif config["vec_env"] == "vector":
        venv = VecMonitor(VectorVecEnv(make_vector_train_env(config)), info_keywords=("is_success",))
    else:
        fns = [_env_factory(config, i) for i in range(config["n_envs"])]
        venv = SubprocVecEnv(fns, start_method="forkserver") if config["vec_env"] == "subproc" else DummyVecEnv(fns)
    venv.seed(config["seed"])
    if config["normalize"]:
        norm = dict(config["normalize"])
        if "gamma" not in norm and "gamma" in config["algo_kwargs"]:
            norm["gamma"] = config["algo_kwargs"]["gamma"]
        venv = VecNormalize(venv, **norm)
    return venv


def idle_cores(loadavg: Path = Path("/proc/loadavg")) -> int:
    """This process's cores that nothing else runs on now: its cores less the other runnable threads, at least 1.

    Reads the kernel's count of runnable threads (Linux's ``/proc/loadavg``; the caller is one of them);
    where that is not available, all of the process's cores.
    """
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    try:
        runnable = int(loadavg.read_text().split()[3].split("/")[0])
    except (OSError, ValueError, IndexError):
        return cores
    return max(1, cores - (runnable - 1))


def with_update_threads(cls: Any, threads: int, idle: Callable[[], int] = idle_cores) -> Any:
    """``cls`` (an SB3 algorithm) whose gradient updates (``train``) run on up to ``threads`` torch threads.

    The rollout keeps the threads set before (a batch of a few dozen observations gains nothing from more);
    the updates, which alternate with it, use the cores it leaves idle: each update takes as many threads as
    cores are idle when it starts (``idle()``), at most ``threads``. A thread more than the free cores does
    not help, it hurts: its peers wait for it at every parallel region while the OS runs another process on
    its core (``benchmarks/bench_update_threads.py``). The count goes to the logger as ``train/update_threads``.
    """
    import torch

    class UpdateThreads(cls):  # type: ignore[misc,valid-type]
        def train(self, *args: Any, **kwargs: Any) -> Any:
            before = torch.get_num_threads()
            now = max(1, min(threads, idle()))
            torch.set_num_threads(now)
            self.logger.record("train/update_threads", now)
            try:
                return super().train(*args, **kwargs)
            finally:
                torch.set_num_threads(before)

    UpdateThreads.__name__ = UpdateThreads.__qualname__ = cls.__name__
    return UpdateThreads


class _LivePolicy:
    """The policy being trained, driving a raw env through the training wrappers and current statistics.

    It acts through the same CPU-independent forward pass as a loaded policy (:meth:`refresh` exports the
    current weights), so a periodic evaluation scores what ``agri evaluate`` will score on the saved weights.
    """

    def __init__(self, model: Any, env: Any, config: Mapping[str, Any]) -> None:
        self.model = model
        self.config = config
        self.multiagent = agri_envs.is_parallel_env(env)
        self.replay = ObservationReplay([] if self.multiagent else observation_chain(env, config["wrappers"])[1])
        self._hold = HeldActions(config["action_repeat"])
        self.safety = make_safety_layer(config.get("safety_layer"), env, config["env_id"])
        self.network: PolicyNetwork | None = None

    def refresh(self, normalization: ObsNormalization | None) -> None:
        """Act with the model's current weights and the training's current observation statistics."""
        self.network = PolicyNetwork.from_model(self.model, self.config["algo"], self.config.get("policy_kwargs", {}))
        self.replay.normalization = normalization

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[Any, Any]:
        if self.multiagent:  # per-agent dicts in and out, one batched pass of the shared network
            return predict_shared(self.network, observation, self.replay, deterministic), state
        action, state = decide_held(
            self._hold, self.replay, self.network, observation, state, episode_start, deterministic
        )
        return guarded(self.safety, observation, action, episode_start), state

    def episode_metrics(self, index: int = 0) -> dict[str, float]:
        """The safety layer's counts of the episode (none without a layer)."""
        return {} if self.safety is None else self.safety.episode_metrics()


def save_weights(model: Any, folder: Path) -> None:
    """Write the policy's acting layers (tensors only) and the observation statistics into ``folder``.

    The value network or critics stay out (:func:`~agri_training.learned.inference.acting_state`): nothing reads
    them back, and they are half of a PPO policy's bytes and most of a SAC policy's.
    """
    import torch

    folder.mkdir(parents=True, exist_ok=True)
    full = model.policy.state_dict()
    state = {k: v.detach().cpu().clone() for k, v in acting_state(full, type(model).__name__.lower()).items()}
    torch.save(state, folder / WEIGHTS_FILE)
    venv = model.get_vec_normalize_env()
    stats = ObsNormalization.from_vec_normalize(venv) if venv is not None else None
    if stats is not None:
        (folder / NORMALIZE_FILE).write_text(json.dumps(stats.to_json()))


def _make_callback(
    config: Mapping[str, Any], run_dir: Path, progress: bool, on_eval: Callable[[dict[str, Any]], None] | None = None
) -> Any:
    from stable_baselines3.common.callbacks import BaseCallback

    class TrainMonitor(BaseCallback):  # type: ignore[misc]
        """Periodic evaluation on fixed seeds, checkpoints, best weights, curve CSV and the progress bar."""

        def __init__(self) -> None:
            super().__init__()
            self.t0 = time.perf_counter()
            self.next_eval = 0
            self.next_ckpt = config["checkpoint_freq"] or -1
            self.best: tuple[float, float] | None = None
            self.rows: list[dict[str, Any]] = []
            self.bar: Any = None
            self.eval_env: Any = None
            self.live: _LivePolicy | None = None

        def _on_training_start(self) -> None:
            self.eval_env = make_eval_env(config)
            self.live = _LivePolicy(self.model, self.eval_env, config)
            if progress:
                from tqdm import tqdm

                self.bar = tqdm(  # disable=None: no bar when stderr is not a terminal (logs)
                    total=config.get("timesteps_planned", config["timesteps"]),
                    unit="step",
                    desc="agri train",
                    file=sys.stderr,
                    disable=None,
                )

        def _on_step(self) -> bool:
            n = self.num_timesteps
            if self.bar is not None:
                self.bar.update(n - self.bar.n)
            if n >= self.next_eval:
                self.evaluate()
                self.next_eval = n + config["eval_freq"]
            if self.next_ckpt > 0 and n >= self.next_ckpt:
                save_weights(self.model, run_dir / "checkpoints" / f"step_{n}")
                self.next_ckpt = n + config["checkpoint_freq"]
            return True

        def _on_training_end(self) -> None:
            self.evaluate()
            if self.bar is not None:
                self.bar.close()
            if self.eval_env is not None:
                self.eval_env.close()

        def evaluate(self) -> None:
            assert self.live is not None and self.eval_env is not None
            if self.rows and self.rows[-1]["timesteps"] == self.num_timesteps:
                return
            venv = self.model.get_vec_normalize_env()
            self.live.refresh(ObsNormalization.from_vec_normalize(venv) if venv is not None else None)
            records = [
                run_episode(self.eval_env, self.live, config["eval_seed"] + i, None)["record"]
                for i in range(config["eval_episodes"])
            ]
            success = float(np.mean([r["is_success"] for r in records]))
            row = {
                "timesteps": self.num_timesteps,
                "wall_time_s": round(time.perf_counter() - self.t0, 1),
                "success_rate": success,
                "mean_return": float(np.mean([r["return"] for r in records])),
                "mean_length": float(np.mean([r["steps"] for r in records])),
            }
            if "collision" in records[0]:
                row["collision_rate"] = float(np.mean([bool(r["collision"]) for r in records]))
            if records[0].get("min_clearance") is not None:
                row["mean_min_clearance"] = float(np.mean([r["min_clearance"] for r in records]))
            if records[0].get("coverage") is not None:  # the coverage mission's progress, even without success
                row["mean_coverage"] = float(np.mean([r["coverage"] for r in records]))
            self.rows.append(row)
            for key, value in row.items():
                if key != "timesteps":
                    self.logger.record(f"eval/{key}", value)
            score = (success, row["mean_return"])
            if self.best is None or score > self.best:
                self.best = score
                save_weights(self.model, run_dir / "best")
                (run_dir / "best" / "eval.json").write_text(json.dumps(row, indent=1))
            self.write_curve()
            if on_eval is not None:
                on_eval(dict(row))
            if self.bar is not None:
                self.bar.set_postfix(success=f"{success:.0%}", ret=f"{row['mean_return']:.1f}")
            else:
                print(f"[{self.num_timesteps}] eval success {success:.0%} return {row['mean_return']:.1f}", flush=True)

        def write_curve(self) -> None:
            keys = list(dict.fromkeys(k for r in self.rows for k in r))
            with (run_dir / "curve.csv").open("w", newline="") as fh:
                writer = csv.DictWriter(fh, fieldnames=keys)
                writer.writeheader()
                writer.writerows(self.rows)

    return TrainMonitor()


def rollout_size(model: Any) -> tuple[int, str]:
    """The steps SB3 collects between two checks of ``total_timesteps``, and what they are made of.

    On-policy (PPO): ``n_steps`` per env slot; off-policy: ``train_freq`` steps per env slot (an episode
    ``train_freq`` cannot be predicted: then one step per env slot).
    """
    n = int(model.n_envs)
    if not hasattr(model, "train_freq"):
        return int(model.n_steps) * n, f"n_steps {int(model.n_steps)} x {n} env slot(s)"
    freq = model.train_freq
    if str(getattr(freq.unit, "value", freq.unit)) == "step":
        return int(freq.frequency) * n, f"train_freq {int(freq.frequency)} x {n} env slot(s)"
    return n, f"{n} env slot(s)"


def package_versions() -> dict[str, str]:
    """Installed versions of the packages a run depends on."""
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def _stop_on_sigterm() -> Callable[[], None]:
    """Turn SIGTERM into ``KeyboardInterrupt`` while training (main thread only); return the undo."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def stop(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)

    def restore() -> None:
        signal.signal(signal.SIGTERM, previous)

    return restore


def _build_model(cls: Any, config: Mapping[str, Any], venv: Any, run_dir: Path) -> Any:
    """The SB3 model of ``config`` on ``venv`` (nothing written yet: its TensorBoard folder is made by ``learn``).

    Raises:
        ValueError: For algorithm or policy arguments the run cannot take (a misspelled one, HER's
            ``learning_starts``).
    """
    algo_kwargs = resolve_algo_kwargs(config["algo_kwargs"])
    if config["her"] is not None:
        from stable_baselines3 import HerReplayBuffer

        probe = gym.make(config["env_id"], **config["env_kwargs"])
        limit = probe.spec.max_episode_steps if probe.spec is not None else None
        probe.close()
        starts = int(config["algo_kwargs"].get("learning_starts", 100))
        if limit is not None and starts <= limit:
            raise ValueError(
                f"with --her, algo_kwargs.learning_starts ({starts}) must exceed the episode limit ({limit}): "
                "HER samples only finished episodes"
            )

        algo_kwargs.update(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(config["her"]))
    try:
        return cls(
            config["policy"],
            venv,
            policy_kwargs=resolve_policy_kwargs(config["policy_kwargs"]),
            tensorboard_log=str(run_dir / "tb"),
            seed=config["seed"],
            device="cpu",
            verbose=0,
            **algo_kwargs,
        )
    except TypeError as exc:  # an argument the algorithm or its policy does not take: the user's to fix
        raise ValueError(f"{config['algo']}: algo_kwargs or policy_kwargs: {exc}") from exc


def train(
    request: TrainRequest, command: str | None = None, on_eval: Callable[[dict[str, Any]], None] | None = None
) -> Path:
    """Train and write the run directory; return it.

    Ctrl-C or SIGTERM stops training early: the run directory is still written, with the weights reached
    and ``stopped_early`` in ``meta.json`` (the learning curve holds the periodic evaluations done so far).

    Args:
        request: What to train.
        command: The command recorded in ``meta.json`` (default: this process's ``agri`` command line).
        on_eval: Called with each periodic evaluation's curve row (a sweep or a Ray Tune trial reports it).

    Raises:
        ValueError: For a bad request or hyperparameters, or an ``out`` folder that already holds a run.
    """
    import torch

    config = resolve_config(request)
    run_dir = Path(request.out)
    if (run_dir / CONFIG_FILE).exists():
        raise ValueError(f"{run_dir} already holds a run; pass another --out")
    if config["train_env_kwargs"] or config["eval_env_kwargs"]:
        check_same_spaces(config)
    command = command or " ".join(shlex.quote(a) for a in ["agri", *sys.argv[1:]])
    torch.set_num_threads(config["torch_threads"])
    cls = algorithm_class(config["algo"])
    if config.get("update_threads", config["torch_threads"]) != config["torch_threads"]:
        cls = with_update_threads(cls, config["update_threads"])
    # Everything that bad input can break (env arguments, wrappers, algorithm arguments) is built before the
    # run directory is written, so a refused request leaves no half-written folder behind.
    venv = make_vec_env(config)
    try:
        model = _build_model(cls, config, venv, run_dir)
    except BaseException:
        venv.close()
        raise
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / CONFIG_FILE).write_text(yaml.safe_dump(config, sort_keys=False))
    # SB3 collects whole rollouts: PPO n_steps per env, off-policy algorithms train_freq steps per env. It
    # rounds the total up to them, so the bar, the log and meta.json say the number it will train, and why.
    unit, why = rollout_size(model)
    planned = -(-int(config["timesteps"]) // unit) * unit
    if planned != config["timesteps"]:
        print(
            f"agri train: training {planned} steps, not {config['timesteps']}: SB3 collects whole rollouts of "
            f"{why} = {unit} steps",
            file=sys.stderr,
        )
    config = {**config, "timesteps_planned": planned}
    callback = _make_callback(config, run_dir, request.progress, on_eval)
    load_before = os.getloadavg()
    commit = git_commit()  # the code that trains, even if the tree changes while it does
    t0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    stopped_early = False
    pretrained = None
    restore = _stop_on_sigterm()
    try:
        if config["pretrain"]:  # inside the wall time; its weights are checkpoint step_0, a validation candidate
            pretrained = pretrain_from_baseline(model, model.get_vec_normalize_env(), config)
            pretrained["wall_time_s"] = round(time.perf_counter() - t0, 1)
            save_weights(model, run_dir / "checkpoints" / "step_0")
        normalizer = model.get_vec_normalize_env()
        if planned == 0 and normalizer is not None:
            # Imitation only: learn() still resets the envs, and a training VecNormalize would fold those first
            # observations into the clone's statistics. The run's weights are the clone's, unchanged.
            normalizer.training = False
        model.learn(total_timesteps=planned, callback=callback, tb_log_name="run")
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: keep what was learned, write a complete run directory
        stopped_early = True
        print(f"agri train: stopped at {model.num_timesteps} steps; writing the run directory", file=sys.stderr)
    finally:
        restore()
        wall = time.perf_counter() - t0
        save_weights(model, run_dir)
        venv.close()
        meta = {
            "command": command,
            "started_utc": started,
            "wall_time_s": round(wall, 1),
            "timesteps_requested": int(config["timesteps"]),
            "timesteps_planned": planned,
            "timesteps_rounding": f"whole rollouts of {why} = {unit} steps",
            "timesteps_done": int(model.num_timesteps),
            "stopped_early": stopped_early,
            "pretrain": pretrained,
            "git_commit": commit,
            "packages": package_versions(),
            "cpu_count": os.cpu_count(),
            "load_average_start": [round(x, 2) for x in load_before],
            "load_average_end": [round(x, 2) for x in os.getloadavg()],
            "best_eval": json.loads((run_dir / "best" / "eval.json").read_text())
            if (run_dir / "best" / "eval.json").exists()
            else None,
        }
        (run_dir / "meta.json").write_text(json.dumps(meta, indent=1))
        (run_dir / "command.txt").write_text(command + "\n")
    return run_dir
