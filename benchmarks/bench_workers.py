"""Evaluation wall time with 1 and N worker processes (and Ray) in one run, with the records compared.

The serial run (``--workers 1``, episodes in this process) is the peer. Each parallel run must return the
same per-episode records (every number but the wall-clock timings); the script says whether it did.

    python benchmarks/bench_workers.py                        # harik-apf on sim-loop, 20 episodes, 1 vs 2 workers
    python benchmarks/bench_workers.py --ray                  # also --ray local with the same CPUs, and Ray's overhead
    python benchmarks/bench_workers.py --policy harik-apf-gt --episodes 40

Ray's overhead per episode is measured two ways: the round trip of an empty task (submitted in bulk, after
the workers started), and ``(wall on Ray with 1 CPU - serial wall) / episodes`` for the same episodes,
which also counts moving the records back and building the env once in the Ray worker.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

from agri_training.evaluation.evaluate import evaluate_many
from agri_training.evaluation.policies import EvalRequest

TIMINGS = ("wall_time_s", "planning_time_ms")


def strip_timings(doc: Any) -> Any:
    """The documents without wall-clock timings (the only numbers allowed to differ between runs)."""
    if isinstance(doc, dict):
        return {k: strip_timings(v) for k, v in doc.items() if not any(t in k for t in TIMINGS)}
    if isinstance(doc, list):
        return [strip_timings(v) for v in doc]
    return doc


def timed(requests: list[EvalRequest], workers: int, ray: str | None = None) -> tuple[float, list[dict[str, Any]]]:
    t0 = time.perf_counter()
    docs = evaluate_many(requests, progress=False, workers=workers, ray=ray)
    return time.perf_counter() - t0, docs


def episode_seconds(docs: list[dict[str, Any]]) -> list[float]:
    out = []
    for d in docs:
        for level in d.get("levels", [d]):
            out += [e["wall_time_s"] for e in level["episodes"]]
    return out


def ray_noop_overhead(cpus: int, tasks: int = 500) -> dict[str, float]:
    import ray

    from agri_training.core.pool import init_ray

    t0 = time.perf_counter()
    init_ray("local", cpus)
    noop = ray.remote(num_cpus=1)(_noop)
    ray.get([noop.remote(i) for i in range(4 * cpus)])  # workers up
    t1 = time.perf_counter()
    ray.get([noop.remote(i) for i in range(tasks)])
    t2 = time.perf_counter()
    ray.shutdown()
    return {"init_s": t1 - t0, "per_task_ms": (t2 - t1) / tasks * 1000.0 * cpus}


def _noop(i: int) -> int:
    return i


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="agri_envs/GreenhouseNav-v2")
    parser.add_argument("--policy", default="harik-apf")
    parser.add_argument("--scenario", default="sim-loop")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2, help="workers of the parallel run")
    parser.add_argument("--ray", action="store_true", help="also run on a local Ray instance and measure overhead")
    parser.add_argument("--json", default=None, help="also write the numbers to this file")
    args = parser.parse_args()
    requests = [EvalRequest(args.env, args.policy, args.episodes, 0, args.scenario or None)]
    print(f"{args.policy} on {args.env} [{args.scenario}], {args.episodes} episodes; {os.cpu_count()} cores, ")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())} (other processes share the cores)")

    # warm-up: numba's on-disk kernel cache and the imports, so neither run pays them
    evaluate_many([EvalRequest(args.env, args.policy, 1, 0, args.scenario or None)], progress=False, workers=1)

    rows: list[tuple[str, float, bool]] = []
    serial_s, serial = timed(requests, 1)
    rows.append(("--workers 1 (serial, the peer)", serial_s, True))
    par_s, par = timed(requests, args.workers)
    same = strip_timings(par) == strip_timings(serial)
    rows.append((f"--workers {args.workers}", par_s, same))
    result: dict[str, Any] = {
        "episodes": args.episodes,
        "serial_s": serial_s,
        "workers": args.workers,
        "parallel_s": par_s,
        "speedup": serial_s / par_s,
        "identical": same,
        "mean_episode_s": sum(episode_seconds(serial)) / args.episodes,
    }
    if args.ray:
        ray_s, on_ray = timed(requests, args.workers, "local")
        ray_same = strip_timings(on_ray) == strip_timings(serial)
        rows.append((f"--ray local ({args.workers} CPUs, incl. start-up)", ray_s, ray_same))
        ray1_s, on_ray1 = timed(requests, 1, "local")
        rows.append(("--ray local (1 CPU, incl. start-up)", ray1_s, strip_timings(on_ray1) == strip_timings(serial)))
        noop = ray_noop_overhead(1)
        result.update(
            ray_s=ray_s,
            ray_identical=ray_same,
            ray_1cpu_s=ray1_s,
            ray_init_s=noop["init_s"],
            ray_noop_task_ms=noop["per_task_ms"],
            ray_overhead_per_episode_s=(ray1_s - noop["init_s"] - serial_s) / args.episodes,
        )
    print(f"{'run':<44} {'wall [s]':>9} {'speed-up':>9} {'records':>10}")
    for name, wall, ok in rows:
        print(f"{name:<44} {wall:>9.2f} {serial_s / wall:>8.2f}x {'identical' if ok else 'DIFFER':>10}")
    print(f"mean episode (serial run): {result['mean_episode_s']:.3f} s")
    if args.ray:
        print(
            f"Ray: start-up {result['ray_init_s']:.2f} s; empty task round trip {result['ray_noop_task_ms']:.2f} ms "
            f"= {result['ray_noop_task_ms'] / 1000 / result['mean_episode_s']:.2%} of a mean episode; "
            "(1-CPU Ray wall - start-up - serial wall) / episodes = "
            f"{result['ray_overhead_per_episode_s'] * 1000:.1f} ms "
            f"= {result['ray_overhead_per_episode_s'] / result['mean_episode_s']:.1%} of a mean episode"
        )
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
