"""Report section of GrapeHarvest-v1: Luo's Table 2 side by side with ours, success rate, Fig. 6-style 3D path."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

#: Luo et al. 2018, Table 2: clusters, order, path length (printed "cm", read as mm), path points,
#: collision, planning time (ms).
PAPER_TABLE2 = (
    (3, "2->3->1", 635.78, 108, "N", 152),
    (2, "2->1", 448.67, 72, "N", 108),
    (4, "3->4->1->2", 985.23, 172, "N", 215),
    (5, "2->4->3->1->5", 1362.45, 206, "N", 261),
    (3, "1->3->2", 723.33, 102, "N", 163),
    (4, "2->3->4->1", 1061.58, 170, "N", 203),
    (5, "5->3->1->2->4", 1472.65, 216, "Y", 274),
    (2, "1->2", 463.65, 91, "N", 98),
    (3, "2->3->1", 756.87, 127, "N", 151),
    (4, "3->2->4->1", 1045.26, 162, "N", 199),
)


def table2_rows(result: dict[str, Any]) -> list[str]:
    """Markdown table: each trial of ours next to the paper's trial of the same number."""
    rows = [
        "| trial | clusters (paper / ours) | order (paper / ours) | path length mm (paper / ours) | "
        "path points (paper / ours) | collision (paper / ours) | planning ms (paper / ours) | success (ours) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for k, e in enumerate(result["episodes"]):
        p = PAPER_TABLE2[k] if k < len(PAPER_TABLE2) else ("-",) * 6
        ours_len = f"{e['path_length_mm']:.1f}" if e.get("path_length_mm") is not None else "-"
        ours_ms = f"{e['planning_time_ms']:.1f}" if e.get("planning_time_ms") is not None else "-"
        collision = "Y" if e.get("collision") else "N"
        rows.append(
            f"| {k + 1} (seed {e['seed']}) | {p[0]} / {e.get('n_clusters', '-')} | {p[1]} / {e.get('order', '-')} | "
            f"{p[2]} / {ours_len} | {p[3]} / {e.get('path_points', '-')} | {p[4]} / {collision} "
            f"| {p[5]} / {ours_ms} | {'yes' if e['is_success'] else 'no'} |"
        )
    return rows


def _box_edges(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    edges = []
    for i in range(8):
        for j in range(i + 1, 8):
            if np.sum(corners[i] != corners[j]) == 1:
                edges.append(corners[[i, j]])
    return edges


def plot_planned_path(result: dict[str, Any], seed: int, out_dir: Path, stem: str) -> list[str]:
    """Plan the episode ``seed`` again with luo-apf and draw it in 3D (Fig. 6); also save a camera frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agri_baselines import make_policy

    env = gym.make(
        result["env_id"], render_mode="rgb_array", render_width=640, render_height=480, **result["env_kwargs"]
    )
    obs, _ = env.reset(seed=seed)
    policy = make_policy(result["policy"], env)
    policy.predict(obs, episode_start=np.array([True]))
    plan = policy.plans[0]
    unwrapped: Any = env.unwrapped
    scene = unwrapped.scene
    frame = np.asarray(env.render())
    env.close()
    fig = plt.figure(figsize=(8, 6.5))
    ax = fig.add_subplot(projection="3d")
    for i, c in enumerate(scene.clusters):
        for e in _box_edges(c.box_lo, c.box_hi):
            ax.plot(*e.T, color="#c0392b", lw=0.8)
        ax.scatter(*c.berries[:, :3].T, color="#5b2c6f", s=18, depthshade=False)
        ax.text(*(c.cut_point + [0, 0, 0.03]), str(i + 1), color="#a01010", fontsize=11)
    for o in scene.obstacles:
        colour = "#3c8c3c" if o.kind == "leaf" else "#7a5a3a"
        for e in _box_edges(np.maximum(o.lo, [-1, -1, -0.6]), o.hi):
            ax.plot(*e.T, color=colour, lw=0.6)
    pts = plan.points
    ax.plot(*pts.T, color="#2859c8", lw=0.8)
    ax.scatter(*pts.T, color="#1a1a1a", s=6, depthshade=False, label="path points (clamp centre)")
    ax.scatter(*pts[plan.cuts].T, color="#e67e22", s=40, marker="*", label="cutting points", depthshade=False)
    ax.scatter(*pts[0], color="#27ae60", s=50, marker="o", label="home", depthshade=False)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.set_title(
        f"luo-apf, seed {seed}: order {policy.episode_metrics(0)['order']}, {len(pts)} path points, "
        f"{plan.path_length * 1000:.0f} mm (Luo Fig. 6)",
        fontsize=9,
    )
    ax.view_init(elev=22, azim=-130)
    ax.legend(loc="upper left", fontsize=8)
    name = f"{stem}_path3d.png"
    fig.tight_layout()
    fig.savefig(out_dir / name, dpi=110)
    plt.close(fig)
    frame_name = f"{stem}_scene.png"
    from PIL import Image

    Image.fromarray(frame).save(out_dir / frame_name)
    return [name, frame_name]


def report_section(results: list[dict[str, Any]], out_dir: Path) -> str:
    """Markdown (with PNG plots written to ``out_dir``) for every GrapeHarvest-v1 result."""
    parts = []
    for result in results:
        label = result.get("label") or result["scenario"] or "default"
        s = result["summary"]
        parts.append(f"### {result['policy']} ({label})")
        lo, hi = s["success_rate_ci"]
        parts.append(
            f"Success {s['success_rate']:.0%} over {s['episodes']} episodes (95 % CI {lo:.0%}-{hi:.0%}); "
            f"the paper reports 90 % (9 of 10 trials)."
        )
        eps = result["episodes"]
        if eps and "planning_time_ms" in eps[0]:
            ms = np.array([e["planning_time_ms"] for e in eps], float)
            parts.append(
                f"Planning time per full plan: median {np.median(ms):.1f} ms, max {ms.max():.1f} ms "
                f"(paper: 98-274 ms on a 2012 laptop)."
            )
        if result["scenario"] == "table2":
            parts += ["", *table2_rows(result), ""]
            parts.append(
                "Path lengths are the clamp centre's polyline through the path points (eq. 17) for the whole "
                "harvest: home, every cluster with its straight approach and retreat, and back home. The "
                "paper's lengths are printed in cm but read as mm for an arm of this size."
            )
            if eps:
                stem = f"grape_{label.replace(' ', '_')}_{result['policy']}"
                for name in plot_planned_path(result, int(eps[0]["seed"]), out_dir, stem):
                    parts.append(f"![{name}]({name})")
        fails = [e for e in eps if not e["is_success"]]
        if fails:
            parts.append(
                "Failures: "
                + ", ".join(
                    f"seed {e['seed']} ({'collision' if e.get('collision') else 'plan incomplete'}, "
                    f"{e.get('harvested', '?')}/{e.get('n_clusters', '?')} cut)"
                    for e in fails
                )
            )
        parts.append("")
    return "\n".join(parts)
