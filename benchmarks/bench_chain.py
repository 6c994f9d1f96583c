"""Speed of robot_chain_v1 next to VMAS's navigation scenario, and of agri_baselines.astar next to compiled peers.

Prints parallel steps/s (every robot moves once per step; random actions; one process pinned to one core;
median of several runs) for the chain with 4 and 64 robots and for VMAS ``navigation`` (4 agents, 1 env,
CPU, torch on one thread), all measured in this run; then milliseconds per search on 1000 x 1000 grids for
our A* (numba), tcod's A* (libtcod, C) and scikit-image's ``MCP_Geometric`` (Cython Dijkstra). The peers do
not search exactly our graph: tcod and MCP allow diagonal steps past blocked corners (MCP also costs a step
by the mean of its two cells), so their path costs are printed too.

    python benchmarks/bench_chain.py [--seconds 3] [--runs 3]

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


def chain_rate(n_robots: int, seconds: float, runs: int) -> float:
    """Parallel steps/s of robot_chain_v1 under random actions (no termination on contact)."""
    kwargs: dict[str, object] = {"n_robots": n_robots, "terminate_on_collision": False, "max_cycles": 1_000_000}
    if n_robots > 16:  # room for a long chain
        kwargs.update(office_width=24.0, office_height=16.0, min_goal_distance=2.0)
    env = robot_chain_v1.parallel_env(**kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (1000, n_robots, 2)).astype(np.float32)
    agents = list(env.agents)
    batches = [dict(zip(agents, actions[i], strict=True)) for i in range(1000)]
    for i in range(100):  # warm-up: numba compilation and caches
        env.step(batches[i])

    def step(i: int) -> None:
        if not env.agents:
            env.reset(seed=i)
        env.step(batches[i % 1000])

    return _rate(step, seconds, runs)


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
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):  # one core for every contender
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    chain4 = chain_rate(4, args.seconds, args.runs)
    chain64 = chain_rate(64, args.seconds, args.runs)
    try:
        peer = vmas_rate(args.seconds, args.runs)
    except ImportError as exc:
        print(f"VMAS unavailable ({exc}); pip install -e '.[bench]'")
        peer = float("nan")
    print(f"{'env (random actions, one core)':<48}{'steps/s':>10}{'vs VMAS':>9}")
    print(f"{'robot_chain_v1, 4 robots':<48}{chain4:>10.0f}{chain4 / peer:>8.1f}x")
    print(f"{'robot_chain_v1, 64 robots':<48}{chain64:>10.0f}{chain64 / peer:>8.1f}x")
    print(f"{'VMAS navigation, 4 agents, 1 env, CPU':<48}{peer:>10.0f}{1.0:>8.1f}x")
    print()
    print(f"A* on 1000 x 1000 grids, (0, 0) -> (999, 999), best of {args.runs}: ms, path cost (cells), ours / peer")
    head = ("ours ms", "cost", "tcod ms", "cost", "ratio", "MCP ms", "cost", "ratio")
    print(f"{'grid':<22}" + "".join(f"{h:>{10 if 'ms' in h else 9}}" for h in head))
    for line in astar_table(args.runs):
        print(line)
    print(f"median of {args.runs} runs of {args.seconds} s; numpy {np.__version__}")


if __name__ == "__main__":
    main()
