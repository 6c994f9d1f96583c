"""Speed of GrapeHarvest-v1 next to panda-gym's PandaReach-v3, and luo-apf's planning time per full plan.

Prints steps/s (random actions, one process, median of several runs, both envs measured in this run; the
peer needs ``pip install -e ".[bench]"``) and the median / 90th-percentile wall time of one full
``luo-apf`` plan (order + path points of every cluster + the way home) over many seeds of ``table2``,
with the plan's success rate.

    python benchmarks/bench_grape.py [--steps 5000] [--runs 5] [--plans 200]
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from bench_greenhouse import steps_per_second  # the same measurement: median steps/s of random actions

import agri_envs  # noqa: F401
from agri_baselines.luo_apf import joints_from_observation, plan_harvest, targets_from_observation
from agri_envs.scenarios import scenario

ENV_ID = "agri_envs/GrapeHarvest-v1"


def planning_times(n: int) -> tuple[np.ndarray, float]:
    """Wall time (ms) of ``n`` full plans on seeds 0..n-1 of the table2 scenario, and their success rate."""
    env = gym.make(ENV_ID, **scenario(ENV_ID, "table2").env_kwargs)
    times, ok = [], []
    for seed in range(n):
        obs, _ = env.reset(seed=seed)
        targets, lo, hi = targets_from_observation(obs, env.unwrapped.layout)
        plan = plan_harvest(joints_from_observation(obs["observation"]), targets, lo, hi, np.random.default_rng(seed))
        times.append(plan.planning_time * 1000.0)
        ok.append(plan.success)
    env.close()
    return np.array(times), float(np.mean(ok))


def main() -> None:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--plans", type=int, default=200)
    args = parser.parse_args()
    ours = steps_per_second(ENV_ID, args.steps, args.runs, terminate_on_collision=False)
    ours_default = steps_per_second(ENV_ID, args.steps, args.runs)
    try:
        import panda_gym  # noqa: F401

        peer = steps_per_second("PandaReach-v3", args.steps, args.runs)
    except Exception as exc:  # panda-gym missing: say so, keep our numbers
        print(f"PandaReach-v3 unavailable ({exc}); install the bench extra: pip install -e '.[bench]'")
        peer = float("nan")
    print(f"{'env':<56}{'steps/s':>10}{'vs peer':>9}")
    print(f"{ENV_ID + ' (no termination)':<56}{ours:>10.0f}{ours / peer:>8.2f}x")
    print(f"{ENV_ID + ' (default: ends on collision)':<56}{ours_default:>10.0f}{ours_default / peer:>8.2f}x")
    print(f"{'PandaReach-v3 (panda-gym, pybullet)':<56}{peer:>10.0f}{1.0:>8.2f}x")
    times, success = planning_times(args.plans)
    print(
        f"luo-apf full plan over {args.plans} table2 seeds: median {np.median(times):.1f} ms, "
        f"p90 {np.percentile(times, 90):.1f} ms, max {times.max():.1f} ms (goal: median <= 27 ms); "
        f"plans complete: {success:.0%}"
    )
    print(
        f"median of {args.runs} runs of {args.steps} random-action steps, one process, "
        f"numpy {np.__version__}, gymnasium {gym.__version__}"
    )


if __name__ == "__main__":
    main()
