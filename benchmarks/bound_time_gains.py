"""How much time any policy could save against the best scripted one: GreenhouseCoverage and robot_chain.

Issue 38 asks, for one of these two envs, a learned policy at least 10 % faster than the best scripted entry on
every suite of the env that is not a stress suite, at 1.00 success without contact. This script measures how much
room the envs leave, on the suites' own held-out seeds and arguments, against the committed entries (the best
scripted entry as the leaderboard's "Where learning beats the papers" picks it):

* GreenhouseCoverage: the training teacher ``coverage-half-circle`` (``agri_baselines.coverage_teacher``), an
  oracle that knows the true corridor centre lines (``env.unwrapped.corridor_lines()``), drives them end to end
  and turns into the next corridor on a half circle that starts right at the corridor's end, with Pure Pursuit
  at the Fitorobot's limits (``gonzalez-deliberative``'s tracker, the same speed, turn rate and acceleration).
  The straights at the speed limit take most of the time; only the headland turns can get shorter.
  ``--extend`` moves the turns out into the headland (m).
* robot_chain: ``apoorva-chain`` with the ghost (the env's pace setter along the A* path, 0.35 m/s, which is
  all the leader sees of its path) run at the robots' top speed 0.4 m/s and beyond (the leader then runs at
  its limit the whole way). A leader that ignores the ghost has no path ahead of it: only the goal's direction
  and its sonars.

The time it prints is the mean episode time (s); ``oracle / best`` below 0.90 leaves room for the 10 %.

    python benchmarks/bound_time_gains.py [--episodes 20] [--extend 0.0] [--ghost-speeds 0.4 0.6]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import agri_envs
from agri_baselines import make_policy
from agri_baselines.coverage_teacher import HalfCircleTeacher
from agri_training.evaluation.episode import run_episode
from agri_training.leaderboard.entries import load_entries
from agri_training.leaderboard.gains import best_scripted
from agri_training.leaderboard.suites import Suite, load_suites

COVERAGE = "agri_envs/GreenhouseCoverage-v2"
CHAIN = "robot_chain_v1"


def coverage_oracle_times(suite: Suite, extend: float, episodes: int) -> list[tuple[float, bool, bool]]:
    """``(episode time, success, contact)`` of the half-circle teacher on the suite's first ``episodes`` seeds."""
    env = gym.make(COVERAGE, **{**suite.env_kwargs, "localization": "ground_truth"})
    out = []
    for seed in suite.seeds[:episodes]:
        record = run_episode(env, HalfCircleTeacher(env, extend=extend), seed, None)["record"]
        out.append((float(record["episode_time"]), bool(record["is_success"]), bool(record["collision"])))
    env.close()
    return out


def chain_times(suite: Suite, ghost_speed: float, episodes: int) -> list[tuple[float, bool, bool]]:
    """``(episode time, success, contact)`` of ``apoorva-chain`` with the ghost at ``ghost_speed`` (m/s)."""
    env = agri_envs.make(CHAIN, **{**suite.env_kwargs, "ghost_speed": ghost_speed})
    out = []
    for seed in suite.seeds[:episodes]:
        record = run_episode(env, make_policy("apoorva-chain", env), seed, None)["record"]
        out.append((float(record["episode_time"]), bool(record["is_success"]), bool(record["collision"])))
    return out


def best_time(suite: Suite, entries: Sequence[dict[str, Any]]) -> tuple[str, float]:
    """The best scripted entry's name and mean episode time on ``suite`` (as the gains section picks it)."""
    group = [e for e in entries if e["suite"]["name"] == suite.name]
    best = best_scripted(group, "mean_episode_time", higher_is_better=False)
    if best is None:
        raise ValueError(f"suite {suite.name} has no scripted entry with an episode time")
    return best["policy"]["name"], float(best["summary"]["mean_episode_time"])


def main() -> None:
    """Print the bounds, one line per suite and setting."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=20, help="seeds of each suite (from its first)")
    parser.add_argument("--extend", type=float, default=0.0, help="oracle turns this far past the corridor ends (m)")
    parser.add_argument("--ghost-speeds", type=float, nargs="+", default=[0.4, 0.6], help="ghost speeds (m/s)")
    args = parser.parse_args()
    entries = load_entries()
    learned_suites = {e["suite"]["name"] for e in entries if e["policy"]["kind"] == "learned"}
    suites = [s for s in load_suites() if s.stress is None and s.name in learned_suites]
    print(f"{'suite':28s} {'best scripted':24s} {'its time':>9s} {'setting':>18s} {'time':>7s} {'ratio':>6s} ok")
    for suite in suites:
        if suite.env_id == COVERAGE:
            runs = [(f"extend {args.extend:.2f} m", coverage_oracle_times(suite, args.extend, args.episodes))]
        elif suite.env_id == CHAIN:
            runs = [(f"ghost {g:.2f} m/s", chain_times(suite, g, args.episodes)) for g in args.ghost_speeds]
        else:
            continue
        name, scripted = best_time(suite, entries)
        for setting, results in runs:
            mean = float(np.mean([t for t, _, _ in results]))
            ok = sum(s and not c for _, s, c in results)
            print(
                f"{suite.name:28s} {name:24s} {scripted:9.1f} {setting:>18s} {mean:7.1f} {mean / scripted:6.3f} "
                f"{ok}/{len(results)}"
            )


if __name__ == "__main__":
    main()
