"""Evaluate any policy (a registered baseline or an SB3 checkpoint) on an env over a range of seeds.

Episode ``i`` is reset with seed ``seed + i``. The env's final ``info`` supplies the keys listed in its
``metadata["episode_metric_keys"]``; a policy may add its own through ``episode_metrics(index)``. The
first ``record_traces`` episodes also record the ``metadata["trace_keys"]`` of every step, for plots.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import agri_envs
from agri_baselines import list_policies, make_policy, policy_spec
from agri_envs.scenarios import scenario as get_scenario
from agri_training.multiagent import is_parallel_env, run_chain_episode
from agri_training.parallel import EpisodeJob, run_episodes
from agri_training.stats import format_interval, iqm, rate_interval, stratified_bootstrap_ci


@dataclasses.dataclass(frozen=True)
class EvalRequest:
    """What to evaluate.

    Attributes:
        env_id: Registered env id.
        policy: Baseline name (see ``agri_baselines``) or path to an SB3 ``.zip`` checkpoint.
        episodes: Number of episodes (seeds ``seed`` .. ``seed + episodes - 1``).
        seed: First seed.
        scenario: Name of an env-argument preset (``agri_envs.scenarios``), or None.
        env_kwargs: Extra env arguments (override the scenario's; must not contradict the policy's needs).
        record_traces: How many episodes record per-step traces.
        label: Name of the evaluation in progress displays and in the result (default: the scenario's).
    """

    env_id: str
    policy: str
    episodes: int = 20
    seed: int = 0
    scenario: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    record_traces: int = 1
    label: str | None = None


def resolve_env_kwargs(request: EvalRequest, base: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], bool]:
    """Env arguments = scenario preset + user arguments + what the policy needs; and whether it is privileged.

    Args:
        request: The evaluation.
        base: Preset arguments (one level of the scenario); defaults to the scenario's own.

    Raises:
        ValueError: When a user argument contradicts what the policy needs, or the policy drives another env.
    """
    kwargs: dict[str, Any] = {}
    if base is not None:
        kwargs.update(base)
    elif request.scenario:
        kwargs.update(get_scenario(request.env_id, request.scenario).env_kwargs)
    kwargs.update(request.env_kwargs)
    privileged = False
    from agri_training.learned import is_run_path, read_config, refuse_pickled

    refuse_pickled(request.policy)
    if is_run_path(request.policy):  # a training run: its env id and env arguments, like a baseline's needs
        config = read_config(Path(request.policy))
        if config["env_id"] != request.env_id:
            raise ValueError(f"run {request.policy} was trained on {config['env_id']}, not {request.env_id}")
        for key, value in config["env_kwargs"].items():
            if key in request.env_kwargs and request.env_kwargs[key] != value:
                raise ValueError(
                    f"run {request.policy} was trained with {key}={value!r}, got {request.env_kwargs[key]!r}"
                )
            kwargs[key] = value
        privileged = bool(config.get("privileged", False))
    else:
        spec = policy_spec(request.policy)
        if spec.env_id != request.env_id:
            raise ValueError(f"policy {spec.name!r} drives {spec.env_id}, not {request.env_id}")
        for key, value in spec.env_kwargs.items():
            if key in request.env_kwargs and request.env_kwargs[key] != value:
                raise ValueError(f"policy {spec.name!r} needs {key}={value!r}, got {request.env_kwargs[key]!r}")
            kwargs[key] = value
        privileged = spec.privileged
    return kwargs, privileged


def load_policy(name_or_path: str, env: gym.Env[Any, Any]) -> Any:
    """A registered policy by name (baseline or trained), or an ``agri train`` run directory, weights-only.

    Raises:
        ValueError: For an unknown name; :class:`agri_training.learned.UnsafeCheckpointError` for checkpoints
            that need unpickling (SB3 ``.zip`` files).
    """
    from agri_training.learned import LearnedPolicy, is_run_path, refuse_pickled

    refuse_pickled(name_or_path)
    if is_run_path(name_or_path):
        return LearnedPolicy(name_or_path, env)
    return make_policy(name_or_path, env)


def git_commit() -> str:
    """Current git commit of the working tree, or ``"unknown"``."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, cwd=Path(__file__).resolve().parent
        )
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _jsonable(v: Any) -> Any:
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    return v


def run_episode(env: gym.Env[Any, Any], policy: Any, seed: int, trace_keys: tuple[str, ...] | None) -> dict[str, Any]:
    """One episode from ``reset(seed=seed)``: return, steps, final info and optionally the trace."""
    if is_parallel_env(env):  # PettingZoo envs (the robot chain): per-agent dicts
        return run_chain_episode(env, policy, seed, trace_keys)
    obs, info = env.reset(seed=seed)
    start = True
    state = None
    total = 0.0
    steps = 0
    trace: dict[str, list[Any]] = {k: [info.get(k)] for k in trace_keys} if trace_keys else {}
    localizes = hasattr(policy, "pose_estimate") and "x" in info
    truth: list[tuple[float, float, float]] = []
    estimate: list[np.ndarray] = []
    t0 = time.perf_counter()
    while True:
        action, state = policy.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        start = False
        if localizes:  # the estimate for this observation, paired with the true pose it was taken at
            truth.append((info["x"], info["y"], info["yaw"]))
            estimate.append(np.asarray(policy.pose_estimate(0), dtype=np.float64))
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        steps += 1
        for k in trace:
            trace[k].append(info.get(k))
        if terminated or truncated:
            break
    wall = time.perf_counter() - t0
    record: dict[str, Any] = {
        "seed": seed,
        "return": total,
        "steps": steps,
        "truncated": bool(truncated),
        "is_success": bool(info.get("is_success", False)),
        "wall_time_s": wall,
    }
    for key in env.unwrapped.metadata.get("episode_metric_keys", ()):
        record[key] = info.get(key)
    if hasattr(policy, "episode_metrics"):
        record.update(policy.episode_metrics(0))
    if localizes and truth:
        world_est = start_frame_to_world(np.array(truth[0]), np.array(estimate))
        record.update(localization_errors(np.array(truth), world_est))
        if trace:
            trace.update(
                slam_x=world_est[:, 0].tolist(), slam_y=world_est[:, 1].tolist(), slam_yaw=world_est[:, 2].tolist()
            )
    return {"record": _jsonable(record), "trace": _jsonable(trace) if trace else None}


def start_frame_to_world(start: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses ``(n, 3)`` given in the frame of the robot's start pose, expressed in the world frame."""
    c, s = np.cos(start[2]), np.sin(start[2])
    out = np.empty_like(poses)
    out[:, 0] = start[0] + c * poses[:, 0] - s * poses[:, 1]
    out[:, 1] = start[1] + s * poses[:, 0] + c * poses[:, 1]
    out[:, 2] = np.arctan2(np.sin(poses[:, 2] + start[2]), np.cos(poses[:, 2] + start[2]))
    return out


def localization_errors(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """Absolute trajectory error and final-pose error of a pose estimate against the ground truth.

    Both trajectories share the start pose (the estimate's map frame is anchored there, as on the robot),
    so no alignment is fitted: the ATE is what the controller actually drove on.

    Returns:
        ``ate_rmse`` (m), ``ate_max`` (m), ``final_position_error`` (m), ``final_heading_error`` (rad).
    """
    err = np.hypot(estimate[:, 0] - truth[:, 0], estimate[:, 1] - truth[:, 1])
    dyaw = np.arctan2(np.sin(estimate[-1, 2] - truth[-1, 2]), np.cos(estimate[-1, 2] - truth[-1, 2]))
    return {
        "ate_rmse": float(np.sqrt(np.mean(err**2))),
        "ate_max": float(err.max()),
        "final_position_error": float(err[-1]),
        "final_heading_error": float(abs(dyaw)),
    }


#: Per-episode keys that measure the computer, not the policy (wall-clock and planning times): they are
#: summarised but never expected to reproduce, so the leaderboard's verify skips them.
TIMING_KEYS = frozenset({"wall_time_s", "planning_time_ms", "plan_time_ms"})


def is_timing_key(key: str) -> bool:
    """True for a record or summary key derived from wall-clock time (see :data:`TIMING_KEYS`)."""
    return any(t in key for t in TIMING_KEYS)


#: How the summary's intervals are computed (printed under every table).
INTERVALS_NOTE = (
    "95 % intervals: Wilson score intervals for rates; stratified percentile bootstrap (2000 resamples, "
    "seed 0, strata = scenario levels) for means and interquartile means (IQM)."
)


def summarize(episodes: list[dict[str, Any]], strata: list[str] | None = None) -> dict[str, Any]:
    """Rates with Wilson intervals; mean and IQM of every numeric metric with stratified bootstrap intervals.

    Args:
        episodes: Per-episode records.
        strata: Optional label per episode (the scenario level it ran in) for the stratified bootstrap.

    Returns:
        ``episodes``, ``success_rate`` (+ ``_ci``), ``collision_rate`` (+ ``_ci``), ``mean_KEY`` and
        ``iqm_KEY`` (+ ``_ci``) for every numeric key, and the shortcuts ``mean_time``,
        ``mean_time_successful``, ``ate_rmse`` and ``min_clearance`` (the worst episode's) where they apply.
    """
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
    skip = {"seed", "is_success", "collision", "truncated"}
    for key, value in episodes[0].items():
        if key in skip or isinstance(value, bool) or not isinstance(value, (int, float)):
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


def _plan(requests: list[EvalRequest]) -> list[_Level]:
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
            jobs = [
                EpisodeJob(request.env_id, kwargs, request.policy, request.seed + i, i < request.record_traces)
                for i in range(request.episodes)
            ]
            levels.append(_Level(r, k, request, label or request.label, kwargs, privileged, jobs))
    return levels


def evaluate(
    request: EvalRequest, progress: bool = True, workers: int | None = 1, ray: str | None = None
) -> dict[str, Any]:
    """Run the request and return the result document.

    For a scenario that sweeps an argument the document holds one result per value under ``levels`` (and
    the ``summary`` of all levels pooled); otherwise it is a single result. ``workers`` and ``ray`` choose
    where the episodes run (see :func:`evaluate_many`); the document is the same wherever they run.
    """
    return evaluate_many([request], progress, workers, ray)[0]


def evaluate_many(
    requests: list[EvalRequest],
    progress: bool = True,
    workers: int | None = 1,
    ray: str | None = None,
    on_episode: Callable[[EpisodeProgress], None] | None = None,
) -> list[dict[str, Any]]:
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

    Raises:
        ValueError: For bad arguments (unknown scenario, policy, env argument, ``workers < 1``).
        agri_training.parallel.EpisodeError: When an episode raises; it names the seed and the exception.
    """
    levels = _plan(requests)
    jobs = [job for level in levels for job in level.jobs]
    where = [(level, i) for level in levels for i in range(len(level.jobs))]
    display = _OrderedDisplay(where, progress)
    t0 = time.perf_counter()
    done = 0

    def on_result(index: int, job: EpisodeJob, out: dict[str, Any]) -> None:
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
        outs = run_episodes(jobs, workers=workers, ray=ray, on_result=on_result)
    finally:
        display.close()
    docs: list[list[dict[str, Any]]] = [[] for _ in requests]
    start = 0
    for level in levels:
        level_outs = outs[start : start + len(level.jobs)]
        start += len(level.jobs)
        docs[level.request_index].append(_level_doc(level, level_outs))
    results = []
    for request, level_docs in zip(requests, docs, strict=True):
        sc = get_scenario(request.env_id, request.scenario) if request.scenario else None
        if sc is None or sc.sweep is None:
            results.append(level_docs[0])
            continue
        pooled = [e for level_doc in level_docs for e in level_doc["episodes"]]
        drop = ("episodes", "traces", "summary", "env_kwargs", "label")
        doc = {k: v for k, v in level_docs[0].items() if k not in drop}
        doc.update(
            sweep={"parameter": sc.sweep[0], "values": list(sc.sweep[1])},
            levels=level_docs,
            summary=_jsonable(summarize(pooled, [d["label"] for d in level_docs for _ in d["episodes"]])),
        )
        results.append(doc)
    return results


def evaluate_level(
    request: EvalRequest,
    base: Mapping[str, Any] | None,
    progress: bool = True,
    label: str | None = None,
    workers: int | None = 1,
    ray: str | None = None,
) -> dict[str, Any]:
    """Evaluate one set of env arguments (one level of a scenario)."""
    kwargs, privileged = resolve_env_kwargs(request, base)
    jobs = [
        EpisodeJob(request.env_id, kwargs, request.policy, request.seed + i, i < request.record_traces)
        for i in range(request.episodes)
    ]
    level = _Level(0, 0, request, label, kwargs, privileged, jobs)
    display = _OrderedDisplay([(level, i) for i in range(len(jobs))], progress)
    try:
        outs = run_episodes(
            jobs, workers=workers, ray=ray, on_result=lambda k, _, out: display.finished(k, out["record"])
        )
    finally:
        display.close()
    return _level_doc(level, outs)


def _level_doc(level: _Level, outs: list[dict[str, Any]]) -> dict[str, Any]:
    request = level.request
    episodes = [out["record"] for out in outs]
    traces = [
        {"seed": job.seed, "data": out["trace"]}
        for job, out in zip(level.jobs, outs, strict=True)
        if out["trace"] is not None
    ]
    return {
        "env_id": request.env_id,
        "scenario": request.scenario,
        "label": level.label or request.scenario,
        "policy": request.policy,
        "privileged": level.privileged,
        "seed": request.seed,
        "env_kwargs": _jsonable(level.kwargs),
        "package_version": agri_envs.__version__,
        "git_commit": git_commit(),
        "command": " ".join(sys.argv),
        "summary": _jsonable(summarize(episodes)),
        "episodes": episodes,
        "traces": traces,
    }


class Progress:
    """One progress display over a whole job of evaluation blocks (a policy on one scenario level each).

    On a terminal it is a tqdm bar counting episodes over all blocks (so its remaining time is the ETA of
    the whole job), labelled with the running block (``[k/N] policy on env [level]``) and its success rate
    so far. Elsewhere (CI logs, ``make test`` piped to a file) a bar would print nothing useful, so a plain
    line goes to stdout at least every ``heartbeat_s`` seconds instead: block k of N, episodes done,
    elapsed time and ETA. Nothing is printed per episode.

    Args:
        total_episodes: Episodes of the whole job.
        total_blocks: Blocks of the whole job (1 for a single evaluation).
        enabled: False for no output at all.
        heartbeat_s: Seconds between plain progress lines when stderr is not a terminal.
    """

    def __init__(
        self, total_episodes: int, total_blocks: int = 1, enabled: bool = True, heartbeat_s: float = 20.0
    ) -> None:
        self.total_episodes = total_episodes
        self.total_blocks = total_blocks
        self.block = 0
        self.desc = ""
        self._successes = 0
        self._done = 0
        self._episodes_done = 0
        self._bar: Any = None
        self._heartbeat: Heartbeat | None = None
        if not enabled:
            return
        if sys.stderr.isatty():
            try:
                from tqdm import tqdm

                self._bar = tqdm(total=total_episodes, unit="ep", file=sys.stderr, dynamic_ncols=True)
                return
            except ImportError:
                pass
        self._heartbeat = Heartbeat(self.status_line, heartbeat_s)

    def status_line(self, elapsed: float) -> str:
        """``block k/N (what runs), e/E episodes, elapsed, ETA``: the plain progress line."""
        done, total = self._episodes_done, self.total_episodes
        eta = format_duration(elapsed / done * (total - done)) if done else "?"
        what = f" ({self.desc})" if self.desc else ""
        return (
            f"progress: block {max(self.block, 1)}/{self.total_blocks}{what}, {done}/{total} episodes, "
            f"{format_duration(elapsed)} elapsed, ETA {eta}"
        )

    def start_block(self, desc: str) -> None:
        """Announce the next block."""
        self.block += 1
        self.desc = desc
        self._successes = self._done = 0
        if self._bar is not None:
            self._bar.set_description(f"[{self.block}/{self.total_blocks}] {desc}")

    def episode_done(self, record: Mapping[str, Any]) -> None:
        """Count one finished episode of the current block."""
        self._done += 1
        self._episodes_done += 1
        self._successes += bool(record.get("is_success"))
        if self._bar is not None:
            self._bar.set_postfix_str(f"success {self._successes}/{self._done}", refresh=False)
            self._bar.update(1)

    def advance(self, block: int, desc: str, postfix: str) -> None:
        """Count one finished episode of block ``block`` (1-based), whichever block runs now."""
        self.block, self.desc = block, desc
        self._episodes_done += 1
        if self._bar is not None:
            self._bar.set_description(f"[{block}/{self.total_blocks}] {desc}", refresh=False)
            self._bar.set_postfix_str(postfix, refresh=False)
            self._bar.update(1)

    def skip(self, episodes: int, desc: str) -> None:
        """Count a block that needs no run (e.g. a leaderboard entry that is up to date)."""
        self.start_block(desc)
        self._episodes_done += episodes
        if self._bar is not None:
            self._bar.update(episodes)

    def close(self) -> None:
        """Close the bar, or print the last plain line."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self._heartbeat is not None:
            self._heartbeat.stop()
            self._heartbeat = None


def format_duration(seconds: float) -> str:
    """``1h02m``, ``3m07s`` or ``42s``."""
    s = int(round(seconds))
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class Heartbeat:
    """Prints ``line(elapsed_s)`` to stdout every ``interval_s`` seconds from a daemon thread, and at stop.

    For long jobs whose output is not a terminal: a reader of a log sees that the job lives and when it
    will end, even while one long episode runs.
    """

    def __init__(self, line: Callable[[float], str], interval_s: float) -> None:
        self._line = line
        self._interval = float(interval_s)
        self._t0 = time.perf_counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="progress-heartbeat", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self._interval):
            self._print()

    def _print(self) -> None:
        print(self._line(time.perf_counter() - self._t0), flush=True)

    def stop(self) -> None:
        """Stop the thread and print the final line."""
        self._stop.set()
        self._thread.join()
        self._print()


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
        desc = f"{level.request.policy} on {level.request.env_id.split('/')[-1]} [{where}]"
        self.bar.advance(self._block[id(level)], desc, f"success {ok}/{done} of {len(level.jobs)}")

    def close(self) -> None:
        self.bar.close()


_FORMATS = {"episode_time": "{:.1f}", "path_length": "{:.2f}", "min_clearance": "{:.3f}", "return": "{:.1f}"}


def format_summary(result: dict[str, Any]) -> str:
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
    lines.append("  " + INTERVALS_NOTE)
    return "\n".join(lines)


def all_baselines() -> list[str]:
    """Names of every registered baseline."""
    return [p.name for p in list_policies()]
