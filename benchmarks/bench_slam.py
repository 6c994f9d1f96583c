"""Hector SLAM speed and accuracy on recorded GreenhouseNav-v2 drives, next to KISS-ICP on the same scans.

Records drives of the privileged ``harik-apf-gt`` controller (811-beam scans with the env's noise and
dropouts, people walking), then replays the scans through

* ``HectorSlam`` (ours, with its free-space guard and step check: the ``harik-apf`` default),
* ``HectorSlam`` without them (plain Hector, as ROS ``hector_mapping``),
* KISS-ICP (``pip install kiss-icp``), a LIDAR odometry from PyPI, as a peer (skipped when missing),

and prints, per method, the time of one update (median and 95th percentile, one core) and the absolute
trajectory error against the ground truth (no alignment fitted: every estimate starts at the true start
pose, as on the robot)::

    python benchmarks/bench_slam.py [--scenario sim-loop] [--episodes 3]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import agri_envs  # noqa: F401
from agri_baselines import make_policy
from agri_baselines.hector_slam import HectorSlam, HectorSlamConfig
from agri_envs.scenarios import scenario
from agri_training.evaluation.episode import localization_errors, start_frame_to_world

ENV_ID = "agri_envs/GreenhouseNav-v2"


def record(scenario_name: str, seed: int) -> tuple[np.ndarray, np.ndarray, gym.Env]:
    """Scans (m) and true poses of one ``harik-apf-gt`` episode of the scenario's first level."""
    _, kwargs = scenario(ENV_ID, scenario_name).levels()[0]
    env = gym.make(ENV_ID, **{**kwargs, "full_scan": True, "localization": "ground_truth"})
    policy = make_policy("harik-apf-gt", env)
    max_range = env.unwrapped.lidar.spec.max_range
    obs, info = env.reset(seed=seed)
    scans, truth, start = [], [], True
    while True:
        scans.append(obs["scan"].astype(np.float64) * max_range)
        truth.append((info["x"], info["y"], info["yaw"]))
        action, _ = policy.predict(obs, episode_start=np.array([start]))
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    return np.array(scans), np.array(truth), env


def run_hector(config: HectorSlamConfig, env: gym.Env) -> Callable[[np.ndarray], np.ndarray]:
    """A fresh Hector SLAM; the returned function maps one scan to the robot pose in the start frame."""
    spec = env.unwrapped.lidar.spec
    slam = HectorSlam(config, spec.beam_angles, spec.mount)
    return slam.update


def run_kiss_icp(env: gym.Env) -> Callable[[np.ndarray], np.ndarray] | None:
    """A fresh KISS-ICP odometry on the scan's 3D points (z = 0), or None when kiss-icp is not installed."""
    try:
        from kiss_icp.config import KISSConfig
        from kiss_icp.kiss_icp import KissICP
    except ImportError:
        return None
    spec = env.unwrapped.lidar.spec
    config = KISSConfig()
    config.data.max_range = spec.max_range - 1e-3  # drop no-echo beams
    config.data.min_range = spec.min_range
    config.data.deskew = False
    config.mapping.voxel_size = 0.05  # its best ATE here among 0.05, 0.1 (its default) and 0.2 m
    config.registration.max_num_threads = 1  # one core, like Hector here
    odometry = KissICP(config)
    angles = spec.beam_angles
    mx, my, myaw = spec.mount
    mount = np.array([[math.cos(myaw), -math.sin(myaw), mx], [math.sin(myaw), math.cos(myaw), my], [0, 0, 1]])
    mount_inv = np.linalg.inv(mount)

    def update(ranges: np.ndarray) -> np.ndarray:
        keep = ranges < spec.max_range - 1e-6
        r = ranges[keep]
        points = np.stack([r * np.cos(angles[keep]), r * np.sin(angles[keep]), np.zeros(r.size)], axis=1)
        odometry.register_frame(points, np.zeros(0))
        sensor = odometry.last_pose  # sensor pose in the first sensor frame (4x4)
        planar = np.eye(3)
        planar[:2, :2] = sensor[:2, :2]
        planar[:2, 2] = sensor[:2, 3]
        robot = mount @ planar @ mount_inv  # robot pose in the robot's start frame
        return np.array([robot[0, 2], robot[1, 2], math.atan2(robot[1, 0], robot[0, 0])])

    return update


def replay(
    update: Callable[[np.ndarray], np.ndarray], scans: np.ndarray, truth: np.ndarray
) -> tuple[list[float], dict[str, float]]:
    """Per-scan update times (s) and the localization errors of the estimate."""
    times, estimate = [], []
    for ranges in scans:
        t0 = time.perf_counter()
        estimate.append(update(ranges))
        times.append(time.perf_counter() - t0)
    return times, localization_errors(truth, start_frame_to_world(truth[0], np.array(estimate)))


def main() -> None:
    """Record, replay, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="sim-loop")
    parser.add_argument("--episodes", type=int, default=3)
    args = parser.parse_args()
    methods: dict[str, Callable[[gym.Env], Callable[[np.ndarray], np.ndarray] | None]] = {
        "hector (ours, with safeguards)": lambda env: run_hector(HectorSlamConfig(), env),
        "hector (plain)": lambda env: run_hector(HectorSlamConfig(free_space_guard=None, max_step_halvings=0), env),
        "kiss-icp (PyPI peer)": run_kiss_icp,
    }
    # Compile the numba kernels outside the timed runs.
    scans, truth, env = record(args.scenario, 10_000)
    replay(run_hector(HectorSlamConfig(), env), scans[:50], truth[:50])
    times: dict[str, list[float]] = {m: [] for m in methods}
    errors: dict[str, list[dict]] = {m: [] for m in methods}
    n_scans = 0
    for seed in range(args.episodes):
        scans, truth, env = record(args.scenario, seed)
        n_scans += len(scans)
        for name, factory in methods.items():
            update = factory(env)
            if update is None:
                continue
            t, e = replay(update, scans, truth)
            times[name] += t[1:]  # the first scan only initialises the map
            errors[name].append(e)
        env.close()
    beams = scans.shape[1]
    print(f"{args.scenario}: {args.episodes} drives of harik-apf-gt, {n_scans} scans of {beams} beams at 15 Hz")
    print(f"{'method':34s} {'median ms':>9s} {'p95 ms':>7s} {'x real time':>11s} {'ATE RMSE m':>10s} {'final m':>8s}")
    for name in methods:
        if not times[name]:
            print(f"{name:34s} (not installed: pip install kiss-icp)")
            continue
        median = statistics.median(times[name]) * 1e3
        p95 = float(np.percentile(times[name], 95)) * 1e3
        ate = statistics.mean(e["ate_rmse"] for e in errors[name])
        final = statistics.mean(e["final_position_error"] for e in errors[name])
        realtime = (1 / 15) / statistics.mean(times[name])
        print(f"{name:34s} {median:9.3f} {p95:7.3f} {realtime:10.0f}x {ate:10.3f} {final:8.3f}")
    print("x real time: the 15 Hz scan period over the mean update time; one process, one thread.")


if __name__ == "__main__":
    main()
