"""Robustness on stress suites: where each policy first drops below 0.90 success, and why.

A stress suite (:attr:`~agri_training.leaderboard.suites.Suite.stress`) sweeps one axis from the env's default
out to the limits its config allows. For every policy and stress suite, :func:`first_drop` finds the first level
whose success rate falls below :data:`SUCCESS_FLOOR` and names the dominant kind of failure among that level's
failed episodes. Both LEADERBOARD.md and the report print the same lines (:func:`robustness_lines`).

Failure kinds are read from each episode's record (the scalars an entry keeps; they differ per env):

| kind | meaning | read from |
|---|---|---|
| crash | a collision or a contact | ``collision`` (every env records it) |
| chain break | robot_chain: a gap in the chain ended the episode | ``chain_intact`` false |
| stall | truncated with the robot not moving at the end | see below |
| time-out | truncated otherwise, or where the record cannot tell a stall | ``truncated`` |
| ended | ended early for none of the reasons above | |

A stall is told apart where a record says the robot stood still at the end: GreenhouseNav, ``blocked_at_end``
(Harik's safety stop was holding it); GrapeHarvest, ``plan_success`` false (Luo's planner gave up, so the arm
holds its last pose). Learned policies record no controller state, and the coverage and chain records hold no
motion at the end: their truncated episodes count as time-outs.

Per-env rules live in :data:`FAILURE_KIND_READERS`, keyed by env family (the id without its version, so a
version bump needs no change here).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from agri_training.core.stats import format_interval, wilson_interval
from agri_training.leaderboard.suites import Suite, is_learned

#: The success rate below which a policy counts as broken at a stress level.
SUCCESS_FLOOR = 0.90

#: Failure kinds, in the order a tie between them is broken.
FAILURE_KINDS = ("crash", "chain break", "stall", "time-out", "ended")


def env_family(env_id: str) -> str:
    """The env id without package prefix and version: ``agri_envs/GreenhouseNav-v2`` -> ``GreenhouseNav``."""
    return re.sub(r"[-_]v\d+$", "", env_id.removeprefix("agri_envs/"))


def _nav_kind(record: Mapping[str, Any]) -> str | None:
    return "stall" if record.get("truncated") and record.get("blocked_at_end") else None


def _chain_kind(record: Mapping[str, Any]) -> str | None:
    return "chain break" if record.get("chain_intact") is False else None


def _arm_kind(record: Mapping[str, Any]) -> str | None:
    return "stall" if record.get("truncated") and record.get("plan_success") is False else None


#: Env family -> a reader of the kinds only that env's records can tell (None: the generic rule decides).
FAILURE_KIND_READERS: dict[str, Callable[[Mapping[str, Any]], str | None]] = {
    "GreenhouseNav": _nav_kind,
    "robot_chain": _chain_kind,
    "GrapeHarvest": _arm_kind,
}


def failure_kind(env_id: str, record: Mapping[str, Any]) -> str:
    """The kind of a failed episode (one of :data:`FAILURE_KINDS`), from its record.

    Args:
        env_id: The env the episode ran on (selects the per-env reader).
        record: The episode's record in an entry.

    Returns:
        ``crash`` for any collision; else the env's own reading (a stall, a chain break); else ``time-out``
        when the episode was truncated and ``ended`` when it was not.
    """
    if record.get("collision"):
        return "crash"
    reader = FAILURE_KIND_READERS.get(env_family(env_id))
    kind = reader(record) if reader else None
    if kind:
        return kind
    return "time-out" if record.get("truncated") else "ended"


def failure_counts(env_id: str, episodes: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """Failed episodes counted by kind, most frequent first (ties in :data:`FAILURE_KINDS` order)."""
    counts: dict[str, int] = {}
    for record in episodes:
        if not record.get("is_success"):
            kind = failure_kind(env_id, record)
            counts[kind] = counts.get(kind, 0) + 1
    return dict(sorted(counts.items(), key=lambda kv: (-kv[1], FAILURE_KINDS.index(kv[0]))))


def level_success(level: Mapping[str, Any]) -> tuple[int, int]:
    """``(successes, episodes)`` of one level of an entry, counted from its episodes."""
    episodes = level["episodes"]
    return sum(bool(e.get("is_success")) for e in episodes), len(episodes)


@dataclasses.dataclass(frozen=True)
class Drop:
    """The first level of a stress suite where a policy's success falls below :data:`SUCCESS_FLOOR`.

    Attributes:
        suite: The stress suite's name.
        axis: Its robustness axis (``crowd``, ``speed``, ...).
        index: The level's position (0 is the env's default).
        levels: How many levels the suite has.
        value: The level's swept values (``n_people=8``).
        successes: Successful episodes at that level.
        episodes: Episodes at that level.
        failures: Failed episodes by kind, most frequent first.
    """

    suite: str
    axis: str
    index: int
    levels: int
    value: str
    successes: int
    episodes: int
    failures: Mapping[str, int]

    @property
    def kind(self) -> str:
        """The dominant failure kind."""
        return next(iter(self.failures), "ended")

    def describe(self) -> str:
        """``first below 0.90 at `n_people=8` (level 3 of 4): 0.85 [0.64, 0.95], crash (3 of 3 failures)``."""
        rate = self.successes / self.episodes
        failed = self.episodes - self.successes
        others = [f"{n} {k}" for k, n in list(self.failures.items())[1:]]
        why = f"{self.kind} ({self.failures.get(self.kind, 0)} of {failed} failures{'; ' if others else ''}"
        return (
            f"first below {SUCCESS_FLOOR:.2f} at `{self.value}` (level {self.index + 1} of {self.levels}): "
            f"{format_interval(rate, wilson_interval(self.successes, self.episodes))}, "
            f"{why}{', '.join(others)})"
        )


def first_drop(suite: Suite, entry: Mapping[str, Any]) -> Drop | None:
    """The first level of ``suite`` at which ``entry`` succeeds less often than :data:`SUCCESS_FLOOR`.

    Args:
        suite: A stress suite (any swept suite works; its axis then reads ``sweep``).
        entry: A policy's entry on it.

    Returns:
        The level and its failures, or None when the policy holds on every level.
    """
    values = suite.level_values()
    for k, level in enumerate(entry["levels"]):
        successes, n = level_success(level)
        if n and successes / n < SUCCESS_FLOOR - 1e-9:
            return Drop(
                suite.name,
                suite.stress or "sweep",
                k,
                len(entry["levels"]),
                values[k] if k < len(values) else str(level.get("label", k)),
                successes,
                n,
                failure_counts(entry["env_id"], level["episodes"]),
            )
    return None


def stress_suites(suites: Sequence[Suite], env_id: str | None = None) -> list[Suite]:
    """The stress suites among ``suites`` (of one env when ``env_id`` is given), in the given order."""
    return [s for s in suites if s.stress and (env_id is None or s.env_id == env_id)]


def policy_order(entries: Sequence[Mapping[str, Any]]) -> list[tuple[str, bool, bool]]:
    """``(name, learned, privileged)`` of every policy with an entry: scripted first, then learned, by name."""
    seen: dict[str, tuple[str, bool, bool]] = {}
    for e in entries:
        name = e["policy"]["name"]
        seen.setdefault(name, (name, is_learned(e["policy"]), bool(e.get("privileged"))))
    return sorted(seen.values(), key=lambda p: (p[1], p[0]))


def policy_name(name: str, learned: bool, privileged: bool) -> str:
    """A policy as the robustness lines name it: `` `name` **P** (learned)``."""
    return f"`{name}`" + (" **P**" if privileged else "") + (" (learned)" if learned else "")


def robustness_lines(env_id: str, suites: Sequence[Suite], entries: Sequence[Mapping[str, Any]]) -> list[str]:
    """One Markdown bullet per policy: on each stress suite of the env, where it first drops and why.

    Args:
        env_id: The env.
        suites: Suites (those of other envs and the non-stress ones are skipped).
        entries: Entries (matched to the suites by name).

    Returns:
        Bullets, scripted policies first; empty when the env has no stress suite with an entry.
    """
    mine = stress_suites(suites, env_id)
    by_suite = {s.name: s for s in mine}
    relevant = [e for e in entries if e["suite"]["name"] in by_suite]
    lines = []
    for name, learned, privileged in policy_order(relevant):
        have = {e["suite"]["name"]: e for e in relevant if e["policy"]["name"] == name}
        drops = []
        holds = []
        missing = []
        for suite in mine:
            entry = have.get(suite.name)
            if entry is None:
                missing.append(suite.stress or suite.name)
                continue
            drop = first_drop(suite, entry)
            if drop is None:
                holds.append(suite.stress or suite.name)
            else:
                drops.append(f"{drop.axis}: {drop.describe()}")
        if not drops:
            text = "holds on every level" + (f" of {', '.join(holds)}" if missing else "")
        else:
            text = "; ".join(drops) + (f"; holds on every level of {', '.join(holds)}" if holds else "")
        if missing:
            text += f"; no entry on {', '.join(missing)}"
        lines.append(f"- {policy_name(name, learned, privileged)}: {text}.")
    return lines
