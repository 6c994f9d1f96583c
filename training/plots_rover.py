"""Report section of GreenhouseNav-v0: trajectory on the greenhouse map, d(t) and alpha(t) (Harik Figs. 7-9)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agri_envs.sim2d.geometry import Geometry, Kind

_KIND_COLOURS = {
    Kind.WALL: "#5a5a5f",
    Kind.POST: "#28282d",
    Kind.PLANT: "#3c963c",
    Kind.LEAF: "#78be5a",
    Kind.TREE: "#1e6e2d",
    Kind.OBSTACLE: "#464646",
}


def draw_geometry(ax: Any, geometry: Geometry) -> None:
    """Draw the static scene on a matplotlib axis (metres, equal aspect)."""
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Polygon

    for (x, y, r), k in zip(geometry.circles, geometry.circle_kinds, strict=True):
        ax.add_patch(Circle((x, y), r, color=_KIND_COLOURS.get(Kind(int(k)), "k"), lw=0))
    for poly, k in zip(geometry.polygons, geometry.polygon_kinds, strict=True):
        ax.add_patch(Polygon(poly, closed=True, color=_KIND_COLOURS.get(Kind(k), "k"), lw=0))
    for kind in (Kind.WALL, Kind.LEAF):
        sel = (geometry.capsule_kinds == kind) & (geometry.capsules[:, 4] > 0)
        if np.any(sel):
            caps = geometry.capsules[sel]
            width_pt = 3.0 if kind == Kind.WALL else 1.2
            ax.add_collection(
                LineCollection(caps[:, :4].reshape(-1, 2, 2), colors=_KIND_COLOURS[kind], linewidths=width_pt)
            )
    xmin, ymin, xmax, ymax = geometry.bounds
    ax.set_xlim(xmin - 0.2, xmax + 0.2)
    ax.set_ylim(ymin - 0.2, ymax + 0.2)
    ax.set_aspect("equal")


def scene_of(result: dict[str, Any], seed: int) -> Any:
    """Rebuild the env of a result at ``seed`` (same arguments) and return it after reset."""
    env = gym.make(result["env_id"], **result["env_kwargs"])
    env.reset(seed=seed)
    return env


def plot_trace(result: dict[str, Any], trace: dict[str, Any], out_dir: Path, stem: str) -> list[str]:
    """Save the trajectory map and the d(t) / alpha(t) figure of one recorded episode; return file names."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = trace["data"]
    env = scene_of(result, trace["seed"])
    e = env.unwrapped
    geometry = e.layout.geometry
    waypoints = e.layout.waypoints
    env.close()
    x, y = np.array(data["x"], float), np.array(data["y"], float)
    fig, ax = plt.subplots(figsize=(8, 5.5))
    draw_geometry(ax, geometry)
    ax.plot(x, y, color="#2859c8", lw=1.6, label="robot (true pose)")
    est_x = np.array([np.nan if v is None else v for v in data.get("est_x", [])], float)
    if est_x.size and np.any(np.isfinite(est_x)) and not np.allclose(est_x, x, equal_nan=True):
        est_y = np.array([np.nan if v is None else v for v in data["est_y"]], float)
        ax.plot(est_x, est_y, color="#d08020", lw=1.0, ls="--", label="estimated pose")
    ax.scatter(waypoints[:, 0], waypoints[:, 1], color="#d21e1e", zorder=5, s=30)
    for i, (wx, wy) in enumerate(waypoints):
        ax.annotate(str(i), (wx, wy), textcoords="offset points", xytext=(5, 5), color="#a01010", fontsize=10)
    ax.plot(x[:1], y[:1], marker="o", color="#2859c8", ms=8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{result['policy']}: trajectory, seed {trace['seed']} (Harik Fig. 9)")
    ax.legend(loc="upper right", fontsize=8)
    traj_name = f"{stem}_trajectory.png"
    fig.tight_layout()
    fig.savefig(out_dir / traj_name, dpi=110)
    plt.close(fig)

    dt = float(result["env_kwargs"].get("control_period", 1 / 15))
    t = dt * np.arange(len(x))
    d = np.array(data["distance_to_waypoint"], float)
    alpha = np.degrees(np.array(data["bearing_to_waypoint"], float))
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    axes[0].plot(t, d, color="#2859c8")
    axes[0].set_ylabel("d [m]")
    axes[0].set_title("distance to the current waypoint (Fig. 7) and angle alpha (Fig. 8)")
    axes[1].plot(t, alpha, color="#c83c28")
    axes[1].set_ylabel("alpha [deg]")
    axes[1].set_xlabel("time [s]")
    for a in axes:
        a.grid(alpha=0.3)
    curves_name = f"{stem}_d_alpha.png"
    fig.tight_layout()
    fig.savefig(out_dir / curves_name, dpi=110)
    plt.close(fig)
    return [traj_name, curves_name]


def failure_lines(result: dict[str, Any]) -> list[str]:
    """One line per failed episode: seed and cause (collision, or time limit with waypoints reached)."""
    lines = []
    for e in result["episodes"]:
        if e["is_success"]:
            continue
        cause = "collision" if e.get("collision") else "time limit"
        lines.append(
            f"- seed {e['seed']}: {cause} after {e.get('episode_time', 0):.1f} s, "
            f"{e.get('waypoints_reached', '?')}/{e.get('n_waypoints', '?')} waypoints"
        )
    return lines


def report_section(results: list[dict[str, Any]], out_dir: Path) -> str:
    """Markdown (with PNG plots written to ``out_dir``) for every GreenhouseNav-v0 result."""
    parts = []
    for result in results:
        label = result.get("label") or result["scenario"] or "default"
        stem = f"greenhouse_{label.replace(' ', '_').replace('=', '')}_{result['policy']}"
        parts.append(f"### {result['policy']} ({label})")
        s = result["summary"]
        if "mean_safety_stops" in s:
            parts.append(f"Passive safety stops per episode (mean): {s['mean_safety_stops']:.2f}.")
        fails = failure_lines(result)
        parts.append("Failures:" if fails else "No failures.")
        parts += fails
        if "ate_rmse" in s:
            parts.append(
                f"Localization: ATE RMSE {s['mean_ate_rmse']:.3f} m (95 % CI {s['mean_ate_rmse_ci'][0]:.3f}-"
                f"{s['mean_ate_rmse_ci'][1]:.3f}), final position error {s['mean_final_position_error']:.3f} m, "
                f"largest error {s['mean_ate_max']:.3f} m (means over episodes)."
            )
        if int(result["env_kwargs"].get("mission_cycles", 1)) > 1:
            parts += repeatability_section(result, out_dir, stem)
        else:
            for trace in result.get("traces", [])[:1]:
                for name in plot_trace(result, trace, out_dir, stem):
                    parts.append(f"![{name}]({name})")
        parts.append("")
    return "\n".join(parts)


def cycle_ends(waypoint_index: np.ndarray, per_cycle: int) -> list[int]:
    """Trace indices at which each full mission cycle was completed."""
    ends = []
    for c in range(1, int(waypoint_index.max()) // per_cycle + 1):
        hit = np.flatnonzero(waypoint_index >= c * per_cycle)
        if hit.size:
            ends.append(int(hit[0]))
    return ends


def repeatability_stats(result: dict[str, Any], trace: dict[str, Any]) -> dict[str, Any]:
    """Pose drift at the end of each cycle (estimate vs truth) and the spread of the cycles' trajectories.

    The spread of cycle ``c`` is the mean and the largest distance from its path to the first cycle's path.
    """
    data = trace["data"]
    x, y = np.array(data["x"], float), np.array(data["y"], float)
    wi = np.array(data["waypoint_index"], float)
    cycles = int(result["env_kwargs"].get("mission_cycles", 1))
    n_wp = int(result["episodes"][0]["n_waypoints"]) if result["episodes"] else 0
    per_cycle = max(1, n_wp // max(cycles, 1))
    ends = cycle_ends(wi, per_cycle)
    has_est = "slam_x" in data
    if has_est:
        ex, ey = np.array(data["slam_x"], float), np.array(data["slam_y"], float)
    drift = []
    for k in ends:
        if has_est:
            j = min(k, len(ex) - 1)
            drift.append(float(np.hypot(ex[j] - x[j], ey[j] - y[j])))
        else:
            drift.append(0.0)
    bounds = [0, *ends]
    paths = [np.stack([x[a : b + 1], y[a : b + 1]], 1) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    spread = []
    for p in paths[1:]:
        d = np.min(np.hypot(p[:, None, 0] - paths[0][None, :, 0], p[:, None, 1] - paths[0][None, :, 1]), axis=1)
        spread.append((float(d.mean()), float(d.max())))
    return {"drift": drift, "spread": spread, "paths": paths, "has_estimate": has_est}


def plot_repeatability(
    result: dict[str, Any], trace: dict[str, Any], stats: dict[str, Any], out_dir: Path, stem: str
) -> str:
    """Overlay of every cycle's trajectory on the map (Harik Fig. 17); returns the file name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    env = scene_of(result, trace["seed"])
    geometry = env.unwrapped.layout.geometry
    env.close()
    fig, ax = plt.subplots(figsize=(8, 5.5))
    draw_geometry(ax, geometry)
    colours = plt.get_cmap("viridis")(np.linspace(0, 1, max(1, len(stats["paths"]))))
    for c, (p, col) in enumerate(zip(stats["paths"], colours, strict=True)):
        ax.plot(
            p[:, 0], p[:, 1], color=col, lw=1.0, label=f"cycle {c + 1}" if c in (0, len(stats["paths"]) - 1) else None
        )
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(f"{result['policy']}: {len(stats['paths'])} cycles without re-initialisation (Harik Fig. 17)")
    name = f"{stem}_cycles.png"
    fig.tight_layout()
    fig.savefig(out_dir / name, dpi=110)
    plt.close(fig)
    return name


def repeatability_section(result: dict[str, Any], out_dir: Path, stem: str) -> list[str]:
    """Markdown lines: per-cycle drift table, spread, and the overlay plot."""
    traces = result.get("traces", [])
    if not traces:
        return []
    stats = repeatability_stats(result, traces[0])
    lines = [f"Cycles completed in the traced episode (seed {traces[0]['seed']}): {len(stats['drift'])}.", ""]
    if stats["has_estimate"]:
        lines += ["| cycle | pose drift at the end of the cycle [m] |", "|---|---|"]
        lines += [f"| {c + 1} | {d:.3f} |" for c, d in enumerate(stats["drift"])]
        lines.append("")
    else:
        lines.append("The pose is ground truth here, so there is no drift; the spread shows the control alone.")
    if stats["spread"]:
        means = [m for m, _ in stats["spread"]]
        worst = max(w for _, w in stats["spread"])
        lines.append(
            f"Spread of cycles 2-{len(stats['paths'])} around cycle 1: mean distance "
            f"{np.mean(means):.3f} m, largest {worst:.3f} m."
        )
    name = plot_repeatability(result, traces[0], stats, out_dir, stem)
    lines += ["", f"![{name}]({name})"]
    return lines
