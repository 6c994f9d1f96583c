"""Digests of GreenhouseNav-v2 and GreenhouseCoverage-v2 rollouts, to keep episodes seed-identical across refactorings.

``tests/data/greenhouse_digests.json`` holds the digests the two envs gave before their resets were made
fast (pymunk worlds moved instead of rebuilt, static scenes cached): GreenhouseNav's as recorded then,
GreenhouseCoverage-v2's and the ``distribution`` cases' recorded on the ``learn2d`` branch before it merged the
fast resets (commit a6d4610, whose GreenhouseNav digests equal the recorded ones); ``test_greenhouse_env.py`` and
``test_coverage_env.py`` recompute them. GreenhouseCoverage's ``distribution`` digests were recorded anew when
its sensors began to take each episode's drawn arguments (the drawn ``vegetation_echo_prob`` had been ignored;
no version bump: only ``scene_distribution="training"`` episodes changed, every other digest stayed). Write
the file anew only for a deliberate change of the envs' episodes (which also bumps their versions):

    python tests/envs/greenhouse_reference.py tests/data/greenhouse_digests.json
"""

import hashlib
import json
import math
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import agri_envs  # noqa: F401
from agri_envs.scenes import EXAMPLE_MAP

NAV_ID = "agri_envs/GreenhouseNav-v2"
COVERAGE_ID = "agri_envs/GreenhouseCoverage-v2"
MAP_WAYPOINTS = [[1.0, 0.6], [8.6, 0.6], [8.6, 2.2], [1.0, 2.2]]

#: GreenhouseNav-v2 arguments whose episodes are pinned (``max_episode_steps`` goes to ``gym.make``).
NAV_CASES: dict[str, dict] = {
    "default": {},
    "people-tease": {"n_people": 5, "people_tease_prob": 0.9, "terminate_on_collision": False, "max_episode_steps": 90},
    "growth-trees": {"n_rows": 4, "growth": 0.8, "n_trees": 6, "corridor_width": 1.4, "max_episode_steps": 70},
    "layout-fixed": {"layout_seed": 7, "n_people": 3, "max_episode_steps": 60},
    "corridor": {"scene": "corridor", "n_people": 3, "terminate_on_collision": False, "max_episode_steps": 80},
    "corridor-repeatability": {"scene": "corridor", "office_route": "repeatability", "office_length": 9.0},
    "map": {"scene": "map", "map_yaml": str(EXAMPLE_MAP), "waypoints": MAP_WAYPOINTS, "n_people": 1},
    "odometry": {"localization": "odometry", "n_people": 0, "max_episode_steps": 50},
    "none-full-scan": {"localization": "none", "full_scan": True, "lidar_beams": 811, "max_episode_steps": 40},
    "frame-skip": {"frame_skip": 4, "n_people": 3, "terminate_on_collision": False},
    "short-limit": {"max_episode_steps": 25, "n_people": 2},
    "short-limit-skip": {"max_episode_steps": 9, "frame_skip": 3, "localization": "odometry"},
    "noisy": {"lidar_noise_std": 0.3, "lidar_dropout": 0.3, "sonar_noise_std": 0.2, "lidar_beams": 17},
    "noise-free": {"lidar_noise_std": 0.0, "lidar_dropout": 0.0, "sonar_noise_std": 0.0, "odometry_gyro_bias": 0.0},
    "small-mission": {
        "n_rows": 1,
        "row_length": 2.0,
        "n_people": 0,
        "time_limit_speed_fraction": 1.0,
        "waypoint_radius": 1.0,
        "safety_margin": 0.0,
    },
    "cycles": {
        "mission_cycles": 2,
        "time_limit_speed_fraction": 0.8,
        "n_rows": 1,
        "row_length": 2.0,
        "n_people": 1,
        "waypoint_radius": 0.8,
    },
    "fast-robot": {"max_speed": 2.0, "max_turn_rate": 4.0, "max_accel": 10.0, "control_period": 0.2},
    "distribution": {"scene_distribution": "training", "max_episode_steps": 120},
}

#: GreenhouseCoverage-v2 arguments whose episodes are pinned.
COVERAGE_CASES: dict[str, dict] = {
    "default": {},
    "ground-truth": {"localization": "ground_truth", "n_rows": 2, "row_length": 5.0},
    "layout-fixed": {"layout_seed": 3},
    "shaped": {"row_bend": 0.2, "row_incline": 0.02, "corridor_width": 2.0, "corridor_width_jitter": 0.3},
    "short-limit": {"time_limit": 3.0, "n_rows": 1},
    "no-termination": {"terminate_on_contact": False, "vegetation_echo_prob": 0.9, "reward_cross_track": 1.0},
    "noise-free": {"sonar_noise_std": 0.0, "vegetation_echo_prob": 0.0, "compass_noise_std": 0.0, "encoder_noise": 0.0},
    "quick": {"max_speed": 1.5, "max_accel": 2.0, "control_period": 0.5, "growth": 0.0, "bin_length": 1.0},
    "distribution": {"scene_distribution": "training", "time_limit": 40.0},
}


def _nav_action(info: dict, rng: np.random.Generator, steer: bool) -> np.ndarray:
    """A noisy drive toward the waypoint (``steer``), else a uniformly random action."""
    if not steer:
        return rng.uniform(-1, 1, 2).astype(np.float32)
    bearing = float(info["bearing_to_waypoint"])
    turn = max(-1.0, min(1.0, 2.0 * bearing)) + rng.normal(0.0, 0.3)
    forward = (0.8 if abs(bearing) < 0.6 else 0.1) + rng.normal(0.0, 0.2)
    return np.array([forward, turn], np.float32)


def _coverage_action(info: dict, rng: np.random.Generator, steer: bool) -> np.ndarray:
    """Mostly forward with a wandering turn (``steer``), else a uniformly random action."""
    if not steer:
        return rng.uniform(-1, 1, 2).astype(np.float32)
    return np.array([0.9 + rng.normal(0.0, 0.2), rng.normal(0.0, 0.6) - 0.3 * math.sin(info["yaw"])], np.float32)


def _nav_options(k: int, rng: np.random.Generator) -> dict | None:
    """Reset options that vary per episode: a later start, a season or a layout, or none."""
    kind = k % 4
    if kind == 1:
        return {"start_waypoint": int(rng.integers(0, 3))}
    if kind == 2:
        return {"growth": float(rng.uniform(0.0, 0.5)), "n_trees": int(rng.integers(0, 4))}
    if kind == 3:
        return {"layout_seed": int(rng.integers(0, 3))}
    return None


def rollout_digest(env_id: str, kwargs: dict, seed: int, steps: int = 400) -> tuple[str, dict[str, int]]:
    """SHA-256 of every observation, reward, flag and info of a seeded rollout (resets included), with counts.

    Episodes alternate between steered and random actions; GreenhouseNav resets also vary their options.

    Returns:
        The digest and how many episodes ended by termination, truncation, collision and success.
    """
    nav = env_id == NAV_ID
    env = gym.make(env_id, **kwargs)
    rng = np.random.default_rng(seed + 1000)
    h = hashlib.sha256()
    counts = {"episodes": 1, "terminated": 0, "truncated": 0, "collision": 0, "success": 0, "waypoints": 0}

    def add(obs, info, *rest):
        for k in sorted(obs):
            h.update(k.encode() + np.ascontiguousarray(obs[k], dtype=np.float32).tobytes())
        h.update(json.dumps(info, sort_keys=True).encode() + repr(rest).encode())

    obs, info = env.reset(seed=seed)
    add(obs, info)
    policy = _nav_action if nav else _coverage_action
    episode = 0
    for _ in range(steps):
        obs, r, term, trunc, info = env.step(policy(info, rng, steer=episode % 2 == 0))
        add(obs, info, float(r), term, trunc)
        if term or trunc:
            counts["terminated"] += int(term)
            counts["truncated"] += int(trunc)
            counts["collision"] += int(bool(info["collision"]))
            counts["success"] += int(bool(info["is_success"]))
            counts["waypoints"] += int(info.get("waypoints_reached", info.get("corridors_covered", 0)))
            episode += 1
            counts["episodes"] += 1
            options = _nav_options(episode, rng) if nav else None
            if nav and options and "start_waypoint" in options and kwargs.get("scene") == "map":
                options = None  # the map's short loop: keep the start
            obs, info = env.reset(options=options)
            add(obs, info)
    env.close()
    return h.hexdigest(), counts


def digests(env_id: str | None = None) -> dict[str, str]:
    """Digest of every case of both envs (or of ``env_id`` only) for seeds 0 and 1."""
    out = {}
    for eid, cases in ((NAV_ID, NAV_CASES), (COVERAGE_ID, COVERAGE_CASES)):
        if env_id not in (None, eid):
            continue
        for name, kw in cases.items():
            for seed in (0, 1):
                out[f"{eid}/{name}/seed-{seed}"] = rollout_digest(eid, kw, seed)[0]
    return out


def recorded(env_id: str) -> dict[str, str]:
    """The digests of ``env_id``'s cases in ``tests/data/greenhouse_digests.json``."""
    path = Path(__file__).parents[1] / "data" / "greenhouse_digests.json"
    return {k: v for k, v in json.loads(path.read_text()).items() if k.startswith(env_id + "/")}


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[2] == "--counts":
        for env_id, cases in ((NAV_ID, NAV_CASES), (COVERAGE_ID, COVERAGE_CASES)):
            for name, kw in cases.items():
                print(env_id, name, [rollout_digest(env_id, kw, s)[1] for s in (0, 1)])
    with open(sys.argv[1], "w") as f:
        json.dump(digests(), f, indent=1, sort_keys=True)
        f.write("\n")
