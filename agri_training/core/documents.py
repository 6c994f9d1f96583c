"""The documents that evaluation, the leaderboard and the report pass along: typed, and JSON-able.

An episode's output (:class:`EpisodeOutput`) is its record (seed, success, return, time and the env's
episode metrics) and optionally its per-step trace; an evaluation result (:class:`EvaluationDocument`)
holds the records of one level of a scenario with their summary. Both go to JSON files unchanged, so
their values are plain Python (:func:`jsonable`).
"""

from __future__ import annotations

import hashlib
import math
import subprocess
from pathlib import Path
from typing import Any, NotRequired, TypedDict

import numpy as np

#: One episode's metrics (``seed``, ``return``, ``steps``, ``truncated``, ``is_success``, ``wall_time_s``
#: and the env's ``episode_metric_keys``), JSON-able.
EpisodeRecord = dict[str, Any]


class EpisodeOutput(TypedDict):
    """What running one episode returns."""

    record: EpisodeRecord
    trace: dict[str, Any] | None
    #: With ``EpisodeJob(record=True)``: the recorded trajectories (``agri_training.core.datasets.EpisodeSteps``).
    steps: NotRequired[list[Any]]


class TraceDocument(TypedDict):
    """The per-step trace of one episode of an evaluation (``record``: its whole record, where a report keeps it)."""

    seed: int
    data: dict[str, Any]
    record: NotRequired[dict[str, Any] | None]


class EvaluationDocument(TypedDict, total=False):
    """The result of evaluating a policy on one env (one level of a scenario, or all levels pooled).

    A scenario that sweeps an argument has ``sweep`` and ``levels`` (one document per value) instead of
    ``episodes`` and ``traces``; ``summary`` is then pooled over the levels. An evaluation in campaigns has
    ``campaign_runs`` (runs per campaign; the records carry ``campaign_run`` and ``layout_seed``).
    """

    env_id: str
    scenario: str | None
    label: str | None
    policy: str
    privileged: bool
    seed: int
    env_kwargs: dict[str, Any]
    package_version: str
    git_commit: str
    command: str
    summary: dict[str, Any]
    episodes: list[EpisodeRecord]
    traces: list[TraceDocument]
    sweep: dict[str, Any]
    levels: list[EvaluationDocument]
    campaign_runs: int


#: Per-episode keys that measure the computer, not the policy (wall-clock and planning times): they are
#: summarised but never expected to reproduce, so the leaderboard's verify skips them.
TIMING_KEYS = frozenset({"wall_time_s", "planning_time_ms", "plan_time_ms"})


def is_timing_key(key: str) -> bool:
    """True for a record or summary key derived from wall-clock time (see :data:`TIMING_KEYS`)."""
    return any(t in key for t in TIMING_KEYS)


def jsonable(v: Any) -> Any:
    """``v`` with numpy scalars and arrays turned into Python numbers and lists (NaN and inf -> None)."""
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, np.ndarray):
        return [jsonable(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, dict):
        return {k: jsonable(x) for k, x in v.items()}
    return v


def git_commit() -> str:
    """Current git commit of the working tree, or ``"unknown"``."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, cwd=Path(__file__).resolve().parent
        )
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def sha256_file(path: Path | str) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
