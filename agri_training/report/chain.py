"""Report section of robot_chain_v1: formation snapshots (Fig. 8), straightness, the A* path on the map.

Straightness is compared with and without the elastic strip (the two registered policies).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from agri_envs.chain import robot_chain_v1
from agri_training.report.rover import draw_geometry


def _scene(result: dict[str, Any], seed: int) -> Any:
    """The env of a result rebuilt at ``seed`` (the map and the A* path are deterministic)."""
    env = robot_chain_v1.parallel_env(**result["env_kwargs"])
    env.reset(seed=seed)
    return env


def _draw_frame(
    ax: Any, env: Any, trace: dict[str, Any], k: int, radius: float, span: tuple[float, float], with_path: bool = True
) -> None:
    """One formation snapshot at step ``k``, centred on the robots, ``span`` (width, height) metres wide."""
    from matplotlib.patches import Circle

    draw_geometry(ax, env.chain_map.geometry)
    if with_path:
        path = np.asarray(trace["astar_path"])
        ax.plot(path[:, 0], path[:, 1], color="#c83c3c", lw=0.8, ls="--")
    for x, y, r in trace.get("obstacles", []):
        ax.add_patch(Circle((x, y), r, color="#444444"))
    p = np.asarray(trace["positions"][k])
    lead = np.asarray([q[0] for q in trace["positions"][: k + 1]])
    ax.plot(lead[:, 0], lead[:, 1], color="#1f3c88", lw=0.8)
    if len(p) >= 3:
        ax.plot([p[0, 0], p[-1, 0]], [p[0, 1], p[-1, 1]], color="#9640c8", lw=1.0)
    for j, (x, y) in enumerate(p):
        ax.add_patch(Circle((x, y), radius, color="#14327f" if j == 0 else "#2f6fd0", ec="k", lw=0.4))
    if "ghost_x" in trace:
        ax.plot(trace["ghost_x"][k], trace["ghost_y"][k], marker="o", mfc="none", mec="#5050ff", ms=5)
    centre = 0.5 * (p[:, :2].min(axis=0) + p[:, :2].max(axis=0))
    ax.set_xlim(centre[0] - span[0] / 2, centre[0] + span[0] / 2)
    ax.set_ylim(centre[1] - span[1] / 2, centre[1] + span[1] / 2)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=7)


def _formation_span(trace: dict[str, Any], picks: Any, pad: float = 1.5) -> tuple[float, float]:
    """One (width, height) in metres for every snapshot: the largest extent of the chain plus ``pad``."""
    ext = np.array([np.ptp(np.asarray(trace["positions"][int(k)])[:, :2], axis=0) for k in picks])
    return float(ext[:, 0].max() + 2 * pad), float(ext[:, 1].max() + 2 * pad)


def report_section(results: list[dict[str, Any]], out_dir: Path) -> str:
    """Plots and a table for the chain results; returns the Markdown section (images saved in ``out_dir``).

    Args:
        results: Evaluation results of robot_chain_v1 (one per policy and scenario level).
        out_dir: Report folder; figures go there.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = [
        "### Robot chain (Apoorva 2018)",
        "",
        "| policy | scenario | success | mean distance to strip [m] | max distance to strip [m] | max gap [m] "
        "| leader path / A* | time [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def fmt(s: dict[str, Any], key: str, f: str = "{:.3f}") -> str:
        v = s.get(key)
        if v is None:
            return "-"
        ci = s.get(f"{key}_ci")
        return f.format(v) + (f" [{f.format(ci[0])}, {f.format(ci[1])}]" if ci and None not in ci else "")

    for r in results:
        s = r["summary"]
        label = r.get("label") or r.get("scenario") or "default"
        lines.append(
            f"| {r['policy']} | {label} | {fmt(s, 'success_rate', '{:.2f}')} "
            f"| {fmt(s, 'mean_mean_strip_distance')} | {fmt(s, 'mean_max_strip_distance')} | "
            f"{fmt(s, 'mean_max_gap')} | {fmt(s, 'mean_path_ratio')} | {fmt(s, 'mean_episode_time', '{:.1f}')} |"
        )
    lines.append("")
    traced = [r for r in results if r.get("traces")]
    if not traced:
        return "\n".join(lines)
    main = next((r for r in traced if r["policy"] == "apoorva-chain"), traced[0])
    trace = main["traces"][0]["data"]
    seed = main["traces"][0]["seed"]
    env = _scene(main, seed)
    radius = env.robot_radius
    n = len(trace["positions"])
    # Fig. 8: formation snapshots along the run.
    picks = np.linspace(0, n - 1, 6).round().astype(int)
    span = _formation_span(trace, picks)
    fig, axes = plt.subplots(2, 3, figsize=(12, 2 * 4.0 * span[1] / span[0] + 1.6), layout="constrained")
    for ax, k, tag in zip(axes.ravel(), picks, "abcdef", strict=True):
        _draw_frame(ax, env, trace, int(k), radius, span)
        ax.set_title(f"({tag}) t = {k * env.config.control_period:.1f} s", fontsize=9)
    for ax in axes[1]:
        ax.set_xlabel("x [m]", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("y [m]", fontsize=8)
    fig.suptitle(
        f"{main['policy']} on {main.get('label') or main.get('scenario')}, seed {seed}: formation every "
        f"{(picks[1] - picks[0]) * env.config.control_period:.0f} s (every panel {span[0]:.1f} x {span[1]:.1f} m)",
        fontsize=10,
    )
    snap = "chain_formation.png"
    fig.savefig(out_dir / snap, dpi=110)
    plt.close(fig)
    # Straightness over time with and without the strip.
    fig, ax = plt.subplots(figsize=(8, 3.2))
    for r in traced:
        for tr in r["traces"][:1]:
            d = np.asarray(tr["data"]["mean_strip_distance_now"], dtype=float)
            t = np.arange(len(d)) * env.config.control_period
            ax.plot(t, d, label=f"{r['policy']} (seed {tr['seed']})")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mean distance to strip [m]")
    ax.set_title("Straightness of the chain: mean distance of the robots to the strip", fontsize=10)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    ax.grid(alpha=0.3)
    straight = "chain_straightness.png"
    fig.savefig(out_dir / straight, dpi=110, bbox_inches="tight")
    plt.close(fig)
    # The A* path on the whole map, with the leader's driven path.
    fig, ax = plt.subplots(figsize=(8, 6.2), layout="constrained")
    draw_geometry(ax, env.chain_map.geometry)
    blocked = env.chain_map.blocked
    xmin, ymin, xmax, ymax = env.chain_map.grid.bounds
    ax.imshow(
        np.where(blocked, 0.25, np.nan), origin="lower", extent=(xmin, xmax, ymin, ymax), cmap="Greys", vmin=0, vmax=1
    )
    path = np.asarray(trace["astar_path"])
    lead = np.asarray([q[0] for q in trace["positions"]])
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch

    ax.plot(path[:, 0], path[:, 1], color="#c83c3c", lw=1.5, label="A* path (inflated map)")
    ax.plot(lead[:, 0], lead[:, 1], color="#1f3c88", lw=1.0, label="leader's driven path")
    ax.plot(*path[0], "o", color="#1f3c88", ms=8, ls="", label="start")
    ax.plot(*path[-1], "*", color="#2a9d2a", ms=14, ls="", label="goal")
    handles, labels = ax.get_legend_handles_labels()
    obstacles = trace.get("obstacles", [])
    for x, y, r in obstacles:
        ax.add_patch(Circle((x, y), r, color="#e08a00", ec="k", lw=0.6, zorder=5))
    if obstacles:
        handles.append(Line2D([], [], marker="o", color="#e08a00", mec="k", ls="", ms=8))
        labels.append("dropped obstacle (where it rests)")
    handles.append(Patch(color="#d9d9d9"))
    labels.append("inflated obstacles (robot radius + margin)")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{main['policy']}, seed {seed}: the A* path on the map and the leader's path", fontsize=10)
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    amap = "chain_astar_map.png"
    fig.savefig(out_dir / amap, dpi=110)
    plt.close(fig)
    env.close()
    lines += [
        f"Formation snapshots of seed {seed} ({main['policy']}; like the paper's Fig. 8; purple: the elastic strip "
        "between the first and the last robot; dashed red: the A* path; circle: the ghost):",
        "",
        f"![chain formation]({snap})",
        "",
        "Straightness (mean distance of the robots to the strip) over time, with and without the strip:",
        "",
        f"![straightness]({straight})",
        "",
        "A* path on the map inflated by the robot radius plus the planning margin (grey), and the leader's path:",
        "",
        f"![A* path]({amap})",
    ]
    return "\n".join(lines)
