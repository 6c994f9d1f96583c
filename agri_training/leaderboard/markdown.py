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
from agri_training.leaderboard.robustness import SUCCESS_FLOOR, level_success, robustness_lines
from agri_training.leaderboard.suites import (
    ENTRIES_DIR,
    LEADERBOARD_MD,
    MIN_EPISODES,
    SUITES_DIR,
    RankKey,
    Suite,
    load_suites,
)


def rank_key(entry: Mapping[str, Any], rank_by: Sequence[RankKey]) -> tuple[float, ...]:
    """Sort key of an entry on its suite's ranking keys (best first; a missing metric ranks last)."""
    key = []
    for r in rank_by:
        v = entry["summary"].get(r.metric)
        v = float("inf") if v is None else (-float(v) if r.higher_is_better else float(v))
        key.append(v)
    return tuple(key)


#: Prefixes of the summary keys of campaigns' first runs and later runs (``later_runs_success_rate``).
CAMPAIGN_PARTS = {"first_run_": "first run", "later_runs_": "later runs"}


def _campaign_part(metric: str) -> tuple[str | None, str]:
    """``(prefix, rest)`` of a campaign summary key (``(None, metric)`` for any other key)."""
    for prefix in CAMPAIGN_PARTS:
        if metric.startswith(prefix):
            return prefix, metric[len(prefix) :]
    return None, metric


def _base_key(metric: str) -> str:
    """The per-episode key behind a summary key: ``later_runs_mean_max_cross_track`` -> ``max_cross_track``."""
    key = _campaign_part(metric)[1]
    for prefix in ("mean_", "iqm_"):
        if key.startswith(prefix):
            return key[len(prefix) :]
    return key


def metric_scale(metric: str) -> float:
    """Factor from a metric's stored unit to the unit tables show it in (cross-track errors: m -> cm)."""
    return 100.0 if "cross_track" in metric else 1.0


def metric_format(metric: str) -> str:
    """The format of a metric's values in tables (after :func:`metric_scale`).

    Rates and ratios to 2 decimals; cross-track errors in cm to 1 (mm); other distances in m to 3 (mm).
    """
    key = _base_key(metric)
    if metric.endswith(("_rate", "_ratio")) or key.endswith("_ratio") or "path_length" in key:
        return "{:.2f}"
    if "cross_track" in key:
        return "{:.1f}"
    if key.startswith("ate_") or any(k in key for k in ("coverage", "clearance", "error", "distance", "gap")):
        return "{:.3f}"
    return "{:.1f}"


def format_metric(metric: str, value: Any, ci: Any = None) -> str:
    """A summary value with its interval as a table shows it: scaled (:func:`metric_scale`) and formatted."""
    f = metric_scale(metric)
    scaled = None if value is None else float(value) * f
    interval = None if ci is None else [None if c is None else float(c) * f for c in ci]
    return format_interval(scaled, interval, metric_format(metric))


#: Units of the per-episode keys behind summary metrics (``mean_<key>``, ``iqm_<key>``), as tables show them.
UNITS = {
    "episode_time": "s",
    "path_length": "m",
    "min_clearance": "m",
    "ate_rmse": "m",
    "final_position_error": "m",
    "max_cross_track": "cm",
    "mean_cross_track": "cm",
    "cross_track_corridors_max": "cm",
    "cross_track_corridors_mean": "cm",
    "cross_track_turns_max": "cm",
    "cross_track_turns_mean": "cm",
    "mean_strip_distance": "m",
    "max_strip_distance": "m",
    "max_gap": "m",
}

#: Column names of per-episode keys whose own names read badly.
NAMES = {
    "episode time": "time",
    "success rate": "success",
    "collision rate": "collisions",
    "max cross track": "max cross-track to centre line",
    "mean cross track": "mean cross-track to centre line",
    "cross track corridors max": "max cross-track to plan, corridors",
    "cross track corridors mean": "mean cross-track to plan, corridors",
    "cross track turns max": "max cross-track to plan, turns",
    "cross track turns mean": "mean cross-track to plan, turns",
}


def metric_label(metric: str) -> str:
    """A summary key as a column name: ``mean_mean_strip_distance`` -> ``mean strip distance [m]``.

    Means drop their prefix (every metric but a rate is a mean over episodes); IQMs keep it as "IQM";
    campaign parts lead (``later_runs_success_rate`` -> ``later runs: success``).
    """
    part, rest = _campaign_part(metric)
    key = _base_key(metric)
    name = key.replace("_", " ")
    name = ("IQM " if rest.startswith("iqm_") else "") + NAMES.get(name, name)
    label = f"{name} [{UNITS[key]}]" if key in UNITS else name
    return f"{CAMPAIGN_PARTS[part]}: {label}" if part else label


def episode_values(entry: Mapping[str, Any], metric: str) -> tuple[list[Any], bool]:
    """Per-episode values behind a summary key (paired by seed order) and whether the metric is a rate.

    A campaign part's key (``later_runs_...``) takes the episodes of that part only.
    """
    part, rest = _campaign_part(metric)
    episodes = [e for lv in entry["levels"] for e in lv["episodes"]]
    if part is not None:
        episodes = [e for e in episodes if bool(e.get("campaign_run")) == (part == "later_runs_")]
    if rest in ("success_rate", "collision_rate"):
        key = "is_success" if rest == "success_rate" else "collision"
        return [bool(e.get(key)) for e in episodes], True
    for prefix in ("mean_", "iqm_"):
        if rest.startswith(prefix):
            key = rest[len(prefix) :]
            return [e.get(key) for e in episodes], False
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
    if metric.endswith("_rate"):
        return False
    return _base_key(metric) not in PROGRESS_METRICS


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
    part = _campaign_part(metric)[0] or ""
    sx, _ = episode_values(x, part + "success_rate")
    sy, _ = episode_values(y, part + "success_rate")
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


def policy_kind(policy: Mapping[str, Any]) -> str:
    """The ``kind`` cell of an entry's policy.

    Learned and file policies show their weights' sha256 (its first 10 digits); a Python callable says when its
    actions may differ on another CPU.
    """
    kind = str(policy["kind"])
    if kind in ("learned", "onnx", "sb3-zip") and policy.get("sha256"):
        return f"{kind} (`{policy['sha256'][:10]}`)"
    if kind == "callable" and not policy.get("reverifiable", False):
        return "callable, not re-verifiable on another CPU"
    return kind


def render_markdown(entries: Sequence[Mapping[str, Any]], suites: Sequence[Suite]) -> str:
    """LEADERBOARD.md: per env and suite, every entry ranked, with 95 % intervals; privileged ones marked.

    Stress suites add each policy's success by level, and each env with stress suites ends with its
    robustness lines (:func:`~agri_training.leaderboard.robustness.robustness_lines`).
    """
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
                by_suite.get(suite.name, []), key=lambda e: (rank_key(e, suite.rank_by), e["policy"]["name"])
            )
            lines += [f"### {suite.name} (v{suite.version})", "", suite.description, ""]
            levels = len(suite.levels())
            swept = " and ".join(f"`{p}`" for p in suite.sweep[0]) if suite.sweep else ""
            # one argument: its values; several changed together: each level's assignment
            one = suite.sweep is not None and len(suite.sweep[0]) == 1
            values = ", ".join(
                f"`{row[0]}`" if one else f"`{v}`"
                for row, v in zip(suite.sweep[1] if suite.sweep else [], suite.level_values(), strict=False)
            )
            lines.append(
                (f"Stress suite, axis **{suite.stress}**. " if suite.stress else "")
                + f"Seeds {suite.seed_start}-{suite.seed_start + suite.episodes - 1}"
                + (f" at each of {levels} levels of {swept} ({values})" if suite.sweep else "")
                + (
                    f", in {suite.episodes // suite.campaign_runs} campaigns of {suite.campaign_runs} runs "
                    "(one world and one policy each)"
                    if suite.campaign_runs > 1
                    else ""
                )
                + f"; env arguments `{json.dumps(dict(suite.env_kwargs), sort_keys=True)}`."
                + (f" Under {MIN_EPISODES} episodes per level: {suite.fewer_episodes}" * bool(suite.fewer_episodes))
            )
            lines.append("")
            if not group:
                lines += ["No entries yet.", ""]
                continue
            head = (
                ["#", "policy", "kind", "episodes"]
                + [f"{metric_label(r.metric)} {'↑' if r.higher_is_better else '↓'}" for r in suite.rank_by]
                + ["vs #1"]
                + (["success by level"] if suite.stress else [])
            )
            lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
            first = suite.rank_by[0]
            for rank, e in enumerate(group, 1):
                s = e["summary"]
                name = e["policy"]["name"] + (" **P**" if e.get("privileged") else "")
                kind = policy_kind(e["policy"])
                cells = [
                    str(rank),
                    f"`{e['policy']['name']}`" + name[len(e["policy"]["name"]) :],
                    kind,
                    str(s["episodes"]),
                ]
                for r in suite.rank_by:
                    cells.append(format_metric(r.metric, s.get(r.metric), s.get(f"{r.metric}_ci")))
                if rank == 1:
                    cells.append("-")
                else:
                    c = compare_entries(e, group[0], first.metric, first.higher_is_better)
                    cells.append("n/a" if c is None else ("worse" if c.verdict == "worse" else "not distinguishable"))
                if suite.stress:
                    cells.append(level_rates(e))
                lines.append("| " + " | ".join(cells) + " |")
            lines.append("")
        robust = robustness_lines(env_id, suites, entries)
        if robust:
            lines += [
                f"### Robustness: where each policy first drops below {SUCCESS_FLOOR:.2f} success",
                "",
                "On each stress suite above (levels from the env's default out to its limits), the first level "
                f"whose success falls below {SUCCESS_FLOOR:.2f}, with its interval, and the dominant kind of "
                "failure there (crash, stall, time-out; see `agri_training/leaderboard/robustness.py`).",
                "",
                *robust,
                "",
            ]
    return "\n".join(lines).rstrip() + "\n"


def level_rates(entry: Mapping[str, Any]) -> str:
    """An entry's success rate at each level, in order: ``1.00 / 0.95 / 0.60`` (below the floor in bold)."""
    rates = []
    for level in entry["levels"]:
        k, n = level_success(level)
        text = f"{k / n:.2f}" if n else "-"
        rates.append(f"**{text}**" if n and k / n < SUCCESS_FLOOR - 1e-9 else text)
    return " / ".join(rates)


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


