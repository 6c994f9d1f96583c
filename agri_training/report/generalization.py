"""How well each learned policy generalizes: its training distribution beside every suite of its env.

For a learned policy of the zoo with a validation document (``agri_training/zoo/NAME/validation.json``,
written by ``agri validate``), the section puts side by side:

* its success on its training distribution, on validation seeds (20000 and up: seeds that neither its
  training envs nor its periodic evaluation used), and on every suite of its env (held-out seeds 100000
  and up), each marked inside or outside the training distribution, with the reason;
* the gap: a suite's success minus the training distribution's, with Newcombe's interval of a difference
  of two independent rates;
* the worst 10 % of episodes (:func:`~agri_training.core.stats.lower_tail_mean`) of each: how far they
  got (waypoints reached, corridors covered) and their return;
* the spread across training seeds: each run of the recipe with its best weights on validation seeds.

An env without a declared training distribution (the chain, the arm) gets the last part alone
(:func:`seed_spread_section`), with the env arguments each validation document names.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

import agri_envs
from agri_training import leaderboard as lb
from agri_training.core.stats import (
    format_interval,
    lower_tail_mean,
    newcombe_interval,
    stratified_bootstrap_ci,
    wilson_interval,
)
from agri_training.learned.policy import WEIGHTS_FILE, read_config
from agri_training.learned.zoo import ZOO_DIR

#: The worst share of episodes the section averages (CVaR level).
WORST_FRACTION = 0.1
VALIDATION_FILE = "validation.json"

INTRO = """\
How each learned policy does away from the scenes it was trained on. *Training distribution* is its own
distribution of scenes, on validation seeds (20000 and up) that no training episode and no periodic
evaluation used; the suites run held-out seeds (100000 and up). *Scenes* says whether a suite's scenes lie
inside the training distribution (some family of it draws them) or outside (and which arguments no
family reaches). *Gap* is the suite's success minus the training distribution's, with the 95 % interval
of that difference: an interval below zero means the policy does worse there than on what it trained on.
*Worst 10 %* averages the worst tenth of the episodes: *progress* is the share of the mission they
finished (waypoints reached, corridor bins covered), *return* the env's reward summed over the episode.
"""

SEED_SPREAD_INTRO = """\
How much each shipped learned policy owes to its training seed: every run of its recipe at its best weights on
validation seeds (20000 and up, used by no training episode and no periodic evaluation), which the shipped
weights were chosen among; held-out suites never took part in the choice.
"""


def episode_progress(record: Mapping[str, Any]) -> float:
    """How much of its mission an episode finished, in [0, 1]: coverage, waypoints reached, or success."""
    if record.get("coverage") is not None:
        return float(record["coverage"])
    if record.get("n_waypoints"):
        return float(record["waypoints_reached"]) / float(record["n_waypoints"])
    return float(bool(record["is_success"]))


def _tail(values: Sequence[float]) -> str:
    ci = stratified_bootstrap_ci(values, lambda x: lower_tail_mean(x, WORST_FRACTION))
    value = lower_tail_mean(values, WORST_FRACTION)
    fmt = "{:.2f}" if all(0.0 <= v <= 1.0 for v in values) else "{:.1f}"
    return format_interval(value, ci, fmt)


def _rate(k: int, n: int) -> str:
    return format_interval(k / n, wilson_interval(k, n))


def _row(label: str, scenes: str, records: Sequence[Mapping[str, Any]], reference: tuple[int, int] | None) -> str:
    n = len(records)
    k = sum(bool(r["is_success"]) for r in records)
    gap = "—"
    if reference is not None:
        k0, n0 = reference
        gap = format_interval(k / n - k0 / n0, newcombe_interval(k, n, k0, n0), "{:+.2f}")
    collisions = sum(bool(r.get("collision")) for r in records)
    progress = [episode_progress(r) for r in records]
    returns = [float(r["return"]) for r in records]
    return (
        f"| {label} | {scenes} | {n} | {_rate(k, n)} | {gap} | {_rate(collisions, n)} | {_tail(progress)} | "
        f"{_tail(returns)} |"
    )


def scenes_verdict(suite: lb.Suite) -> str:
    """``inside``, or ``outside:`` and what no scene of the nearest training family has (the first level's)."""
    declared = agri_envs.training_distribution(suite.env_id)
    if declared is None:
        return "(no training distribution)"
    distribution, defaults = declared
    reasons = [distribution.nearest(kwargs, defaults)[1] for _, kwargs in suite.levels()]
    outside = [r for r in reasons if r]
    if len(outside) < len(reasons):
        return "inside" if not outside else f"{len(reasons) - len(outside)} of {len(reasons)} levels inside"
    return "outside: " + "; ".join(outside[0])


def load_validation(name: str, zoo_dir: Path = ZOO_DIR) -> dict[str, Any] | None:
    """The validation document of the zoo policy ``name``, or None when it has none."""
    path = zoo_dir / name / VALIDATION_FILE
    return json.loads(path.read_text()) if path.is_file() else None


def _weights_match(doc: Mapping[str, Any], name: str, zoo_dir: Path) -> bool:
    weights = zoo_dir / name / WEIGHTS_FILE
    chosen = next(c for c in doc["candidates"] if c["path"] == doc["chosen"])
    return weights.is_file() and hashlib.sha256(weights.read_bytes()).hexdigest() == chosen["weights_sha256"]


def seed_spread(doc: Mapping[str, Any]) -> list[str]:
    """Markdown: every training run of the recipe with its best weights on validation seeds, and the spread."""
    by_path = {c["path"]: c for c in doc["candidates"]}
    runs = sorted((by_path[p] for p in doc["best_per_run"].values()), key=lambda c: c["seed"])
    n_candidates = {run: sum(c["run"] == run for c in doc["candidates"]) for run in doc["best_per_run"]}
    lines = [
        "| training seed | run | weights (best of) | success | collisions | mean return |",
        "|---|---|---|---|---|---|",
    ]
    rates = []
    for c in runs:
        s = c["summary"]
        n = int(s["episodes"])
        k = round(float(s["success_rate"]) * n)
        rates.append(k / n)
        crashes = round(float(s.get("collision_rate") or 0.0) * n)
        chosen = " (shipped)" if c["path"] == doc["chosen"] else ""
        step = c["timesteps"] if isinstance(c["timesteps"], int) else f"`{c['timesteps']}`"
        lines.append(
            f"| {c['seed']}{chosen} | `{Path(c['run']).name}` | {step} ({n_candidates[c['run']]}) | {_rate(k, n)} | "
            f"{_rate(crashes, n)} | {format_interval(s['mean_return'], s.get('mean_return_ci'), '{:.1f}')} |"
        )
    lines += [
        "",
        f"Across {len(rates)} training seeds the validation success ranges from {min(rates):.2f} to "
        f"{max(rates):.2f} (standard deviation {float(np.std(rates)):.2f}).",
    ]
    return lines


def trained_on_distribution(name: str, zoo_dir: Path = ZOO_DIR) -> bool:
    """Whether the shipped policy ``name`` trained on its env's scene distribution (its config's training envs)."""
    folder = zoo_dir / name
    if not (folder / "config.yaml").is_file():
        return False
    config = read_config(folder)
    kwargs = {**config.get("env_kwargs", {}), **(config.get("train_env_kwargs") or {})}
    return kwargs.get("scene_distribution") not in (None, "off")


def _learned_names(env_id: str, entries: Sequence[tuple[lb.Suite, Mapping[str, Any]]]) -> list[str]:
    """The learned policies of ``env_id`` among the entries, in order of appearance."""
    learned = (e["policy"]["name"] for s, e in entries if s.env_id == env_id and e["policy"]["kind"] == "learned")
    return list(dict.fromkeys(learned))


def _mismatch_warning(doc: Mapping[str, Any], name: str, zoo_dir: Path) -> list[str]:
    """A bold line when the validation document chose other weights than the shipped ones, else nothing."""
    if _weights_match(doc, name, zoo_dir):
        return []
    return [f"**`{VALIDATION_FILE}` chose other weights than the ones shipped in `zoo/{name}`.**", ""]


def seed_spread_section(
    env_id: str, entries: Sequence[tuple[lb.Suite, Mapping[str, Any]]], zoo_dir: Path = ZOO_DIR
) -> list[str]:
    """Markdown: per learned policy of ``env_id`` with a validation document, the spread across its training seeds.

    For an env that declares no training distribution (:func:`generalization_section` covers the others): each
    document says what its runs were validated on (its env arguments and seeds).

    Args:
        env_id: The env.
        entries: ``(suite, entry)`` for every entry the report shows (entries of other envs are ignored).
        zoo_dir: Where the shipped policies and their validation documents live.
    """
    out: list[str] = []
    for name in _learned_names(env_id, entries):
        doc = load_validation(name, zoo_dir)
        if doc is None:
            continue
        first, count = doc["seeds"]["start"], doc["seeds"]["episodes"]
        arguments = ", ".join(f"{k}={v}" for k, v in sorted(doc.get("env_kwargs", {}).items())) or "the defaults"
        seeds = f"seeds {first}-{first + count - 1}"
        out += [f"#### `{name}`", "", f"{count} validation episodes per candidate ({seeds}; {arguments}):", ""]
        out += [*_mismatch_warning(doc, name, zoo_dir), *seed_spread(doc), ""]
    return out or ["No learned policy of this env has a validation document."]


def generalization_section(
    env_id: str, entries: Sequence[tuple[lb.Suite, Mapping[str, Any]]], zoo_dir: Path = ZOO_DIR
) -> list[str]:
    """Markdown: per learned policy of ``env_id``, training distribution and suites side by side, and seeds.

    Args:
        env_id: The env.
        entries: ``(suite, entry)`` for every entry the report shows (entries of other envs are ignored).
        zoo_dir: Where the shipped policies and their validation documents live.
    """
    mine = [(s, e) for s, e in entries if s.env_id == env_id and e["policy"]["kind"] == "learned"]
    names = _learned_names(env_id, entries)
    if not names:
        return ["No learned policy of this env has leaderboard entries."]
    out = [INTRO]
    for name in names:
        doc = load_validation(name, zoo_dir)
        out += [f"#### `{name}`", ""]
        reference = None
        header = [
            "| evaluated on | scenes | episodes | success | gap to training | collisions | worst 10 %: progress "
            "| worst 10 %: return |",
            "|---|---|---|---|---|---|---|---|",
        ]
        rows = []
        if doc is None:
            out += [f"No validation on its training distribution recorded (`zoo/{name}/{VALIDATION_FILE}`).", ""]
        else:
            records = doc["episodes"][doc["chosen"]]
            reference = (sum(bool(r["is_success"]) for r in records), len(records))
            first, count = doc["seeds"]["start"], doc["seeds"]["episodes"]
            rows.append(_row(f"training distribution (seeds {first}-{first + count - 1})", "inside", records, None))
            out += _mismatch_warning(doc, name, zoo_dir)
        on_distribution = trained_on_distribution(name, zoo_dir)
        if not on_distribution:
            out += [
                f"`{name}` trained on fixed scenes, not on the env's training distribution: *scenes* is left "
                "blank, since inside or outside that distribution says nothing about what this policy saw.",
                "",
            ]
        for suite, entry in mine:
            if entry["policy"]["name"] != name:
                continue
            records = [r for level in entry["levels"] for r in level["episodes"]]
            scenes = scenes_verdict(suite) if on_distribution else "—"
            rows.append(_row(f"{suite.name} (v{suite.version})", scenes, records, reference))
        out += [*header, *rows, ""]
        if doc is not None:
            out += ["Spread across training seeds (the recipe's runs, each at its best weights on validation seeds; "
                    "the shipped weights were chosen among them):", "", *seed_spread(doc), ""]  # fmt: skip
    return out
