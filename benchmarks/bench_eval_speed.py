"""Verify's hot paths next to what they replaced, in one run: the same results, and the time of each.

Every pair computes the same bits (the tests check it); this script times them side by side, taking turns
round by round so that a change of machine load hits both alike, and prints the median of the rounds:

* Hector SLAM, one scan: the compiled per-scan path against the earlier implementation
  (``tests/baselines/hector_reference.py``), on scans recorded from ``harik-apf-gt`` driving the default
  greenhouse with two people;
* a learned policy's forward pass, one decision: the compiled layers against the numpy reference, for each
  zoo network;
* harik's scan zones: compiled against the numpy statement;
* whole leaderboard entries (``--entries``, default: one of each kind that runs batched): verify with
  episodes stepped together in the env's batched form (``--batch 16``) against one episode at a time.

    python benchmarks/bench_eval_speed.py [--rounds 5] [--entries greenhouse-sim-loop/harik-apf-gt ...]

Run it alone on its cores (``cpuslot``), and read the load it prints.
"""

from __future__ import annotations

import os  # isort: skip
import sys  # isort: skip

from agri_training.__main__ import pin_numeric_kernels  # isort: skip  (before numpy)

if "numpy" not in sys.modules:  # a worker process importing this script as __mp_main__ has them already
    pin_numeric_kernels()

import argparse  # noqa: E402
import functools  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import agri_envs  # noqa: E402, F401
from agri_baselines import make_policy  # noqa: E402
from agri_baselines.harik_apf import scan_zones, scan_zones_reference  # noqa: E402
from agri_baselines.hector_slam import HectorSlam, HectorSlamConfig  # noqa: E402
from agri_training import leaderboard as lb  # noqa: E402
from agri_training.evaluation.policies import load_policy  # noqa: E402
from agri_training.learned.zoo import ZOO_DIR  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "baselines"))
from hector_reference import ReferenceHectorSlam  # noqa: E402

NAV = "agri_envs/GreenhouseNav-v2"
DEFAULT_ENTRIES = (
    "greenhouse-sim-loop/harik-apf-gt",
    "greenhouse-sim-loop/harik-apf.json",
    "greenhouse-sim-loop/ppo-greenhouse-nav",
    "greenhouse-corridor/ppo-greenhouse-nav",
)


def recorded_scans(steps: int = 1200) -> tuple[list[np.ndarray], dict[str, np.ndarray]]:
    """Full scans (m) of harik-apf-gt driving the default greenhouse, and the LIDAR's geometry."""
    env = gym.make(NAV, full_scan=True, localization="ground_truth")
    policy = make_policy("harik-apf-gt", env)
    obs, _ = env.reset(seed=3)
    spec = env.unwrapped.lidar.spec
    scans = []
    for k in range(steps):
        scans.append(obs["scan"].astype(np.float64) * spec.max_range)
        action, _ = policy.predict(obs, episode_start=np.array([k == 0]))
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
    return scans, {"beam_angles": spec.beam_angles, "lidar_mount": spec.mount}


def take_turns(runs: dict[str, Callable[[], float]], rounds: int) -> dict[str, float]:
    """Median over ``rounds`` of each measurement (each returns its own time per unit), taking turns.

    One round first warms both up (compiled kernels loaded from numba's cache, imports), untimed.
    """
    for run in runs.values():
        run()
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            times[name].append(run())
    return {name: statistics.median(values) for name, values in times.items()}


def per_call(fn: Callable[[], object], calls: int) -> Callable[[], float]:
    def run() -> float:
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        return (time.perf_counter() - t0) / calls

    return run


def slam_rows(rounds: int) -> list[tuple[str, str, float, float]]:
    scans, geometry = recorded_scans()

    def per_scan(cls: type) -> Callable[[], float]:
        def run() -> float:
            slam = cls(HectorSlamConfig(), **geometry)
            t0 = time.perf_counter()
            for scan in scans:
                slam.update(scan)
            return (time.perf_counter() - t0) / len(scans)

        return run

    t = take_turns({"new": per_scan(HectorSlam), "old": per_scan(ReferenceHectorSlam)}, rounds)
    return [("Hector SLAM update", "us a scan", t["old"] * 1e6, t["new"] * 1e6)]


def network_rows(rounds: int) -> list[tuple[str, str, float, float]]:
    rows = []
    for name, env_id, kwargs in (
        ("ppo-greenhouse-nav", NAV, {"localization": "ground_truth"}),
        ("ppo-coverage-almeria", "agri_envs/GreenhouseCoverage-v0", {}),
    ):
        if not (ZOO_DIR / name).is_dir():
            continue
        env = agri_envs.make(env_id, **kwargs)
        net = load_policy(name, env).network
        x = np.random.default_rng(0).normal(size=(1, net.hidden[0][0].shape[1])).astype(np.float32)
        compiled, reference = functools.partial(net.output_layer, x), functools.partial(net.reference_output_layer, x)
        t = take_turns({"new": per_call(compiled, 2000), "old": per_call(reference, 500)}, rounds)
        rows.append((f"forward pass, {name}", "us a decision", t["old"] * 1e6, t["new"] * 1e6))
    return rows


def zones_rows(rounds: int) -> list[tuple[str, str, float, float]]:
    scans, geometry = recorded_scans(300)
    angles = geometry["beam_angles"] + geometry["lidar_mount"][2]
    cos, sin = np.cos(angles), np.sin(angles)
    mount = geometry["lidar_mount"]
    args = (cos, sin, float(mount[0]), float(mount[1]), 10.0 - 1e-6, 0.3, 0.25, 0.05, 0.3)

    def over(fn: Callable[..., object]) -> Callable[[], float]:
        def run() -> float:
            t0 = time.perf_counter()
            for scan in scans:
                fn(scan, *args)
            return (time.perf_counter() - t0) / len(scans)

        return run

    t = take_turns({"new": over(scan_zones), "old": over(scan_zones_reference)}, rounds)
    return [("harik scan zones", "us a step", t["old"] * 1e6, t["new"] * 1e6)]


def entry_rows(names: list[str], rounds: int) -> list[tuple[str, str, float, float]]:
    rows = []
    entries = lb.load_entries()
    for name in names:
        entry = next(e for e in entries if name in e["_path"])

        def verify(batch: int, entry: dict = entry) -> Callable[[], float]:
            def run() -> float:
                t0 = time.perf_counter()
                problems = lb.verify_entries([entry], workers=1, progress=False, batch=batch)
                if problems:
                    raise SystemExit(f"{entry['_path']} (batch {batch}): {problems[:3]}")
                return time.perf_counter() - t0

            return run

        t = take_turns({"batched": verify(16), "one at a time": verify(1)}, max(1, rounds // 2))
        label = f"verify {entry['suite']['name']}/{entry['policy']['name']}"
        rows.append((label, "s", t["one at a time"], t["batched"]))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--entries", nargs="*", default=list(DEFAULT_ENTRIES))
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} at the start; median of {args.rounds} rounds", flush=True)
    rows = slam_rows(args.rounds) + network_rows(args.rounds) + zones_rows(args.rounds)
    rows += entry_rows(args.entries, args.rounds)
    print(f"{'':62s} {'before':>10s} {'after':>10s} {'speed-up':>9s}")
    for label, unit, old, new in rows:
        print(f"{label + ' [' + unit + ']':62s} {old:10.2f} {new:10.2f} {old / new:8.2f}x")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
