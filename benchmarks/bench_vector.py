"""Env-steps/s of the batched 2D envs next to their single envs and BipedalWalker-v3, with resets, in one run.

Every env runs uniformly random actions on one core with its default arguments, so episodes end as they
do for a learner that has not learned anything yet (collisions, time limits), and the time of every reset
counts. An env-step is one transition of one env: a batched env's ``step`` is ``num_envs`` of them, less
the sub-envs it resets instead (next-step autoreset). The measurements take turns round by round, so that a
change of machine load hits them all alike; each rate is the median over the rounds. Then the median reset
time of the single envs next to BipedalWalker-v3's.

    python benchmarks/bench_vector.py [--seconds 2] [--rounds 5] [--sizes 1 16 64 256] [--resets 300]

Goals (issue 20): batched GreenhouseNav at 64 envs >= 3x BipedalWalker-v3's steps/s and >= 3x the single
env's; single-env median resets <= half of BipedalWalker-v3's. GreenhouseCoverage is measured the same way.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np
from bench_grape import peer, reset_ms

import agri_envs  # noqa: F401

NAV = "agri_envs/GreenhouseNav-v2"
COVERAGE = "agri_envs/GreenhouseCoverage-v2"
WALKER = "BipedalWalker-v3"


def single_runner(env_id: str) -> Callable[[float], float]:
    """A measurement of ``gym.make(env_id)``: steps/s over about ``seconds`` (resets on episode end included)."""
    env = gym.make(env_id)
    env.action_space.seed(0)
    env.reset(seed=0)
    actions = [env.action_space.sample() for _ in range(4096)]

    def run(seconds: float) -> float:
        steps = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            for a in actions[steps % 4000 : steps % 4000 + 64]:
                _, _, terminated, truncated, _ = env.step(a)
                if terminated or truncated:
                    env.reset()
            steps += 64
        return steps / (time.perf_counter() - t0)

    run(0.2)  # warm-up: imports, compilation, caches
    return run


def batched_runner(env_id: str, num_envs: int) -> Callable[[float], float]:
    """A measurement of ``gym.make_vec(env_id, num_envs)``: env-steps/s (transitions, autoresets not counted)."""
    envs = gym.make_vec(env_id, num_envs=num_envs)
    envs.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.0, 1.0, (64, num_envs, 2)).astype(np.float32)

    def run(seconds: float) -> float:
        transitions = 0
        calls = 0
        pending = np.zeros(num_envs, dtype=bool)  # sub-envs the next step resets instead of stepping
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            _, _, terminated, truncated, _ = envs.step(actions[calls % 64])
            transitions += num_envs - int(pending.sum())
            pending = terminated | truncated
            calls += 1
        return transitions / (time.perf_counter() - t0)

    run(0.2)
    return run


def main() -> None:
    """Run the benchmark and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="length of one measurement")
    parser.add_argument("--rounds", type=int, default=5, help="measurements of each env, taken in turns")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 16, 64, 256])
    parser.add_argument("--resets", type=int, default=300)
    parser.add_argument("--envs", nargs="+", default=[NAV, COVERAGE], help="batched env ids to measure")
    args = parser.parse_args()
    box2d_hint = "install box2d (dev extra; pip install box2d, which may need swig)"
    runners: dict[str, Callable[[float], float]] = {}
    try:
        runners[WALKER] = single_runner(WALKER)
    except Exception as exc:  # box2d missing: say so, keep our numbers
        print(f"{WALKER} unavailable ({type(exc).__name__}: {exc}); {box2d_hint}")
    for env_id in args.envs:
        runners[f"{env_id} (single env)"] = single_runner(env_id)
        for n in args.sizes:
            runners[f"{env_id} (batched, {n} envs)"] = batched_runner(env_id, n)
    rates: dict[str, list[float]] = {name: [] for name in runners}
    for _ in range(args.rounds):
        for name, run in runners.items():
            rates[name].append(run(args.seconds))
    median = {name: statistics.median(r) for name, r in rates.items()}
    walker = median.get(WALKER, float("nan"))
    print(f"{'env-steps/s, random actions, resets included':<58}{'median':>10}{'min':>9}{'max':>9}{'vs Walker':>11}")
    for name, r in rates.items():
        print(f"{name:<58}{median[name]:>10.0f}{min(r):>9.0f}{max(r):>9.0f}{median[name] / walker:>10.2f}x")
    for env_id in args.envs:
        single = median[f"{env_id} (single env)"]
        for n in args.sizes:
            rate = median[f"{env_id} (batched, {n} envs)"]
            print(f"{env_id} batched x{n}: {rate / single:.2f}x the single env, {rate / walker:.2f}x {WALKER}")
    resets = [(env_id, reset_ms(env_id, args.resets)) for env_id in (NAV, COVERAGE)]
    walker_reset = peer(WALKER, box2d_hint, lambda: reset_ms(WALKER, args.resets))
    title = f"median reset over {args.resets} seeds (3 random steps between)"
    print(f"{title:<58}{'ms':>10}{'vs Walker':>20}")
    for name, ms in [*resets, (WALKER, walker_reset)]:
        print(f"{name:<58}{ms:>10.2f}{ms / walker_reset:>19.2f}x")
    print(
        f"{args.rounds} rounds of {args.seconds:g} s per env, taken in turns; one process; load average "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at the end; numpy {np.__version__}, "
        f"gymnasium {gym.__version__}"
    )


if __name__ == "__main__":
    main()
