"""The evaluation report: one Markdown + HTML page over every suite, baseline and learned policy.

The page is built from the committed leaderboard entries (``leaderboard/entries``); an entry that is
missing or stale (its suite changed) is evaluated afresh and written under ``OUT/results``. The episodes
that are plotted (the first seed of the lead policy and the first failure of every policy, per level) are
re-run with per-step traces: every episode is deterministic under its seed, so the re-run is the episode
the entry counted.

Per-env sections come from builders named in :data:`SECTION_HOOKS` (``"module:function"``, called as
``function(results, out_dir) -> markdown``, where ``results`` are the evaluator's per-level result
documents with traces). An env with another layout (the chain's PettingZoo env, the coverage env) adds
its builder there with one line.
"""

from __future__ import annotations

import csv
import dataclasses
import html
import importlib
import json
import math
import re
import sys
import time
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import agri_envs
from agri_envs.scenarios import scenario as get_scenario
from agri_training import leaderboard as lb
from agri_training.core.documents import git_commit
from agri_training.core.progress import Progress
from agri_training.core.stats import bootstrap_ci, newcombe_interval, paired_comparison, wilson_interval
from agri_training.evaluation.episode import run_episode
from agri_training.evaluation.evaluate import INTERVALS_NOTE
from agri_training.evaluation.reference import PolicyRef, build_policy
from agri_training.evaluation.video import shrink_frame, write_clip
from agri_training.learned.zoo import ZOO_DIR
from agri_training.report.generalization import SEED_SPREAD_INTRO, generalization_section, seed_spread_section
from agri_training.report.robustness import glance_table, own_sensors_section, robustness_section

#: Per-env report sections: env id -> ``"module:function"`` (see the module docstring).
SECTION_HOOKS: dict[str, str] = {
    "agri_envs/GreenhouseNav-v2": "agri_training.report.rover:report_section",
    "agri_envs/GrapeHarvest-v1": "agri_training.report.arm:report_section",
    "robot_chain_v1": "agri_training.report.chain:report_section",
    "agri_envs/GreenhouseCoverage-v2": "agri_training.report.coverage:report_section",
}

#: Success rates the papers report, as (successes, trials, source), per suite name: our rate is compared
#: with theirs by an interval of the difference, not by eye.
PAPER_RATES: dict[str, tuple[int, int, str]] = {
    "grape-table2": (9, 10, "Luo et al. 2018, Table 2"),
}

#: Equivalence margins for "matches": rates within +-0.10; other metrics within +-5 % of the reference mean.
RATE_MARGIN = 0.10
RELATIVE_MARGIN = 0.05

INTRO = """\
This page compares every policy of `agri_envs` on pinned evaluation suites: the scripted controllers of
the papers the envs reproduce (*baselines*) and policies trained with reinforcement learning (*learned*).
Each suite fixes an env, its arguments and the seeds (100000 and up, which training never uses); every
policy runs the same episodes, so their results can be compared seed by seed.

How to read the numbers:

- Every number comes with a 95 % interval in brackets: `0.95 [0.76, 0.99]`. Rates (success, collision) use
  Wilson score intervals, so 20 successes in 20 episodes read `1.00 [0.84, 1.00]`: the data are consistent
  with a true rate as low as 84 %. Means use a percentile bootstrap over episodes.
- A policy *beats* another only where the paired comparison's interval of the difference excludes zero; it
  *matches* only where that interval lies within a small margin (0.10 for rates, 5 % of the other's mean
  for times and lengths). Everything else is *not distinguishable* with these episodes.
- Secondary metrics (time, path length, clearance, cross-track, path ratio, ...) are compared only over
  the episodes that both policies completed, and not at all (*n/a*) when fewer than 5 are: a failed
  episode ends early, which makes a policy look faster or straighter without being so. Rates and progress
  (coverage, waypoints reached) are compared over every episode. A policy that is worse on a suite's first
  ranking metric (success) is never said to beat another on the others, nor a better one to be worse.
- **P** marks *privileged* policies: they use what a real robot would not have (such as the true pose),
  so they show what the controller could do with perfect localization, not what the robot does.
"""


@dataclasses.dataclass
class Row:
    """One policy on one suite: its entry and whether it came from the committed leaderboard.

    A quick look, which evaluates afresh, also keeps the per-step traces of every episode of each level.
    """

    suite: lb.Suite
    entry: dict[str, Any]
    committed: bool
    traces: list[list[Any]] | None = None


def _entry_is_current(entry: Mapping[str, Any], suite: lb.Suite) -> bool:
    return entry["suite"]["sha256"] == suite.sha256 and entry["suite"]["version"] == suite.version


def collect_rows(
    suites: Sequence[lb.Suite],
    entries: Sequence[dict[str, Any]],
    out_dir: Path,
    workers: int | None = 1,
    progress: bool = True,
    episodes: int | None = None,
    ray: str | None = None,
) -> list[Row]:
    """Committed entries that are current, plus fresh evaluations for every missing or stale one.

    Args:
        suites: The suites to report.
        entries: Committed entries (learned ones are reported on the suites they have entries for).
        out_dir: Fresh entries are written to ``out_dir/results``.
        workers: Worker processes for fresh evaluations.
        progress: Show the progress bar.
        episodes: Override the suites' episode counts (a quick look; then nothing committed is used).
        ray: Run fresh episodes as Ray tasks (see :func:`agri_training.evaluate.evaluate_many`).
    """
    rows: list[Row] = []
    todo: list[tuple[lb.Suite, dict[str, Any]]] = []
    for suite in suites:
        if episodes is not None:
            runs = suite.campaign_runs  # a campaign suite runs whole campaigns: at least one
            suite = dataclasses.replace(suite, episodes=-(-episodes // runs) * runs)
        have = {e["policy"]["name"]: e for e in entries if e["suite"]["name"] == suite.name}
        refs = [ref for _, ref in lb.all_baseline_pairs([suite])]  # the policies that can run this suite
        named = {ref["name"] for ref in refs}  # registered learned policies are among them already
        refs += [
            e["policy"] for e in have.values() if e["policy"]["kind"] == "learned" and e["policy"]["name"] not in named
        ]
        for ref in refs:
            entry = have.get(ref["name"])
            if episodes is None and entry is not None and _entry_is_current(entry, suite):
                rows.append(Row(suite, entry, True))
            else:
                todo.append((suite, dict(ref)))
    if todo:
        print(f"evaluating {len(todo)} missing or stale (suite, policy) pairs", file=sys.stderr)
        # A quick look traces every episode as it runs (a few per level), so that nothing is run twice.
        traces: list[list[Any]] | None = [] if episodes is not None else None
        fresh = lb.evaluate_entries(todo, workers, progress, "agri report", ray, traces)
        for k, ((suite, _), entry) in enumerate(zip(todo, fresh, strict=True)):
            lb.write_entry(entry, out_dir / "results")
            rows.append(Row(suite, entry, False, None if traces is None else traces[k]))
    order = {s.name: i for i, s in enumerate(suites)}
    rows.sort(key=lambda r: (order[r.suite.name], r.entry["policy"]["name"]))
    return rows


#: Most frames of a clip (the episode is sampled evenly), and the shrink factor of its frames.
CLIP_FRAMES = 60
CLIP_SCALE = 0.4


def level_results(
    rows: Sequence[Row], progress: bool = True, out_dir: Path | None = None, clips: bool = True
) -> list[dict[str, Any]]:
    """The evaluator's per-level result documents of the rows, with traces of the episodes to be plotted.

    Traced: per level, the first seed of the lead policy (the first unprivileged scripted one: the paper's robot;
    else the first unprivileged one) and the first failed
    seed of every policy; nothing of a stress suite, which the report shows as its robustness matrix (its many
    levels would re-run a failure of nearly every policy at every level). With ``clips`` (and ``out_dir``),
    every policy also gets a clip of one success and one failure per suite (where it has both), recorded
    while its episode is re-run: the first traced
    episode of that outcome, or else its first episode of that outcome. A row that carries its traces (a
    quick look) is not re-run for them; its clips are only the lead policy's.
    """
    plan: list[tuple[Row, int, list[int], dict[int, str]]] = []
    for suite_name in dict.fromkeys(r.suite.name for r in rows):
        group = [r for r in rows if r.suite.name == suite_name]
        unprivileged = [r for r in group if not r.entry.get("privileged")]
        scripted = [r for r in unprivileged if not lb.is_learned(r.entry["policy"])]
        lead = (scripted or unprivileged or group)[0]
        for r in group:
            levels = r.entry["levels"]
            seeds: list[list[int]] = []
            for level in levels:
                if r.suite.stress:
                    seeds.append([])
                    continue
                first = r is lead and r.suite.traces > 0 and level["episodes"]
                chosen = [level["episodes"][0]["seed"]] if first else []
                if first and r.suite.campaign_runs > 1:  # and the first later run of its first campaign
                    chosen.append(level["episodes"][1]["seed"])
                failed = [e["seed"] for e in level["episodes"] if not e["is_success"]]
                if failed and failed[0] not in chosen:
                    chosen.append(failed[0])
                seeds.append(chosen)
            films: dict[tuple[int, int], str] = {}
            if clips and out_dir is not None and (r.traces is None or r is lead) and not r.suite.stress:
                for outcome, name in ((True, "success"), (False, "failure")):
                    traced = [(k, s) for k, ss in enumerate(seeds) for s in ss]
                    where = [(k, s) for k, s in traced if _record_of(levels[k], s).get("is_success") == outcome]
                    # in a campaign, show a later run (what the runs before it taught the policy) where traced
                    where.sort(key=lambda ks: not _record_of(levels[ks[0]], ks[1]).get("campaign_run"))
                    if not where:
                        episodes = [(k, e) for k, lv in enumerate(levels) for e in lv["episodes"]]
                        where = [(k, e["seed"]) for k, e in episodes if e["is_success"] == outcome][:1]
                        if where:
                            seeds[where[0][0]].append(where[0][1])
                    if where:
                        films[where[0]] = name
            for k in range(len(levels)):
                plan.append((r, k, seeds[k], {s: name for (kk, s), name in films.items() if kk == k}))
    reruns = sum(len(s) for r, _, s, f in plan if r.traces is None) + sum(len(f) for r, _, _, f in plan if r.traces)
    bar = Progress(reruns, sum(1 for _, _, s, _ in plan if s), progress)
    out = []
    try:
        for r, k, level_seeds, level_films in plan:
            out.append(_level_document(r, k, level_seeds, level_films, bar, out_dir))
    finally:
        bar.close()
    return out


def _level_document(
    row: Row, k: int, seeds: list[int], films: Mapping[int, str], bar: Any, out_dir: Path | None
) -> dict[str, Any]:
    entry, level = row.entry, row.entry["levels"][k]
    doc = {
        "env_id": entry["env_id"],
        "scenario": row.suite.scenario,
        "suite": row.suite.name,
        "label": level["label"],
        "policy": entry["policy"]["name"],
        "policy_kind": entry["policy"]["kind"],
        "privileged": bool(entry.get("privileged")),
        "seed": row.suite.seed_start,
        "env_kwargs": level["env_kwargs"],
        "package_version": entry["package_version"],
        "git_commit": entry["git_commit"],
        "summary": level["summary"],
        "episodes": level["episodes"],
        "traces": [],
        "clips": [],
    }
    if not seeds:
        return doc
    bar.start_block(f"traces: {doc['policy']} on {doc['label']}")
    kept = {t["seed"]: t for t in row.traces[k]} if row.traces is not None else {}
    replay = _Replay(doc["env_id"], doc["env_kwargs"], lb.policy_from_entry(entry["policy"]))
    try:
        for seed in seeds:
            record = _record_of(level, seed)
            if seed in kept and seed not in films:
                trace = kept[seed]
                whole = trace.get("record") or record
                doc["traces"].append(
                    {"seed": seed, "data": trace["data"], "is_success": record.get("is_success"), "record": whole}
                )
                continue
            film = films.get(seed)
            ep, frames = replay.run(record, film is not None)
            if ep["record"]["is_success"] != record.get("is_success"):
                print(f"warning: {doc['policy']} seed {seed} did not reproduce its recorded outcome", file=sys.stderr)
            # the re-run's whole record: the entry keeps scalars only (lb.entry_record), plots read maps and paths
            doc["traces"].append(
                {"seed": seed, "data": ep["trace"], "is_success": ep["record"]["is_success"], "record": ep["record"]}
            )
            if film is not None and frames and out_dir is not None:
                stem = f"clip_{_anchor(row.suite.name)}_{lb.slug(doc['policy'])}_{film}"
                clip = {"outcome": film, "seed": seed, "steps": ep["record"]["steps"]}
                doc["clips"].append({**clip, **_write_clip(frames, out_dir, stem)})
            bar.episode_done(ep["record"])
    finally:
        replay.close()
    return doc


class _Replay:
    """Re-runs recorded episodes of one level, exactly as the entry counted them, with traces and frames.

    A fresh policy per episode, as the evaluator's workers build it; a later run of a campaign is re-run
    after the campaign's earlier runs, with the same policy, in the campaign's world (``layout_seed``).
    """

    def __init__(self, env_id: str, env_kwargs: Mapping[str, Any], policy: PolicyRef) -> None:
        self.env_id, self.env_kwargs, self.policy = env_id, dict(env_kwargs), policy
        self._envs: dict[tuple[Any, bool], Any] = {}

    def _env(self, layout_seed: Any, render: bool) -> Any:
        key = (layout_seed, render)
        if key not in self._envs:
            kwargs = dict(self.env_kwargs)
            if layout_seed is not None:
                kwargs["layout_seed"] = layout_seed
            self._envs[key] = agri_envs.make(self.env_id, **kwargs, render_mode="rgb_array" if render else None)
        return self._envs[key]

    def run(self, record: Mapping[str, Any], film: bool) -> tuple[Any, list[np.ndarray]]:
        """The episode of ``record`` with its trace, and (``film``) about :data:`CLIP_FRAMES` frames of it."""
        env = self._env(record.get("layout_seed"), film)
        keys = tuple(getattr(env, "unwrapped", env).metadata.get("trace_keys", ()))
        policy = build_policy(self.policy, env)
        seed, run = int(record["seed"]), int(record.get("campaign_run") or 0)
        for earlier in range(seed - run, seed):
            run_episode(env, policy, earlier, None)
        frames: list[np.ndarray] = []
        every = max(1, math.ceil(int(record.get("steps") or 1) / CLIP_FRAMES))

        def on_step(step: int) -> bool:
            if step % every == 0:
                frame = env.render()
                if frame is not None:
                    frames.append(shrink_frame(np.asarray(frame, dtype=np.uint8), CLIP_SCALE))
            return False

        ep = run_episode(env, policy, seed, keys, on_step if film else None)
        if film and ep["record"]["steps"] % every:  # and the episode's last state (the poster)
            frames.append(shrink_frame(np.asarray(env.render(), dtype=np.uint8), CLIP_SCALE))
        return ep, frames

    def close(self) -> None:
        for env in self._envs.values():
            env.close()


def _write_clip(frames: list[np.ndarray], out_dir: Path, stem: str) -> dict[str, str]:
    """An MP4 with a poster frame (PNG of the last frame) where imageio's ffmpeg is installed, else a GIF."""
    try:
        write_clip(frames, out_dir / f"{stem}.mp4", 10.0)
    except ImportError:
        write_clip(frames, out_dir / f"{stem}.gif", 10.0)
        return {"file": f"{stem}.gif"}
    from PIL import Image

    Image.fromarray(frames[-1]).save(out_dir / f"{stem}.png", optimize=True)
    return {"file": f"{stem}.mp4", "poster": f"{stem}.png"}


def clip_lines(docs: Sequence[Mapping[str, Any]]) -> list[str]:
    """Markdown for the clips of one suite: per policy, its success and its failure, labelled."""
    lines: list[str] = []
    for doc in docs:
        for clip in doc.get("clips", []):
            what = f"`{doc['policy']}` on `{doc['label']}`, seed {clip['seed']}: a {clip['outcome']}"
            what += f" ({clip['steps']} steps)"
            lines += [what, "", _clip_tag(clip), ""]
    return lines


def _clip_tag(clip: Mapping[str, Any]) -> str:
    if "poster" in clip:
        return f'<video controls preload="none" poster="{clip["poster"]}" src="{clip["file"]}"></video>'
    return f"![{clip['file']}]({clip['file']})"


def _record_of(level: Mapping[str, Any], seed: int) -> dict[str, Any]:
    return next((e for e in level["episodes"] if e["seed"] == seed), {})


# ---------------------------------------------------------------- comparisons


def _margin(metric: str, reference: float) -> float:
    return RATE_MARGIN if metric.endswith("_rate") else RELATIVE_MARGIN * abs(reference)


def compare(x: Mapping[str, Any], y: Mapping[str, Any], metric: str, higher_is_better: bool) -> Any:
    """Paired comparison of entry ``x`` with entry ``y`` on a suite metric, with the report's margins.

    Secondary metrics (time, path length, clearance, cross-track, path ratio, ...) are compared over the
    episodes both policies completed (:func:`agri_training.leaderboard.paired_values`); with fewer than
    :data:`agri_training.leaderboard.MIN_COMPLETED_PAIRS` of them, not at all (None).
    """
    vx, vy, binary, completed = lb.paired_values(x, y, metric)
    if not vx or len(vx) != len(vy) or (completed is not None and completed < lb.MIN_COMPLETED_PAIRS):
        return None
    finite = [float(v) for v in vy if v is not None and math.isfinite(float(v))]
    if not finite:
        return None
    ref = sum(finite) / len(finite)
    try:
        return paired_comparison(vx, vy, metric, higher_is_better, binary=binary, margin=_margin(metric, ref))
    except ValueError:
        return None


def _completed(x: Mapping[str, Any], y: Mapping[str, Any], metric: str) -> tuple[int | None, int]:
    """(episodes both completed or None for an unconditional metric, episodes in all) of a pair."""
    vx, _, _, completed = lb.paired_values(x, y, metric)
    return completed, len(vx)


def _metric_name(metric: str) -> str:
    return lb.metric_label(metric)


def _pairs(group: Sequence[Row]) -> list[tuple[Row, Row]]:
    """Which pairs a suite compares.

    Every learned policy against every baseline; without learned ones, every pair of baselines (the
    unprivileged before the privileged).
    """
    learned = [r for r in group if lb.is_learned(r.entry["policy"])]
    base = [r for r in group if not lb.is_learned(r.entry["policy"])]
    if learned:
        return [(a, b) for a in learned for b in base]
    base = sorted(base, key=lambda r: (bool(r.entry.get("privileged")), r.entry["policy"]["name"]))
    return [(base[i], base[j]) for i in range(len(base)) for j in range(i + 1, len(base))]


def comparison_table(group: Sequence[Row]) -> tuple[list[str], list[str]]:
    """Markdown table of the paired comparisons of one suite, and sentences for the claims it supports."""
    suite = group[0].suite
    head = ["X vs Y"] + [_metric_name(r.metric) for r in suite.rank_by]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    claims: list[str] = []
    for a, b in _pairs(group):
        na, nb = a.entry["policy"]["name"], b.entry["policy"]["name"]
        cells = [f"`{na}` vs `{nb}`"]
        wins: list[str] = []
        losses: list[str] = []
        same: list[str] = []
        primary = "inconclusive"
        for i, rk in enumerate(suite.rank_by):
            c = compare(a.entry, b.entry, rk.metric, rk.higher_is_better)
            completed, n = _completed(a.entry, b.entry, rk.metric)
            if c is None:
                cells.append(
                    f"n/a: both completed {completed} of {n} episodes"
                    if completed is not None and completed < lb.MIN_COMPLETED_PAIRS
                    else "n/a"
                )
                continue
            fmt = "{:+" + lb.metric_format(rk.metric)[2:]
            f = lb.metric_scale(rk.metric)
            diff, lo, hi = c.difference * f, c.ci[0] * f, c.ci[1] * f
            verdict = c.verdict
            if i == 0:
                primary = verdict
            # The one that succeeds less often is never said to do better on the others, nor the one that
            # succeeds more often worse: the episodes both completed are too few a share to rank them on.
            elif (primary == "worse" and verdict == "better") or (primary == "better" and verdict == "worse"):
                verdict = "not claimed"
            word = {
                "better": "**X better**",
                "worse": "**X worse**",
                "matches": "match",
                "inconclusive": "-",
                "not claimed": f"- (not claimed: X succeeds {'less' if primary == 'worse' else 'more'} often)",
            }
            over = f" over the {completed} episodes both completed" if completed is not None else ""
            cells.append(
                f"{fmt.format(diff)} [{fmt.format(lo)}, {fmt.format(hi)}], "
                f"P(X better) {c.prob_improvement:.2f}; {word[verdict]}{over}"
            )
            text = (
                f"{_metric_name(rk.metric)} ({fmt.format(diff)} [{fmt.format(lo)}, {fmt.format(hi)}]"
                f"{'; ' + over.strip() if over else ''})"
            )
            {"better": wins, "worse": losses, "matches": same}.get(verdict, []).append(text)
        lines.append("| " + " | ".join(cells) + " |")
        parts = []
        if wins:
            parts.append(f"`{na}` beats `{nb}` on " + ", ".join(wins))
        if losses:
            parts.append(("it" if wins else f"`{na}`") + f" is worse than `{nb}` on " + ", ".join(losses))
        if same:
            parts.append(("it" if wins or losses else f"`{na}`") + f" matches `{nb}` on " + ", ".join(same))
        if parts:
            claims.append(f"{suite.name}: " + "; ".join(parts) + ".")
        else:
            claims.append(f"{suite.name}: `{na}` and `{nb}` are not distinguishable on any ranking metric.")
    return lines, claims


def paper_rate_line(row: Row) -> str | None:
    """Our success rate against the paper's, with the interval of the difference (None when not reported)."""
    ref = PAPER_RATES.get(row.suite.name)
    if ref is None:
        return None
    k_ref, n_ref, source = ref
    eps = [e for lv in row.entry["levels"] for e in lv["episodes"]]
    k, n = sum(bool(e["is_success"]) for e in eps), len(eps)
    lo, hi = newcombe_interval(k, n, k_ref, n_ref)
    ours, theirs = wilson_interval(k, n), wilson_interval(k_ref, n_ref)
    if lo > 0:
        verdict = "higher than the paper's, and the interval supports it"
    elif hi < 0:
        verdict = "lower than the paper's, and the interval supports it"
    else:
        verdict = "not distinguishable from the paper's (the interval of the difference includes 0)"
    return (
        f"`{row.entry['policy']['name']}` succeeds in {k} of {n} episodes, {k / n:.2f} [{ours[0]:.2f}, {ours[1]:.2f}]; "
        f"{source} reports {k_ref} of {n_ref}, {k_ref / n_ref:.2f} [{theirs[0]:.2f}, {theirs[1]:.2f}]. Difference "
        f"{k / n - k_ref / n_ref:+.2f} [{lo:+.2f}, {hi:+.2f}]: {verdict}."
    )


# ---------------------------------------------------------------- learning curves


def find_runs(runs_dir: Path) -> list[dict[str, Any]]:
    """Training runs under ``runs_dir`` that have a learning curve.

    A run is a folder holding ``progress.csv`` (stable-baselines3's CSV logger) or ``*curve*.csv``, and a
    config (``config.yaml``, ``config.yml``, ``config.json``, ``run.json`` or ``meta.json``) naming its env
    (``env_id`` or ``env``). Runs without a readable env id are skipped.
    """
    runs: list[dict[str, Any]] = []
    if not runs_dir.is_dir():
        return runs
    csvs = sorted(set(runs_dir.rglob("progress.csv")) | set(runs_dir.rglob("*curve*.csv")))
    for path in csvs:
        env_id = None
        config: Mapping[str, Any] = {}
        for folder in (path.parent, path.parent.parent):
            for name in ("config.yaml", "config.yml", "config.json", "run.json", "meta.json"):
                cfg = folder / name
                if cfg.exists():
                    try:
                        doc = yaml.safe_load(cfg.read_text())
                    except yaml.YAMLError:
                        continue
                    if isinstance(doc, Mapping):
                        env_id = doc.get("env_id") or doc.get("env")
                        config = doc
                if env_id:
                    break
            if env_id:
                break
        if not isinstance(env_id, str):
            continue
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        if rows:
            runs.append(
                {"env_id": env_id, "name": str(path.parent.relative_to(runs_dir)), "rows": rows, "config": config}
            )
    return runs


def zoo_runs() -> list[dict[str, Any]]:
    """The learning curves of the shipped trained policies (``agri_training/zoo/NAME``), named ``zoo/NAME``."""
    return [{**run, "name": f"zoo/{run['name']}"} for run in find_runs(ZOO_DIR)]


_X_KEYS = ("time/total_timesteps", "total_timesteps", "timesteps", "timestep", "step")
_Y_KEYS = (
    ("eval/success_rate", "success rate (evaluation)"),
    ("success_rate", "success rate"),
    ("rollout/success_rate", "success rate (training episodes)"),
    ("eval/mean_reward", "mean return (evaluation)"),
    ("rollout/ep_rew_mean", "mean return (training episodes)"),
    ("mean_reward", "mean return"),
)


def _curve(rows: list[dict[str, str]]) -> tuple[str, str, list[float], list[float]] | None:
    keys = rows[0].keys()
    xk = next((k for k in _X_KEYS if k in keys), None)
    if xk is None:
        return None
    for yk, label in _Y_KEYS:
        if yk in keys:
            pts = [(float(r[xk]), float(r[yk])) for r in rows if r.get(xk) and r.get(yk)]
            if pts:
                return yk, label, [p[0] for p in pts], [p[1] for p in pts]
    return None


#: Env arguments that change what a policy observes or how it commands, not the task or the scene: a run
#: and a suite that differ only in these are drawn together (a learned rover on the true pose against
#: ``harik-apf`` on its SLAM pose, both on the same scene).
POLICY_SIDE_KWARGS = frozenset({"localization", "full_scan", "control", "max_ee_step", "max_ee_rotation"})


def run_env_kwargs(run: Mapping[str, Any]) -> dict[str, Any] | None:
    """The env arguments of a run's periodic evaluation (its scenario's preset, then its ``env_kwargs``).

    None when the run's config does not say (an SB3 ``progress.csv`` with a bare config): then it cannot be
    matched with a suite.
    """
    config = run.get("config") or {}
    if "env_kwargs" not in config and not config.get("scenario"):
        return None
    kwargs: dict[str, Any] = {}
    if config.get("scenario"):
        try:
            kwargs.update(get_scenario(run["env_id"], str(config["scenario"])).env_kwargs)
        except ValueError:
            return None
    kwargs.update(config.get("env_kwargs") or {})
    return kwargs


def _task_kwargs(kwargs: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in kwargs.items() if k not in POLICY_SIDE_KWARGS}


def curve_suite(run: Mapping[str, Any], suites: Sequence[lb.Suite]) -> lb.Suite | None:
    """The suite of the run's task and scene: same env id, same env arguments (less the policy-side ones).

    Sweeping suites (several levels) never match: a curve has one scene.
    """
    kwargs = run_env_kwargs(run)
    if kwargs is None:
        return None
    for suite in suites:
        if suite.env_id == run["env_id"] and not suite.sweep:
            if _task_kwargs(suite.env_kwargs) == _task_kwargs(kwargs):
                return suite
    return None


def _baseline_groups(base: Sequence[Row], key: str) -> list[tuple[str, float, tuple[float, float]]]:
    """Baselines with the same value and interval merged into one line: ``(label, value, (lo, hi))``."""
    groups: dict[tuple[float, float, float], list[str]] = {}
    for b in base:
        s = b.entry["summary"]
        if s.get(key) is None:
            continue
        lo, hi = s.get(f"{key}_ci") or (s[key], s[key])
        groups.setdefault((round(float(s[key]), 3), round(float(lo), 3), round(float(hi), 3)), []).append(
            b.entry["policy"]["name"]
        )
    return [
        (f"{', '.join(names)}: {v:.2f} [{lo:.2f}, {hi:.2f}] (baseline{'s' if len(names) > 1 else ''})", v, (lo, hi))
        for (v, lo, hi), names in groups.items()
    ]


_Curve = tuple[str, str, list[float], list[float]]


def seed_groups(curves: Sequence[tuple[dict[str, Any], _Curve]]) -> list[list[tuple[dict[str, Any], _Curve]]]:
    """Runs grouped by configuration: the same config (but the seed) and the same logged key, in order."""
    groups: dict[str, list[tuple[dict[str, Any], _Curve]]] = {}
    for run, c in curves:
        config = {k: v for k, v in (run.get("config") or {}).items() if k != "seed"}
        key = json.dumps(config, sort_keys=True, default=str) + c[0] if config else f"{run['name']}:{c[0]}"
        groups.setdefault(key, []).append((run, c))
    return list(groups.values())


def across_seeds(curves: Sequence[_Curve]) -> tuple[list[float], list[float], list[float], list[float]]:
    """Mean over seeds at the steps every seed logged, with a 95 % bootstrap interval of that mean."""
    common = sorted(set.intersection(*(set(c[2]) for c in curves)))
    values = [[dict(zip(c[2], c[3], strict=True))[x] for c in curves] for x in common]
    cis = [bootstrap_ci(v) for v in values]
    return common, [float(np.mean(v)) for v in values], [c[0] for c in cis], [c[1] for c in cis]


def _common_name(names: Sequence[str]) -> str:
    """``runs/sweep/seed0``, ``runs/sweep/seed1`` -> ``runs/sweep/seed*``."""
    prefix = names[0]
    for n in names[1:]:
        while not n.startswith(prefix):
            prefix = prefix[:-1]
    return (prefix or "runs") + "*"


def learning_curves(env_id: str, runs: list[dict[str, Any]], rows: Sequence[Row], out_dir: Path) -> list[str]:
    """Markdown: learning curves of the env's runs, each against the baselines of its own task and scene.

    A run is drawn with the baselines' 95 % bands of the suite with its env id and env arguments
    (:func:`curve_suite`); a run that no suite matches is drawn alone, with a note. Success-rate points
    carry their Wilson interval over the run's evaluation episodes; return curves get the baselines' mean
    returns.
    """
    mine = [r for r in runs if r["env_id"] == env_id]
    if not mine:
        return [
            "No training runs with a learning curve were found for this env (looked for `curve.csv` or "
            "`progress.csv` under the runs folder). Train one with `agri train` and rebuild the report."
        ]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves: list[tuple[dict[str, Any], tuple[str, str, list[float], list[float]]]] = []
    for run in mine:
        c = _curve(run["rows"])
        if c is not None:
            curves.append((run, c))
    if not curves:
        return ["Training runs were found, but none logs a success rate or a return."]
    env_suites = list({r.suite.name: r.suite for r in rows if r.suite.env_id == env_id}.values())
    by_suite: dict[str | None, list[tuple[dict[str, Any], tuple[str, str, list[float], list[float]]]]] = {}
    for run, c in curves:
        suite = curve_suite(run, env_suites)
        by_suite.setdefault(suite.name if suite else None, []).append((run, c))
    out: list[str] = []
    for suite_name, group in by_suite.items():
        base = [r for r in rows if r.suite.name == suite_name and r.entry["policy"]["kind"] == "baseline"]
        for kind in ("success", "return"):
            sel = [(run, c) for run, c in group if (kind == "success") == ("success" in c[0])]
            if not sel:
                continue
            fig, ax = plt.subplots(figsize=(8, 4.5))
            colours = plt.get_cmap("tab10")
            key = "success_rate" if kind == "success" else "mean_return"
            for i, (label, v, (lo, hi)) in enumerate(_baseline_groups(base, key)):
                col = colours(i + 5)
                ax.axhspan(lo, hi, color=col, alpha=0.15, lw=0, zorder=1)
                ax.axhline(v, color=col, ls="--", lw=1.2, label=label, zorder=2)
            for i, members in enumerate(seed_groups(sel)):
                col = colours(i)
                if len(members) > 1:  # one configuration over several training seeds: mean and interval
                    xs, mean, low, high = across_seeds([c for _, c in members])
                    for _, (_, _, mx, my) in members:
                        ax.plot(mx, my, color=col, lw=0.6, alpha=0.35, zorder=3)
                    ax.fill_between(xs, low, high, color=col, alpha=0.2, lw=0, zorder=3)
                    ax.plot(
                        xs,
                        mean,
                        color=col,
                        lw=2.0,
                        marker="o",
                        ms=4,
                        zorder=4,
                        label=f"{_common_name([r['name'] for r, _ in members])} ({members[0][1][1]}; mean of "
                        f"{len(members)} seeds, 95 % bootstrap interval across seeds; thin: each seed)",
                    )
                    continue
                run, (_, label, xs, ys) = members[0]
                n = (run.get("config") or {}).get("eval_episodes")
                counted = f"{n} episodes per point" if n else "episodes per point not logged"
                ax.plot(
                    xs,
                    ys,
                    color=col,
                    lw=1.6,
                    marker="o",
                    ms=4,
                    zorder=4,
                    label=f"{run['name']} ({label}; {counted})",
                )
                if kind == "success" and n:
                    ci = [wilson_interval(round(y * int(n)), int(n)) for y in ys]
                    ax.fill_between(xs, [c[0] for c in ci], [c[1] for c in ci], color=col, alpha=0.15, lw=0, zorder=3)
            if kind == "success":
                ax.set_ylim(-0.03, 1.05)
            ax.set_xlabel("training steps (policy decisions, as --timesteps counts them)")
            ax.set_ylabel("success rate (95 % interval shaded)" if kind == "success" else "episode return")
            where = f"baselines on suite {suite_name}" if suite_name else "no suite of the same task and scene"
            ax.set_title(f"{env_id}: learning curves ({where})", fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
            stem = env_id.split("/")[-1] + (f"_{suite_name}" if suite_name else "_own-scene")
            name = f"{stem}_learning_{kind}.png"
            fig.savefig(out_dir / name, dpi=110, bbox_inches="tight")
            plt.close(fig)
            out += [f"![{name}]({name})", ""]
        names = ", ".join(f"`{run['name']}`" for run, _ in group)
        if suite_name is None:
            out += [
                f"{names}: no suite has this run's env arguments (its task and scene), so no baseline is drawn "
                "beside it; bands from another scene would not compare like with like.",
                "",
            ]
        elif not base:
            out += [f"{names}: suite `{suite_name}` has the same task and scene but no baseline entry to draw.", ""]
        else:
            out += [f"{names} against the baselines of suite `{suite_name}` (same env arguments).", ""]
    return out


# ---------------------------------------------------------------- the page


def _env_blurb(env_id: str) -> str:
    """The first paragraph of the env class's docstring (its Description), or ''."""
    try:
        if agri_envs.is_parallel_id(env_id):  # a PettingZoo module: the class its parallel_env returns
            factory = importlib.import_module(agri_envs.PARALLEL_ENVS[env_id]).parallel_env
            doc = typing.get_type_hints(factory)["return"].__doc__ or ""
        else:
            entry = gym.spec(env_id).entry_point
            if not isinstance(entry, str):
                return ""
            module, attr = entry.split(":")
            doc = getattr(importlib.import_module(module), attr).__doc__ or ""
    except Exception:  # noqa: BLE001 - a missing description must not break the report
        return ""
    text = re.sub(r"^#+ *Description\s*", "", doc.strip())
    return " ".join(text.split("\n\n")[0].split())


def leaderboard_table(group: Sequence[Row]) -> list[str]:
    """The suite's ranked table with intervals (as in LEADERBOARD.md) plus where each number came from."""
    md = lb.render_markdown([r.entry for r in group], [group[0].suite])
    body = md.split(f"### {group[0].suite.name} (v{group[0].suite.version})", 1)[1].strip().splitlines()
    # up to the next heading (a stress suite's env section ends with its robustness lines, drawn elsewhere here)
    body = body[: next((i for i, line in enumerate(body) if line.startswith("#")), len(body))]
    while body and not body[-1].strip():
        body.pop()
    fresh = [r.entry["policy"]["name"] for r in group if not r.committed]
    if fresh:
        body += [
            "",
            "Evaluated for this report (no current leaderboard entry): " + ", ".join(f"`{n}`" for n in fresh) + ".",
        ]
    return body


def build_report(
    out_dir: Path,
    suites_dir: Path = lb.SUITES_DIR,
    entries_dir: Path = lb.ENTRIES_DIR,
    runs_dir: Path = Path("runs"),
    only_env: str | None = None,
    episodes: int | None = None,
    workers: int | None = 2,
    progress: bool = True,
    ray: str | None = None,
) -> Path:
    """Write ``report.md``, ``report.html`` and the PNG plots into ``out_dir``.

    Args:
        out_dir: Output folder.
        suites_dir: Pinned suites.
        entries_dir: Committed leaderboard entries.
        runs_dir: Training runs (learning curves).
        only_env: Report one env id only.
        episodes: Override the suites' episode counts (a quick look; committed entries are then not used).
        workers: Worker processes for fresh evaluations.
        progress: Show progress bars.
        ray: Run fresh episodes as Ray tasks.

    Returns:
        Path of ``report.md``.
    """
    t0 = time.perf_counter()
    out_dir.mkdir(parents=True, exist_ok=True)
    suites = [s for s in lb.load_suites(suites_dir) if not only_env or s.env_id == only_env]
    if not suites:
        raise ValueError(f"no suite in {suites_dir}" + (f" for {only_env}" if only_env else ""))
    rows = collect_rows(suites, lb.load_entries(entries_dir), out_dir, workers, progress, episodes, ray)
    results = level_results(rows, progress, out_dir)
    runs = find_runs(runs_dir) + zoo_runs()
    env_ids = list(dict.fromkeys(s.env_id for s in suites))

    parts = ["# agri_envs evaluation report", ""]
    if episodes is not None:
        parts += [
            f"**Smoke test, not results. Quick look: {episodes} episodes per suite level** (`--episodes "
            f"{episodes}`; campaign suites one campaign), evaluated afresh instead of the committed entries, "
            "with the plotted episodes traced as they ran and clips of the lead policy of each suite only. "
            "Intervals from so few episodes are wide or degenerate: no claim below is a result. For results, "
            "run `agri report` without `--episodes`.",
            "",
        ]
    shown = [(r.suite, r.entry) for r in rows]
    parts += glance_lines(env_ids, suites, shown)
    parts += ["## How to read this report", "", INTRO]
    for env_id in env_ids:
        env_suites = [s for s in suites if s.env_id == env_id]
        parts += [f"## {env_id}", "", _env_blurb(env_id), ""]
        own = own_sensors_section(env_id, shown)
        if own:
            parts += ["### Learned and scripted from the robot's own sensors", "", *own]
        robust = robustness_section(env_id, suites, shown, out_dir)
        if robust:
            parts += [f"### {_robustness_heading(env_id)}", "", *robust, ""]
        parts += ["### Leaderboard", "", INTERVALS_NOTE, ""]
        for suite in env_suites:
            group = [r for r in rows if r.suite.name == suite.name]
            parts += [f"#### {suite.name} (v{suite.version})", "", *leaderboard_table(group), ""]
            table = comparison_table(group)[0] if len(group) > 1 else []
            if len(table) > 2:  # a header alone (no pair to compare) is not shown
                parts += [
                    "Paired comparisons on the same seeds: difference X - Y of the means (or rates) with its "
                    "95 % interval, the probability that X does better than Y on a random pair of episodes, "
                    "and what the interval supports.",
                    "",
                    *table,
                    "",
                ]
            clips = clip_lines([d for d in results if d["suite"] == suite.name])
            if clips:
                parts += [
                    "Clips: a success and a failure of each policy (where it has both), re-run from their seeds "
                    f"as the entries counted them; about {CLIP_FRAMES} frames sampled evenly from the episode, at "
                    "10 fps; a clip loads only when played. "
                    "Record any episode with `agri record --env ENV --policy NAME --seed S --out clip.mp4`.",
                    "",
                    *clips,
                ]
        shown = [(r.suite, r.entry) for r in rows]
        if agri_envs.training_distribution(env_id) is not None:
            parts += ["### How the learned policies generalize", "", *generalization_section(env_id, shown), ""]
        else:
            parts += ["### Spread across training seeds", "", SEED_SPREAD_INTRO, *seed_spread_section(env_id, shown)]
        parts += ["### Learning curves", "", *learning_curves(env_id, runs, rows, out_dir), ""]
        hook = SECTION_HOOKS.get(env_id)
        if hook:
            module, attr = hook.split(":")
            env_results = [r for r in results if r["env_id"] == env_id]
            try:
                section = getattr(importlib.import_module(module), attr)(env_results, out_dir)
            except ImportError as exc:
                section = f"(plots unavailable: {exc})"
            parts += ["### Paper reproduction and plots", "", section, ""]
    gains = lb.gains_lines(env_ids, suites, [r.entry for r in rows])
    if gains:
        parts += ["## Where learning beats the papers", "", lb.GAINS_NOTE, "", *gains]
    parts += who_wins_where(env_ids, suites, rows)
    commits = sorted({r.entry["git_commit"][:10] for r in rows})
    parts += [
        "## How this report was made",
        "",
        f"`agri report` at commit `{git_commit()[:10]}` in {time.perf_counter() - t0:.0f} s: "
        f"{sum(r.committed for r in rows)} committed leaderboard entries (made at commits "
        f"{', '.join(f'`{c}`' for c in commits)}), {sum(not r.committed for r in rows)} evaluated afresh "
        f"(written to `{out_dir / 'results'}`), plotted episodes re-run from their seeds. Suites: "
        f"`{suites_dir}`; training runs: `{runs_dir}`.",
        "",
    ]
    md_path = out_dir / "report.md"
    md = "\n".join(parts)
    md_path.write_text(md)
    md_path.with_suffix(".html").write_text(markdown_to_html(md, title="agri_envs evaluation report"))
    (out_dir / "summary.json").write_text(
        json.dumps(
            [{"suite": r.suite.name, "policy": r.entry["policy"], "summary": r.entry["summary"]} for r in rows],
            indent=1,
        )
    )
    return md_path


def _anchor(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def _robustness_heading(env_id: str) -> str:
    return f"{env_id}: robustness under stress"


def glance_lines(
    env_ids: Sequence[str], suites: Sequence[lb.Suite], shown: Sequence[tuple[lb.Suite, Mapping[str, Any]]]
) -> list[str]:
    """The page's opening: per env, every policy's success on every suite, in one table each.

    Args:
        env_ids: The envs of the report, in order.
        suites: The report's suites.
        shown: ``(suite, entry)`` pairs of the report.

    Returns:
        Markdown lines: the ``At a glance`` heading, a legend, and one table per env.
    """
    lines = [
        "## At a glance",
        "",
        "Success rate of every policy on every suite, over the suite's held-out episodes: the papers' suites, "
        "the generalization suites (scenes outside every training range) and the stress suites (one axis swept "
        f"from the env's default out to its limits). **Bold**: below {lb.SUCCESS_FLOOR:.2f}. A stress cell pools "
        "its levels; ▾ gives its worst level, and the cell is bold when that level is. **P**: privileged (uses "
        "what a real robot lacks, such as the true pose). `-`: no entry. Intervals, paired comparisons and plots "
        "are in each env's section below.",
        "",
    ]
    for env_id in env_ids:
        table = glance_table(env_id, shown)
        if not table:
            continue
        where = f"[details](#{_anchor(env_id)})"
        if lb.stress_suites(suites, env_id):
            where += f", [robustness matrix](#{_anchor(_robustness_heading(env_id))})"
        lines += [f"**{env_id}** ({where})", "", *table, ""]
    return lines


def success_claims(group: Sequence[Row]) -> list[str]:
    """The paired differences on a suite's first ranking key whose interval excludes zero, as sentences."""
    suite = group[0].suite
    first = suite.rank_by[0]
    fmt = "{:+" + lb.metric_format(first.metric)[2:]
    claims = []
    for a, b in _pairs(group):
        c = compare(a.entry, b.entry, first.metric, first.higher_is_better)
        if c is None or c.verdict not in ("better", "worse"):
            continue
        f = lb.metric_scale(first.metric)
        diff = f"{fmt.format(c.difference * f)} [{fmt.format(c.ci[0] * f)}, {fmt.format(c.ci[1] * f)}]"
        verb = "beats" if c.verdict == "better" else "is worse than"
        na, nb = a.entry["policy"]["name"], b.entry["policy"]["name"]
        claims.append(f"{suite.name}: `{na}` {verb} `{nb}` on {_metric_name(first.metric)} ({diff}).")
    return claims


def who_wins_where(env_ids: Sequence[str], suites: Sequence[lb.Suite], rows: Sequence[Row]) -> list[str]:
    """The paired differences on each suite's first ranking key that the intervals support; the rest collapsed.

    Args:
        env_ids: The envs of the report, in order.
        suites: The report's suites.
        rows: The report's rows.

    Returns:
        Markdown lines: the ``Who wins where`` section.
    """
    short: list[str] = []
    every: list[str] = []
    for env_id in env_ids:
        for suite in (s for s in suites if s.env_id == env_id):
            group = [r for r in rows if r.suite.name == suite.name]
            if len(group) > 1:
                short += success_claims(group)
                every += comparison_table(group)[1]
            for r in group:
                line = paper_rate_line(r)
                if line:
                    short.append(f"{suite.name}: {line}")
    lines = [
        "## Who wins where",
        "",
        "Only the differences on each suite's first ranking key (success) whose paired 95 % interval excludes "
        "zero; each suite's table above has every pair and metric.",
        "",
    ]
    lines += [f"- {c}" for c in short] or ["No paired difference on success is supported by its interval."]
    if every:
        lines += [
            "",
            f"<details><summary>Every paired claim, on every ranking metric ({len(every)})</summary>",
            "",
            *(f"- {c}" for c in every),
            "",
            "</details>",
        ]
    if not any(lb.is_learned(r.entry["policy"]) for r in rows):
        lines += [
            "",
            "No learned policy has an entry yet: the comparisons are between the baselines. Submit one with "
            "`agri leaderboard submit --suite all --policy RUN_DIR` (docs/leaderboard.md).",
        ]
    return [*lines, ""]


def markdown_to_html(md: str, title: str) -> str:
    """Render the report's small Markdown subset (headings, tables, images, lists, links, paragraphs) as HTML."""

    def inline(text: str) -> str:
        text = html.escape(text, quote=False)
        text = re.sub(
            r"!\[([^\]]*)\]\(([^)]+)\)", r'<img alt="\1" src="\2" loading="lazy" style="max-width:100%">', text
        )
        text = re.sub(r"\[([^\]]+)\]\(([^)]+)\)", r'<a href="\2">\1</a>', text)
        text = re.sub(r"`([^`]+)`", r"<code>\1</code>", text)
        text = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", text)
        return re.sub(r"(?<![\w*])\*([^*\s][^*]*)\*", r"<i>\1</i>", text)

    out = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>",
        "<style>body{font-family:sans-serif;max-width:1150px;margin:auto;padding:1em;line-height:1.4}"
        "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;font-size:0.9em}"
        "th{background:#eee}code{background:#f4f4f4;padding:0 2px}img{display:block;margin:0.5em 0}"
        "img,video{max-width:100%;height:auto}summary{cursor:pointer;font-weight:bold}</style>"
        "</head><body>",
    ]
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("<!--"):
            i += 1
            continue
        if line.startswith(("<details>", "</details>")):  # a collapsed block: its Markdown inside is rendered
            out.append(line)
            i += 1
            continue
        if line.startswith("<video ") and line.endswith("</video>"):  # a clip: loads only when played
            out.append(line)
            i += 1
            continue
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            text = line[level:].strip()
            out.append(f"<h{level} id='{_anchor(text)}'>{inline(text)}</h{level}>")
        elif line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            out.append("<table>")
            for k, cells in enumerate(rows):
                if k == 1 and all(set(c) <= set("-:") for c in cells):
                    continue
                tag = "th" if k == 0 else "td"
                out.append("<tr>" + "".join(f"<{tag}>{inline(c)}</{tag}>" for c in cells) + "</tr>")
            out.append("</table>")
            continue
        elif line.startswith("- "):
            out.append("<ul>")
            while i < len(lines) and lines[i].startswith("- "):
                item = lines[i][2:]
                i += 1
                while i < len(lines) and lines[i].startswith("  ") and lines[i].strip():
                    item += " " + lines[i].strip()
                    i += 1
                out.append(f"<li>{inline(item)}</li>")
            out.append("</ul>")
            continue
        elif line.strip():
            para = [line]
            i += 1
            while i < len(lines) and lines[i].strip() and not lines[i].startswith(("#", "|", "- ", "![", "<!--")):
                if para[-1].startswith("!["):
                    break
                para.append(lines[i])
                i += 1
            out.append(f"<p>{inline(' '.join(para))}</p>")
            continue
        i += 1
    out.append("</body></html>")
    return "\n".join(out)
