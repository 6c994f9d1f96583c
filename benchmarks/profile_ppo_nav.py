"""Where PPO training on GreenhouseNav-v2 spends its wall time: the env against the learner.

Trains with the committed PPO hyperparameters (4 envs, action_repeat 4, ...) for ``--timesteps`` decisions
and times, with ``perf_counter`` around the calls (no profiler overhead):

* the env's ``step`` and ``reset`` (physics, people, sensors, reward), and within them the observation;
* ``PPO.train`` (the gradient updates);
* the rest: SB3's rollout loop (policy forward passes, VecNormalize, Monitor, the wrappers), callbacks.

The periodic evaluations (one episode at the start and one at the end) are timed apart and left out.

``--repeat-path wrapper`` trains as before GreenhouseNav had ``frame_skip``: the ``ActionRepeat`` wrapper
steps the env 4 times per decision and the env makes an observation every time.

    python benchmarks/profile_ppo_nav.py --timesteps 65536
    python benchmarks/profile_ppo_nav.py --timesteps 65536 --repeat-path wrapper
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

import agri_training.train as train_module
from agri_envs.rover.greenhouse_nav import GreenhouseNavEnv
from agri_training.learned.policy import ActionRepeat
from agri_training.train import TrainRequest, train

SPENT: defaultdict[str, float] = defaultdict(float)
EVALUATING = [False]


def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` adding its wall time to ``SPENT[name]`` (not while a periodic evaluation runs)."""

    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        if EVALUATING[0] and name != "evaluation":
            return fn(*args, **kwargs)
        EVALUATING[0] = name == "evaluation"
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            SPENT[name] += time.perf_counter() - t0
            EVALUATING[0] = False

    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=65536, help="decisions to train")
    parser.add_argument("--repeat-path", choices=("frame_skip", "wrapper"), default="frame_skip")
    parser.add_argument("--action-repeat", type=int, default=None, help="override the YAML's action_repeat (4)")
    args = parser.parse_args()

    from stable_baselines3 import PPO

    GreenhouseNavEnv.step = timed("env step", GreenhouseNavEnv.step)  # type: ignore[method-assign]
    GreenhouseNavEnv.reset = timed("env reset", GreenhouseNavEnv.reset)  # type: ignore[method-assign]
    GreenhouseNavEnv._observe = timed("env observation", GreenhouseNavEnv._observe)  # type: ignore[method-assign]
    PPO.train = timed("PPO.train", PPO.train)  # type: ignore[method-assign]
    train_module.run_episode = timed("evaluation", train_module.run_episode)  # the periodic evaluation
    if args.repeat_path == "wrapper":

        def make_repeating(env_id: str, env_kwargs: Any, repeat: int) -> gym.Env[Any, Any]:
            env = gym.make(env_id, **env_kwargs)
            return ActionRepeat(env, repeat) if repeat > 1 else env

        train_module.make_repeating = make_repeating  # type: ignore[assignment]

    out = Path(tempfile.mkdtemp()) / "run"
    request = TrainRequest(
        "agri_envs/GreenhouseNav-v2",
        "ppo",
        out,
        timesteps=args.timesteps,
        overrides={"eval_freq": 10**9, "eval_episodes": 1, "checkpoint_freq": 0}
        | ({} if args.action_repeat is None else {"action_repeat": args.action_repeat}),
        progress=False,
    )
    t0 = time.perf_counter()
    train(request, "profile")
    wall = time.perf_counter() - t0 - SPENT["evaluation"]
    env = SPENT["env step"] + SPENT["env reset"]
    done = json.loads((out / "meta.json").read_text())["timesteps_done"]  # whole rollouts: n_steps x n_envs
    print(
        f"{done} decisions, {args.repeat_path} path, {wall:.1f} s ({done / wall:,.0f} decisions/s),"
        f" load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )
    rows = [
        ("env step + reset", env),
        ("  of which the observation", SPENT["env observation"]),
        ("PPO.train (gradient updates)", SPENT["PPO.train"]),
        ("the rest (rollout loop, policy forward, VecNormalize, wrappers)", wall - env - SPENT["PPO.train"]),
    ]
    for name, seconds in rows:
        print(f"{name:66s} {seconds:7.1f} s  {100 * seconds / wall:5.1f} %")


if __name__ == "__main__":
    main()
