"""Where PPO training on GreenhouseNav-v2 spends its wall time, in microseconds per decision.

Trains the committed PPO recipe (``--path new``, the YAML as it is) or the recipe as ``ppo-greenhouse-nav``
was trained (``--path old``: 4 single envs in ``DummyVecEnv``, ``n_steps`` 2048; ``bench_training.OLD_PATH``)
for ``--timesteps`` decisions, with ``perf_counter`` timers around the calls (no profiler overhead). Each
timer counts its own time only (the time of the timed calls inside it goes to theirs), so the rows add
up to the wall time:

* the env: physics, people, task and reward (``step`` / ``reset`` of the single env, or of the batched
  env), and apart from it the observation (sensors, pooling);
* the wrappers around each single env (``gym.make``'s checkers, frame skip, curricula, observation
  wrappers) or their vector forms, and ``Monitor`` / ``VecMonitor``;
* the vector env's own loop: ``DummyVecEnv``, ``SyncVectorEnv``, the SB3 adapter (info dicts, resets);
* ``VecNormalize``; the policy's forward passes in the rollout; the rollout buffer's writes; GAE
  (``compute_returns_and_advantage``); ``PPO.train`` (the gradient updates); the callbacks;
* the rest of SB3's rollout loop (tensor conversion, action clipping, the time-limit bootstrap loop) and
  of ``learn``.

The periodic evaluations (one episode at the start and one at the end) are timed apart and left out.

``--repeat-path wrapper`` trains as before GreenhouseNav had ``frame_skip``: the ``ActionRepeat`` wrapper
steps the env 4 times per decision and the env makes an observation every time.

    python benchmarks/profile_ppo_nav.py --timesteps 65536               # the committed recipe
    python benchmarks/profile_ppo_nav.py --timesteps 65536 --path old    # as ppo-greenhouse-nav trained
    python benchmarks/profile_ppo_nav.py --timesteps 65536 --path old --repeat-path wrapper
    python benchmarks/profile_ppo_nav.py --timesteps 65536 --action-repeat 1   # one env step per decision
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
from bench_training import OLD_PATH

import agri_training.train as train_module
from agri_envs.rover.greenhouse_nav import GreenhouseNavEnv
from agri_training.__main__ import settle_idle_threads
from agri_training.learned.policy import ActionRepeat
from agri_training.learned.vec_env import VectorVecEnv
from agri_training.train import TrainRequest, train

#: Exclusive wall time per row.
SPENT: defaultdict[str, float] = defaultdict(float)
#: Time of the timed calls inside each running timed call (the innermost last).
_INNER: list[float] = []
EVALUATING = [False]
ENV = "env: physics, people, task, reward"
OBSERVATION = "env: observation (LIDAR, sonars, pooling)"
WRAPPERS = "wrappers around the env (checkers, curricula, frame skip, observation wrappers)"
MONITOR = "Monitor / VecMonitor"
VEC_LOOP = "vector env loop (DummyVecEnv / SyncVectorEnv / adapter: infos, resets)"
NORMALIZE = "VecNormalize"
FORWARD = "policy forward passes (rollout)"
BUFFER = "rollout buffer writes"
GAE = "GAE (compute_returns_and_advantage)"
UPDATES = "PPO.train (gradient updates)"
CALLBACKS = "callbacks (progress, checkpoints)"
ROLLOUT = "SB3 rollout loop (tensors, clipping, time-limit bootstrap)"
ORDER = (ENV, OBSERVATION, WRAPPERS, MONITOR, VEC_LOOP, NORMALIZE, FORWARD, BUFFER, GAE, UPDATES, CALLBACKS, ROLLOUT)


def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` adding its own wall time (less that of timed calls inside it) to ``SPENT[name]``.

    Nothing is counted while a periodic evaluation runs (``name == "evaluation"`` counts that apart).
    """

    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        if EVALUATING[0]:
            return fn(*args, **kwargs)
        EVALUATING[0] = name == "evaluation"
        _INNER.append(0.0)
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            elapsed = time.perf_counter() - t0
            SPENT[name] += elapsed - _INNER.pop()
            if _INNER:
                _INNER[-1] += elapsed
            EVALUATING[0] = False

    run.__wrapped_by_profile__ = True  # type: ignore[attr-defined]
    return run


def patch(cls: type, methods: tuple[str, ...], name: str) -> None:
    """Time the methods that ``cls`` itself defines (once per class)."""
    for method in methods:
        fn = cls.__dict__.get(method)
        if fn is not None and callable(fn) and not getattr(fn, "__wrapped_by_profile__", False):
            setattr(cls, method, timed(name, fn))


def patch_layers(venv: Any) -> None:
    """Time every layer of a training VecEnv (built by ``make_vec_env``), down to the single envs."""
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper, VecMonitor, VecNormalize

    layer = venv
    while isinstance(layer, VecEnvWrapper):
        kind = NORMALIZE if isinstance(layer, VecNormalize) else MONITOR if isinstance(layer, VecMonitor) else VEC_LOOP
        patch(type(layer), ("step_wait", "reset"), kind)
        layer = layer.venv
    patch(type(layer), ("step_wait", "reset"), VEC_LOOP)
    singles: list[Any] = []
    if isinstance(layer, DummyVecEnv):
        singles = list(layer.envs)
    elif isinstance(layer, VectorVecEnv):
        vector = layer.venv
        while isinstance(vector, gym.vector.VectorWrapper):
            for cls in type(vector).__mro__:
                if cls in (gym.vector.VectorWrapper, object):
                    break
                patch(cls, ("step", "reset", "observations"), WRAPPERS)
            vector = vector.env
        if isinstance(vector, gym.vector.SyncVectorEnv):
            for cls in type(vector).__mro__:
                patch(cls, ("step", "reset"), VEC_LOOP)
            singles = list(vector.envs)
        else:  # the batched env: its step and reset are the env
            patch(type(vector), ("step", "reset"), ENV)
    for env in singles:
        while isinstance(env, gym.Wrapper):
            for cls in type(env).__mro__:
                if cls is object:
                    break
                patch(cls, ("step", "reset", "observation"), MONITOR if cls is Monitor else WRAPPERS)
            env = env.env


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=65536, help="decisions to train")
    parser.add_argument("--path", choices=("new", "old"), default="new", help="the committed recipe, or as shipped")
    parser.add_argument("--sync", action="store_true", help="new path on single envs (SyncVectorEnv), not batched")
    parser.add_argument("--repeat-path", choices=("frame_skip", "wrapper"), default="frame_skip")
    parser.add_argument("--action-repeat", type=int, default=None, help="override the YAML's action_repeat (4)")
    args = parser.parse_args()
    settle_idle_threads()  # as the agri command does, before torch is imported

    from stable_baselines3 import PPO
    from stable_baselines3.common.buffers import RolloutBuffer
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm
    from stable_baselines3.common.policies import ActorCriticPolicy

    GreenhouseNavEnv.step = timed(ENV, GreenhouseNavEnv.step)  # type: ignore[method-assign]
    GreenhouseNavEnv.reset = timed(ENV, GreenhouseNavEnv.reset)  # type: ignore[method-assign]
    GreenhouseNavEnv._observe = timed(OBSERVATION, GreenhouseNavEnv._observe)  # type: ignore[method-assign]
    PPO.train = timed(UPDATES, PPO.train)  # type: ignore[method-assign]
    ActorCriticPolicy.forward = timed(FORWARD, ActorCriticPolicy.forward)  # type: ignore[method-assign]
    ActorCriticPolicy.predict_values = timed(FORWARD, ActorCriticPolicy.predict_values)  # type: ignore[method-assign]
    RolloutBuffer.add = timed(BUFFER, RolloutBuffer.add)  # type: ignore[method-assign]
    RolloutBuffer.compute_returns_and_advantage = timed(GAE, RolloutBuffer.compute_returns_and_advantage)  # type: ignore[method-assign]
    BaseCallback.on_step = timed(CALLBACKS, BaseCallback.on_step)  # type: ignore[method-assign]
    OnPolicyAlgorithm.collect_rollouts = timed(ROLLOUT, OnPolicyAlgorithm.collect_rollouts)  # type: ignore[method-assign]
    train_module.run_episode = timed("evaluation", train_module.run_episode)  # the periodic evaluation
    make_vec_env = train_module.make_vec_env

    def make_and_patch(config: Any) -> Any:
        venv = make_vec_env(config)
        patch_layers(venv)
        return venv

    train_module.make_vec_env = make_and_patch  # type: ignore[assignment]
    if args.sync:
        train_module.make_vector_train_env = functools.partial(  # type: ignore[assignment]
            train_module.make_vector_train_env, batched=False
        )
    if args.repeat_path == "wrapper":

        def make_repeating(env_id: str, env_kwargs: Any, repeat: int) -> gym.Env[Any, Any]:
            env = gym.make(env_id, **env_kwargs)
            return ActionRepeat(env, repeat) if repeat > 1 else env

        train_module.make_repeating = make_repeating  # type: ignore[assignment]

    out = Path(tempfile.mkdtemp()) / "run"
    overrides: dict[str, Any] = {"eval_freq": 10**9, "eval_episodes": 1, "checkpoint_freq": 0}
    if args.path == "old":
        overrides |= OLD_PATH
    if args.action_repeat is not None:
        overrides["action_repeat"] = args.action_repeat
    request = TrainRequest("agri_envs/GreenhouseNav-v2", "ppo", out, timesteps=args.timesteps, overrides=overrides)
    load = os.getloadavg()[0]
    train(request, "profile")
    meta = json.loads((out / "meta.json").read_text())
    wall = meta["wall_time_s"] - SPENT["evaluation"]  # PPO.learn without the periodic evaluations
    done = meta["timesteps_done"]  # whole rollouts: n_steps x n_envs
    print(
        f"{done} decisions, {args.path} path{' (sync envs)' if args.sync else ''}, {args.repeat_path}:"
        f" {wall:.1f} s ({done / wall:,.0f} decisions/s), load average {load:.1f} -> {os.getloadavg()[0]:.1f}"
        f" on {os.cpu_count()} cores"
    )
    counted = sum(SPENT[name] for name in ORDER)
    for name, seconds in [*((n, SPENT[n]) for n in ORDER), ("the rest (learn loop, logging)", wall - counted)]:
        print(f"{name:80s} {1e6 * seconds / done:7.1f} us  {100 * seconds / wall:5.1f} %")
    print(f"{'total':80s} {1e6 * wall / done:7.1f} us per decision")


if __name__ == "__main__":
    main()
