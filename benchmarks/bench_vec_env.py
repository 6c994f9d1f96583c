"""DummyVecEnv against SubprocVecEnv for GreenhouseNav-v2 training envs (random actions, steps/s).

python benchmarks/bench_vec_env.py --n-envs 4 --steps 2000
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from agri_training.train import TrainRequest, make_vec_env, resolve_config


def rate(vec_env: str, n_envs: int, steps: int) -> float:
    """Env steps per second of ``n_envs`` training envs stepped together (VecNormalize included)."""
    config = resolve_config(
        TrainRequest("agri_envs/GreenhouseNav-v2", "ppo", "unused", overrides={"n_envs": n_envs, "vec_env": vec_env})
    )
    venv = make_vec_env(config)
    venv.reset()
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(steps):
        venv.step(rng.uniform(-1, 1, (n_envs, 2)).astype(np.float32))
    dt = time.perf_counter() - t0
    venv.close()
    return steps * n_envs / dt


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--n-envs", type=int, default=4)
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for kind in ("dummy", "subproc"):
        print(f"{kind:8s} {args.n_envs} envs: {rate(kind, args.n_envs, args.steps):8.0f} steps/s")


if __name__ == "__main__":
    main()
