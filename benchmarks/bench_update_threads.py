"""PPO's gradient updates on 1 and 2 torch threads, and how long idle OpenMP threads spin, side by side.

One update of GreenhouseNav's PPO recipe (8,192 decisions, 10 epochs of minibatches of 512, the recipe's
networks and its 3-frame observation of 312 floats; the rollout is synthetic, the update is the real
``PPO.train``) in a fresh process per setting, since OpenMP reads its settings when torch is imported:

* 1 thread;
* 2 threads with libgomp's default wait;
* 2 threads, idle threads spin 10,000 iterations and then sleep (``GOMP_SPINCOUNT=10000``, what the
  ``agri`` command sets, :data:`agri_training.__main__.THREAD_SETTINGS`);
* 2 threads, idle threads sleep at once (``OMP_WAIT_POLICY=PASSIVE``).

``--busy N`` runs N busy processes meanwhile: the cores are then shared, as on a busy machine.

    python benchmarks/bench_update_threads.py
    python benchmarks/bench_update_threads.py --busy 2
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

SETTINGS = (
    ("1 thread", 1, {}),
    ("2 threads, libgomp's default wait", 2, {}),
    ("2 threads, GOMP_SPINCOUNT=10000 (agri)", 2, {"GOMP_SPINCOUNT": "10000"}),
    ("2 threads, OMP_WAIT_POLICY=PASSIVE", 2, {"OMP_WAIT_POLICY": "PASSIVE"}),
)
WAIT_VARIABLES = ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")


def one_update(threads: int) -> float:
    """Microseconds per decision of one ``PPO.train`` call on the recipe's networks, with ``threads`` threads."""
    import gymnasium as gym
    import numpy as np
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agri_training.learned.policy import resolve_algo_kwargs, resolve_policy_kwargs
    from agri_training.train import load_hyperparams

    torch.set_num_threads(threads)
    hp = load_hyperparams("agri_envs/GreenhouseNav-v2", "ppo")
    size = 312  # FlattenObservation (104 floats) x ObservationHistory's 3 frames

    class Synthetic(gym.Env[np.ndarray, np.ndarray]):
        observation_space = gym.spaces.Box(-1, 1, (size,), np.float32)
        action_space = gym.spaces.Box(-1, 1, (2,), np.float32)

        def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
            super().reset(seed=seed)
            return np.zeros(size, np.float32), {}

        def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
            return self.np_random.uniform(-1, 1, size).astype(np.float32), 0.0, False, False, {}

    algo_kwargs = resolve_algo_kwargs(hp["algo_kwargs"])
    venv = DummyVecEnv([Synthetic] * hp["n_envs"])
    model = PPO(
        "MlpPolicy", venv, policy_kwargs=resolve_policy_kwargs(hp["policy_kwargs"]), device="cpu", seed=0, **algo_kwargs
    )
    model.learn(model.n_steps * model.n_envs)  # one rollout and one update (warm-up)
    t0 = time.perf_counter()
    model.train()
    return 1e6 * (time.perf_counter() - t0) / (model.n_steps * model.n_envs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--busy", type=int, default=0, help="busy processes running meanwhile")
    parser.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        print(one_update(args.child))
        return
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.busy)]
    try:
        print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores, {args.busy} busy processes")
        for name, threads, variables in SETTINGS:
            env = {k: v for k, v in os.environ.items() if k not in WAIT_VARIABLES} | variables
            out = subprocess.run(
                [sys.executable, __file__, "--child", str(threads)], env=env, capture_output=True, text=True, check=True
            )
            print(f"{name:42s} {float(out.stdout.split()[-1]):8.0f} us per decision")
    finally:
        for process in busy:
            process.kill()


if __name__ == "__main__":
    main()
