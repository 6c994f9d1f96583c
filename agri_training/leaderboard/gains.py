"""Where learning beats the papers: each learned policy against the best scripted one, at equal safety.

On every suite that is not a stress suite (the papers' suites and the generalization suites), each learned entry
is paired, seed by seed, with the suite's best scripted entry (:func:`best_scripted`: the most efficient of the
scripted entries with the highest success rate) on:

* safety: success (Newcombe's paired interval) and collisions (the counts);
* efficiency: the suite's time key (``mean_episode_time``), or its path length (``mean_path_length``) where it
  ranks by no time (the arm), over the episodes both completed (:func:`~.markdown.compare_entries`).

A learned policy **beats** the scripted one on a suite when its efficiency difference's interval excludes zero in
its favour, its success is not worse (the interval does not exclude zero against it) and it collides no more
often. :func:`gain_rows` computes the pairs; :func:`gains_lines` writes LEADERBOARD.md's and the report's section.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

from agri_training.leaderboard.pairing import compare_entries, episode_values
from agri_training.leaderboard.suites import Suite
from agri_training.learned.zoo import training_teacher

#: The efficiency keys a suite may rank by, in order of preference (the first one the suite ranks by is used).
EFFICIENCY_METRICS = ("mean_episode_time", "mean_path_length")

#: What the section compares, for its readers (LEADERBOARD.md and the report).
GAINS_NOTE = (
    "Each learned policy that is faster (or, for the arm, has a shorter path) than its env's best scripted "
    "policy on some suite, against that policy, on every suite that is not a stress suite. Efficiency: time, "
    "or path length where a suite ranks by no time, over the episodes both completed; its paired difference "
    "with a 95 % bootstrap interval, and learned / scripted - 1 of the means. Equal safety: success not worse "
    "(Newcombe's paired interval does not exclude zero against it) and no more episodes with a collision. A "
    "policy with a safety layer (a fixed rule between its network and the robot; `agri_training/learned/"
    "safety.py`) shows how often the rule changed its action."
)

#: Per-episode counts of a safety layer (:mod:`agri_training.learned.safety`), shown beside a policy that has one.
SAFETY_LAYER_KEY = "safety_interventions"


@dataclasses.dataclass(frozen=True)
class Gain:
    """One learned entry against the best scripted entry of one suite.

    Attributes:
        suite: The suite's name.
        policy: The learned policy's name.
        scripted: The best scripted policy's name.
        metric: The efficiency key compared.
        relative: ``learned / scripted - 1`` of the efficiency key's means over the episodes both completed.
        comparison: The paired comparison on that key (:class:`~agri_training.core.stats.Comparison`), or None.
        success: ``(learned, scripted)`` success rates.
        success_verdict: The paired success comparison's verdict (``better``, ``worse``, ...), or None.
        collisions: ``(learned, scripted)`` episodes with a collision.
        episodes: Episodes of the suite.
        interventions: Mean safety-layer interventions per episode (None without a layer).
    """

    suite: str
    policy: str
    scripted: str
    metric: str
    relative: float | None
    comparison: Any
    success: tuple[float, float]
    success_verdict: str | None
    collisions: tuple[int, int]
    episodes: int
    interventions: float | None

    @property
    def faster(self) -> bool:
        """The efficiency difference's interval excludes zero in the learned policy's favour."""
        return self.comparison is not None and self.comparison.verdict == "better"

    @property
    def as_safe(self) -> bool:
        """Success not worse (interval) and no more episodes with a collision than the scripted policy."""
        return self.success_verdict != "worse" and self.collisions[0] <= self.collisions[1]

    @property
    def beats(self) -> bool:
        """Better on efficiency at equal safety."""
        return self.faster and self.as_safe


def efficiency_metric(suite: Suite) -> str | None:
    """The suite's efficiency key (:data:`EFFICIENCY_METRICS`), or None when it ranks by neither."""
    ranked = [r.metric for r in suite.rank_by]
    return next((m for m in EFFICIENCY_METRICS if m in ranked), None)


def _collisions(entry: Mapping[str, Any]) -> int:
    return sum(episode_values(entry, "collision_rate")[0])


def _mean_interventions(entry: Mapping[str, Any]) -> float | None:
    values = [v for v in episode_values(entry, "mean_" + SAFETY_LAYER_KEY)[0] if v is not None]
    return sum(values) / len(values) if values else None


def best_scripted(group: Sequence[Mapping[str, Any]], metric: str, higher_is_better: bool) -> Mapping[str, Any] | None:
    """The scripted entry a learned one must beat: the most efficient of those with the highest success rate.

    Not simply the suite's first baseline: a suite may rank a slower policy first on another key (a smaller
    cross-track error), and a learned policy faster than that one only would claim too much.
    """
    scripted = [e for e in group if e["policy"]["kind"] == "baseline" and e["summary"].get(metric) is not None]
    if not scripted:
        return None
    top = max(float(e["summary"]["success_rate"]) for e in scripted)
    safest = [e for e in scripted if float(e["summary"]["success_rate"]) == top]
    sign = -1.0 if higher_is_better else 1.0
    return min(safest, key=lambda e: (sign * float(e["summary"][metric]), e["policy"]["name"]))


def gain_rows(env_id: str, suites: Sequence[Suite], entries: Sequence[Mapping[str, Any]]) -> list[Gain]:
    """Every learned entry of ``env_id`` against its suite's best scripted entry, on the suites that are not stress.

    Suites without a scripted entry or an efficiency key are skipped.
    """
    rows: list[Gain] = []
    for suite in suites:
        metric = efficiency_metric(suite)
        if suite.env_id != env_id or suite.stress or metric is None:
            continue
        group = [e for e in entries if e["suite"]["name"] == suite.name]
        higher = next(r.higher_is_better for r in suite.rank_by if r.metric == metric)
        best = best_scripted(group, metric, higher)
        if best is None:
            continue
        for e in sorted(group, key=lambda e: e["policy"]["name"]):
            if e["policy"]["kind"] == "baseline":
                continue
            c = compare_entries(e, best, metric, higher)
            s = compare_entries(e, best, "success_rate", True)
            rows.append(
                Gain(
                    suite=suite.name,
                    policy=e["policy"]["name"],
                    scripted=best["policy"]["name"],
                    metric=metric,
                    relative=(c.x / c.y - 1.0) if c is not None and c.y else None,
                    comparison=c,
                    success=(float(e["summary"]["success_rate"]), float(best["summary"]["success_rate"])),
                    success_verdict=None if s is None else s.verdict,
                    collisions=(_collisions(e), _collisions(best)),
                    episodes=int(e["summary"]["episodes"]),
                    interventions=_mean_interventions(e),
                )
            )
    return rows


def _unit(metric: str) -> str:
    return "s" if "time" in metric else "m"


def gains_lines(env_ids: Sequence[str], suites: Sequence[Suite], entries: Sequence[Mapping[str, Any]]) -> list[str]:
    """Markdown: per env, the learned policies faster (or shorter) than the best scripted one on some suite.

    Each such policy gets one row per suite that is not a stress suite; a closing line per env says which
    policies beat the scripted one at equal safety on every one of those suites. Envs where no learned policy is
    faster anywhere get one line saying so.
    """
    lines: list[str] = []
    for env_id in env_ids:
        rows = gain_rows(env_id, suites, entries)
        if not rows:
            continue
        faster = sorted({g.policy for g in rows if g.faster})
        lines += [f"**{env_id}**", ""]
        if not faster:
            lines += ["No learned policy is faster (or shorter) than the best scripted one on any of its suites.", ""]
            continue
        lines += [
            "| policy | suite | vs scripted | success | collisions | efficiency: learned - scripted [95 %] | "
            "relative | safety layer interventions / episode | verdict |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for name in faster:
            for g in (g for g in rows if g.policy == name):
                c = g.comparison
                unit = _unit(g.metric)
                diff = "n/a" if c is None else f"{c.difference:+.1f} {unit} [{c.ci[0]:+.1f}, {c.ci[1]:+.1f}]"
                rel = "n/a" if g.relative is None else f"{100 * g.relative:+.0f} %"
                verdict = (
                    "**beats it at equal safety**"
                    if g.beats
                    else "faster, less safe"
                    if g.faster
                    else "less safe"
                    if not g.as_safe
                    else "not faster"
                )
                layer = "-" if g.interventions is None else f"{g.interventions:.1f}"
                lines.append(
                    f"| `{g.policy}` | {g.suite} | `{g.scripted}` | {g.success[0]:.2f} vs {g.success[1]:.2f} | "
                    f"{g.collisions[0]} vs {g.collisions[1]} of {g.episodes} | {diff} | {rel} | {layer} | {verdict} |"
                )
        lines.append("")
        for name in faster:
            mine = [g for g in rows if g.policy == name]
            won = [g.suite for g in mine if g.beats]
            teacher = training_teacher(name)
            lines.append(
                f"- `{name}` beats the best scripted policy at equal safety on {len(won)} of its {len(mine)} suites"
                + (f" ({', '.join(won)})." if 0 < len(won) < len(mine) else ".")
                + (
                    f" It was cloned from `{teacher}`, a training teacher that is no paper's controller: the time "
                    "it gains is its teacher's."
                    if teacher
                    else ""
                )
            )
        lines.append("")
    return lines
