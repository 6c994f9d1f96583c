"""Leaderboard entries: one JSON document per (suite, policy), made by evaluation and checked by verify.

``leaderboard/entries/<suite>/<policy>.json`` holds the suite's name, version and sha256, the policy
reference (a registered name, or a learned run with the sha256 of its weights), env id and version,
package version, git commit, the pooled summary and, per level, its summary and per-episode records.

Verify re-runs an entry's policy on its suite and compares every number of the committed entry with the
fresh one. Wall-clock keys (:data:`agri_training.core.documents.TIMING_KEYS`) are skipped; everything
else must be identical (the envs, the baselines and the learned policies' forward pass compute the same
bits on every x86-64 CPU), or within ``rtol`` when asked for.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import agri_envs
from agri_baselines import list_policies
from agri_training.core.documents import EvaluationDocument, git_commit, is_timing_key, jsonable
from agri_training.evaluation.batched import BATCH_SIZE
from agri_training.evaluation.evaluate import EvalRequest, evaluate_many, summarize
from agri_training.evaluation.reference import PolicyRef, resolve_policy
from agri_training.leaderboard.suites import ENTRIES_DIR, ENTRY_FORMAT, ROOT, SUITES_DIR, Suite, find_suite, sha256_file


def policy_reference(policy: str | PolicyRef, name: str | None = None) -> dict[str, Any]:
    """What an entry records about its policy (:meth:`~agri_training.evaluation.reference.PolicyRef.to_entry`).

    Args:
        policy: Anything :func:`~agri_training.evaluation.reference.resolve_policy` takes: a registered name, an
            ``agri train`` run folder, an ONNX or SB3 ``.zip`` file, ``module:attribute``, or a reference.
        name: Display name (default: the registered name, the run folder's or the file's name).

    Raises:
        ValueError: For an unknown name, or a file that is missing or refused.
    """
    return resolve_policy(policy, name, ROOT).to_entry()


def policy_from_entry(ref: Mapping[str, Any]) -> PolicyRef:
    """The policy of a committed entry, resolved, after checking that its weights are the committed ones.

    The reference keeps the entry's own name and path, so that a fresh entry records the same ``policy``.

    Raises:
        ValueError: When the weights (or a sidecar) are missing or their sha256 changed, or the kind is unknown.
    """
    kind = ref.get("kind")
    if kind == "baseline" or (kind == "learned" and "path" not in ref):
        fresh = resolve_policy(str(ref["name"]))
        if ref.get("sha256") and fresh.sha256 != ref["sha256"]:
            raise ValueError(
                f"weights of {ref['name']!r} changed: sha256 {str(fresh.sha256)[:12]} != {ref['sha256'][:12]}"
            )
        return fresh
    if kind == "callable":
        fresh = resolve_policy(str(ref["spec"]), str(ref["name"]))
        return dataclasses.replace(fresh, privileged=bool(ref.get("privileged", fresh.privileged)))
    if kind == "object":
        raise ValueError(f"policy {ref.get('name')!r} was a live Python object: nothing names it to re-run it")
    if kind not in ("learned", "onnx", "sb3-zip"):
        raise ValueError(f"policy {ref.get('name')!r}: unknown kind {kind!r}")
    path = Path(ref["path"])
    if not path.is_absolute():
        path = ROOT / path
    weights = path / RUN_WEIGHTS if kind == "learned" else path
    if not weights.is_file():
        raise ValueError(f"weights of {ref['name']!r} not found at {weights}")
    digest = sha256_file(weights)
    if digest != ref["sha256"]:
        raise ValueError(f"weights of {ref['name']!r} changed: sha256 {digest[:12]} != committed {ref['sha256'][:12]}")
    fresh = resolve_policy(str(path), str(ref["name"]), ROOT)
    if fresh.sidecar_sha256 != ref.get("sidecar_sha256"):
        raise ValueError(f"the sidecar of {ref['name']!r} changed (or appeared, or went): its sha256 differs")
    return dataclasses.replace(fresh, shown_path=str(ref["path"]))


#: The weights file of an ``agri train`` run directory (hashed into learned entries).
RUN_WEIGHTS = "policy.pt"


def policy_argument(ref: Mapping[str, Any]) -> str:
    """The ``policy`` argument of the evaluator for an entry's reference (checks the weights' sha256).

    Raises:
        ValueError: When a learned policy's weights are missing or their sha256 changed.
    """
    return policy_from_entry(ref).spec


def slug(name: str) -> str:
    """File-name-safe form of a policy name."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")


def entry_path(suite: str, policy_name: str, entries_dir: Path | str = ENTRIES_DIR) -> Path:
    """Where the entry of ``policy_name`` on ``suite`` lives."""
    return Path(entries_dir) / suite / f"{slug(policy_name)}.json"


# ---------------------------------------------------------------- evaluation


@dataclasses.dataclass(frozen=True)
class Block:
    """One unit of work: a policy on one level of a suite."""

    suite: Suite
    policy: PolicyRef
    label: str
    env_kwargs: Mapping[str, Any]
    traces: int = 0


def run_blocks(
    blocks: Sequence[Block],
    workers: int | None = 1,
    progress: bool = True,
    ray: str | None = None,
    batch: int = BATCH_SIZE,
    costs: Sequence[Sequence[float] | None] | None = None,
) -> list[EvaluationDocument]:
    """Evaluate blocks and return the evaluator's level document of each, in order.

    All episodes of all blocks go to one pool of ``workers`` processes (or Ray tasks; see
    :func:`agri_training.evaluate.evaluate_many`, which also says what ``batch`` and ``costs``, one per
    block, do) behind one progress bar (block k of N, overall ETA). Results do not depend on where or how
    episodes run: each is seeded by the suite.
    """
    requests = [
        EvalRequest(
            env_id=b.suite.env_id,
            policy=b.policy,
            episodes=b.suite.episodes,
            seed=b.suite.seed_start,
            env_kwargs=dict(b.env_kwargs),
            record_traces=b.traces,
            label=b.label,
            campaign_runs=b.suite.campaign_runs,
            env_kwargs_from=f"suite {b.suite.name}",
        )
        for b in blocks
    ]
    docs = evaluate_many(requests, progress=progress, workers=workers, ray=ray, batch=batch, costs=costs)
    for b, doc in zip(blocks, docs, strict=True):
        doc["scenario"] = b.suite.scenario
    return docs


def blocks_of(suite: Suite, policy: PolicyRef, traces: int = 0) -> list[Block]:
    """The blocks of a policy on a suite (one per level)."""
    return [Block(suite, policy, label, kwargs, traces) for label, kwargs in suite.levels()]


def entry_record(record: Mapping[str, Any]) -> dict[str, Any]:
    """An episode's record as an entry keeps it: its numbers, flags and names, without lists and mappings.

    The lists a policy's ``episode_metrics`` may add (gonzalez-pseudo-reactive's sensory map and odometry
    path, the deliberative planner's path) draw the report's plots of a few traced episodes, which the
    report re-runs; kept for every episode they made a coverage entry 60 times larger (about 300,000 lines).
    """
    return {k: v for k, v in record.items() if not isinstance(v, (list, tuple, dict))}


def make_entry(
    suite: Suite, ref: Mapping[str, Any], levels: Sequence[Mapping[str, Any]], command: str
) -> dict[str, Any]:
    """Assemble an entry from the level results of one policy on one suite (records: :func:`entry_record`)."""
    pooled = [e for lv in levels for e in lv["episodes"]]
    strata = [lv["label"] for lv in levels for _ in lv["episodes"]]
    return {
        "format": ENTRY_FORMAT,
        "suite": {"name": suite.name, "version": suite.version, "sha256": suite.sha256},
        "policy": dict(ref),
        "env_id": suite.env_id,
        "env_version": suite.env_version,
        "package_version": agri_envs.__version__,
        "git_commit": git_commit(),
        "command": command,
        "privileged": bool(levels[0]["privileged"]) if levels else bool(ref.get("privileged")),
        "summary": jsonable(summarize(pooled, strata if suite.sweep else None)),
        "levels": [
            {
                "label": lv["label"],
                "env_kwargs": lv["env_kwargs"],
                "summary": lv["summary"],
                "episodes": [entry_record(e) for e in lv["episodes"]],
            }
            for lv in levels
        ],
    }


def evaluate_entries(
    pairs: Sequence[tuple[Suite, Mapping[str, Any] | PolicyRef]],
    workers: int | None = 1,
    progress: bool = True,
    command: str = "",
    ray: str | None = None,
    traces: list[list[Any]] | None = None,
    batch: int = BATCH_SIZE,
    costs: Sequence[Sequence[Sequence[float]] | None] | None = None,
) -> list[dict[str, Any]]:
    """Evaluate each (suite, policy reference) pair and return the entries, all blocks in one pool.

    Args:
        pairs: The (suite, policy) pairs: a resolved policy, or an entry's ``policy`` record (its weights are
            checked, and the entry records it as it is).
        workers: Worker processes (see :func:`run_blocks`).
        progress: Show the progress bar.
        command: The command recorded in the entries.
        ray: Run the episodes as Ray tasks.
        traces: When given, every episode records its per-step trace, and this list receives, per pair, the
            traces of each level (entries never hold traces; a report that evaluates afresh plots them).
        batch: Most episodes stepped together in an env's batched form (see :func:`run_blocks`).
        costs: Per pair, the expected cost of each episode of each level (or None): longest jobs start first.
    """
    blocks: list[Block] = []
    spans = []
    block_costs: list[Sequence[float] | None] = []
    recorded: list[Mapping[str, Any]] = []
    for p, (suite, ref) in enumerate(pairs):
        policy = ref if isinstance(ref, PolicyRef) else policy_from_entry(ref)
        recorded.append(policy.to_entry() if isinstance(ref, PolicyRef) else ref)
        bl = blocks_of(suite, policy, suite.episodes if traces is not None else 0)
        spans.append((len(blocks), len(blocks) + len(bl)))
        blocks += bl
        pair_costs = costs[p] if costs is not None else None
        block_costs += list(pair_costs) if pair_costs is not None and len(pair_costs) == len(bl) else [None] * len(bl)
    results = run_blocks(blocks, workers, progress, ray, batch, block_costs if costs is not None else None)
    if traces is not None:  # each trace with its episode's whole record (the entry keeps scalars only)
        for doc in results:
            records = {e["seed"]: e for e in doc["episodes"]}
            for trace in doc["traces"]:
                trace["record"] = records.get(trace["seed"])
        traces += [[doc["traces"] for doc in results[a:b]] for a, b in spans]
    return [
        make_entry(suite, record, results[a:b], command)
        for (suite, _), record, (a, b) in zip(pairs, recorded, spans, strict=True)
    ]


def write_entry(entry: Mapping[str, Any], entries_dir: Path | str = ENTRIES_DIR) -> Path:
    """Write an entry as indented JSON (one key per line, so diffs are readable) and return its path."""
    path = entry_path(entry["suite"]["name"], entry["policy"]["name"], entries_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(entry, indent=1, sort_keys=False) + "\n")
    return path


def load_entries(entries_dir: Path | str = ENTRIES_DIR) -> list[dict[str, Any]]:
    """Every committed entry, sorted by suite then policy name."""
    out = []
    for p in sorted(Path(entries_dir).glob("*/*.json")):
        doc = json.loads(p.read_text())
        doc["_path"] = str(p)
        out.append(doc)
    return sorted(out, key=lambda e: (e["suite"]["name"], e["policy"]["name"]))


def all_baseline_pairs(suites: Iterable[Suite]) -> list[tuple[Suite, dict[str, Any]]]:
    """Every registered policy (baselines and shipped learned ones) on every suite of its env it can run.

    A suite that names its ``policies`` gets those only.
    """
    pairs = []
    for suite in suites:
        for spec in list_policies(suite.env_id):
            if suite.policies is not None and spec.name not in suite.policies:
                continue
            # a policy that needs other env arguments than the suite pins cannot run it (luo-apf drives joints,
            # the reach suite end-effector steps; the learned reach policy is sized for one cluster)
            if any(k in suite.env_kwargs and suite.env_kwargs[k] != v for k, v in spec.env_kwargs.items()):
                continue
            pairs.append((suite, policy_reference(spec.name)))
    return pairs


# ---------------------------------------------------------------- verify


def compare_documents(committed: Any, fresh: Any, rtol: float = 0.0, path: str = "") -> list[str]:
    """Differences between a committed and a fresh document, skipping wall-clock keys.

    Args:
        committed: The committed value (JSON types).
        fresh: The recomputed value.
        rtol: Relative tolerance for floats (0: exact). Integers, strings and booleans are always exact.
        path: Location prefix for messages.

    Returns:
        One message per difference (empty when everything reproduces).

    Raises:
        ValueError: For a negative ``rtol``.
    """
    if rtol < 0:
        raise ValueError(f"rtol must be >= 0, got {rtol}")
    out: list[str] = []
    if isinstance(committed, Mapping) and isinstance(fresh, Mapping):
        for key in sorted(set(committed) | set(fresh)):
            if is_timing_key(str(key)):
                continue
            where = f"{path}.{key}" if path else str(key)
            if key not in fresh:
                out.append(f"{where}: committed but not reproduced")
            elif key not in committed:
                out.append(f"{where}: reproduced but not committed")
            else:
                out += compare_documents(committed[key], fresh[key], rtol, where)
        return out
    if isinstance(committed, list) and isinstance(fresh, list):
        if len(committed) != len(fresh):
            return [f"{path}: {len(committed)} items committed, {len(fresh)} reproduced"]
        for i, (a, b) in enumerate(zip(committed, fresh, strict=True)):
            out += compare_documents(a, b, rtol, f"{path}[{i}]")
        return out
    floats = isinstance(committed, float) or isinstance(fresh, float)
    numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (committed, fresh))
    if floats and numbers and rtol > 0:
        if math.isclose(float(committed), float(fresh), rel_tol=rtol, abs_tol=rtol * 1e-3):
            return []
    elif committed == fresh and type(committed) is type(fresh):
        return []
    elif numbers and committed == fresh and floats:  # 1 vs 1.0 after a JSON round trip
        return []
    return [f"{path}: committed {committed!r} != reproduced {fresh!r}"]


#: Entry keys that describe the run, not its results (not compared by verify).
_META_KEYS = ("git_commit", "command", "package_version", "_path")


def _entry_suite_and_policy(entry: Mapping[str, Any], suites_dir: Path | str) -> tuple[Suite, PolicyRef]:
    """The suite an entry was made for and its resolved policy.

    Raises:
        ValueError: When the suite changed since the entry was made (stale), or the policy's files are missing
            or changed.
    """
    suite = find_suite(entry["suite"]["name"], suites_dir)
    if suite.sha256 != entry["suite"]["sha256"] or suite.version != entry["suite"]["version"]:
        raise ValueError(
            f"stale, made for suite version {entry['suite']['version']} ({entry['suite']['sha256'][:12]}), the "
            f"suite is now v{suite.version} ({suite.sha256[:12]}); regenerate it"
        )
    return suite, policy_from_entry(entry["policy"])


def verify_entries(
    entries: Sequence[Mapping[str, Any]],
    suites_dir: Path | str = SUITES_DIR,
    workers: int | None = 1,
    rtol: float = 0.0,
    progress: bool = True,
    ray: str | None = None,
    batch: int = BATCH_SIZE,
) -> list[str]:
    """Re-evaluate entries on their pinned seeds and list every number that does not reproduce.

    Also fails an entry whose suite file changed since it was made (stale: the suite's sha256 differs).
    The jobs start longest first by the committed episodes' wall times; ``batch`` as in :func:`run_blocks`.

    Returns:
        Problems, one line each (empty when all reproduce).
    """
    problems: list[str] = []
    pairs = []
    kept = []
    for entry in entries:
        try:
            suite, policy = _entry_suite_and_policy(entry, suites_dir)
        except ValueError as exc:
            problems.append(f"{entry['suite']['name']}/{entry['policy']['name']}: {exc}")
            continue
        pairs.append((suite, policy))
        kept.append(entry)
    costs = [[[float(e.get("wall_time_s") or 0.0) for e in lv["episodes"]] for lv in entry["levels"]] for entry in kept]
    fresh = evaluate_entries(pairs, workers, progress, ray=ray, batch=batch, costs=costs)
    for entry, new in zip(kept, fresh, strict=True):
        name = f"{entry['suite']['name']}/{entry['policy']['name']}"
        committed = {k: v for k, v in entry.items() if k not in _META_KEYS}
        recomputed = {k: v for k, v in new.items() if k not in _META_KEYS}
        problems += [f"{name}: {d}" for d in compare_documents(committed, recomputed, rtol)]
    return problems


def sample_indices(episodes: int, campaign_runs: int, per_level: int) -> list[int]:
    """The episodes of a level that a sampled verify re-runs: ``per_level`` of them (whole campaigns), evenly spaced.

    Deterministic: the first episode (campaign) always, then evenly spaced ones; all of them when ``per_level``
    covers the level.

    Raises:
        ValueError: For ``per_level < 1``.
    """
    if per_level < 1:
        raise ValueError(f"the sample must hold at least one episode per level, got {per_level}")
    starts = list(range(0, episodes, campaign_runs))
    n = min(per_level, len(starts))
    picked = [starts[(k * len(starts)) // n] for k in range(n)]
    return [start + run for start in picked for run in range(campaign_runs)]


def verify_sample(
    entries: Sequence[Mapping[str, Any]],
    per_level: int,
    suites_dir: Path | str = SUITES_DIR,
    workers: int | None = 1,
    rtol: float = 0.0,
    progress: bool = True,
    ray: str | None = None,
    batch: int = BATCH_SIZE,
) -> list[str]:
    """Verify every entry on a deterministic sample of its episodes, and every summary on its committed records.

    Each level of each entry re-runs the episodes :func:`sample_indices` picks (seeded as in the suite, so
    each is the very episode the entry counted) and compares their records with the committed ones; the
    level summaries and the pooled summary are recomputed from the committed records and compared with the
    committed summaries. An entry whose suite changed is stale, as in :func:`verify_entries`. Every suite,
    policy and level is checked; a number changed anywhere in an entry is caught (in a record that is
    re-run, by the re-run; in a summary, by the recomputation); a record that is not re-run is checked only
    through the summaries it feeds.

    Returns:
        Problems, one line each (empty when all reproduce).
    """
    problems: list[str] = []
    requests: list[EvalRequest] = []
    checks: list[tuple[str, list[Mapping[str, Any]]]] = []
    costs: list[list[float]] = []
    for entry in entries:
        name = f"{entry['suite']['name']}/{entry['policy']['name']}"
        try:
            suite, policy = _entry_suite_and_policy(entry, suites_dir)
        except ValueError as exc:
            problems.append(f"{name}: {exc}")
            continue
        problems += [f"{name}: {d}" for d in _summary_problems(suite, entry, rtol)]
        levels = suite.levels()
        if [lv["label"] for lv in entry["levels"]] != [label for label, _ in levels]:
            problems.append(f"{name}: its levels are not the suite's ({len(entry['levels'])} != {len(levels)})")
            continue
        for (label, kwargs), level in zip(levels, entry["levels"], strict=True):
            picked = sample_indices(suite.episodes, suite.campaign_runs, per_level)
            for first in picked[:: suite.campaign_runs]:
                n = suite.campaign_runs
                requests.append(
                    EvalRequest(
                        env_id=suite.env_id,
                        policy=policy,
                        episodes=n,
                        seed=suite.seed_start + first,
                        env_kwargs=dict(kwargs),
                        label=label,
                        campaign_runs=n,
                        env_kwargs_from=f"suite {suite.name}",
                    )
                )
                committed = level["episodes"][first : first + n]
                checks.append((f"{name} [{label}]", committed))
                costs.append([float(e.get("wall_time_s") or 0.0) for e in committed])
    fresh = evaluate_many(requests, progress=progress, workers=workers, ray=ray, batch=batch, costs=costs)
    for (where, committed), doc in zip(checks, fresh, strict=True):
        records = [entry_record(e) for e in doc["episodes"]]
        problems += [f"{where}: {d}" for d in compare_documents(committed, records, rtol, "episodes")]
    return problems


def _summary_problems(suite: Suite, entry: Mapping[str, Any], rtol: float) -> list[str]:
    """Differences between an entry's committed summaries and those recomputed from its committed records."""
    out = []
    for level in entry["levels"]:
        fresh = jsonable(summarize(list(level["episodes"])))
        out += compare_documents(level["summary"], fresh, rtol, f"levels[{level['label']}].summary")
    pooled = [e for lv in entry["levels"] for e in lv["episodes"]]
    strata = [lv["label"] for lv in entry["levels"] for _ in lv["episodes"]]
    fresh = jsonable(summarize(pooled, strata if suite.sweep else None))
    return out + compare_documents(entry["summary"], fresh, rtol, "summary")


def timed(fn: Any, *args: Any, **kwargs: Any) -> tuple[Any, float]:
    """``(fn(*args, **kwargs), seconds)``."""
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


def print_problems(problems: Sequence[str], per_entry: int = 5) -> None:
    """Print verify's problems to stderr: how many per entry, and the first ``per_entry`` of each."""
    groups: dict[str, list[str]] = {}
    for line in problems:
        groups.setdefault(line.split(": ", 1)[0], []).append(line)
    for name, lines in groups.items():
        print(f"  {name}: {len(lines)} difference(s)", file=sys.stderr)
        for line in lines[:per_entry]:
            print(f"    {line}", file=sys.stderr)
        if len(lines) > per_entry:
            print(f"    ... and {len(lines) - per_entry} more", file=sys.stderr)
