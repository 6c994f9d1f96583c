"""Report section of GreenhouseNav-v2: trajectory on the greenhouse map, d(t) and alpha(t) (Harik Figs. 7-9)."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agri_baselines import policy_spec
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


_KIND_NAMES = {
    Kind.WALL: "walls",
    Kind.POST: "posts",
    Kind.PLANT: "plants",
    Kind.LEAF: "leaves",
    Kind.TREE: "trees",
    Kind.OBSTACLE: "obstacles",
}


def scene_legend_entries(ax: Any, geometry: Geometry) -> None:
    """Legend entries (empty proxies) for every kind of object the scene holds: plants, posts, trees, ..."""
    kinds = {int(k) for k in geometry.circle_kinds} | {int(k) for k in geometry.polygon_kinds}
    kinds |= {int(k) for k, w in zip(geometry.capsule_kinds, geometry.capsules[:, 4], strict=True) if w > 0}
    for kind, name in _KIND_NAMES.items():
        if int(kind) in kinds:
            ax.plot([], [], marker="s", ls="", ms=7, color=_KIND_COLOURS[kind], label=name)


def scene_of(result: dict[str, Any], seed: int) -> Any:
    """Rebuild the env of a result at ``seed`` (same arguments) and return it after reset."""
    env = gym.make(result["env_id"], **result["env_kwargs"])
    env.reset(seed=seed)
    return env


def _trajectory_axes(ax: Any, result: dict[str, Any], trace: dict[str, Any], legend: bool = True) -> None:
    """Draw the scene, the true path, the pose estimate, waypoints, start and (for a failure) the end."""
    data = trace["data"]
    env = scene_of(result, trace["seed"])
    e = env.unwrapped
    geometry = e.layout.geometry
    waypoints = e.layout.waypoints
    crowd = getattr(e, "crowd", None)
    people = np.array(crowd.pos, float) if crowd is not None and int(getattr(crowd, "n", 0)) > 0 else np.zeros((0, 2))
    env.close()
    x, y = np.array(data["x"], float), np.array(data["y"], float)
    draw_geometry(ax, geometry)
    scene_legend_entries(ax, geometry)
    if len(people):
        ax.scatter(
            people[:, 0],
            people[:, 1],
            s=40,
            facecolors="none",
            edgecolors="#e07000",
            lw=1.4,
            zorder=5,
            label="people at the start (they walk)",
        )
    ax.plot(x, y, color="#2859c8", lw=1.4, label="robot (true pose)")
    for kx, ky, what in (("est_x", "est_y", "odometry"), ("slam_x", "slam_y", "SLAM")):
        est_x = np.array([np.nan if v is None else v for v in data.get(kx, [])], float)
        if est_x.size and np.any(np.isfinite(est_x)) and not np.allclose(est_x, x[: est_x.size], equal_nan=True):
            est_y = np.array([np.nan if v is None else v for v in data[ky]], float)
            ax.plot(est_x, est_y, color="#d08020", lw=1.0, ls="--", label=f"pose estimate ({what})")
    ax.scatter(waypoints[:, 0], waypoints[:, 1], color="#d21e1e", zorder=5, s=24, label="waypoints")
    for i, (wx, wy) in enumerate(waypoints):
        ax.annotate(str(i), (wx, wy), textcoords="offset points", xytext=(4, 4), color="#a01010", fontsize=8)
    ax.plot(x[:1], y[:1], marker="o", color="#2859c8", ms=7, ls="", label="start")
    if not trace.get("is_success", True):
        ax.plot(x[-1:], y[-1:], marker="X", color="#e00000", ms=11, ls="", zorder=6, label="end (failed)")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if legend:
        # outside the axes, right of the map: never on top of the x label or the path
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)


def _where(result: dict[str, Any]) -> str:
    return str(result.get("label") or result.get("suite") or result["scenario"] or "default env")


def plot_trace(
    result: dict[str, Any], trace: dict[str, Any], out_dir: Path, stem: str, curves: bool = True
) -> list[str]:
    """Save the trajectory map (and with ``curves`` the d(t) / alpha(t) figure) of one episode; return file names.

    Every title names the policy, the suite level and the seed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = trace["data"]
    fig, ax = plt.subplots(figsize=(9, 5.5))
    _trajectory_axes(ax, result, trace)
    outcome = "" if trace.get("is_success", True) else " (failed)"
    ax.set_title(f"{result['policy']} on {_where(result)}, seed {trace['seed']}{outcome}: trajectory")
    traj_name = f"{stem}_seed{trace['seed']}_trajectory.png"
    fig.savefig(out_dir / traj_name, dpi=110, bbox_inches="tight")
    plt.close(fig)
    if not curves:
        return [traj_name]

    dt = float(result["env_kwargs"].get("control_period", 1 / 15))
    d = np.array([np.nan if v is None else v for v in data["distance_to_waypoint"]], float)
    alpha = np.degrees(np.array([np.nan if v is None else v for v in data["bearing_to_waypoint"]], float))
    t = dt * np.arange(len(d))
    fig, axes = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    axes[0].plot(t, d, color="#2859c8")
    axes[0].set_ylabel("d [m]")
    axes[0].set_title(
        f"{result['policy']} on {_where(result)}, seed {trace['seed']}: distance d to the current waypoint "
        "(Harik Fig. 7) and its bearing alpha (Fig. 8)",
        fontsize=9,
    )
    axes[1].plot(t, alpha, color="#c83c28")
    axes[1].set_ylabel("alpha [deg]")
    axes[1].set_xlabel("time [s]")
    if "waypoint_index" in data:  # mark where each waypoint was reached: the jumps of d are not glitches
        wi = np.array([np.nan if v is None else v for v in data["waypoint_index"]], float)
        for k in np.flatnonzero(np.diff(wi) > 0):
            for a in axes:
                a.axvline(t[k + 1], color="#999999", lw=0.6, ls=":")
    for a in axes:
        a.grid(alpha=0.3)
    curves_name = f"{stem}_seed{trace['seed']}_d_alpha.png"
    fig.tight_layout()
    fig.savefig(out_dir / curves_name, dpi=110)
    plt.close(fig)
    return [traj_name, curves_name]


def plot_panels(
    items: list[tuple[dict[str, Any], dict[str, Any], str]], out_dir: Path, name: str, title: str, ncols: int = 3
) -> str:
    """One figure with a trajectory panel per ``(result, trace, panel title)``; returns the file name."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(items)
    cols = min(ncols, n)
    rows = (n + cols - 1) // cols
    xmin, ymin, xmax, ymax = scene_of(items[0][0], items[0][1]["seed"]).unwrapped.layout.geometry.bounds
    aspect = (ymax - ymin + 0.4) / (xmax - xmin + 0.4)
    width = 6.0 if cols > 1 else 9.0
    fig, axes = plt.subplots(
        rows, cols, figsize=(width * cols, (width * aspect + 1.2) * rows + 0.8), squeeze=False, layout="constrained"
    )
    for ax, (result, trace, panel) in zip(axes.ravel(), items, strict=False):
        _trajectory_axes(ax, result, trace, legend=False)
        ax.set_title(textwrap.fill(panel, 70), fontsize=9)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    for ax in axes.ravel()[1:n]:  # collect the failure marker if only a later panel has it
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 5), fontsize=8, frameon=False)
    fig.suptitle(textwrap.fill(title, 100), fontsize=11)
    fig.savefig(out_dir / name, dpi=100)
    plt.close(fig)
    return name


#: What a reader needs to know to compare the rover policies (printed under the policy list).
ROVER_NOTES = (
    "The SLAM policies get no pose from the env: they run Hector SLAM on the full scan from the start "
    "pose. Since the env, not the robot, decides when a waypoint is reached (by default within 0.3 m of the true "
    "position), they aim 0.1 m inside that radius; with d_min = 0.3 m on the estimate they would stop "
    "a centimetre short and wait forever. `harik-apf` adds three safeguards to Hector (no mapping of beams "
    "that end in known free space, a cost check on each Gauss-Newton step, a constant-velocity start for "
    "each match); `harik-apf-hector-plain` runs without them, so the difference between the two rows is "
    "what they buy. Failures are "
    "classified from the episode's end: collision, localization lost (final pose error over "
    "0.25 m), waiting at the safety stop with something in front, or stuck while free to move."
)

#: Final position error (m) above which a failed episode counts as lost localization.
LOST_LOCALIZATION = 0.25


def failure_cause(record: dict[str, Any], learned: bool = False) -> str:
    """Why an episode failed, from its record: collision, lost localization, blocked in front, or stuck.

    A learned policy has no APF and no safety stop, so its failures are not named after them.
    """
    if record.get("collision"):
        return "collision"
    if (record.get("final_position_error") or 0.0) > LOST_LOCALIZATION:
        return "localization lost"
    if learned:
        return "time limit (stopped with something in front)" if record.get("blocked_at_end") else "time limit"
    if record.get("blocked_at_end"):
        return "waiting at the safety stop (something stays in front)"
    return "time limit while free to move (APF local minimum or too slow)"


def _learned(result: dict[str, Any]) -> bool:
    return result.get("policy_kind") == "learned"


def failure_counts(episodes: list[dict[str, Any]], learned: bool = False) -> str:
    """``"2 localization lost, 1 collision"``: failed episodes counted by cause, most frequent first."""
    causes: dict[str, int] = {}
    for e in episodes:
        if not e["is_success"]:
            cause = failure_cause(e, learned)
            causes[cause] = causes.get(cause, 0) + 1
    return ", ".join(f"{n} {cause}" for cause, n in sorted(causes.items(), key=lambda kv: -kv[1]))


def failure_lines(result: dict[str, Any]) -> list[str]:
    """Counts of failures by cause, then one line per failed episode (seed, cause, progress)."""
    failed = [e for e in result["episodes"] if not e["is_success"]]
    if not failed:
        return ["No failures."]
    counts = failure_counts(failed, _learned(result))
    lines = [f"Failures: {len(failed)} of {len(result['episodes'])} ({counts}).", ""]
    for e in failed:
        extra = ""
        if e.get("final_position_error") is not None:
            extra = f", final localization error {e['final_position_error']:.2f} m"
        lines.append(
            f"- seed {e['seed']}: {failure_cause(e, _learned(result))} after {e.get('episode_time', 0):.1f} s, "
            f"{e.get('waypoints_reached', '?')}/{e.get('n_waypoints', '?')} waypoints{extra}"
        )
    return lines


def _ci_text(summary: dict[str, Any], key: str) -> str:
    value = summary.get(key)
    if value is None:
        return "-"
    lo, hi = summary.get(f"{key}_ci") or (None, None)
    return f"{value:.3f}" if lo is None else f"{value:.3f} [{lo:.3f}, {hi:.3f}]"


def policy_table(results: list[dict[str, Any]]) -> list[str]:
    """Per-policy lines of one scenario: failures by cause, safety stops, waiting time, localization."""
    rows = [
        "| policy | failures | safety stops / episode | waiting at the stop [s] | ATE RMSE [m] "
        "| final pose error [m] |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        s = r["summary"]
        failed = [e for e in r["episodes"] if not e["is_success"]]
        fails = failure_counts(failed, _learned(r)) or "none"
        stops = f"{s['mean_safety_stops']:.2f}" if s.get("mean_safety_stops") is not None else "-"
        waiting = f"{s['mean_blocked_time']:.1f}" if s.get("mean_blocked_time") is not None else "-"
        rows.append(
            f"| {r['policy']} | {len(failed)} of {s['episodes']}: {fails} | {stops} | {waiting} | "
            f"{_ci_text(s, 'mean_ate_rmse')} | {_ci_text(s, 'mean_final_position_error')} |"
        )
    return rows


def lead_result(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The result whose episode is plotted: the first scripted policy that is not privileged (the paper's robot)."""
    scripted = [r for r in results if _is_baseline(r["policy"])]
    return next((r for r in scripted + results if not r["privileged"]), results[0])


def _is_baseline(name: str) -> bool:
    try:
        return not policy_spec(name).learned
    except ValueError:  # not registered: a run folder, an ONNX or SB3 file, a module:attribute
        return False


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


def report_section(results: list[dict[str, Any]], out_dir: Path) -> str:
    """Markdown (with PNG plots written to ``out_dir``) for the GreenhouseNav-v2 results, one part per suite.

    Each part has a table of the policies (failures counted by cause, safety stops, localization error
    with 95 % intervals), the failed seeds, and plots: for a single mission the lead policy's trajectory
    with its pose estimate (Harik Figs. 9, 16) and d(t) / alpha(t) (Figs. 7-8, 14-15); for a sweep one panel
    figure with a trajectory per level (Figs. 10-12); for repeated missions the overlay of the cycles and
    the drift per cycle (Fig. 17); and one panel figure of failed episodes, one per policy and level.
    """
    parts: list[str] = ["Policies:", ""]
    for name in dict.fromkeys(r["policy"] for r in results):
        try:
            parts.append(f"- `{name}`: {policy_spec(name).description}.")
        except ValueError:  # a learned policy, not a registered baseline
            parts.append(f"- `{name}`: a learned policy.")
    parts += ["", ROVER_NOTES, ""]
    by_suite: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        by_suite.setdefault(str(r.get("suite") or r["scenario"] or "default"), []).append(r)
    for suite, group in by_suite.items():
        parts += [f"#### {suite}", ""]
        labels = list(dict.fromkeys(_where(r) for r in group))
        for label in labels:
            level = [r for r in group if _where(r) == label]
            if len(labels) > 1:
                parts += [f"{label}:", ""]
            parts += policy_table(level) + [""]
            for r in level:
                failed = failure_lines(r)
                if failed != ["No failures."]:
                    parts += [f"`{r['policy']}`: " + failed[0], ""] + failed[2:] + [""]
        cycles = int(group[0]["env_kwargs"].get("mission_cycles", 1))
        leads = [lead_result([r for r in group if _where(r) == label]) for label in labels]
        first = [
            (r, r["traces"][0]) for r in leads if r["traces"] and r["traces"][0]["seed"] == r["episodes"][0]["seed"]
        ]
        if cycles > 1:
            for r, _ in first[:1]:
                parts += [f"Episode of `{r['policy']}`:", ""] + repeatability_section(
                    r, out_dir, _slug(f"greenhouse_{suite}_{r['policy']}")
                )
        elif len(labels) > 1 and first:
            name = plot_panels(
                [(r, t, f"{_where(r)}, seed {t['seed']}") for r, t in first],
                out_dir,
                _slug(f"greenhouse_{suite}_{first[0][0]['policy']}_levels.png"),
                f"{first[0][0]['policy']}: one episode per level of {suite}",
            )
            parts += [f"![{name}]({name})", ""]
        else:
            for r, t in first:
                names = plot_trace(r, t, out_dir, _slug(f"greenhouse_{suite}_{r['policy']}"))
                parts += [f"![{n}]({n})" for n in names] + [""]
        fails = [
            (
                r,
                t,
                f"{r['policy']} on {_where(r)}, seed {t['seed']}: {failure_cause(_record(r, t['seed']), _learned(r))}",
            )
            for r in group
            for t in r["traces"]
            if not t.get("is_success", True)
        ]
        if fails and cycles == 1:
            shown = fails[:6]
            name = plot_panels(
                shown,
                out_dir,
                _slug(f"greenhouse_{suite}_failures.png"),
                f"Failed episodes on {suite} (the first of each policy and level"
                + (f"; {len(shown)} of {len(fails)} shown)" if len(fails) > len(shown) else ")"),
            )
            parts += ["Failed episodes (the red cross is where each ended):", "", f"![{name}]({name})", ""]
        elif fails:
            for r, t, panel in fails[:2]:
                names = plot_trace(r, t, out_dir, _slug(f"greenhouse_{suite}_{r['policy']}_failed"), curves=False)
                parts += [f"Failed episode, {panel}:", ""] + [f"![{n}]({n})" for n in names] + [""]
    return "\n".join(parts)


def _record(result: dict[str, Any], seed: int) -> dict[str, Any]:
    return next((e for e in result["episodes"] if e["seed"] == seed), {})


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
    """Every cycle's trajectory on the map in its own colour (Harik Fig. 17), and the drift / spread per cycle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    env = scene_of(result, trace["seed"])
    geometry = env.unwrapped.layout.geometry
    env.close()
    xmin, ymin, xmax, ymax = geometry.bounds
    aspect = (ymax - ymin + 0.4) / (xmax - xmin + 0.4)
    fig, (ax, bx) = plt.subplots(
        2,
        1,
        figsize=(10, 10 * aspect + 4.6),
        gridspec_kw={"height_ratios": [10 * aspect + 0.8, 3.2]},
        layout="constrained",
    )
    draw_geometry(ax, geometry)
    scene_legend_entries(ax, geometry)
    n = len(stats["paths"])
    cmap = plt.get_cmap("viridis", max(1, n))
    colours = cmap(np.arange(max(1, n)))
    styles = ["-", "--", ":", "-."]
    # Cycle 1 drawn thickest and underneath, each later one thinner on top: where the cycles coincide (the
    # point of the experiment) every colour still shows as a band edge.
    widths = np.linspace(5.0, 0.8, max(1, n))
    for c, (p, col) in enumerate(zip(stats["paths"], colours, strict=True)):
        ax.plot(p[:, 0], p[:, 1], color=col, lw=widths[c], ls=styles[(c // 10) % 4])
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    spread = max((w for _, w in stats["spread"]), default=0.0)
    ax.set_title(
        f"{result['policy']} on {_where(result)}, seed {trace['seed']}: {n} cycles without re-initialisation\n"
        f"(true path; later cycles stay within {spread:.2f} m of cycle 1)",
        fontsize=10,
    )
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import BoundaryNorm

    bar = fig.colorbar(
        ScalarMappable(BoundaryNorm(np.arange(0.5, n + 1.5), cmap.N), cmap), cax=ax.inset_axes((1.02, 0.0, 0.02, 1.0))
    )
    bar.set_label("cycle (1 thickest, underneath)")
    bar.set_ticks(list(range(1, n + 1)))
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.12), ncol=6, fontsize=8, frameon=False)
    cyc = np.arange(1, n + 1)
    if stats["has_estimate"] and stats["drift"]:
        bx.plot(cyc[: len(stats["drift"])], stats["drift"], "o-", color="#d08020", label="pose drift at cycle end")
    if stats["spread"]:
        means = [m for m, _ in stats["spread"]]
        worst = [w for _, w in stats["spread"]]
        bx.plot(cyc[1 : len(means) + 1], means, "s-", color="#2859c8", label="mean distance to cycle 1 path")
        bx.plot(cyc[1 : len(worst) + 1], worst, "^:", color="#2859c8", label="largest distance to cycle 1 path")
    bx.set_xlabel("cycle")
    bx.set_ylabel("distance [m]")
    bx.set_xticks(cyc)
    bx.set_title("drift and spread per cycle (Harik Fig. 17)", fontsize=10)
    bx.grid(alpha=0.3)
    bx.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    name = f"{stem}_cycles.png"
    fig.savefig(out_dir / name, dpi=110, bbox_inches="tight")
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
