"""``LEADERBOARD.md``: the entries of every suite ranked, with intervals and paired comparisons.

The page is generated; verify fails when it differs from what :func:`render_markdown` makes of the
committed entries.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agri_training.core.stats import format_interval, paired_comparison
from agri_training.evaluation.evaluate import INTERVALS_NOTE
from agri_training.leaderboard.entries import load_entries
from agri_training.leaderboard.suites import ENTRIES_DIR, LEADERBOARD_MD, SUITES_DIR, RankKey, Suite, load_suites


def _sort_key(entry: Mapping[str, Any], rank_by: Sequence[RankKey]) -> tuple[float, ...]:
    key = []
    for r in rank_by:
        v = entry["summary"].get(r.metric)
        v = float("inf") if v is None else (-float(v) if r.higher_is_better else float(v))
        key.append(v)
    return tuple(key)


def metric_format(metric: str) -> str:
    """The format of a metric's values in tables: rates and ratios to 2 decimals, distances in m to 3 (mm)."""
    if metric.endswith(("_rate", "_ratio")) or "path_length" in metric:
        return "{:.2f}"
    if any(k in metric for k in ("coverage", "clearance", "error", "ate", "cross_track", "distance", "gap")):
        return "{:.3f}"
    return "{:.1f}"


#: Units of the per-episode keys behind summary metrics (``mean_<key>``, ``iqm_<key>``).
UNITS = {
    "episode_time": "s",
    "path_length": "m",
    "min_clearance": "m",
    "ate_rmse": "m",
    "final_position_error": "m",
    "max_cross_track": "m",
    "mean_cross_track": "m",
    "mean_strip_distance": "m",
    "max_strip_distance": "m",
    "max_gap": "m",
}


def metric_label(metric: str) -> str:
    """A summary key as a column name: ``mean_mean_strip_distance`` -> ``mean strip distance [m]``.

    Means drop their prefix (every metric but a rate is a mean over episodes); IQMs keep it as "IQM".
    """
    key = metric
    for prefix in ("mean_", "iqm_"):
        if metric.startswith(prefix):
            key = metric[len(prefix) :]
    name = key.replace("_", " ")
    name = ("IQM " if metric.startswith("iqm_") else "") + {
        "episode time": "time",
        "success rate": "success",
        "collision rate": "collisions",
    }.get(name, name)
    return f"{name} [{UNITS[key]}]" if key in UNITS else name


def episode_values(entry: Mapping[str, Any], metric: str) -> tuple[list[Any], bool]:
    """Per-episode values behind a summary key (paired by seed order) and whether the metric is a rate."""
    if metric in ("success_rate", "collision_rate"):
        key = "is_success" if metric == "success_rate" else "collision"
        return [bool(e.get(key)) for lv in entry["levels"] for e in lv["episodes"]], True
    for prefix in ("mean_", "iqm_"):
        if metric.startswith(prefix):
            key = metric[len(prefix) :]
            return [e.get(key) for lv in entry["levels"] for e in lv["episodes"]], False
    return [], False


#: Metrics that measure progress toward the task itself: compared over every episode, like the rates.
PROGRESS_METRICS = frozenset({"coverage", "waypoints_reached"})

#: Fewest episodes that both policies completed for a comparison of a secondary metric.
MIN_COMPLETED_PAIRS = 5


def is_conditional(metric: str) -> bool:
    """True for a metric compared only over the episodes both policies completed (time, path length, ...).

    Rates and progress metrics (:data:`PROGRESS_METRICS`) are compared over every episode; any other
    metric describes how an episode went, and a failed episode (a crash that ends it early, a chain that
    never arrived) makes it look better than it is.
    """
    if metric in ("success_rate", "collision_rate") or metric.endswith("_rate"):
        return False
    key = metric.split("_", 1)[1] if metric.startswith(("mean_", "iqm_")) else metric
    return key not in PROGRESS_METRICS


def paired_values(
    x: Mapping[str, Any], y: Mapping[str, Any], metric: str
) -> tuple[list[Any], list[Any], bool, int | None]:
    """The per-episode values of two entries on one metric, paired by seed, as the comparison uses them.

    Returns:
        ``(vx, vy, binary, completed)``: for a conditional metric (:func:`is_conditional`) the values of
        episodes that either policy failed are None (the comparison drops them) and ``completed`` counts the
        episodes both completed; otherwise ``completed`` is None.
    """
    vx, binary = episode_values(x, metric)
    vy, _ = episode_values(y, metric)
    if not vx or len(vx) != len(vy) or not is_conditional(metric):
        return vx, vy, binary, None
    sx, _ = episode_values(x, "success_rate")
    sy, _ = episode_values(y, "success_rate")
    both = [a and b for a, b in zip(sx, sy, strict=True)]
    vx = [v if ok else None for v, ok in zip(vx, both, strict=True)]
    vy = [v if ok else None for v, ok in zip(vy, both, strict=True)]
    return vx, vy, binary, sum(both)


def compare_entries(x: Mapping[str, Any], y: Mapping[str, Any], metric: str, higher_is_better: bool) -> Any:
    """Paired comparison of two entries of one suite on one summary key (None when not comparable).

    Secondary metrics are compared over the episodes both completed, and not at all when fewer than
    :data:`MIN_COMPLETED_PAIRS` are.
    """
    vx, vy, binary, completed = paired_values(x, y, metric)
    if not vx or len(vx) != len(vy) or (completed is not None and completed < MIN_COMPLETED_PAIRS):
        return None
    try:
        return paired_comparison(vx, vy, metric, higher_is_better, binary=binary)
    except ValueError:
        return None


def render_markdown(entries: Sequence[Mapping[str, Any]], suites: Sequence[Suite]) -> str:
    """LEADERBOARD.md: per env and suite, every entry ranked, with 95 % intervals; privileged ones marked."""
    lines = [
        "# agri_envs leaderboard",
        "",
        "<!-- Generated by `agri leaderboard render` from leaderboard/entries/*; do not edit by hand. -->",
        "",
        "Every policy is evaluated on each suite's pinned, held-out seeds (100000 and up; training never uses "
        "them). Rows are ordered by the suite's ranking keys (point estimates, left to right); every column "
        "but a rate is the mean over the episodes. "
        + INTERVALS_NOTE
        + " The column *vs #1* is the paired comparison with the first row on the first ranking key, over "
        "the same seeds: *worse* only when its interval excludes zero, otherwise *not distinguishable*. "
        "**P** marks privileged policies (they use information a real robot lacks, such as the true pose). "
        "`agri leaderboard verify` re-computes every number here; see docs/leaderboard.md to submit.",
        "",
    ]
    by_suite: dict[str, list[Mapping[str, Any]]] = {}
    for e in entries:
        by_suite.setdefault(e["suite"]["name"], []).append(e)
    env_ids = list(dict.fromkeys(s.env_id for s in suites))
    for env_id in env_ids:
        lines += [f"## {env_id}", ""]
        for suite in (s for s in suites if s.env_id == env_id):
            group = sorted(
                by_suite.get(suite.name, []), key=lambda e: (_sort_key(e, suite.rank_by), e["policy"]["name"])
            )
            lines += [f"### {suite.name} (v{suite.version})", "", suite.description, ""]
            levels = len(suite.levels())
            lines.append(
                f"Seeds {suite.seed_start}-{suite.seed_start + suite.episodes - 1}"
                + (f" at each of {levels} levels of `{suite.sweep[0]}`" if suite.sweep else "")
                + f"; env arguments `{json.dumps(dict(suite.env_kwargs), sort_keys=True)}`."
            )
            lines.append("")
            if not group:
                lines += ["No entries yet.", ""]
                continue
            head = (
                ["#", "policy", "kind", "episodes"]
                + [f"{metric_label(r.metric)} {'↑' if r.higher_is_better else '↓'}" for r in suite.rank_by]
                + ["vs #1"]
            )
            lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
            first = suite.rank_by[0]
            for rank, e in enumerate(group, 1):
                s = e["summary"]
                name = e["policy"]["name"] + (" **P**" if e.get("privileged") else "")
                kind = e["policy"]["kind"]
                if kind == "learned":
                    kind = f"learned (`{e['policy']['sha256'][:10]}`)"
                cells = [
                    str(rank),
                    f"`{e['policy']['name']}`" + name[len(e["policy"]["name"]) :],
                    kind,
                    str(s["episodes"]),
                ]
                for r in suite.rank_by:
                    cells.append(format_interval(s.get(r.metric), s.get(f"{r.metric}_ci"), metric_format(r.metric)))
                if rank == 1:
                    cells.append("-")
                else:
                    c = compare_entries(e, group[0], first.metric, first.higher_is_better)
                    cells.append("n/a" if c is None else ("worse" if c.verdict == "worse" else "not distinguishable"))
                lines.append("| " + " | ".join(cells) + " |")
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def leaderboard_is_current(
    path: Path | str = LEADERBOARD_MD, entries_dir: Path | str = ENTRIES_DIR, suites_dir: Path | str = SUITES_DIR
) -> bool:
    """True when the file equals what the entries render to."""
    p = Path(path)
    return p.exists() and p.read_text() == render_markdown(load_entries(entries_dir), load_suites(suites_dir))


def write_markdown(
    path: Path | str = LEADERBOARD_MD, entries_dir: Path | str = ENTRIES_DIR, suites_dir: Path | str = SUITES_DIR
) -> Path:
    """Render LEADERBOARD.md from the entries."""
    p = Path(path)
    p.write_text(render_markdown(load_entries(entries_dir), load_suites(suites_dir)))
    return p


