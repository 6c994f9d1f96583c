"""Evaluate any policy (a name, a run folder, an ONNX or SB3 file, ``module:attribute``) on an env over seeds.

Episode ``i`` is reset with seed ``seed + i``. The env's final ``info`` supplies the keys listed in its
``metadata["episode_metric_keys"]``; a policy may add its own through ``episode_metrics(index)``. The
first ``record_traces`` episodes also record the ``metadata["trace_keys"]`` of every step, for plots.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, cast

import numpy as np

import agri_envs
from agri_envs.scenarios import scenario as get_scenario
from agri_training.core.documents import (
    EpisodeOutput,
    EpisodeRecord,
    EvaluationDocument,
    TraceDocument,
    git_commit,
    jsonable,
)
from agri_training.core.progress import Progress
from agri_training.core.stats import format_interval, iqm, rate_interval, stratified_bootstrap_ci
from agri_training.evaluation.batched import BATCH_SIZE, batchable
from agri_training.evaluation.parallel import EpisodeJob, run_episodes
from agri_training.evaluation.policies import EvalRequest, resolve_env_kwargs

#: How the summary's intervals are computed (printed under every table).
INTERVALS_NOTE = (
    "95 % intervals: Wilson score intervals for rates; stratified percentile bootstrap (2000 resamples, "
    "seed 0, strata = scenario levels) for means and interquartile means (IQM)."
)


def summarize(episodes: list[EpisodeRecord], strata: list[str] | None = None) -> dict[str, Any]:
    """Rates with Wilson intervals; mean and IQM of every numeric metric with stratified bootstrap intervals.

    Args:
        episodes: Per-episode records.
        strata: Optional label per episode (the scenario level it ran in) for the stratified bootstrap.

    Returns:
        ``episodes``, ``success_rate`` (+ ``_ci``), ``collision_rate`` (+ ``_ci``), ``mean_KEY`` and
        ``iqm_KEY`` (+ ``_ci``) for every numeric key, and the shortcuts ``mean_time``,
        ``mean_time_successful``, ``ate_rmse`` and ``min_clearance`` (the worst episode's) where they apply.
        Episodes of campaigns (records with ``campaign_run``) add the same keys over the first runs only,
        prefixed ``first_run_``, and over the later runs, prefixed ``later_runs_`` (e.g.
        ``later_runs_mean_episode_time``). The runs of one campaign share a world, so their intervals,
        which treat the episodes as independent, are somewhat too narrow.
    """
    summary = _summarize(episodes, strata)
    if any("campaign_run" in e for e in episodes):
        for part, later in (("first_run", False), ("later_runs", True)):
            pick = [i for i, e in enumerate(episodes) if bool(e.get("campaign_run")) == later]
            if pick:
                sub = _summarize([episodes[i] for i in pick], None if strata is None else [strata[i] for i in pick])
                summary.update({f"{part}_{k}": v for k, v in sub.items()})
    return summary


#: Record keys that are not metrics: never summarised.
_NOT_METRICS = frozenset({"seed", "is_success", "collision", "truncated", "campaign_run", "layout_seed"})


def _summarize(episodes: list[EpisodeRecord], strata: list[str] | None) -> dict[str, Any]:
    summary: dict[str, Any] = {"episodes": len(episodes)}
    if not episodes:
        return summary
    success = [bool(e["is_success"]) for e in episodes]
    summary["success_rate"] = float(np.mean(success))
    summary["success_rate_ci"] = rate_interval(success)
    if "collision" in episodes[0]:
        col = [bool(e["collision"]) for e in episodes]
        summary["collision_rate"] = float(np.mean(col))
        summary["collision_rate_ci"] = rate_interval(col)
    keys = dict.fromkeys(k for e in episodes for k in e)  # in order; a key may be None in some episodes
    for key in keys:
        values = [e.get(key) for e in episodes]
        if key in _NOT_METRICS or not any(_is_number(v) for v in values) or any(isinstance(v, bool) for v in values):
            continue
        vals = np.array([e[key] if e.get(key) is not None else np.nan for e in episodes], dtype=float)
        finite = np.any(np.isfinite(vals))
        summary[f"mean_{key}"] = float(np.nanmean(vals)) if finite else None
        summary[f"mean_{key}_ci"] = stratified_bootstrap_ci(vals, np.mean, strata)
        summary[f"iqm_{key}"] = iqm(vals) if finite else None
        summary[f"iqm_{key}_ci"] = stratified_bootstrap_ci(vals, iqm, strata)
    if "episode_time" in episodes[0]:
        ok = [e["episode_time"] for e in episodes if e["is_success"]]
        summary["mean_time"] = summary["mean_episode_time"]
        summary["mean_time_successful"] = float(np.mean(ok)) if ok else None
    if "ate_rmse" in episodes[0]:
        summary["ate_rmse"] = summary["mean_ate_rmse"]
    if "min_clearance" in episodes[0]:
        clearances = [e["min_clearance"] for e in episodes if e.get("min_clearance") is not None]
        summary["min_clearance"] = float(np.min(clearances)) if clearances else None
    return summary


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclasses.dataclass(frozen=True)
class EpisodeProgress:
    """What :func:`evaluate_many` reports after each finished episode (for progress displays and ETAs).

    Attributes:
        request: Index of the request in the list evaluated.
        level: Index of the level (sweep value) within the request.
        episode: Index of the episode within the level (seed = request seed + episode).
        done: Episodes finished so far, over all requests.
        total: Episodes in the whole run.
        elapsed_s: Wall time since the run started.
        record: The episode's record.
    """

    request: int
    level: int
    episode: int
    done: int
    total: int
    elapsed_s: float
    record: dict[str, Any]


@dataclasses.dataclass
class _Level:
    request_index: int
    level_index: int
    request: EvalRequest
    label: str | None
    kwargs: dict[str, Any]
    privileged: bool
    jobs: list[EpisodeJob]


def _plan(requests: list[EvalRequest], batch: int) -> list[_Level]:
    levels = []
    for r, request in enumerate(requests):
        if request.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {request.episodes}")
        sc = get_scenario(request.env_id, request.scenario) if request.scenario else None
        bases: list[tuple[str | None, Mapping[str, Any] | None]] = (
            [(None, None)] if sc is None or sc.sweep is None else list(sc.levels())
        )
        for k, (label, base) in enumerate(bases):
            kwargs, privileged = resolve_env_kwargs(request, base)
            jobs = episode_jobs(request, kwargs, batch)
            levels.append(_Level(r, k, request, label or request.label, kwargs, privileged, jobs))
    return levels


def episode_jobs(request: EvalRequest, kwargs: Mapping[str, Any], batch: int = 1) -> list[EpisodeJob]:
    """The jobs of one level: one per episode or batch of episodes, or one per campaign of ``campaign_runs``.

    Campaign c runs seeds ``seed + c * runs ..`` in the world of ``layout_seed = seed + c * runs`` (its first
    seed), unless the arguments already fix ``layout_seed`` (then every campaign drives that one world).
    With ``batch > 1``, a policy that :func:`~agri_training.evaluation.batched.batchable` allows on an env with
    a batched form runs its episodes in batches of at most ``batch`` consecutive seeds, as equal in size as
    can be (the episodes that record traces apart from the others).

    Raises:
        ValueError: For ``batch < 1``.
    """
    if isinstance(batch, bool) or not isinstance(batch, int) or batch < 1:
        raise ValueError(f"batch must be an int >= 1, got {batch!r}")
    runs = request.campaign_runs
    if runs == 1 and batch > 1 and batchable(request.env_id, request.ref, kwargs):
        traced = min(request.record_traces, request.episodes)
        return [
            EpisodeJob(request.env_id, kwargs, request.ref, request.seed + first, first < traced, batch=size)
            for first, size in _batches(0, traced, batch) + _batches(traced, request.episodes, batch)
        ]
    if runs == 1:
        return [
            EpisodeJob(request.env_id, kwargs, request.ref, request.seed + i, i < request.record_traces)
            for i in range(request.episodes)
        ]
    jobs = []
    for c in range(request.episodes // runs):
        first = request.seed + c * runs
        fixed = dict(kwargs)
        if int(fixed.get("layout_seed", -1)) < 0:
            fixed["layout_seed"] = first
        jobs.append(EpisodeJob(request.env_id, fixed, request.ref, first, c < request.record_traces, runs))
    return jobs


def _batches(start: int, stop: int, most: int) -> list[tuple[int, int]]:
    """``(first, size)`` of the fewest runs of at most ``most`` indices covering ``[start, stop)``, sizes within 1."""
    count = stop - start
    if count <= 0:
        return []
    n = -(-count // most)
    sizes = [count // n + (1 if k < count % n else 0) for k in range(n)]
    firsts = [start + sum(sizes[:k]) for k in range(n)]
    return list(zip(firsts, sizes, strict=True))


def evaluate(
    request: EvalRequest,
    progress: bool = True,
    workers: int | None = 1,
    ray: str | None = None,
    batch: int = BATCH_SIZE,
) -> EvaluationDocument:
    """Run the request and return the result document.

    For a scenario that sweeps an argument the document holds one result per value under ``levels`` (and
    the ``summary`` of all levels pooled); otherwise it is a single result. ``workers``, ``ray`` and ``batch``
    choose where and how the episodes run (see :func:`evaluate_many`); the document is the same whichever.
    """
    return evaluate_many([request], progress, workers, ray, batch=batch)[0]


def evaluate_many(
    requests: list[EvalRequest],
    progress: bool = True,
    workers: int | None = 1,
    ray: str | None = None,
    on_episode: Callable[[EpisodeProgress], None] | None = None,
    batch: int = BATCH_SIZE,
    costs: Sequence[Sequence[float] | None] | None = None,
) -> list[EvaluationDocument]:
    """Evaluate several requests in one run of episodes, and return one result document per request.

    All episodes of all requests go to one worker pool (or one Ray session), so the cores stay busy
    across requests. Episode ``i`` of a request is seeded ``seed + i`` wherever it runs, and the documents
    equal those of a serial run (``workers=1``) in everything but the episodes' ``wall_time_s``.

    Args:
        requests: What to evaluate.
        progress: Show one progress bar (level k of N, overall ETA; nothing per episode).
        workers: Worker processes (1: in this process; None: one per core; see
            :func:`agri_training.parallel.run_episodes`).
        ray: Run the episodes as Ray tasks: ``"local"``, ``"auto"`` or a cluster address.
        on_episode: Called after each finished episode (in completion order) with an
            :class:`EpisodeProgress`.
        batch: Most episodes stepped together in the env's batched form, where the env has one and the
            policy acts on its observations alone (:mod:`agri_training.evaluation.batched`); 1 runs every
            episode in the reference loop. The records are the same.
        costs: Per request, the expected cost of each of its episodes (levels one after the other; any unit,
            e.g. the seconds a committed entry took), or None. The jobs then start longest first, so that
            the workers finish together; results do not depend on the order.

    Raises:
        ValueError: For bad arguments (unknown scenario, policy, env argument, ``workers < 1``).
        agri_training.parallel.EpisodeError: When an episode raises; it names the seed and the exception.
    """
    live = [r.ref.name for r in requests if r.ref.instance is not None]
    if live and (workers != 1 or ray is not None):
        raise ValueError(f"policy {live[0]!r} is a live Python object: it runs in this process only (workers=1)")
    levels = _plan(requests, batch)
    jobs = [job for level in levels for job in level.jobs]
    priority = _job_costs(levels, costs) if costs is not None else None
    where = [(level, i) for level in levels for i in range(level.request.episodes)]
    display = _OrderedDisplay(where, progress)
    t0 = time.perf_counter()
    done = 0

    def on_result(index: int, job: EpisodeJob, out: EpisodeOutput) -> None:
        nonlocal done
        done += 1
        display.finished(index, out["record"])
        if on_episode is not None:
            level, i = where[index]
            on_episode(
                EpisodeProgress(
                    level.request_index, level.level_index, i, done, len(jobs), time.perf_counter() - t0, out["record"]
                )
            )

    try:
        outs = run_episodes(jobs, workers=workers, ray=ray, on_result=on_result, priority=priority)
    finally:
        display.close()
    docs: list[list[EvaluationDocument]] = [[] for _ in requests]
    start = 0
    for level in levels:
        level_outs = outs[start : start + level.request.episodes]
        start += level.request.episodes
        docs[level.request_index].append(_level_doc(level, level_outs))
    results: list[EvaluationDocument] = []
    for request, level_docs in zip(requests, docs, strict=True):
        sc = get_scenario(request.env_id, request.scenario) if request.scenario else None
        if sc is None or sc.sweep is None:
            results.append(level_docs[0])
            continue
        pooled = [e for level_doc in level_docs for e in level_doc["episodes"]]
        drop = ("episodes", "traces", "summary", "env_kwargs", "label")
        doc = cast(EvaluationDocument, {k: v for k, v in level_docs[0].items() if k not in drop})
        doc["sweep"] = {"parameter": sc.sweep[0], "values": list(sc.sweep[1])}
        doc["levels"] = level_docs
        doc["summary"] = jsonable(summarize(pooled, [str(d["label"]) for d in level_docs for _ in d["episodes"]]))
        results.append(doc)
    return results


def _job_costs(levels: list[_Level], costs: Sequence[Sequence[float] | None]) -> list[float]:
    """Each job's expected cost: the sum of its episodes' (0 where a request has none)."""
    if len(costs) != len({level.request_index for level in levels}):
        raise ValueError(f"costs: one entry per request expected, got {len(costs)}")
    out = []
    offset = {r: 0 for r in range(len(costs))}
    for level in levels:
        per_episode = costs[level.request_index]
        for job in level.jobs:
            start = offset[level.request_index]
            offset[level.request_index] += job.episodes
            out.append(float(sum(per_episode[start : start + job.episodes])) if per_episode is not None else 0.0)
    return out


def evaluate_level(
    request: EvalRequest,
    base: Mapping[str, Any] | None,
    progress: bool = True,
    label: str | None = None,
    workers: int | None = 1,
    ray: str | None = None,
    batch: int = BATCH_SIZE,
) -> EvaluationDocument:
    """Evaluate one set of env arguments (one level of a scenario)."""
    kwargs, privileged = resolve_env_kwargs(request, base)
    level = _Level(0, 0, request, label, kwargs, privileged, episode_jobs(request, kwargs, batch))
    display = _OrderedDisplay([(level, i) for i in range(request.episodes)], progress)
    try:
        outs = run_episodes(
            level.jobs, workers=workers, ray=ray, on_result=lambda k, _, out: display.finished(k, out["record"])
        )
    finally:
        display.close()
    return _level_doc(level, outs)


def _level_doc(level: _Level, outs: list[EpisodeOutput]) -> EvaluationDocument:
    request = level.request
    episodes = [out["record"] for out in outs]
    if request.campaign_runs > 1:  # the world each campaign drove
        for job in level.jobs:
            for k in range(job.runs):
                episodes[job.seed - request.seed + k]["layout_seed"] = int(job.env_kwargs["layout_seed"])
    traces: list[TraceDocument] = [
        {"seed": request.seed + i, "data": out["trace"]} for i, out in enumerate(outs) if out["trace"] is not None
    ]
    doc: EvaluationDocument = {
        "env_id": request.env_id,
        "scenario": request.scenario,
        "label": level.label or request.scenario,
        "policy": request.ref.spec,
        "privileged": level.privileged,
        "seed": request.seed,
        "env_kwargs": jsonable(level.kwargs),
        "package_version": agri_envs.__version__,
        "git_commit": git_commit(),
        "command": " ".join(sys.argv),
        "summary": jsonable(summarize(episodes)),
        "episodes": episodes,
        "traces": traces,
    }
    if request.campaign_runs > 1:
        doc["campaign_runs"] = request.campaign_runs
    return doc


class _OrderedDisplay:
    """The display of a run of episodes: one :class:`Progress` bar, nothing per episode.

    The bar's label names the level whose episode finished last (``[k/N] policy on env [level]``) with
    its successes so far; its remaining time is the whole run's ETA. Episodes may finish out of order.
    """

    def __init__(self, where: list[tuple[_Level, int]], enabled: bool) -> None:
        self.where = where
        order = list(dict.fromkeys(id(level) for level, _ in where))
        self._block = {lid: k + 1 for k, lid in enumerate(order)}
        self._counts: dict[int, tuple[int, int]] = {}
        self.bar = Progress(len(where), len(order), enabled)

    def finished(self, index: int, record: dict[str, Any]) -> None:
        level, _ = self.where[index]
        done, ok = self._counts.get(id(level), (0, 0))
        done, ok = done + 1, ok + bool(record.get("is_success"))
        self._counts[id(level)] = (done, ok)
        where = level.label or level.request.scenario or "default"
        desc = f"{level.request.ref.name} on {level.request.env_id.split('/')[-1]} [{where}]"
        self.bar.advance(self._block[id(level)], desc, f"success {ok}/{done} of {len(level.jobs)}")

    def close(self) -> None:
        self.bar.close()


_FORMATS = {"episode_time": "{:.1f}", "path_length": "{:.2f}", "min_clearance": "{:.3f}", "return": "{:.1f}"}


def format_summary(result: Mapping[str, Any]) -> str:
    """Human-readable summary: rates with Wilson intervals, means and IQMs with bootstrap intervals."""
    s = result["summary"]
    lines = [
        f"{result['policy']} on {result['env_id']}"
        + (f" [{result['scenario']}]" if result["scenario"] else "")
        + (" (privileged)" if result["privileged"] else "")
        + f", {s['episodes']} episodes",
        f"  {'metric':<24} {'value [95 % CI]':<30} IQM [95 % CI]",
    ]
    for key in ("success_rate", "collision_rate"):
        if key in s:
            lines.append(f"  {key:<24} {format_interval(s[key], s.get(key + '_ci'))}")
    for key, value in s.items():
        if key.startswith("mean_") and not key.endswith("_ci") and f"{key}_ci" in s:
            name = key[len("mean_") :]
            fmt = _FORMATS.get(name, "{:.3g}")
            iqm_text = format_interval(s.get(f"iqm_{name}"), s.get(f"iqm_{name}_ci"), fmt)
            lines.append(f"  {name:<24} {format_interval(value, s.get(key + '_ci'), fmt):<30} {iqm_text}")
    if s.get("min_clearance") is not None:
        lines.append(f"  {'min_clearance (worst)':<24} {s['min_clearance']:.3f}")
    for part, name in (("first_run_", "first runs"), ("later_runs_", "later runs")):
        if f"{part}episodes" not in s:
            continue
        lines.append(f"  campaigns, {name} ({s[part + 'episodes']} episodes):")
        for key in ("success_rate", "mean_episode_time", "mean_max_cross_track", "mean_cross_track_corridors_max"):
            if s.get(part + key) is not None:
                fmt = "{:.2f}" if key.endswith("rate") else _FORMATS.get(key[len("mean_") :], "{:.3g}")
                lines.append(f"    {key:<30} {format_interval(s[part + key], s.get(part + key + '_ci'), fmt)}")
    lines.append("  " + INTERVALS_NOTE)
    return "\n".join(lines)


