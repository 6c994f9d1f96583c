"""PPO on GreenhouseNav-v2, the shipped recipe, on the old training path and on the new one, in one run.

Trains the YAML block of ``agri_envs/GreenhouseNav-v2`` (``agri_training/hyperparams/ppo.yml``) for
``--timesteps`` decisions twice, in this process, one path after the other:

* **old path**: the recipe as it trained ``ppo-greenhouse-nav`` (4 single envs in SB3's ``DummyVecEnv``,
  each in ``Monitor`` and the wrappers, ``n_steps`` 2048, 10 epochs per rollout; torch on one thread; SB3's
  default Adam), :data:`OLD_PATH`;
* **new path**: the recipe as committed (``vec_env: vector``: the env's batched form through the SB3
  adapter, 64 envs x ``n_steps`` 128, the same 8192 decisions per rollout; 5 epochs; ``update_threads: 2``;
  fused Adam). ``--epochs 10`` gives the new path the old recipe's 10 epochs, to see the path alone.

Decisions per second count ``PPO.learn``'s wall time without the periodic evaluations (one episode at
the start and one at the end, timed apart and left out), as ``benchmarks/profile_ppo_nav.py`` does. The
last line is ``old path X decisions/s, new path Y decisions/s, ratio R``. Run it alone on the machine
(``cpuslot --all``): the new path's gradient updates use both cores.

    python benchmarks/bench_training.py --timesteps 65536
    python benchmarks/bench_training.py --timesteps 65536 --new-path sync   # the new path on single envs
    python benchmarks/bench_training.py --timesteps 65536 --update-threads 1   # updates on one core
    python benchmarks/bench_training.py --timesteps 65536 --epochs 10   # the old recipe's update on the new path
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import agri_training.train as train_module
from agri_training.__main__ import settle_idle_threads
from agri_training.train import TrainRequest, train

ENV_ID = "agri_envs/GreenhouseNav-v2"
#: The recipe as ``ppo-greenhouse-nav`` was trained (before ``vec_env: vector``): overrides of today's YAML.
OLD_PATH: dict[str, Any] = {
    "vec_env": "dummy",
    "n_envs": 4,
    "algo_kwargs": {"n_steps": 2048, "n_epochs": 10, "learning_rate": 3e-4},
    "train_wrappers": [{"RandomStartWaypoint": {"prob": 0.5}}, {"CrashCostRamp": {"start": 0.1, "ramp_steps": 100000}}],
    "update_threads": 1,
    "policy_kwargs": {"optimizer_kwargs": {"eps": 1e-5, "fused": False}},  # SB3's Adam, one tensor at a time
}
#: Keep the periodic evaluation to one episode at the start and one at the end, and write no checkpoints.
QUIET = {"eval_freq": 10**9, "eval_episodes": 1, "checkpoint_freq": 0}


def timed_evaluations(spent: list[float]) -> Callable[[], None]:
    """Add the periodic evaluations' wall time to ``spent[0]``; return the undo."""
    original = train_module.run_episode

    @functools.wraps(original)
    def run(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - t0

    train_module.run_episode = run

    def undo() -> None:
        train_module.run_episode = original

    return undo


def decisions_per_second(overrides: dict[str, Any], timesteps: int, batched: bool = True) -> tuple[float, int]:
    """Train the recipe with ``overrides``; return (decisions/s without the evaluations, decisions)."""
    out = Path(tempfile.mkdtemp()) / "run"
    spent = [0.0]
    undo = timed_evaluations(spent)
    original_make = train_module.make_vector_train_env
    if not batched:
        train_module.make_vector_train_env = functools.partial(original_make, batched=False)  # type: ignore[assignment]
    try:
        train(TrainRequest(ENV_ID, "ppo", out, timesteps=timesteps, overrides={**overrides, **QUIET}, progress=False))
    finally:
        undo()
        train_module.make_vector_train_env = original_make  # type: ignore[assignment]
    meta = json.loads((out / "meta.json").read_text())
    done = int(meta["timesteps_done"])
    return done / (meta["wall_time_s"] - spent[0]), done


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=65536, help="decisions per path (whole rollouts of 8192)")
    parser.add_argument(
        "--new-path", choices=("batched", "sync"), default="batched", help="sync: the new path on single envs"
    )
    parser.add_argument("--update-threads", type=int, default=None, help="the new path's (default: the YAML's)")
    parser.add_argument("--epochs", type=int, default=None, help="the new path's epochs (default: the YAML's)")
    args = parser.parse_args()
    settle_idle_threads()  # as the agri command does, before torch is imported
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores at the start")
    old, done = decisions_per_second(OLD_PATH, args.timesteps)
    print(f"old path: {done} decisions, {old:,.0f} decisions/s", flush=True)
    new_overrides: dict[str, Any] = {} if args.update_threads is None else {"update_threads": args.update_threads}
    if args.epochs is not None:
        new_overrides["algo_kwargs"] = {"n_epochs": args.epochs}
    new, done = decisions_per_second(new_overrides, args.timesteps, batched=args.new_path == "batched")
    print(f"new path ({args.new_path} envs): {done} decisions, {new:,.0f} decisions/s", flush=True)
    print(f"load average {os.getloadavg()[0]:.2f} at the end")
    print(f"old path {old:,.0f} decisions/s, new path {new:,.0f} decisions/s, ratio {new / old:.2f}")


if __name__ == "__main__":
    main()
