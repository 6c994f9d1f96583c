"""Resident memory stays flat over thousands of resets of every env (issue 18, item 7).

Each env runs in its own interpreter, so that one env's memory cannot hide or inflate another's: a
warm-up of resets (caches, numba kernels, allocator pools), then many more resets with a few random
steps each, and the resident set size (``/proc/self/statm``) before and after. The slow test bounds the
growth over 2,000 resets of every registered ``agri_envs/`` id and of the PettingZoo chain to 5 %; the
quick one bounds GrapeHarvest-v1's growth per reset (pybullet shapes made at every reset once leaked
about 160 KiB a reset).
"""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import pytest

import agri_envs  # noqa: F401

pytestmark = pytest.mark.skipif(not Path("/proc/self/statm").exists(), reason="reads /proc/self/statm (Linux)")

CHAIN = "robot_chain_v1"
ENV_IDS = sorted(k for k in gym.registry if k.startswith("agri_envs/")) + [CHAIN]

_PROBE = textwrap.dedent(
    """
    import gc, json, os, sys
    import numpy as np
    import gymnasium as gym
    import agri_envs

    env_id, warmup, total, steps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])

    def rss_mib():
        gc.collect()
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

    rng = np.random.default_rng(0)
    if env_id == "robot_chain_v1":
        from agri_envs.chain import robot_chain_v1

        env = robot_chain_v1.parallel_env()

        def episode(seed):
            env.reset(seed=seed)
            for _ in range(steps):
                if not env.agents:
                    break
                env.step({a: env.action_space(a).sample() for a in env.agents})
    else:
        env = gym.make(env_id)
        env.action_space.seed(0)

        def episode(seed):
            env.reset(seed=seed)
            for _ in range(steps):
                _, _, term, trunc, _ = env.step(env.action_space.sample())
                if term or trunc:
                    break

    for seed in range(warmup):
        episode(seed)
    before = rss_mib()
    for seed in range(warmup, total):
        episode(seed)
    after = rss_mib()
    env.close()
    print(json.dumps({"before": before, "after": after}))
    """
)


def rss_growth(env_id: str, warmup: int, total: int, steps: int = 3) -> tuple[float, float]:
    """RSS (MiB) of a fresh interpreter after ``warmup`` episodes of ``env_id`` and after ``total``."""
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, env_id, str(warmup), str(total), str(steps)],
        capture_output=True,
        text=True,
        check=True,
        timeout=1800,
    )
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result["before"], result["after"]


def test_grape_harvest_resets_do_not_grow_memory():
    before, after = rss_growth("agri_envs/GrapeHarvest-v1", 100, 500)
    per_reset_kib = (after - before) * 1024 / 400
    assert per_reset_kib < 10, f"GrapeHarvest-v1: {before:.1f} -> {after:.1f} MiB, {per_reset_kib:.1f} KiB per reset"


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_two_thousand_resets_keep_memory_flat(env_id):
    before, after = rss_growth(env_id, 200, 2200)
    growth = after / before - 1.0
    assert growth <= 0.05, f"{env_id}: {before:.1f} -> {after:.1f} MiB over 2,000 resets (+{growth:.1%})"
