"""Wall time of a 4-seed training sweep on 2 workers against 2 sequential single runs, in one run.

The peer is what a user does without sweeps: ``agri train`` twice, one after the other (here in this
process, with every module already imported, so the peer pays no start-up at all). The sweep then trains
4 seeds with the same env, algorithm and budget on 2 worker processes (one CPU and one torch thread per run),
and, with ``--ray``, the same 4 seeds as Ray tasks on a private 2-CPU Ray instance (start-up included, and
printed apart). The issue asks: sweep wall <= 1.15 x the 2 sequential runs' wall.

The script also checks that the sweep's seeds 0 and 1 reproduce the sequential runs' learning curves
(every number but wall time): where a run executes must not change what it learns.

    python benchmarks/bench_sweep.py                       # PPO on GreenhouseNav-v2, 32768 steps per run
    python benchmarks/bench_sweep.py --ray                 # also the sweep as Ray tasks (--ray local)
    python benchmarks/bench_sweep.py --timesteps 8192 --env agri_envs/GreenhouseCoverage-v2
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path

from agri_training.sweep import SweepRequest, read_curve, run_sweep
from agri_training.train import TrainRequest, train


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg())


def same_curve(a: Path, b: Path) -> bool:
    strip = [{k: v for k, v in row.items() if k != "wall_time_s"} for row in read_curve(a / "curve.csv")]
    return strip == [{k: v for k, v in row.items() if k != "wall_time_s"} for row in read_curve(b / "curve.csv")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="agri_envs/GreenhouseNav-v2")
    parser.add_argument("--algo", default="ppo")
    parser.add_argument("--timesteps", type=int, default=32768)
    parser.add_argument("--ray", action="store_true", help="also run the sweep as Ray tasks (--ray local, 2 CPUs)")
    parser.add_argument("--out", default=None, help="keep the runs here (default: a temporary folder)")
    args = parser.parse_args()
    root = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    common = {"env_id": args.env, "algo": args.algo, "timesteps": args.timesteps}
    print(f"{args.algo} on {args.env}, {args.timesteps} steps per run, {os.cpu_count()} cores; {load()}")

    t0, c0 = time.perf_counter(), time.process_time()
    single = []
    for seed in (0, 1):
        t, c = time.perf_counter(), time.process_time()
        request = TrainRequest(out=root / f"sequential/seed{seed}", seed=seed, progress=False,
                               overrides={"torch_threads": 1}, **common)  # fmt: skip
        single.append(train(request, "bench_sweep.py sequential"))
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        print(f"  sequential run seed {seed}: {wall:.1f} s wall, {cpu:.1f} s CPU; {load()}", flush=True)
    sequential, sequential_cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"2 sequential runs: {sequential:.1f} s wall, {sequential_cpu:.1f} s CPU", flush=True)

    rows = [("2 sequential runs (the peer)", sequential)]
    backends: list[tuple[str, str | None]] = [("sweep, 4 seeds, --workers 2", None)]
    if args.ray:
        backends.append(("sweep, 4 seeds, --ray local (2 CPUs, incl. start-up)", "local"))
    for label, ray in backends:
        out = root / ("sweep-ray" if ray else "sweep-workers")
        t = time.perf_counter()
        if ray:  # start Ray apart, to print its start-up; the sweep then joins this instance
            import ray as ray_module

            from agri_training.core.pool import init_ray

            init_ray("local", 2)
            print(f"  Ray start-up (ray.init, 2 CPUs): {time.perf_counter() - t:.1f} s", flush=True)
        doc = run_sweep(SweepRequest(out=out, seeds=(0, 1, 2, 3), **common), workers=2, ray=ray, progress=False,
                        command=f"bench_sweep.py {label}")  # fmt: skip
        wall = time.perf_counter() - t
        if ray:
            ray_module.shutdown()
        rows.append((label, wall))
        runs = doc["summary"]["runs"]
        failed = [r["run"] for r in runs if r["status"] != "ok"]
        same = all(same_curve(single[s], out / f"seed{s}") for s in (0, 1)) if not failed else False
        print(
            f"{label}: {wall:.1f} s = {wall / sequential:.3f} x the sequential wall; per run "
            + ", ".join(f"{r['wall_time_s']:.1f}" for r in runs)
            + " s wall, "
            + ", ".join(f"{r['cpu_time_s']:.1f}" for r in runs)
            + f" s CPU (sum {sum(r['cpu_time_s'] for r in runs):.1f} s); failed {failed or 'none'}; "
            + f"seeds 0-1 curves equal the sequential runs': {same}; {load()}",
            flush=True,
        )

    print("\n| run | wall [s] | / 2 sequential runs |\n|---|---|---|")
    for label, wall in rows:
        print(f"| {label} | {wall:.1f} | {wall / sequential:.3f} |")
    verdict = "met" if rows[1][1] <= 1.15 * sequential else "NOT met"
    ratio = rows[1][1] / sequential
    print(f"\nmust reach: 4-seed sweep on 2 workers <= 1.15 x 2 sequential runs: {verdict} ({ratio:.3f})")
    if not args.out:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
