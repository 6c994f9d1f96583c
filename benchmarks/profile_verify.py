"""Where ``agri leaderboard verify`` spends its time: per entry and per part, plus what each process pays once.

Per entry, the entry is verified in this process (``--workers 1``, as one worker of the pool runs it) with
``perf_counter`` timers around the calls (no profiler overhead). Each timer counts its own time only (timed
calls inside it count for themselves), so the parts of an entry add up to its wall time:

* ``env build``: ``agri_envs.make`` (once per entry and level: the worker's env cache);
* ``policy build``: ``build_policy`` (once per episode: a fresh policy per job);
* ``reset`` and ``step``: the env's, through ``gym.make``'s wrappers (the episode loop's calls), or its batched
  form's (``gym.make_vec``) where episodes run batched;
* ``policy``: the policy's ``predict`` without the two parts below;
* ``network``: a learned policy's forward pass (:class:`~agri_training.learned.inference.PolicyNetwork`);
* ``SLAM``: ``HectorSlam.update`` (``harik-apf``'s localization);
* ``summaries``: the summaries and their bootstrap intervals; ``compare``: verify's comparison;
* ``loop``: the rest (the episode loop, records, traces, job plumbing).

Then, with ``--startup``, the parts each verify pays once: the ``agri`` process start-up (imports), the
worker pool's start-up (forkserver with the preloaded modules, 2 workers), each env family's first episode
in a fresh worker beyond its later ones (numba kernels loaded from the on-disk cache, or compiled when the
cache is cold; first imports of the family's modules) and the LEADERBOARD.md check.

    python benchmarks/profile_verify.py --startup --out /tmp/profile.json     # every entry, then start-up
    python benchmarks/profile_verify.py --entries greenhouse-sim-loop/harik   # entries whose path holds this

Run it alone on its cores (``cpuslot``): the times are wall times.
"""

from __future__ import annotations

import os  # isort: skip
import sys  # isort: skip

from agri_training.__main__ import pin_numeric_kernels  # isort: skip  (before numpy)

if "numpy" not in sys.modules:  # a worker process importing this script as __mp_main__ has them already
    pin_numeric_kernels()

import argparse  # noqa: E402
import functools  # noqa: E402
import importlib  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402

import agri_envs  # noqa: E402
import agri_training.evaluation.episode as episode_module  # noqa: E402
import agri_training.evaluation.evaluate as evaluate_module  # noqa: E402
import agri_training.evaluation.parallel as parallel_module  # noqa: E402
import agri_training.leaderboard.entries as entries_module  # noqa: E402
from agri_baselines.hector_slam import HectorSlam  # noqa: E402
from agri_training import leaderboard as lb  # noqa: E402
from agri_training.learned.inference import PolicyNetwork  # noqa: E402

PARTS = ("env build", "policy build", "reset", "step", "policy", "network", "SLAM", "summaries", "compare", "loop")
#: Exclusive seconds per part of the entry being profiled.
SPENT: defaultdict[str, float] = defaultdict(float)
_INNER: list[float] = []


def timed(name: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` adding its own wall time (less that of the timed calls inside it) to ``SPENT[name]``."""

    @functools.wraps(fn)
    def run(*args: Any, **kwargs: Any) -> Any:
        _INNER.append(0.0)
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            elapsed = time.perf_counter() - t0
            SPENT[name] += elapsed - _INNER.pop()
            if _INNER:
                _INNER[-1] += elapsed

    return run


def _timed_policy(load: Callable[..., Any]) -> Callable[..., Any]:
    def build(ref: Any, env: Any) -> Any:
        policy = load(ref, env)
        policy.predict = timed("policy", policy.predict)
        return policy

    return build


def instrument() -> None:
    """Put the timers around the calls of a verify (module globals, so every caller sees them)."""
    agri_envs.make = timed("env build", agri_envs.make)  # type: ignore[assignment]
    parallel_module.build_policy = timed("policy build", _timed_policy(parallel_module.build_policy))
    for driver in (episode_module._SingleAgent, episode_module._Team):
        driver.reset = timed("reset", driver.reset)  # type: ignore[method-assign]
        driver.step = timed("step", driver.step)  # type: ignore[method-assign]
    for env_id in agri_envs.env_ids():  # the batched forms' steps and resets, where an env has one
        entry_point = gym.registry[env_id].vector_entry_point if env_id in gym.registry else None
        if isinstance(entry_point, str):
            module, name = entry_point.split(":")
            vector_class = getattr(importlib.import_module(module), name)
            if not getattr(vector_class.step, "__wrapped__", None):
                vector_class.reset = timed("reset", vector_class.reset)
                vector_class.step = timed("step", vector_class.step)
    PolicyNetwork.act = timed("network", PolicyNetwork.act)  # type: ignore[method-assign]
    HectorSlam.update = timed("SLAM", HectorSlam.update)  # type: ignore[method-assign]
    evaluate_module.summarize = timed("summaries", evaluate_module.summarize)
    entries_module.summarize = evaluate_module.summarize
    entries_module.compare_documents = timed("compare", entries_module.compare_documents)


def profile_entries(selected: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Verify each entry alone, in this process, and return its wall time, parts and problems."""
    rows = []
    for entry in selected:
        name = f"{entry['suite']['name']}/{entry['policy']['name']}"
        SPENT.clear()
        t0 = time.perf_counter()
        problems = lb.verify_entries([entry], workers=1, progress=False)
        wall = time.perf_counter() - t0
        parts = {p: SPENT.get(p, 0.0) for p in PARTS if p != "loop"}
        parts["loop"] = wall - sum(parts.values())
        episodes = sum(len(level["episodes"]) for level in entry["levels"])
        steps = sum(e["steps"] for level in entry["levels"] for e in level["episodes"])
        rows.append({"entry": name, "wall_s": wall, "episodes": episodes, "steps": steps, "parts": parts,
                     "problems": len(problems)})  # fmt: skip
        shown = "  ".join(f"{p} {parts[p]:.1f}" for p in PARTS if parts[p] >= 0.05)
        print(f"{name:58s} {wall:7.1f} s  {'OK ' if not problems else 'FAIL'} {shown}", flush=True)
    return rows


_FIRST_EPISODE = """
import time, json, sys
from agri_training.__main__ import pin_numeric_kernels
pin_numeric_kernels()
t0 = time.perf_counter()
import agri_training.evaluation.parallel as parallel, agri_envs, agri_baselines
preload = time.perf_counter() - t0
job = parallel.EpisodeJob(sys.argv[1], json.loads(sys.argv[2]), sys.argv[3], 100000)
times = []
for seed in (100000, 100001):
    t0 = time.perf_counter()
    result = parallel.run_job(parallel.EpisodeJob(job.env_id, job.env_kwargs, job.policy, seed))
    assert result["ok"], result
    times.append((time.perf_counter() - t0, sum(o["record"]["wall_time_s"] for o in result["outs"])))
print(json.dumps({"preload_s": preload, "first": times[0], "second": times[1]}))
"""


def startup_parts() -> dict[str, Any]:
    """What a verify pays once per process: start-up, the pool, each env family's first episode, the page check."""
    out: dict[str, Any] = {}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "agri_training", "leaderboard", "suites"], check=True, capture_output=True)
    out["agri start-up (imports, `agri leaderboard suites`)"] = time.perf_counter() - t0

    from agri_training.core.pool import run_items
    from agri_training.evaluation.parallel import PRELOAD

    t0 = time.perf_counter()
    run_items(abs, list(range(4)), lambda i, r: None, workers=2, preload=PRELOAD)
    out["worker pool start-up (forkserver, preload, 2 workers)"] = time.perf_counter() - t0

    # one representative (env, policy) per env family, as the suites run them
    nav, coverage = "agri_envs/GreenhouseNav-v2", "agri_envs/GreenhouseCoverage-v2"
    families = {
        "GreenhouseNav, harik-apf (Hector SLAM)": (nav, "greenhouse-sim-loop", "harik-apf"),
        "GreenhouseNav, ppo-greenhouse-nav": (nav, "greenhouse-sim-loop", "ppo-greenhouse-nav"),
        "GreenhouseCoverage, gonzalez-hybrid": (coverage, "coverage-almeria", "gonzalez-hybrid"),
        "robot_chain, apoorva-chain": ("robot_chain_v1", "chain-office", "apoorva-chain"),
        "GrapeHarvest, luo-apf": ("agri_envs/GrapeHarvest-v1", "grape-table2", "luo-apf"),
    }
    for label, (env_id, suite_name, policy) in families.items():
        suite = lb.find_suite(suite_name)
        request = evaluate_module.EvalRequest(env_id, policy, env_kwargs=dict(suite.env_kwargs))
        kwargs, _ = evaluate_module.resolve_env_kwargs(request)
        done = subprocess.run(
            [sys.executable, "-c", _FIRST_EPISODE, env_id, json.dumps(kwargs), policy],
            check=True,
            capture_output=True,
            text=True,
        )
        first = json.loads(done.stdout.splitlines()[-1])
        # first job beyond its episode, less the second job beyond its episode: the one-off cost of a worker
        extra = (first["first"][0] - first["first"][1]) - (first["second"][0] - first["second"][1])
        out[f"first episode in a fresh worker, {label}: beyond later ones"] = extra
        out.setdefault("worker imports (the preload, in a fresh process)", first["preload_s"])
    t0 = time.perf_counter()
    lb.leaderboard_is_current()
    out["LEADERBOARD.md check (render and compare)"] = time.perf_counter() - t0
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--entries", nargs="*", default=[], help="profile entries whose path holds one of these")
    parser.add_argument("--no-entries", action="store_true", help="only the start-up parts")
    parser.add_argument("--startup", action="store_true", help="also the parts each verify pays once")
    parser.add_argument("--out", help="write the numbers as JSON here")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} at the start", flush=True)
    result: dict[str, Any] = {"load_start": os.getloadavg()[0]}
    if not args.no_entries:
        entries = [e for e in lb.load_entries() if not args.entries or any(s in e["_path"] for s in args.entries)]
        instrument()
        rows = profile_entries(entries)
        result["entries"] = rows
        total = sum(r["wall_s"] for r in rows)
        print(f"\n{len(rows)} entries, {total:.0f} s in one process; by part:")
        for part in PARTS:
            seconds = sum(r["parts"][part] for r in rows)
            print(f"  {part:14s} {seconds:8.1f} s  {100 * seconds / total:5.1f} %")
    if args.startup:
        parts = startup_parts()
        result["once"] = parts
        print("\nonce per verify (or per worker):")
        for name, seconds in parts.items():
            print(f"  {name:86s} {seconds:6.2f} s")
    result["load_end"] = os.getloadavg()[0]
    print(f"load average {result['load_end']:.2f} at the end")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
