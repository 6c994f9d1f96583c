"""Two entries of one suite side by side: their ranking, and paired comparisons of their episodes seed by seed.

LEADERBOARD.md (:mod:`.markdown`), the learning-gains section (:mod:`.gains`) and the report pair entries the same
way: rates over every episode, progress metrics too, and any other metric only over the episodes both policies
completed (a crash that ends an episode early must not make it look fast).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from agri_training.core.stats import paired_comparison
from agri_training.leaderboard.suites import RankKey


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


def campaign_part(metric: str) -> tuple[str | None, str]:
    """``(prefix, rest)`` of a campaign summary key (``(None, metric)`` for any other key)."""
    for prefix in CAMPAIGN_PARTS:
        if metric.startswith(prefix):
            return prefix, metric[len(prefix) :]
    return None, metric


def base_key(metric: str) -> str:
    """The per-episode key behind a summary key: ``later_runs_mean_max_cross_track`` -> ``max_cross_track``."""
    key = campaign_part(metric)[1]
    for prefix in ("mean_", "iqm_"):
        if key.startswith(prefix):
            return key[len(prefix) :]
    return key


def episode_values(entry: Mapping[str, Any], metric: str) -> tuple[list[Any], bool]:
    """Per-episode values behind a summary key (paired by seed order) and whether the metric is a rate.

    A campaign part's key (``later_runs_...``) takes the episodes of that part only.
    """
    part, rest = campaign_part(metric)
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
    return base_key(metric) not in PROGRESS_METRICS


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
    part = campaign_part(metric)[0] or ""
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
