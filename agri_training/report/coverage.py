"""Report section of GreenhouseCoverage-v2 (González 2009): coverage table and the paper's figures.

* planned path over the map with the driven trajectory (Figs. 10-12);
* raw and peak-filtered lateral sonar series along a corridor (Fig. 9, eq. 1);
* the sensory map (eq. 2) next to the true map (Figs. 10-11).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agri_baselines.gonzalez import peak_filter
from agri_training.report.rover import draw_geometry, scene_legend_entries

#: The lateral sonar whose series Fig. 9 shows (the middle one on the left).
FIG9_SONAR = "sonar_left_middle"


def _label(r: dict[str, Any]) -> str:
    return str(r.get("label") or r.get("scenario") or "default")


def _median(values: list[Any]) -> float | None:
    v = [float(x) for x in values if x is not None]
    return float(np.median(v)) if v else None


def _cm(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.1f}"


def _parts(result: dict[str, Any]) -> list[tuple[str, list[dict[str, Any]]]]:
    """The result's episodes, split into first and later runs for an evaluation in campaigns."""
    eps = result["episodes"]
    if not any("campaign_run" in e for e in eps):
        return [(_label(result), eps)]
    return [
        (f"{_label(result)}, first runs", [e for e in eps if not e.get("campaign_run")]),
        (f"{_label(result)}, later runs", [e for e in eps if e.get("campaign_run")]),
    ]


def coverage_table(results: list[dict[str, Any]]) -> list[str]:
    """Markdown rows: success (every corridor covered), coverage, cross-track errors (cm), crop contacts, time.

    An evaluation in campaigns gets one row for the first runs and one for the later runs.
    """
    rows = [
        "| policy | scenario | privileged | episodes | all corridors covered | mean coverage | median max "
        "cross-track to centre line [cm] | median mean cross-track to centre line [cm] | median max cross-track to "
        "plan, corridors / turns [cm] | episodes with crop contact | mean time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        for label, eps in _parts(r):
            n = len(eps)
            ok = sum(bool(e["is_success"]) for e in eps)
            cov = np.mean([e.get("coverage") or 0.0 for e in eps]) if eps else float("nan")
            mx = _median([e.get("max_cross_track") for e in eps])
            mean_ct = _median([e.get("mean_cross_track") for e in eps])
            plan = [_median([e.get(f"cross_track_{p}_max") for e in eps]) for p in ("corridors", "turns")]
            crop = sum(1 for e in eps if (e.get("crop_contacts") or 0) > 0)
            t = np.mean([e.get("episode_time") or 0.0 for e in eps]) if eps else float("nan")
            rows.append(
                f"| {r['policy']} | {label} | {'yes' if r['privileged'] else 'no'} | {n} | {ok}/{n} | {cov:.3f} | "
                f"{_cm(mx)} | {_cm(mean_ct)} | {_cm(plan[0])} / {_cm(plan[1])} | {crop} | {t:.1f} |"
            )
    return rows


def failure_lines(result: dict[str, Any]) -> list[str]:
    """One line per failed episode saying how it failed (contact, time limit, where the controller stood)."""
    out = []
    for e in result["episodes"]:
        if e["is_success"]:
            continue
        if (e.get("crop_contacts") or 0) > 0:
            how = "touched the crop"
        elif (e.get("other_contacts") or 0) > 0:
            how = "touched a wall or post"
        else:
            how = "ran out of time"
        phase = f", controller phase `{e['final_phase']}` after {e.get('turns')} turns" if "final_phase" in e else ""
        out.append(
            f"- `{result['policy']}` seed {e['seed']}: {how} with {e.get('corridors_covered')}/"
            f"{e.get('n_corridors')} corridors covered (coverage {e.get('coverage', 0):.2f}){phase}."
        )
    return out


def _scene(result: dict[str, Any], episode: dict[str, Any]) -> Any:
    """The episode's greenhouse (a campaign's episode: its campaign's world, ``layout_seed``)."""
    kwargs = dict(result["env_kwargs"])
    if episode.get("layout_seed") is not None:
        kwargs["layout_seed"] = episode["layout_seed"]
    env = gym.make(result["env_id"], **kwargs)
    env.reset(seed=int(episode["seed"]))
    return env.unwrapped


def plot_paths(result: dict[str, Any], trace: dict[str, Any], episode: dict[str, Any], path: Path) -> None:
    """The greenhouse with the planned path (if any), the driven trajectory and the corridor centre lines."""
    import matplotlib.pyplot as plt

    env = _scene(result, episode)
    fig, ax = plt.subplots(figsize=(9, 6))
    draw_geometry(ax, env.layout.geometry)
    scene_legend_entries(ax, env.layout.geometry)
    for k, line in enumerate(env.corridor_lines()):
        ax.plot(line[:, 0], line[:, 1], ":", color="0.5", lw=0.8, label="corridor centre lines" if k == 0 else None)
    if episode.get("planned_path"):
        plan = np.asarray(episode["planned_path"])
        frame = "odometry frame" if episode.get("hybrid_deliberative") else "reference"
        ax.plot(plan[:, 0], plan[:, 1], "-", color="tab:red", lw=1.2, label=f"planned path ({frame})")
    data = trace["data"]
    ax.plot(data["x"], data["y"], "-", color="k", lw=1.0, label="driven trajectory")
    if "est_x" in data:
        ax.plot(data["est_x"], data["est_y"], "--", color="tab:purple", lw=0.8, label="odometry (encoders + compass)")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{result['policy']} ({_label(result)}), seed {trace['seed']}{_run(episode)}")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, fontsize=8, frameon=False)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    env.close()


def plot_sonar(trace: dict[str, Any], path: Path, n: int = 5, eps: float = 0.3) -> tuple[float, float] | None:
    """Raw and filtered (eq. 1) lateral sonar readings along the longest corridor pass; returns both stds."""
    import matplotlib.pyplot as plt

    data = trace["data"]
    corridor = np.asarray(data["corridor"], dtype=float)
    raw = np.asarray(data[FIG9_SONAR], dtype=float)
    x = np.asarray(data["x"], dtype=float)
    best: tuple[int, int] = (0, 0)
    start = None
    for i, c in enumerate(np.r_[corridor, -1.0]):
        if c >= 0 and start is None:
            start = i
        elif (c < 0 or (start is not None and c != corridor[start])) and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = i if c >= 0 else None
    if best[1] - best[0] < 20:
        return None
    sl = slice(best[0], best[1])
    series = raw[sl]
    filt = peak_filter(series, n=n, eps=eps)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(x[sl], series, "-", color="tab:red", lw=1.0, label=f"raw (std {np.std(series):.2f} m)")
    ax.plot(
        x[sl],
        filt,
        ":",
        color="tab:blue",
        lw=1.8,
        label=f"filtered, eq. 1, n={n}, eps={eps} m (std {np.std(filt):.2f} m)",
    )
    ax.set_xlabel("x along the corridor [m]")
    ax.set_ylabel("left middle sonar [m]")
    ax.set_title(
        f"Sonar peaks from vegetation echoes (Fig. 9), corridor {int(corridor[best[0]])}, seed {trace['seed']}"
    )
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return float(np.std(series)), float(np.std(filt))


def plot_sensory_map(result: dict[str, Any], seed: int, episode: dict[str, Any], path: Path) -> None:
    """The sensory map of eq. 2 (odometry frame) next to the true greenhouse."""
    import matplotlib.pyplot as plt

    env = _scene(result, episode)
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.8), sharex=True, sharey=True)
    pts = np.asarray(episode["sensory_map"]).reshape(-1, 2)
    odo = np.asarray(episode.get("odometry_path") or []).reshape(-1, 2)
    a.plot(pts[:, 0], pts[:, 1], ".", ms=1.5, color="tab:blue", label="sonar echoes (eq. 2)")
    if len(odo):
        a.plot(odo[:, 0], odo[:, 1], "-", color="tab:red", lw=0.8, label="robot (odometry)")
    a.set_aspect("equal")
    a.set_title(f"sensory map, {len(pts)} echoes")
    a.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, frameon=False)
    draw_geometry(b, env.layout.geometry)
    b.set_title("true greenhouse")
    for ax in (a, b):
        ax.set_xlabel("x [m]")
    a.set_ylabel("y [m]")
    fig.suptitle(f"{result['policy']} ({_label(result)}), seed {seed}")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    env.close()


def report_section(results: list[dict[str, Any]], out_dir: Path) -> str:
    """Markdown (with PNG plots written to ``out_dir``) for the GreenhouseCoverage-v2 results.

    Args:
        results: Evaluation result documents (``agri_training.evaluate``), one per policy and scenario.
        out_dir: Folder for the PNG files (referenced relatively from the Markdown).

    Returns:
        The section's Markdown: the coverage table, how failed episodes failed, and per result the planned
        and driven paths (Figs. 10-12), the raw and filtered sonar series (Fig. 9) and, for the map-building
        policies, the sensory map next to the true map.
    """
    import matplotlib

    matplotlib.use("Agg")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    parts = [
        "Coverage: fraction of every corridor's length the robot's centre passed along; success = every "
        "corridor end to end. Cross-track to centre line: distance from the robot's true centre to the centre "
        "line of the corridor it is in (0 in the headlands). Cross-track to plan: distance from the pose the "
        "planner's tracker was given (the true pose of the deliberative, the corrected odometry of the hybrid's "
        "later runs) to the planned path, in the corridors and in the headland turns between them. The paper "
        "reports a tracking error under 10 cm on a turn (sec. 4.2, Fig. 12).",
        "",
        *coverage_table(results),
        "",
    ]
    fails = [line for r in results for line in failure_lines(r)]
    if fails:
        parts += ["Failed episodes:", "", *fails, ""]
    for r in results:
        for trace in _plotted(r):
            parts += _episode_figures(r, trace, out_dir)
    return "\n".join(parts)


def _run(episode: dict[str, Any]) -> str:
    """`` (campaign run k)`` for an episode of a campaign, else ''."""
    return f" (campaign run {int(episode['campaign_run']) + 1})" if "campaign_run" in episode else ""


def _plotted(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The traced episodes to draw: the first, and in a campaign the first later run as well."""
    traces = result.get("traces") or []
    later = [t for t in traces[1:] if (_record(result, t).get("campaign_run") or 0) > 0][:1]
    return traces[:1] + later


def _record(result: dict[str, Any], trace: dict[str, Any]) -> dict[str, Any]:
    """The traced episode's whole record (its maps and paths too), else its record in the entry."""
    if trace.get("record"):
        return dict(trace["record"])
    return next((e for e in result["episodes"] if e["seed"] == trace["seed"]), result["episodes"][0])


def _episode_figures(r: dict[str, Any], trace: dict[str, Any], out_dir: Path) -> list[str]:
    """Markdown and PNGs of one traced episode: paths, sonar series (Fig. 9), the sensory map (eq. 2)."""
    parts: list[str] = []
    seed = int(trace["seed"])
    episode = _record(r, trace)
    stem = f"coverage_{r['policy']}_{_label(r)}_{seed}".replace(" ", "_").replace("=", "-").replace("/", "_")
    parts += [f"#### {r['policy']} ({_label(r)}), seed {seed}{_run(episode)}", ""]
    plot_paths(r, trace, episode, out_dir / f"{stem}_paths.png")
    parts += [f"![paths]({stem}_paths.png)", ""]
    stds = plot_sonar(trace, out_dir / f"{stem}_sonar.png")
    if stds is not None:
        parts += [
            f"![sonar]({stem}_sonar.png)",
            "",
            f"Peak filter (eq. 1): std of the lateral sonar series {stds[0]:.2f} m raw, {stds[1]:.2f} m "
            f"filtered ({stds[0] / max(stds[1], 1e-9):.1f}x less; the paper: 2.17 -> 0.68).",
            "",
        ]
    if episode.get("sensory_map"):
        plot_sensory_map(r, seed, episode, out_dir / f"{stem}_map.png")
        parts += [f"![sensory map]({stem}_map.png)", ""]
    return parts
