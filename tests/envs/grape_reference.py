"""Digests of GrapeHarvest-v1 rollouts, to check that episodes stay seed-identical across refactorings.

``tests/data/grape_harvest_digests.json`` holds the digests that the env gave before its resets were made
fast (pybullet bodies reused, scene sampling sped up); ``test_grape_harvest_env.py`` recomputes them. Write
the file anew only for a deliberate change of the env's episodes (which also bumps its version):

    python tests/envs/grape_reference.py tests/data/grape_harvest_digests.json
"""

import hashlib
import json
import sys

import gymnasium as gym
import numpy as np

import agri_envs  # noqa: F401
from agri_envs.arm.presets import REACH_PRESET

ENV_ID = "agri_envs/GrapeHarvest-v1"

#: Scene and control arguments whose episodes are pinned.
CASES: dict[str, dict] = {
    "default": {},
    "ee": {"control": "ee"},
    "reach": dict(REACH_PRESET),
    "feasible": {"feasible_scenes": True},
    **{f"clusters-{k}": {"min_clusters": k, "max_clusters": k} for k in (1, 3, 5)},
    "feasible-5": {"min_clusters": 5, "max_clusters": 5, "feasible_scenes": True},
    "crowded": {"min_clusters": 5, "n_leaves": 8, "n_canes": 4},
    "dense-no-termination": {"terminate_on_collision": False, "reward_type": "dense", "cluster_tilt": 0.5},
}


def rollout_digest(kwargs: dict, seed: int, steps: int = 40, resets: int = 3) -> str:
    """SHA-256 of every observation, reward, flag and info of a seeded random rollout (resets included)."""
    env = gym.make(ENV_ID, **kwargs)
    rng = np.random.default_rng(seed + 1000)
    h = hashlib.sha256()

    def add(obs, info, *rest):
        for k in sorted(obs):
            h.update(k.encode() + np.ascontiguousarray(obs[k], dtype=np.float32).tobytes())
        h.update(json.dumps(info, sort_keys=True).encode() + repr(rest).encode())

    add(*env.reset(seed=seed))
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
        add(obs, info, float(r), term, trunc)
        if term or trunc:
            add(*env.reset())
    for _ in range(resets):  # unseeded resets continue the episode seed's stream
        add(*env.reset())
        for _ in range(2):
            obs, r, term, trunc, info = env.step(rng.uniform(-1, 1, 6).astype(np.float32))
            add(obs, info, float(r), term, trunc)
    env.close()
    return h.hexdigest()


def digests() -> dict[str, str]:
    """Digest of every case for seeds 0 and 1."""
    return {f"{name}/seed-{seed}": rollout_digest(kw, seed) for name, kw in CASES.items() for seed in (0, 1)}


if __name__ == "__main__":
    with open(sys.argv[1], "w") as f:
        json.dump(digests(), f, indent=1, sort_keys=True)
        f.write("\n")
