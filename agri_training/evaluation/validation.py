"""Choosing a learned policy's weights on validation seeds: its training distribution, on seeds no run used.

Training uses seeds below :data:`VALIDATION_SEED` for its envs (``seed .. seed + n_envs - 1``) and its
periodic evaluation (``eval_seed``, 10000 by default); held-out suites start at 100000. Validation runs
every candidate (a run's final weights, its ``best/`` and its ``checkpoints/step_N``) on the env of the
run's periodic evaluation (``env_kwargs`` with ``eval_env_kwargs`` over them: its training distribution
when the YAML draws scenes, ``scene_distribution: training``; arguments given to :func:`validate` go over
them, e.g. the training distribution of a run whose periodic evaluation ran the env's defaults) at seeds
``VALIDATION_SEED ..``, and picks:

* per training run, its best candidate (the run's score for the recipe's spread across seeds);
* over all runs, the chosen weights, which are then evaluated once on the held-out suites.

Candidates rank by success rate, then fewer collisions, then mean return. The document
(:func:`validate`) records every candidate's summary, the weights' sha256, and the episodes of each
run's best candidate, so the report can show the spread and the worst episodes.
"""

from __future__ import annotations

import hashlib
import shlex
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agri_training.core.documents import git_commit, jsonable
from agri_training.evaluation.evaluate import evaluate_many
from agri_training.evaluation.policies import EvalRequest
from agri_training.learned.policy import WEIGHTS_FILE, find_run_dir, read_config

#: First validation seed: above every training env and periodic-evaluation seed, below the held-out ones.
VALIDATION_SEED = 20_000
#: Version of the validation document.
VALIDATION_FORMAT = 1


def validation_env_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """The env arguments a run is validated on: its periodic evaluation's (``env_kwargs`` + ``eval_env_kwargs``)."""
    return {**config["env_kwargs"], **(config.get("eval_env_kwargs") or {})}


def candidates(run_dir: Path) -> list[Path]:
    """A run's final weights, its ``best/`` and every ``checkpoints/step_N``, in training order (final last)."""
    steps = sorted(
        (p for p in (run_dir / "checkpoints").glob("step_*") if (p / WEIGHTS_FILE).is_file()),
        key=lambda p: int(p.name.split("_")[1]),
    )
    best = [run_dir / "best"] if (run_dir / "best" / WEIGHTS_FILE).is_file() else []
    return [*steps, *best, run_dir]


def _score(summary: Mapping[str, Any]) -> tuple[float, float, float]:
    return (
        float(summary["success_rate"]),
        -float(summary.get("collision_rate") or 0.0),
        float(summary.get("mean_return") or 0.0),
    )


def validate(
    paths: Sequence[Path],
    episodes: int = 100,
    seed: int = VALIDATION_SEED,
    workers: int | None = 1,
    progress: bool = True,
    command: str | None = None,
    ray: str | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Evaluate candidate weights on validation seeds and choose among them.

    Args:
        paths: Run directories or their ``best/`` / ``checkpoints/step_N`` folders, all of one env and
            validated on the same env arguments.
        episodes: Episodes per candidate (seeds ``seed .. seed + episodes - 1``).
        seed: First validation seed, in [``VALIDATION_SEED``, 100000 - episodes].
        workers: Worker processes for the episodes.
        progress: Show the progress bar.
        command: The command recorded in the document (default: this process's).
        ray: Run the episodes as Ray tasks (see :func:`~agri_training.evaluation.evaluate.evaluate_many`).
        env_kwargs: Env arguments over the periodic evaluation's (e.g. ``{"n_robots": 16, "scene_distribution":
            "robust"}``: a recipe's training distribution). They may add arguments or change
            ``eval_env_kwargs``, never change a run's ``env_kwargs`` (what its weights need).

    Returns:
        The validation document: ``env_id``, ``env_kwargs`` (every argument the episodes ran with),
        ``env_kwargs_given`` (those of ``env_kwargs`` here), ``seeds``, every candidate (``path``, ``run``,
        training ``seed``, ``timesteps``, ``weights_sha256``, ``summary``), ``best_per_run`` (run -> path),
        ``chosen`` (path), and ``episodes`` (path -> records) for each run's best candidate.

    Raises:
        ValueError: For no candidates, seeds outside the validation range, candidates of different envs
            or validation arguments, or ``env_kwargs`` that change an argument a run's weights need.
    """
    if not paths:
        raise ValueError("validate needs at least one run or checkpoint folder")
    if seed < VALIDATION_SEED or seed + episodes > 100_000:
        raise ValueError(f"validation seeds must lie in [{VALIDATION_SEED}, 100000), got {seed}..{seed + episodes - 1}")
    configs = [read_config(Path(p)) for p in paths]
    env_id = configs[0]["env_id"]
    given = dict(env_kwargs or {})
    kwargs = validation_env_kwargs(configs[0])
    for p, c in zip(paths, configs, strict=True):
        if c["env_id"] != env_id or validation_env_kwargs(c) != kwargs:
            raise ValueError(f"{p} validates on {c['env_id']} {validation_env_kwargs(c)}, not {env_id} {kwargs}")
        used = {
            "its training envs": (int(c["seed"]), int(c["seed"]) + int(c["n_envs"])),
            "its periodic evaluation": (int(c["eval_seed"]), int(c["eval_seed"]) + int(c["eval_episodes"])),
        }
        if c.get("pretrain"):
            first = int(c["pretrain"].get("seed", 50_000))
            used["its demonstrations"] = (first, first + int(c["pretrain"].get("episodes", 100)))
        for what, (lo, hi) in used.items():
            if lo < seed + episodes and seed < hi:
                raise ValueError(f"{p}: {what} used seeds {lo}..{hi - 1}, which overlap the validation seeds")
        needed = {k: c["env_kwargs"][k] for k, v in given.items() if k in c["env_kwargs"] and c["env_kwargs"][k] != v}
        if needed:
            raise ValueError(f"{p}: its weights need {needed}; validation env_kwargs {given} may not change them")
    extra = {**(configs[0].get("eval_env_kwargs") or {}), **given}  # the run's own env_kwargs come with it
    kwargs = {**kwargs, **given}
    requests = [
        EvalRequest(env_id, str(p), episodes, seed, env_kwargs=extra, record_traces=0, label=str(p)) for p in paths
    ]
    docs = evaluate_many(requests, progress=progress, workers=workers, ray=ray)
    rows: list[dict[str, Any]] = []
    for p, c, doc in zip(paths, configs, docs, strict=True):
        folder = Path(p)
        rows.append(
            {
                "path": str(folder),
                "run": str(find_run_dir(folder)),
                "seed": int(c["seed"]),
                "timesteps": int(folder.name.split("_")[1]) if folder.name.startswith("step_") else folder.name,
                "weights_sha256": hashlib.sha256((folder / WEIGHTS_FILE).read_bytes()).hexdigest(),
                "summary": doc["summary"],
            }
        )
    by_path = {row["path"]: doc for row, doc in zip(rows, docs, strict=True)}
    best_per_run: dict[str, str] = {}
    for row in rows:
        held = best_per_run.get(row["run"])
        if held is None or _score(row["summary"]) > _score(by_path[held]["summary"]):
            best_per_run[row["run"]] = row["path"]
    chosen = max(best_per_run.values(), key=lambda path: _score(by_path[path]["summary"]))
    return jsonable(
        {
            "format": VALIDATION_FORMAT,
            "env_id": env_id,
            "env_kwargs": kwargs,
            "env_kwargs_given": given,
            "seeds": {"start": seed, "episodes": episodes},
            "command": command or " ".join(shlex.quote(a) for a in ["agri", *sys.argv[1:]]),
            "git_commit": git_commit(),
            "candidates": rows,
            "best_per_run": best_per_run,
            "chosen": chosen,
            "episodes": {path: by_path[path]["episodes"] for path in best_per_run.values()},
        }
    )
