"""Leaderboard suites: versioned YAML files that pin an env's arguments, held-out seeds and ranking keys.

A suite is ``leaderboard/suites/<name>.yaml`` (format: ``docs/leaderboard.md``)::

    name: greenhouse-corridor        # unique; the file is <name>.yaml
    version: 1                       # bump on any change: entries of other versions are stale
    env_id: agri_envs/GreenhouseNav-v2
    scenario: corridor               # optional: the named preset it was copied from (informational)
    description: Harik sec. 3.4 ...
    env_kwargs: {scene: corridor, n_people: 1}   # pinned here, not looked up by scenario name
    sweep: {parameter: growth, values: [0.0, 0.5, 1.0]}   # optional: one level per value
    # or several arguments changed together, one row of values per level:
    # sweep: {parameters: [n_robots, office_width], values: [[4, 14.0], [32, 28.0]]}
    stress: crowd                    # optional: a stress suite, sweeping this robustness axis (needs a sweep)
    seeds: {start: 100000, episodes: 20}           # per level; held out: start >= 100000
    campaign: {runs: 4}              # optional: episodes in campaigns of 4 runs, one policy per campaign
    fewer_episodes: why              # required in a committed suite with under 20 episodes per level
    policies: [gonzalez-hybrid]      # optional: only these policies run it (default: every one of the env)
    traces: 1                        # episodes per level the report re-runs with traces for plots
    generalization: true             # optional: held out by construction, every level outside the env's
                                     # training distribution (checked when the suite is loaded)
    rank_by:                         # summary keys, most important first
      - {metric: success_rate, higher_is_better: true}
      - {metric: mean_episode_time, higher_is_better: false}

Evaluation seeds start at :data:`HELD_OUT_SEED`; training never uses seeds at or above it. A generalization
suite is held out twice: by its seeds and by its scenes, which no family of the env's training distribution
(``agri_envs.training_distribution``) can draw; :func:`outside_training` says why, level by level.
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

import agri_envs
from agri_training.core.documents import sha256_file  # noqa: F401  (re-exported: the leaderboard API)

#: First evaluation seed of every suite; training must never use seeds at or above it.
HELD_OUT_SEED = 100_000
#: Fewest episodes per level of a committed suite.
MIN_EPISODES = 20
#: Version of the entry format.
ENTRY_FORMAT = 1

ROOT = Path(__file__).resolve().parents[2]
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
    "campaign",
    "fewer_episodes",
    "policies",
    "traces",
    "rank_by",
    "generalization",
    "stress",
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
        sweep: Optional ``(arguments, rows)``: one level per row, each row the values of ``arguments`` at that
            level (``sweep: {parameter: P, values: [...]}`` is the one-argument form).
        traces: Episodes per level re-run with per-step traces for the report's plots, >= 0.
        generalization: Every level lies outside the env's training distribution (checked here).
        campaign_runs: Runs per campaign (``campaign: {runs: R}``): the episodes of a level are driven in
            campaigns of R consecutive seeds, each in one world by one policy that keeps its state between
            runs (:func:`agri_training.evaluation.evaluate.episode_jobs`); 1: a fresh policy per episode.
        policies: The registered policies that run the suite (its entries), or None for every policy of the
            env that can run it.
        fewer_episodes: Why a level has fewer than :data:`MIN_EPISODES` episodes ("" when it has enough);
            committed suites must give a reason (a test checks it).
        stress: The robustness axis a stress suite sweeps (``crowd``, ``speed``, ``corridor-width``, ...), or
            None for a paper or generalization suite. A stress suite sweeps from the env's default out to the
            limits its config allows, so the report can say at which level each policy breaks.
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
    sweep: tuple[tuple[str, ...], tuple[tuple[Any, ...], ...]] | None = None
    traces: int = 1
    generalization: bool = False
    campaign_runs: int = 1
    policies: tuple[str, ...] | None = None
    fewer_episodes: str = ""
    stress: str | None = None
    sha256: str = ""

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[a-z0-9][a-z0-9-]*", self.name):
            raise ValueError(f"name must be lowercase letters, digits and '-', got {self.name!r}")
        if not isinstance(self.version, int) or self.version < 1:
            raise ValueError(f"version must be an integer >= 1, got {self.version!r}")
        if not (self.env_id.startswith("agri_envs/") or agri_envs.is_parallel_id(self.env_id)):
            raise ValueError(f"env_id must be an agri_envs id or a multi-agent env of the package, got {self.env_id!r}")
        if self.seed_start < HELD_OUT_SEED:
            raise ValueError(f"seeds.start must be >= {HELD_OUT_SEED} (held out from training), got {self.seed_start}")
        if self.episodes < 1:
            raise ValueError(f"seeds.episodes must be >= 1, got {self.episodes}")
        if not self.rank_by:
            raise ValueError("rank_by must name at least one summary key")
        if self.traces < 0:
            raise ValueError(f"traces must be >= 0, got {self.traces}")
        if self.sweep is not None:
            names, rows = self.sweep
            if not names or len(set(names)) != len(names) or set(names) & set(self.env_kwargs):
                raise ValueError(f"sweep must name distinct arguments not also in env_kwargs, got {list(names)}")
            if not rows or any(len(row) != len(names) for row in rows):
                raise ValueError(f"sweep must give, per level, one value for each of {list(names)}, got {rows!r}")
            if len({repr(row) for row in rows}) != len(rows):
                raise ValueError(f"sweep levels must differ, got {rows!r}")
        if self.stress is not None:
            if not re.fullmatch(r"[a-z0-9][a-z0-9-]*", self.stress):
                raise ValueError(f"stress must name an axis (lowercase letters, digits and '-'), got {self.stress!r}")
            if self.sweep is None or len(self.sweep[1]) < 2:
                raise ValueError(f"stress: {self.stress} needs a sweep of at least 2 levels along its axis")
            if self.generalization:
                raise ValueError("a suite is a stress suite or a generalization suite, not both")
        if self.generalization:
            verdict = outside_training(self)
            if verdict is None:
                raise ValueError(f"generalization: {self.env_id} declares no training distribution to lie outside")
            inside = {
                label: [family for family, reasons in families.items() if not reasons]
                for label, families in verdict.items()
                if not all(families.values())
            }
            if inside:
                raise ValueError(
                    f"generalization: levels {inside} lie inside the training distribution (those families can draw "
                    "them); a generalization suite needs an argument outside every family's range"
                )
        if self.campaign_runs < 1 or self.episodes % self.campaign_runs:
            raise ValueError(
                f"campaign.runs must be >= 1 and divide seeds.episodes ({self.episodes}), got {self.campaign_runs}"
            )
        if self.policies is not None and not self.policies:
            raise ValueError("policies must name at least one policy (or be left out: every policy of the env)")

    @property
    def env_version(self) -> str:
        """The env's version tag, e.g. ``v1`` (``v1`` for ``robot_chain_v1``)."""
        return agri_envs.env_version(self.env_id)

    @property
    def seeds(self) -> list[int]:
        """The seeds of every level."""
        return list(range(self.seed_start, self.seed_start + self.episodes))

    def levels(self) -> list[tuple[str, dict[str, Any]]]:
        """``(label, env_kwargs)`` of each level: one, or one per sweep value."""
        if self.sweep is None:
            return [(self.name, dict(self.env_kwargs))]
        names, rows = self.sweep
        return [
            (" ".join([self.name, *(f"{k}={v}" for k, v in zip(names, row, strict=True))]),
             {**self.env_kwargs, **dict(zip(names, row, strict=True))})
            for row in rows
        ]

    def level_values(self) -> list[str]:
        """Each level's swept values, short (``n_people=8``; ``n_robots=32 office_width=28``), for plot axes."""
        return [label.removeprefix(self.name).strip() or self.name for label, _ in self.levels()]


def outside_training(suite: Suite) -> dict[str, dict[str, list[str]]] | None:
    """For each level of ``suite``: why each family of its env's training distribution cannot draw that scene.

    Returns:
        ``{level label: {family: [reasons]}}``; an empty list means that family can draw the level's scene
        (the level lies inside the distribution). None when the env declares no training distribution.
    """
    declared = agri_envs.training_distribution(suite.env_id)
    if declared is None:
        return None
    distribution, defaults = declared
    return {label: distribution.outside(kwargs, defaults) for label, kwargs in suite.levels()}


def parse_sweep(doc: Any) -> tuple[tuple[str, ...], tuple[tuple[Any, ...], ...]] | None:
    """A suite's ``sweep`` mapping as ``(arguments, rows)``: one argument, or several changed together.

    Raises:
        ValueError: For a malformed mapping.
    """
    if doc is None:
        return None
    if isinstance(doc, Mapping) and set(doc) == {"parameter", "values"} and isinstance(doc["values"], list):
        return (str(doc["parameter"]),), tuple((v,) for v in doc["values"])
    if (
        isinstance(doc, Mapping)
        and set(doc) == {"parameters", "values"}
        and isinstance(doc["parameters"], list)
        and isinstance(doc["values"], list)
        and all(isinstance(row, list) for row in doc["values"])
    ):
        return tuple(str(p) for p in doc["parameters"]), tuple(tuple(row) for row in doc["values"])
    raise ValueError(
        "sweep must be {parameter: NAME, values: [...]} or {parameters: [NAME, ...], values: [[...], ...]} "
        f"(one row per level), got {doc!r}"
    )


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
    sweep = parse_sweep(doc.get("sweep"))
    campaign = doc.get("campaign")
    if campaign is not None and (not isinstance(campaign, Mapping) or set(campaign) != {"runs"}):
        raise ValueError(f"campaign must be a mapping with exactly 'runs', got {campaign!r}")
    policies = doc.get("policies")
    if policies is not None and (not isinstance(policies, list) or not all(isinstance(p, str) for p in policies)):
        raise ValueError(f"policies must be a list of policy names, got {policies!r}")
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
        generalization=bool(doc.get("generalization", False)),
        campaign_runs=int(campaign["runs"]) if campaign else 1,
        policies=tuple(policies) if policies is not None else None,
        fewer_episodes=str(doc.get("fewer_episodes") or "").strip(),
        stress=str(doc["stress"]) if doc.get("stress") is not None else None,
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


def is_learned(policy: Mapping[str, Any]) -> bool:
    """Whether an entry's ``policy`` reference is a learned one: every kind but a registered scripted baseline.

    A zoo policy or ``agri train`` run (``learned``), an ONNX file, an SB3 zip, a Python callable or object: the
    report and LEADERBOARD.md compare them with the baselines and list them below the line.
    """
    return policy.get("kind") != "baseline"
