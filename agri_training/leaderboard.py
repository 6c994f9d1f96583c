"""The leaderboard: pinned evaluation suites, one JSON entry per (suite, policy), LEADERBOARD.md, verify.

Suites
    A suite is a versioned YAML file in ``leaderboard/suites/`` (see ``docs/leaderboard.md``)::

        name: greenhouse-corridor        # unique; the file is <name>.yaml
        version: 1                       # bump on any change: entries of other versions are stale
        env_id: agri_envs/GreenhouseNav-v2
        scenario: corridor               # optional: the named preset it was copied from (informational)
        description: Harik sec. 3.4 ...
        env_kwargs: {scene: corridor, n_people: 1}   # pinned here, not looked up by scenario name
        sweep: {parameter: growth, values: [0.0, 0.5, 1.0]}   # optional: one level per value
        seeds: {start: 100000, episodes: 20}           # per level; held out: start >= 100000
        traces: 1                        # episodes per level the report re-runs with traces for plots
        rank_by:                         # summary keys, most important first
          - {metric: success_rate, higher_is_better: true}
          - {metric: mean_episode_time, higher_is_better: false}

    Evaluation seeds start at :data:`HELD_OUT_SEED`; training never uses seeds at or above it.

Entries
    ``leaderboard/entries/<suite>/<policy>.json`` holds the suite's name, version and sha256, the policy
    reference (a baseline name, or a learned run with the sha256 of its weights), env id and version,
    package version, git commit, the pooled summary and, per level, its summary and per-episode records.

Verify
    Re-runs an entry's policy on its suite and compares every number of the committed entry with the
    fresh one. Wall-clock keys (:data:`agri_training.evaluate.TIMING_KEYS`) are skipped; everything else
    must be identical (the envs and baselines are deterministic under a seed on one platform), or within
    ``rtol`` when asked for (for a different CPU or library build, see ``docs/leaderboard.md``).
    ``LEADERBOARD.md`` must equal what :func:`render_markdown` makes of the entries.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import re
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

#: First evaluation seed of every suite; training must never use seeds at or above it.
HELD_OUT_SEED = 100_000
#: Fewest episodes per level of a committed suite.
MIN_EPISODES = 20
#: Version of the entry format.
ENTRY_FORMAT = 1

ROOT = Path(__file__).resolve().parent.parent
LEADERBOARD_DIR = ROOT / "leaderboard"
SUITES_DIR = LEADERBOARD_DIR / "suites"
ENTRIES_DIR = LEADERBOARD_DIR / "entries"
LEADERBOARD_MD = ROOT / "LEADERBOARD.md"


@dataclasses.dataclass(frozen=True)
class RankKey:
    """A summary key a suite ranks by.

    Attributes:
        metric: Key of the summary (``success_rate``, ``mean_episode_time``, ``iqm_path_length``, ...).
        higher_is_better: Orientation.
    """

    metric: str
    higher_is_better: bool = True

    def __post_init__(self) -> None:
        if not self.metric or not re.fullmatch(r"[a-z0-9_]+", self.metric):
            raise ValueError(f"rank_by metric must be a summary key (a-z, 0-9, _), got {self.metric!r}")


_SUITE_KEYS = (
    "name",
    "version",
    "env_id",
    "scenario",
    "description",
    "env_kwargs",
    "sweep",
    "seeds",
    "traces",
    "rank_by",
)


@dataclasses.dataclass(frozen=True)
class Suite:
    """A pinned evaluation suite (one YAML file).

    Attributes:
        name: Unique name (lowercase, digits, ``-``); the file is ``<name>.yaml``.
        version: Integer >= 1, bumped on any change.
        env_id: Registered env id.
        env_kwargs: Env arguments (the policy's own needs are merged in at evaluation).
        seed_start: First seed, >= :data:`HELD_OUT_SEED`.
        episodes: Episodes per level (seeds ``seed_start`` .. ``seed_start + episodes - 1``), >= 1.
        rank_by: Summary keys to rank by, most important first (at least one).
        description: What the suite reproduces.
        scenario: Named preset the arguments were copied from, or None.
        sweep: Optional ``(argument, values)``: one level per value.
        traces: Episodes per level re-run with per-step traces for the report's plots, >= 0.
        sha256: Hash of the file's bytes (set by :func:`load_suite`).
    """

    name: str
    version: int
    env_id: str
    env_kwargs: Mapping[str, Any]
    seed_start: int
    episodes: int
    rank_by: tuple[RankKey, ...]
    description: str = ""
    scenario: str | None = None
    sweep: tuple[str, tuple[Any, ...]] | None = None
    traces: int = 1
    sha256: str = ""

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[a-z0-9][a-z0-9-]*", self.name):
            raise ValueError(f"name must be lowercase letters, digits and '-', got {self.name!r}")
        if not isinstance(self.version, int) or self.version < 1:
            raise ValueError(f"version must be an integer >= 1, got {self.version!r}")
        from agri_training.multiagent import is_multiagent

        if not (self.env_id.startswith("agri_envs/") or is_multiagent(self.env_id)):
            raise ValueError(f"env_id must be an agri_envs id or a multi-agent env of the package, got {self.env_id!r}")
        if self.seed_start < HELD_OUT_SEED:
            raise ValueError(f"seeds.start must be >= {HELD_OUT_SEED} (held out from training), got {self.seed_start}")
        if self.episodes < 1:
            raise ValueError(f"seeds.episodes must be >= 1, got {self.episodes}")
        if not self.rank_by:
            raise ValueError("rank_by must name at least one summary key")
        if self.traces < 0:
            raise ValueError(f"traces must be >= 0, got {self.traces}")
        if self.sweep is not None and (not self.sweep[1] or self.sweep[0] in self.env_kwargs):
            raise ValueError(f"sweep must give values for an argument not also in env_kwargs, got {self.sweep!r}")

    @property
    def env_version(self) -> str:
        """The env's version tag, e.g. ``v1``."""
        return self.env_id.rsplit("-", 1)[-1]

    @property
    def seeds(self) -> list[int]:
        """The seeds of every level."""
        return list(range(self.seed_start, self.seed_start + self.episodes))

    def levels(self) -> list[tuple[str, dict[str, Any]]]:
        """``(label, env_kwargs)`` of each level: one, or one per sweep value."""
        if self.sweep is None:
            return [(self.name, dict(self.env_kwargs))]
        key, values = self.sweep
        return [(f"{self.name} {key}={v}", {**self.env_kwargs, key: v}) for v in values]


def parse_suite(doc: Mapping[str, Any], sha256: str = "") -> Suite:
    """Build a suite from its YAML mapping.

    Raises:
        ValueError: For an unknown or missing key (the message lists the valid ones) or a bad value.
    """
    unknown = sorted(set(doc) - set(_SUITE_KEYS))
    if unknown:
        raise ValueError(f"unknown suite keys {unknown}; valid: {', '.join(_SUITE_KEYS)}")
    for key in ("name", "version", "env_id", "seeds", "rank_by"):
        if key not in doc:
            raise ValueError(f"suite is missing {key!r}")
    seeds = doc["seeds"]
    if not isinstance(seeds, Mapping) or set(seeds) != {"start", "episodes"}:
        raise ValueError(f"seeds must be a mapping with exactly 'start' and 'episodes', got {seeds!r}")
    sweep = doc.get("sweep")
    if sweep is not None:
        if not isinstance(sweep, Mapping) or set(sweep) != {"parameter", "values"}:
            raise ValueError(f"sweep must be a mapping with exactly 'parameter' and 'values', got {sweep!r}")
        sweep = (str(sweep["parameter"]), tuple(sweep["values"]))
    rank = []
    for item in doc["rank_by"]:
        if not isinstance(item, Mapping) or not set(item) <= {"metric", "higher_is_better"} or "metric" not in item:
            raise ValueError(f"rank_by items must be {{metric: KEY, higher_is_better: BOOL}}, got {item!r}")
        rank.append(RankKey(str(item["metric"]), bool(item.get("higher_is_better", True))))
    return Suite(
        name=str(doc["name"]),
        version=doc["version"],
        env_id=str(doc["env_id"]),
        env_kwargs=dict(doc.get("env_kwargs") or {}),
        seed_start=int(seeds["start"]),
        episodes=int(seeds["episodes"]),
        rank_by=tuple(rank),
        description=str(doc.get("description", "")).strip(),
        scenario=doc.get("scenario"),
        sweep=sweep,
        traces=int(doc.get("traces", 1)),
        sha256=sha256,
    )


def load_suite(path: Path | str) -> Suite:
    """Load a suite YAML file (its name must match the file name).

    Raises:
        ValueError: For a malformed file (see :func:`parse_suite`) or a name that differs from the file's.
    """
    path = Path(path)
    raw = path.read_bytes()
    doc = yaml.safe_load(raw)
    if not isinstance(doc, Mapping):
        raise ValueError(f"{path}: a suite is a YAML mapping")
    try:
        suite = parse_suite(doc, hashlib.sha256(raw).hexdigest())
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    if suite.name != path.stem:
        raise ValueError(f"{path}: suite name {suite.name!r} must match the file name")
    return suite


def load_suites(directory: Path | str = SUITES_DIR) -> list[Suite]:
    """Every suite in a folder, sorted by env id then name."""
    suites = [load_suite(p) for p in sorted(Path(directory).glob("*.yaml"))]
    return sorted(suites, key=lambda s: (s.env_id, s.name))


def find_suite(name: str, directory: Path | str = SUITES_DIR) -> Suite:
    """The suite called ``name``.

    Raises:
        ValueError: For an unknown name (listing the known ones).
    """
    path = Path(directory) / f"{name}.yaml"
    if not path.exists():
        known = ", ".join(sorted(p.stem for p in Path(directory).glob("*.yaml")))
        raise ValueError(f"unknown suite {name!r}; known: {known or 'none'}")
    return load_suite(path)


# ---------------------------------------------------------------- policies


def sha256_file(path: Path | str) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


#: The weights file of an ``agri train`` run directory (hashed into learned entries).
RUN_WEIGHTS = "policy.pt"


def _weights_file(path: Path) -> Path:
    """The file whose sha256 identifies a learned policy: a run folder's weights, or the file itself."""
    return path / RUN_WEIGHTS if path.is_dir() else path


def _shown(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def policy_reference(policy: str, name: str | None = None) -> dict[str, Any]:
    """What an entry records about its policy.

    Args:
        policy: A registered policy name (baseline, or trained with ``learned=True`` in its spec), or the
            folder of an ``agri train`` run (its weights are ``policy.pt``).
        name: Display name of a run (default: the run folder's name).

    Raises:
        ValueError: For an unknown name or a run folder without weights.
    """
    path = Path(policy)
    if path.is_dir() or policy.endswith((".zip", ".pt")):
        weights = _weights_file(path)
        if not weights.is_file():
            raise ValueError(f"policy weights {str(weights)!r} not found")
        privileged = False
        config = (path if path.is_dir() else path.parent) / "config.yaml"
        if config.is_file():
            doc = yaml.safe_load(config.read_text())
            privileged = bool(isinstance(doc, Mapping) and doc.get("privileged", False))
        return {
            "kind": "learned",
            "name": name or (path.name if path.is_dir() else f"{path.parent.name}/{path.stem}"),
            "path": _shown(path),
            "sha256": sha256_file(weights),
            "privileged": privileged,
        }
    from agri_baselines import policy_spec

    spec = policy_spec(policy)
    ref: dict[str, Any] = {"kind": "baseline", "name": spec.name, "privileged": spec.privileged}
    if getattr(spec, "learned", False):  # a trained policy registered by name: hash its committed weights
        ref["kind"] = "learned"
        try:
            from agri_training.learned import zoo_path  # type: ignore[attr-defined]

            weights = _weights_file(Path(zoo_path(spec.name)))
            if weights.is_file():
                ref["sha256"] = sha256_file(weights)
        except ImportError:
            pass
    return ref


def _policy_argument(ref: Mapping[str, Any]) -> str:
    """The ``policy`` argument of the evaluator for a reference (checks a learned policy's weights).

    Raises:
        ValueError: When a learned policy's weights are missing or their sha256 changed.
    """
    if "path" not in ref:
        if ref.get("sha256"):
            fresh = policy_reference(str(ref["name"])).get("sha256")
            if fresh != ref["sha256"]:
                raise ValueError(
                    f"weights of {ref['name']!r} changed: sha256 {str(fresh)[:12]} != {ref['sha256'][:12]}"
                )
        return str(ref["name"])
    path = Path(ref["path"])
    if not path.is_absolute():
        path = ROOT / path
    weights = _weights_file(path)
    if not weights.is_file():
        raise ValueError(f"weights of {ref['name']!r} not found at {weights}")
    digest = sha256_file(weights)
    if digest != ref["sha256"]:
        raise ValueError(f"weights of {ref['name']!r} changed: sha256 {digest[:12]} != committed {ref['sha256'][:12]}")
    return str(path)


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
    policy: str
    label: str
    env_kwargs: Mapping[str, Any]
    traces: int = 0


def run_blocks(
    blocks: Sequence[Block], workers: int | None = 1, progress: bool = True, ray: str | None = None
) -> list[dict[str, Any]]:
    """Evaluate blocks and return the evaluator's level document of each, in order.

    All episodes of all blocks go to one pool of ``workers`` processes (or Ray tasks; see
    :func:`agri_training.evaluate.evaluate_many`) behind one progress bar (block k of N, overall ETA).
    Results do not depend on where episodes run: each is seeded by the suite.
    """
    from agri_training.evaluate import EvalRequest, evaluate_many

    requests = [
        EvalRequest(
            env_id=b.suite.env_id,
            policy=b.policy,
            episodes=b.suite.episodes,
            seed=b.suite.seed_start,
            env_kwargs=dict(b.env_kwargs),
            record_traces=b.traces,
            label=b.label,
        )
        for b in blocks
    ]
    docs = evaluate_many(requests, progress=progress, workers=workers, ray=ray)
    for b, doc in zip(blocks, docs, strict=True):
        doc["scenario"] = b.suite.scenario
    return docs


def blocks_of(suite: Suite, policy: str, traces: int = 0) -> list[Block]:
    """The blocks of a policy on a suite (one per level)."""
    return [Block(suite, policy, label, kwargs, traces) for label, kwargs in suite.levels()]


def make_entry(
    suite: Suite, ref: Mapping[str, Any], levels: Sequence[Mapping[str, Any]], command: str
) -> dict[str, Any]:
    """Assemble an entry from the level results of one policy on one suite."""
    import agri_envs
    from agri_training.evaluate import _jsonable, git_commit, summarize

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
        "summary": _jsonable(summarize(pooled, strata if suite.sweep else None)),
        "levels": [
            {
                "label": lv["label"],
                "env_kwargs": lv["env_kwargs"],
                "summary": lv["summary"],
                "episodes": lv["episodes"],
            }
            for lv in levels
        ],
    }


def evaluate_entries(
    pairs: Sequence[tuple[Suite, Mapping[str, Any]]],
    workers: int | None = 1,
    progress: bool = True,
    command: str = "",
    ray: str | None = None,
) -> list[dict[str, Any]]:
    """Evaluate each (suite, policy reference) pair and return the entries, all blocks in one pool."""
    blocks: list[Block] = []
    spans = []
    for suite, ref in pairs:
        bl = blocks_of(suite, _policy_argument(ref))
        spans.append((len(blocks), len(blocks) + len(bl)))
        blocks += bl
    results = run_blocks(blocks, workers, progress, ray)
    return [make_entry(suite, ref, results[a:b], command) for (suite, ref), (a, b) in zip(pairs, spans, strict=True)]


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
    """Every registered policy (baselines and shipped learned ones) on every suite of its env it can run."""
    from agri_baselines import list_policies

    pairs = []
    for suite in suites:
        for spec in list_policies(suite.env_id):
            # a policy that needs other env arguments than the suite pins cannot run it (luo-apf drives joints,
            # the reach suite end-effector steps; the learned reach policy is sized for one cluster)
            if any(k in suite.env_kwargs and suite.env_kwargs[k] != v for k, v in spec.env_kwargs.items()):
                continue
            pairs.append((suite, policy_reference(spec.name)))
    return pairs


# ---------------------------------------------------------------- verify


def _is_timing(key: str) -> bool:
    from agri_training.evaluate import is_timing_key

    return is_timing_key(key)


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
            if _is_timing(str(key)):
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


def verify_entries(
    entries: Sequence[Mapping[str, Any]],
    suites_dir: Path | str = SUITES_DIR,
    workers: int | None = 1,
    rtol: float = 0.0,
    progress: bool = True,
    ray: str | None = None,
) -> list[str]:
    """Re-evaluate entries on their pinned seeds and list every number that does not reproduce.

    Also fails an entry whose suite file changed since it was made (stale: the suite's sha256 differs).

    Returns:
        Problems, one line each (empty when all reproduce).
    """
    problems: list[str] = []
    pairs = []
    kept = []
    for entry in entries:
        name = f"{entry['suite']['name']}/{entry['policy']['name']}"
        try:
            suite = find_suite(entry["suite"]["name"], suites_dir)
            if suite.sha256 != entry["suite"]["sha256"] or suite.version != entry["suite"]["version"]:
                problems.append(
                    f"{name}: stale, made for suite version {entry['suite']['version']} "
                    f"({entry['suite']['sha256'][:12]}), the suite is now v{suite.version} "
                    f"({suite.sha256[:12]}); regenerate it"
                )
                continue
            _policy_argument(entry["policy"])
        except ValueError as exc:
            problems.append(f"{name}: {exc}")
            continue
        pairs.append((suite, entry["policy"]))
        kept.append(entry)
    fresh = evaluate_entries(pairs, workers, progress, ray=ray)
    for entry, new in zip(kept, fresh, strict=True):
        name = f"{entry['suite']['name']}/{entry['policy']['name']}"
        committed = {k: v for k, v in entry.items() if k not in _META_KEYS}
        recomputed = {k: v for k, v in new.items() if k not in _META_KEYS}
        problems += [f"{name}: {d}" for d in compare_documents(committed, recomputed, rtol)]
    return problems


# ---------------------------------------------------------------- LEADERBOARD.md


def _sort_key(entry: Mapping[str, Any], rank_by: Sequence[RankKey]) -> tuple[float, ...]:
    key = []
    for r in rank_by:
        v = entry["summary"].get(r.metric)
        v = float("inf") if v is None else (-float(v) if r.higher_is_better else float(v))
        key.append(v)
    return tuple(key)


def _metric_format(metric: str) -> str:
    if metric.endswith("_rate"):
        return "{:.2f}"
    if "clearance" in metric or "error" in metric or "ate" in metric:
        return "{:.3f}"
    if "path_length" in metric:
        return "{:.2f}"
    return "{:.1f}"


def _episode_values(entry: Mapping[str, Any], metric: str) -> tuple[list[Any], bool]:
    """Per-episode values behind a summary key (paired by seed order) and whether the metric is a rate."""
    if metric in ("success_rate", "collision_rate"):
        key = "is_success" if metric == "success_rate" else "collision"
        return [bool(e.get(key)) for lv in entry["levels"] for e in lv["episodes"]], True
    for prefix in ("mean_", "iqm_"):
        if metric.startswith(prefix):
            key = metric[len(prefix) :]
            return [e.get(key) for lv in entry["levels"] for e in lv["episodes"]], False
    return [], False


def compare_entries(x: Mapping[str, Any], y: Mapping[str, Any], metric: str, higher_is_better: bool) -> Any:
    """Paired comparison of two entries of one suite on one summary key (None when not comparable)."""
    from agri_training.stats import paired_comparison

    vx, binary = _episode_values(x, metric)
    vy, _ = _episode_values(y, metric)
    if not vx or len(vx) != len(vy):
        return None
    try:
        return paired_comparison(vx, vy, metric, higher_is_better, binary=binary)
    except ValueError:
        return None


def render_markdown(entries: Sequence[Mapping[str, Any]], suites: Sequence[Suite]) -> str:
    """LEADERBOARD.md: per env and suite, every entry ranked, with 95 % intervals; privileged ones marked."""
    from agri_training.evaluate import INTERVALS_NOTE
    from agri_training.stats import format_interval

    lines = [
        "# agri_envs leaderboard",
        "",
        "<!-- Generated by `agri leaderboard render` from leaderboard/entries/*; do not edit by hand. -->",
        "",
        "Every policy is evaluated on each suite's pinned, held-out seeds (100000 and up; training never uses "
        "them). Rows are ordered by the suite's ranking keys (point estimates, left to right). "
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
                + [f"{r.metric} {'↑' if r.higher_is_better else '↓'}" for r in suite.rank_by]
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
                    cells.append(format_interval(s.get(r.metric), s.get(f"{r.metric}_ci"), _metric_format(r.metric)))
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
