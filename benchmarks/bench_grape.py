"""Speed of GrapeHarvest-v1 next to panda-gym's PandaReach-v3 and BipedalWalker-v3, and luo-apf's planning time.

Prints steps/s (random actions, one process, median of several runs, every env measured in this run; the
peers need ``pip install -e ".[bench]"`` and box2d from the dev extra), with the default termination
(resets included, as a learner sees them) and without; the median reset time (ms) of GrapeHarvest-v1,
GrapeHarvestReach-v1 and the peers; and the median / 90th-percentile wall time of one full ``luo-apf``
plan (order + path points of every cluster + the way home) over many seeds of ``table2``, with the
plan's success rate.

    python benchmarks/bench_grape.py [--steps 5000] [--runs 5] [--resets 300] [--plans 200]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from bench_greenhouse import steps_per_second  # the same measurement: median steps/s of random actions

import agri_envs  # noqa: F401
from agri_baselines.luo_apf import joints_from_observation, plan_harvest, targets_from_observation
from agri_envs.scenarios import scenario

ENV_ID = "agri_envs/GrapeHarvest-v1"
REACH_ID = "agri_envs/GrapeHarvestReach-v1"


def reset_ms(env_id: str, n: int) -> float:
    """Median wall time (ms) of ``reset(seed=k)`` over ``n`` seeds, each after a few random steps."""
    env = gym.make(env_id)
    env.action_space.seed(0)
    times = []
    for seed in range(n + 20):  # the first 20: warm-up (imports, caches)
        t0 = time.perf_counter()
        env.reset(seed=seed)
        times.append(time.perf_counter() - t0)
        for _ in range(3):
            _, _, term, trunc, _ = env.step(env.action_space.sample())
            if term or trunc:
                break
    env.close()
    return float(np.median(times[20:])) * 1000.0


def peer(env_id: str, hint: str, measure: Callable[[], float]) -> float:
    """``measure()`` for a peer env, or NaN (and a line saying why) when it cannot be made."""
    try:
        return float(measure())
    except Exception as exc:  # the peer's package is missing: say so, keep our numbers
        print(f"{env_id} unavailable ({type(exc).__name__}: {exc}); {hint}")
        return float("nan")


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
    parser.add_argument("--resets", type=int, default=300)
    parser.add_argument("--plans", type=int, default=200)
    args = parser.parse_args()
    ours = steps_per_second(ENV_ID, args.steps, args.runs, terminate_on_collision=False)
    ours_default = steps_per_second(ENV_ID, args.steps, args.runs)
    reach_default = steps_per_second(REACH_ID, args.steps, args.runs)
    panda_hint = "install the bench extra: pip install -e '.[bench]'"
    box2d_hint = "install box2d (dev extra; pip install box2d, which may need swig)"

    def panda_rate() -> float:
        import panda_gym  # noqa: F401

        return steps_per_second("PandaReach-v3", args.steps, args.runs)

    def panda_reset() -> float:
        import panda_gym  # noqa: F401

        return reset_ms("PandaReach-v3", args.resets)

    panda = peer("PandaReach-v3", panda_hint, panda_rate)
    walker = peer("BipedalWalker-v3", box2d_hint, lambda: steps_per_second("BipedalWalker-v3", args.steps, args.runs))
    print(f"{'env':<56}{'steps/s':>10}{'vs Panda':>10}{'vs Walker':>11}")
    rows = [
        (ENV_ID + " (no termination)", ours),
        (ENV_ID + " (default: ends on collision)", ours_default),
        (REACH_ID + " (default)", reach_default),
        ("PandaReach-v3 (panda-gym, pybullet)", panda),
        ("BipedalWalker-v3 (Gymnasium, Box2D)", walker),
    ]
    for name, rate in rows:
        print(f"{name:<56}{rate:>10.0f}{rate / panda:>9.2f}x{rate / walker:>10.2f}x")
    resets = [
        (ENV_ID, reset_ms(ENV_ID, args.resets)),
        (REACH_ID, reset_ms(REACH_ID, args.resets)),
        ("PandaReach-v3", peer("PandaReach-v3", panda_hint, panda_reset)),
        ("BipedalWalker-v3", peer("BipedalWalker-v3", box2d_hint, lambda: reset_ms("BipedalWalker-v3", args.resets))),
    ]
    walker_reset = resets[-1][1]
    print(f"{'median reset over ' + str(args.resets) + ' seeds':<56}{'ms':>10}{'vs Walker':>21}")
    for name, ms in resets:
        print(f"{name:<56}{ms:>10.2f}{ms / walker_reset:>20.2f}x")
    times, success = planning_times(args.plans)
    print(
        f"luo-apf full plan over {args.plans} table2 seeds: median {np.median(times):.1f} ms, "
        f"p90 {np.percentile(times, 90):.1f} ms, max {times.max():.1f} ms (goal: median <= 27 ms); "
        f"plans complete: {success:.0%}"
    )
    print(
        f"steps/s: median of {args.runs} runs of {args.steps} random-action steps (resets included), one process, "
        f"numpy {np.__version__}, gymnasium {gym.__version__}"
    )


if __name__ == "__main__":
    main()
