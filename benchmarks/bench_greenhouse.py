"""Speed of GreenhouseNav-v2 (full 811-beam LIDAR every step) next to Gymnasium's BipedalWalker-v3.

Prints steps/s (random actions, one process, median of several runs, both envs measured in this run)
and the cost of one LIDAR scan in microseconds (numba kernel vs the per-ray pymunk reference).

    python benchmarks/bench_greenhouse.py [--steps 20000] [--runs 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import agri_envs  # noqa: F401
from agri_envs.sim2d.reference import geometry_space, reference_scan


def steps_per_second(env_id: str, steps: int, runs: int, **kwargs: object) -> float:
    """Median steps/s of random actions over ``runs`` runs of ``steps`` steps (resets included)."""
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(0)
    env.reset(seed=0)
    for _ in range(200):  # warm-up (numba compile, caches)
        env.step(env.action_space.sample())
    rates = []
    for run in range(runs):
        env.reset(seed=run)
        actions = [env.action_space.sample() for _ in range(steps)]
        t0 = time.perf_counter()
        for a in actions:
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()
        rates.append(steps / (time.perf_counter() - t0))
    env.close()
    return statistics.median(rates)


def scan_cost_us(repeats: int = 2000) -> tuple[float, float, int, int]:
    """Microseconds per full scan on the default scene: numba kernel, and the per-ray pymunk reference."""
    env = gym.make("agri_envs/GreenhouseNav-v2", n_people=0)
    env.reset(seed=0)
    e = env.unwrapped
    world, lidar, pose = e.world, e.lidar, e.robot.pose
    lidar.exact_scan(pose, world.circles, world.capsules)
    t0 = time.perf_counter()
    for _ in range(repeats):
        lidar.exact_scan(pose, world.circles, world.capsules)
    fast = (time.perf_counter() - t0) / repeats * 1e6
    space = geometry_space(e.layout.geometry)
    sx, sy, sh = lidar.pose_in_world(pose)
    t0 = time.perf_counter()
    for _ in range(20):
        reference_scan(space, sx, sy, sh, lidar.spec.beam_angles, lidar.spec.max_range)
    slow = (time.perf_counter() - t0) / 20 * 1e6
    return fast, slow, len(world.circles), len(world.capsules)


def main() -> None:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args()
    ours = steps_per_second("agri_envs/GreenhouseNav-v2", args.steps, args.runs, terminate_on_collision=False)
    ours_full = steps_per_second(
        "agri_envs/GreenhouseNav-v2", args.steps, args.runs, terminate_on_collision=False, full_scan=True
    )
    try:
        peer = steps_per_second("BipedalWalker-v3", args.steps, args.runs)
    except Exception as exc:  # box2d missing: say so, keep our numbers
        print(f"BipedalWalker-v3 unavailable ({exc}); install the dev extra (box2d)")
        peer = float("nan")
    fast, slow, n_circles, n_capsules = scan_cost_us()
    print(f"{'env':<46}{'steps/s':>10}{'vs peer':>9}")
    print(f"{'agri_envs/GreenhouseNav-v2 (811-beam scan)':<46}{ours:>10.0f}{ours / peer:>8.2f}x")
    print(f"{'agri_envs/GreenhouseNav-v2 full_scan=True':<46}{ours_full:>10.0f}{ours_full / peer:>8.2f}x")
    print(f"{'BipedalWalker-v3 (gymnasium, box2d)':<46}{peer:>10.0f}{1.0:>8.2f}x")
    print(
        f"one 811-beam scan, {n_circles} circles + {n_capsules} capsules: numba {fast:.1f} us, "
        f"pymunk per-ray reference {slow:.0f} us ({slow / fast:.0f}x)"
    )
    print(
        f"median of {args.runs} runs of {args.steps} random-action steps, one process, "
        f"numpy {np.__version__}, gymnasium {gym.__version__}"
    )


if __name__ == "__main__":
    main()
