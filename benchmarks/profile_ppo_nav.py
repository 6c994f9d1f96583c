"""Profile PPO training on GreenhouseNav-v2: the share of wall time spent in the env against the learner.

Trains with the committed PPO hyperparameters for ``--timesteps`` steps under cProfile and prints the
cumulative time of the env's ``step``/``reset`` (physics, sensors, reward), of SB3's rollout collection
(env + policy forward passes + VecNormalize) and of the gradient updates (``PPO.train``).

    python benchmarks/profile_ppo_nav.py --timesteps 16384
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import tempfile
import time
from pathlib import Path

from agri_training.train import TrainRequest, train


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--timesteps", type=int, default=16384)
    args = parser.parse_args()
    out = Path(tempfile.mkdtemp()) / "run"
    request = TrainRequest(
        "agri_envs/GreenhouseNav-v2",
        "ppo",
        out,
        timesteps=args.timesteps,
        overrides={"eval_freq": 10**9, "checkpoint_freq": 0},
        progress=False,
    )
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.runcall(train, request, "profile")
    wall = time.perf_counter() - t0
    stats = pstats.Stats(prof)
    cum = {}
    for (file, _, func), (_, _, _, ct, _) in stats.stats.items():  # type: ignore[attr-defined]
        key = (Path(file).name, func)
        cum[key] = max(cum.get(key, 0.0), ct)
    env_step = cum.get(("greenhouse_nav.py", "step"), 0.0) + cum.get(("greenhouse_nav.py", "reset"), 0.0)
    rollout = cum.get(("on_policy_algorithm.py", "collect_rollouts"), 0.0)
    learner = cum.get(("ppo.py", "train"), 0.0)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; {args.timesteps} steps in {wall:.1f} s")
    print(f"env step+reset          {env_step:7.1f} s  {100 * env_step / wall:5.1f} %")
    print(f"rollout collection      {rollout:7.1f} s  {100 * rollout / wall:5.1f} %  (env + policy forward + wrappers)")
    print(f"PPO.train (gradients)   {learner:7.1f} s  {100 * learner / wall:5.1f} %")
    print("top env functions by own time:")
    stats.sort_stats("tottime")
    rows = [
        (tt, f"{Path(f).name}:{fn}")
        for (f, _, fn), (_, _, tt, _, _) in stats.stats.items()  # type: ignore[attr-defined]
        if "agri_envs" in f
    ]
    for tt, name in sorted(rows, reverse=True)[:8]:
        print(f"  {tt:6.2f} s  {100 * tt / wall:5.1f} %  {name}")


if __name__ == "__main__":
    main()
