"""Speed of robot_chain_v1 next to VMAS's navigation scenario, and of agri_baselines.astar next to compiled peers.

Prints parallel steps/s (every robot moves once per step; random actions; one process pinned to one core;
median of several runs) for the chain with 4 and 64 robots, once with the default termination (a contact or
a break ends the episode, as under a learner's first policies: the resets are counted) and once without
(``terminate_on_collision=False``, ``terminate_on_break=False``, ``max_cycles=1_000_000``: stepping alone),
and the median reset time; next to VMAS ``navigation`` (4 agents, 1 env, CPU, torch on one thread, reset when
done), all measured in this run. Sixty-four robots need a floor with 34.65 m of free path behind the leader:
a 40 x 20 m office with six rooms a side, planned on a 0.1 m grid. Then milliseconds per search on
1000 x 1000 grids for our A* (numba), tcod's A* (libtcod, C) and scikit-image's ``MCP_Geometric`` (Cython
Dijkstra). The peers do not search exactly our graph: tcod and MCP allow diagonal steps past blocked corners
(MCP also costs a step by the mean of its two cells), so their path costs are printed too.

    python benchmarks/bench_chain.py [--seconds 3] [--runs 3] [--resets 100]

VMAS, tcod and scikit-image come with the ``bench`` extra: ``pip install -e ".[bench]"``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable, Iterator

import numpy as np

from agri_baselines import astar
from agri_envs.chain import robot_chain_v1
from agri_envs.sim2d.astar import path_cost


def _rate(step: Callable[[int], None], seconds: float, runs: int) -> float:
    """Median over ``runs`` of the calls per second of ``step(i)`` during ``seconds``."""
    rates = []
    for _ in range(runs):
        n = 0
        t0 = time.perf_counter()
        while True:
            step(n)
            n += 1
            if n % 50 == 0 and time.perf_counter() - t0 >= seconds:
                break
        rates.append(n / (time.perf_counter() - t0))
    return statistics.median(rates)


#: Arguments of the 64-robot chain: an office with room for it (robot_chain_v1 refuses a chain that does not fit).
BIG_FLOOR: dict[str, object] = {
    "office_width": 40.0,
    "office_height": 20.0,
    "office_rooms": 6,
    "min_goal_distance": 2.0,
    "map_resolution": 0.1,
}


def _chain_kwargs(n_robots: int, terminate: bool) -> dict[str, object]:
    kwargs: dict[str, object] = {"n_robots": n_robots, **(BIG_FLOOR if n_robots > 16 else {})}
    if not terminate:
        kwargs.update(terminate_on_collision=False, terminate_on_break=False, max_cycles=1_000_000)
    return kwargs


def chain_rate(n_robots: int, seconds: float, runs: int, terminate: bool = True) -> tuple[float, float]:
    """Parallel steps/s of robot_chain_v1 under random actions, and episodes per 1000 steps.

    With ``terminate`` the env's default termination applies and every reset a learner would see is timed.
    """
    env = robot_chain_v1.parallel_env(**_chain_kwargs(n_robots, terminate))
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (1000, n_robots, 2)).astype(np.float32)
    agents = list(env.possible_agents)
    batches = [dict(zip(agents, actions[i], strict=True)) for i in range(1000)]
    for i in range(100):  # warm-up: numba compilation and caches
        if not env.agents:
            env.reset(seed=i)
        env.step(batches[i])
    episodes = [0]

    def step(i: int) -> None:
        if not env.agents:
            env.reset(seed=i)
            episodes[0] += 1
        env.step(batches[i % 1000])

    steps = [0]

    def counted(i: int) -> None:
        step(i)
        steps[0] += 1

    rate = _rate(counted, seconds, runs)
    return rate, 1000.0 * episodes[0] / max(steps[0], 1)


def reset_ms(n_robots: int, resets: int) -> float:
    """Median time (ms) of ``reset(seed=s)`` for ``resets`` seeds (a new map every episode, the default)."""
    env = robot_chain_v1.parallel_env(**_chain_kwargs(n_robots, True))
    env.reset(seed=0)
    times = []
    for seed in range(1, resets + 1):
        t0 = time.perf_counter()
        env.reset(seed=seed)
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def vmas_rate(seconds: float, runs: int) -> float:
    """Steps/s of VMAS ``navigation`` with 4 agents, 1 env, on the CPU (random continuous actions)."""
    import torch
    import vmas

    torch.set_num_threads(1)
    env = vmas.make_env("navigation", num_envs=1, device="cpu", continuous_actions=True, n_agents=4, seed=0)
    env.reset()
    gen = torch.Generator().manual_seed(0)
    actions = [[torch.rand((1, 2), generator=gen) * 2 - 1 for _ in env.agents] for _ in range(1000)]
    for i in range(100):
        env.step(actions[i])

    def step(i: int) -> None:
        _, _, dones, _ = env.step(actions[i % 1000])
        if bool(dones.any()):
            env.reset()

    return _rate(step, seconds, runs)


def grids() -> Iterator[tuple[str, np.ndarray]]:
    """1000 x 1000 test grids (True = blocked); searches run from the corner (0, 0) to (999, 999)."""
    rng = np.random.default_rng(0)
    g = rng.random((1000, 1000)) < 0.25
    g[0, 0] = g[-1, -1] = False
    yield "random 25 % blocked", g
    g = np.zeros((1000, 1000), dtype=bool)
    g[100:, 300] = True
    g[:900, 600] = True
    yield "two long walls", g
    yield "empty", np.zeros((1000, 1000), dtype=bool)


def _best_ms(fn: Callable[[], object], runs: int) -> float:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times) * 1e3


def astar_table(runs: int) -> list[str]:
    """One line per grid: ms and path cost of our A*, tcod's A* and scikit-image's MCP."""
    lines = []
    try:
        import tcod
    except ImportError:
        tcod = None
    try:
        from skimage.graph import MCP_Geometric
    except ImportError:
        MCP_Geometric = None  # noqa: N806
    start, goal = (0, 0), (999, 999)
    astar(np.zeros((10, 10), dtype=bool), (0, 0), (9, 9))  # compile
    for name, grid in grids():
        path = astar(grid, start, goal)
        ours = _best_ms(lambda g=grid: astar(g, start, goal), runs)
        cells = [f"{name:<22}{ours:>10.1f}{path_cost(path) if path else float('nan'):>9.1f}"]
        if tcod is not None:
            walk = np.where(grid, 0, 1).astype(np.int8)

            def run_tcod(w: np.ndarray = walk) -> list:
                return tcod.path.AStar(w, diagonal=1.41421356).get_path(*start, *goal)

            steps = np.diff(np.array([start, *run_tcod()]), axis=0)
            t_ms = _best_ms(run_tcod, runs)
            cells.append(f"{t_ms:>10.1f}{np.hypot(*steps.T).sum():>9.1f}{ours / t_ms:>8.2f}x")
        else:
            cells.append(f"{'n/a':>27}")
        if MCP_Geometric is not None:
            cost = np.where(grid, np.inf, 1.0)

            def run_mcp(c: np.ndarray = cost) -> np.ndarray:
                return MCP_Geometric(c, fully_connected=True).find_costs([start], [goal])[0]

            m_ms = _best_ms(run_mcp, runs)
            cells.append(f"{m_ms:>10.1f}{run_mcp()[goal]:>9.1f}{ours / m_ms:>8.2f}x")
        lines.append("".join(cells))
    return lines


def main() -> None:
    """Run both benchmarks and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of one timed run")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--resets", type=int, default=100, help="seeds timed for the median reset")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):  # one core for every contender
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    rows = []
    for n in (4, 64):
        free_rate, _ = chain_rate(n, args.seconds, args.runs, terminate=False)
        term_rate, episodes = chain_rate(n, args.seconds, args.runs, terminate=True)
        rows.append((n, free_rate, term_rate, episodes, reset_ms(n, args.resets)))
    try:
        peer = vmas_rate(args.seconds, args.runs)
    except ImportError as exc:
        print(f"VMAS unavailable ({exc}); pip install -e '.[bench]'")
        peer = float("nan")
    head = ("steps/s", "vs VMAS", "ep/1k st", "reset ms")
    print(f"{'env (random actions, one core)':<58}" + "".join(f"{h:>10}" for h in head))
    for n, free_rate, term_rate, episodes, reset in rows:
        label = f"robot_chain_v1, {n} robots"
        ratio = term_rate / peer
        print(f"{label + ', default termination':<58}{term_rate:>10.0f}{ratio:>9.1f}x{episodes:>10.1f}{reset:>10.2f}")
        print(f"{label + ', no termination':<58}{free_rate:>10.0f}{free_rate / peer:>9.1f}x{'':>10}{'':>10}")
    print(f"{'VMAS navigation, 4 agents, 1 env, CPU (reset when done)':<58}{peer:>10.0f}{1.0:>9.1f}x")
    print(f"(64 robots: {', '.join(f'{k}={v}' for k, v in BIG_FLOOR.items())}; reset: median of {args.resets} seeds)")
    print()
    print(f"A* on 1000 x 1000 grids, (0, 0) -> (999, 999), best of {args.runs}: ms, path cost (cells), ours / peer")
    head = ("ours ms", "cost", "tcod ms", "cost", "ratio", "MCP ms", "cost", "ratio")
    print(f"{'grid':<22}" + "".join(f"{h:>{10 if 'ms' in h else 9}}" for h in head))
    for line in astar_table(args.runs):
        print(line)
    print(f"median of {args.runs} runs of {args.seconds} s; numpy {np.__version__}")


if __name__ == "__main__":
    main()
