r"""Training sweeps: one ``agri train`` per (grid point, seed), each on one CPU, with a summary across seeds.

Runs go to local worker processes or Ray tasks::

    agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --timesteps 50000 --seeds 0 1 2 3 \
        --grid algo_kwargs.learning_rate=1e-4,3e-4 --out runs/nav-sweep [--workers 2 | --ray local]

A grid axis is ``KEY=V1,V2,...``: ``KEY`` is a hyperparameter of the YAML (``n_envs``) or a dotted path into
one (``algo_kwargs.learning_rate``, ``policy_kwargs.net_arch``), each value a YAML value (``1e-4``, ``true``,
``[64, 64]``; commas inside brackets belong to the value). The grid is the Cartesian product of its axes;
every point runs with every seed. Each run writes the same run directory as a single ``agri train`` into
``OUT/<run name>/`` (``seed0``, or ``learning_rate=0.0001-seed0`` with a grid), and its ``command.txt`` holds
the single ``agri train`` command that reproduces it. The sweep writes ``OUT/sweep.json`` (everything),
``OUT/summary.md`` and ``OUT/summary.csv`` (one row per run).

Resources are explicit: a run gets one CPU (one worker process, or a Ray task with ``num_cpus=1``) and trains
with ``torch_threads: 1`` and ``update_threads: 1`` (``torch.set_num_threads(1)``) in one process
(``vec_env: subproc`` is refused). Local workers fork from a server that has imported torch (with
``torch._dynamo``, which the optimizers load on their first step), stable-baselines3 and the envs once, and
each keeps its imports and loaded numba kernels for its next runs (every run seeds everything afresh:
``tests/training/test_sweep.py`` checks that a run's learning curve does not depend on where it ran). Every
run's configuration is resolved before the first run starts, so a bad grid value fails at once with a
``ValueError`` that names it. A run that raises is recorded with its seed, grid point and exception (and
``OUT/<run>/error.txt`` with the traceback); the other runs go on.

The summary reports, per run, the final periodic evaluation (the last row of ``curve.csv``: success rate and
mean return over the ``eval_episodes`` fixed evaluation seeds), and per grid point the mean over its seeds
with a 95 % percentile-bootstrap interval of that mean across seeds (:func:`agri_training.stats.bootstrap_ci`,
2000 resamples; with few seeds that interval is narrow, read it as a spread, not a guarantee).
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math
import os
import re
import shlex
import sys
import time
import traceback
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agri_training.core.pool import default_workers, run_items
from agri_training.core.stats import bootstrap_ci, format_interval
from agri_training.core.yaml_values import load_yaml
from agri_training.learned.policy import CONFIG_FILE
from agri_training.train import HELD_OUT_SEED, HYPERPARAM_KEYS, TrainRequest, resolve_config, train

#: Hyperparameters a sweep or a search may vary (``torch_threads`` and ``update_threads`` are pinned to 1,
#: ``scenarios`` is structure).
VARIABLE_KEYS = tuple(k for k in HYPERPARAM_KEYS if k not in ("torch_threads", "update_threads", "scenarios"))
SUMMARY_MD, SUMMARY_CSV, SWEEP_JSON, ERROR_FILE = "summary.md", "summary.csv", "sweep.json", "error.txt"


def parse_value(text: str) -> Any:
    """A YAML value, with ``1e-4``-style numbers read as floats (YAML 1.1 wants ``1.0e-4``).

    Raises:
        ValueError: For text that is not YAML.
    """
    try:
        return load_yaml(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"{text!r} is not a YAML value: {exc}") from None


def split_top_level(text: str) -> list[str]:
    """Split on commas outside brackets and braces: ``1,[64,64]`` -> ``["1", "[64,64]"]``."""
    parts: list[str] = []
    current: list[str] = []
    depth = 0
    for ch in text:
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append("".join(current))
            current = []
        else:
            current.append(ch)
    parts.append("".join(current))
    return parts


def check_key(key: str, option: str) -> None:
    """Check a dotted hyperparameter path (``algo_kwargs.learning_rate``).

    Raises:
        ValueError: For an empty part or a first part that is not a variable hyperparameter.
    """
    parts = key.split(".")
    if not key or any(not p for p in parts):
        raise ValueError(f"{option}: {key!r} is not a dotted hyperparameter path like algo_kwargs.learning_rate")
    if parts[0] not in VARIABLE_KEYS:
        raise ValueError(f"{option}: unknown hyperparameter {parts[0]!r} in {key!r}; valid: {', '.join(VARIABLE_KEYS)}")


def parse_grid(items: Sequence[str]) -> dict[str, tuple[Any, ...]]:
    """``KEY=V1,V2,...`` strings to an ordered grid ``{dotted key: values}``.

    Raises:
        ValueError: For an item without ``=``, an unknown key, a key given twice, an empty or repeated value.
    """
    grid: dict[str, tuple[Any, ...]] = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--grid expects KEY=V1,V2,... (e.g. algo_kwargs.learning_rate=1e-4,3e-4), got {item!r}")
        key, text = (s.strip() for s in item.split("=", 1))
        check_key(key, "--grid")
        if key in grid:
            raise ValueError(f"--grid: {key!r} is given twice")
        raw = [v.strip() for v in split_top_level(text)]
        if any(not v for v in raw):
            raise ValueError(f"--grid: {key!r} has an empty value in {text!r}; give V1,V2,... (one value at least)")
        values = tuple(parse_value(v) for v in raw)
        if len({json.dumps(v, sort_keys=True, default=repr) for v in values}) != len(values):
            raise ValueError(f"--grid: {key!r} repeats a value in {text!r}")
        grid[key] = values
    return grid


def nested(point: Mapping[str, Any]) -> dict[str, Any]:
    """``{"algo_kwargs.learning_rate": 1e-4}`` -> ``{"algo_kwargs": {"learning_rate": 1e-4}}``."""
    out: dict[str, Any] = {}
    for key, value in point.items():
        parts = key.split(".")
        node = out
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return out


def merge(base: Mapping[str, Any], update: Mapping[str, Any]) -> dict[str, Any]:
    """``update`` over ``base``, nested mappings key by key (as the hyperparameter blocks merge)."""
    out = {k: (merge(v, {}) if isinstance(v, Mapping) else v) for k, v in base.items()}
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = merge(out[key], value)
        else:
            out[key] = value
    return out


def _format(value: Any) -> str:
    if isinstance(value, float):
        return format(value, "g")
    if isinstance(value, str | int | bool) or value is None:
        return str(value)
    return json.dumps(value, separators=(",", ":"), sort_keys=True)


def point_label(point: Mapping[str, Any], short: bool = True) -> str:
    """``learning_rate=0.0001,n_epochs=5`` (the last part of each key with ``short``)."""
    return ",".join(f"{k.rsplit('.', 1)[-1] if short else k}={_format(v)}" for k, v in point.items())


def _hp_argument(key: str, value: Any) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=1_000_000).strip()
    return f"{key}={text.removesuffix('...').strip()}"


def train_command(request: TrainRequest) -> str:
    """The single ``agri train`` command line that runs ``request`` (written to each run's ``command.txt``)."""
    args = ["agri", "train", "--env", request.env_id, "--algo", request.algo, "--seed", str(request.seed)]
    if request.scenario:
        args += ["--scenario", request.scenario]
    if request.her:
        args.append("--her")
    if request.timesteps is not None:
        args += ["--timesteps", str(request.timesteps)]
    if request.hyperparams_file is not None:
        args += ["--hyperparams", str(request.hyperparams_file)]
    args += ["--out", str(request.out)]
    if request.overrides:
        args += ["--hp", *(_hp_argument(k, v) for k, v in request.overrides.items())]
    return " ".join(shlex.quote(a) for a in args)


@dataclasses.dataclass(frozen=True)
class SweepRequest:
    """A training sweep: every grid point with every seed.

    Attributes:
        env_id: Registered env id.
        algo: ``ppo``, ``sac``, ``td3`` or ``tqc``.
        out: Sweep folder; run ``NAME`` goes to ``out/NAME``.
        seeds: Training seeds (distinct, each in [0, 100000)).
        grid: Ordered ``{dotted hyperparameter: values}`` (see :func:`parse_grid`); empty for seeds only.
        timesteps: Training steps per run (None: the YAML's ``n_timesteps``).
        scenario: Env-argument preset, or None.
        her: ``HerReplayBuffer`` (off-policy algorithms on goal-conditioned envs).
        overrides: Hyperparameters every run shares (as ``agri train --hp``); the grid goes over them.
        hyperparams_file: YAML to read instead of ``hyperparams/<algo>.yml``.
    """

    env_id: str
    algo: str
    out: Path
    seeds: tuple[int, ...]
    grid: Mapping[str, tuple[Any, ...]] = dataclasses.field(default_factory=dict)
    timesteps: int | None = None
    scenario: str | None = None
    her: bool = False
    overrides: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    hyperparams_file: Path | None = None

    def __post_init__(self) -> None:
        if not self.seeds:
            raise ValueError("seeds must name one seed at least")
        for s in self.seeds:
            if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < HELD_OUT_SEED:
                raise ValueError(f"seeds must be ints in [0, {HELD_OUT_SEED}), got {s!r}")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must be distinct, got {list(self.seeds)}")
        for key, values in self.grid.items():
            check_key(key, "grid")
            if not values:
                raise ValueError(f"grid: {key!r} needs one value at least")

    def points(self) -> list[dict[str, Any]]:
        """The grid points in order (the first axis varies slowest); ``[{}]`` without a grid."""
        keys = list(self.grid)
        return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(self.grid[k] for k in keys))]


@dataclasses.dataclass(frozen=True)
class SweepRun:
    """One planned run of a sweep.

    Attributes:
        name: Folder name under the sweep's ``out``.
        seed: Training seed.
        point: The grid point (``{dotted key: value}``; empty without a grid).
        request: The single-run request (``out`` absolute, so that a Ray worker writes where it should).
        config: Its resolved config (what ``config.yaml`` will hold).
    """

    name: str
    seed: int
    point: Mapping[str, Any]
    request: TrainRequest
    config: Mapping[str, Any]

    def describe(self) -> str:
        """``seed S, grid point K=V`` for messages."""
        return f"seed {self.seed}" + (f", grid point {point_label(self.point, short=False)}" if self.point else "")


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", name)


def plan_sweep(request: SweepRequest) -> list[SweepRun]:
    """Every run of the sweep, with its config resolved (nothing runs).

    Raises:
        ValueError: For a grid value or hyperparameter that does not resolve (naming its grid point and
            seed), ``vec_env: subproc`` (a run gets one CPU), or a run folder that already holds a run.
    """
    points = request.points()
    labels = [point_label(p) for p in points]
    if len(set(labels)) != len(labels):  # two keys end alike (pi.lr, vf.lr): spell them out
        labels = [point_label(p, short=False) for p in points]
    out = Path(request.out).resolve()
    runs = []
    for point, label in zip(points, labels, strict=True):
        overrides = merge(merge(request.overrides, nested(point)), {"torch_threads": 1, "update_threads": 1})
        for seed in request.seeds:
            name = _safe(f"{label}-seed{seed}" if point else f"seed{seed}")
            run = TrainRequest(
                env_id=request.env_id,
                algo=request.algo,
                out=out / name,
                seed=seed,
                timesteps=request.timesteps,
                scenario=request.scenario,
                her=request.her,
                overrides=overrides,
                hyperparams_file=request.hyperparams_file,
                progress=False,
            )
            where = f"seed {seed}" + (f", grid point {point_label(point, short=False)}" if point else "")
            try:
                config = resolve_config(run)
            except (ValueError, TypeError) as exc:
                raise ValueError(f"sweep run with {where}: {exc}") from None
            if config["vec_env"] == "subproc":
                raise ValueError(
                    f"sweep run with {where}: vec_env 'subproc' starts n_envs processes per run; "
                    "a sweep gives each run one CPU, use vec_env: dummy or vector"
                )
            if (run.out / CONFIG_FILE).exists():
                raise ValueError(f"{run.out} already holds a run; pass another --out")
            runs.append(SweepRun(name, seed, point, run, config))
    return runs


def read_curve(path: Path) -> list[dict[str, float]]:
    """The rows of a run's ``curve.csv`` as numbers."""
    with path.open(newline="") as fh:
        return [{k: float(v) for k, v in row.items() if v not in ("", None)} for row in csv.DictReader(fh)]


def run_training(run: SweepRun) -> dict[str, Any]:
    """Train one run in this process with one torch thread; never raises.

    Returns:
        ``{"ok": True, "wall_s": ..., "cpu_s": ..., "curve": [rows of curve.csv]}`` (``cpu_s``: this process's
        CPU time for the run), or ``{"ok": False, "error": "Type:
        message", "traceback": ...}`` (the traceback also goes to the run's ``error.txt``).
    """
    import torch

    torch.set_num_threads(1)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        run_dir = train(run.request, train_command(run.request))
        curve = read_curve(run_dir / "curve.csv")
    except Exception as exc:  # reported with the run's seed and grid point; the other runs go on
        tb = traceback.format_exc()
        try:
            run.request.out.mkdir(parents=True, exist_ok=True)
            (run.request.out / ERROR_FILE).write_text(f"{run.describe()}\n\n{tb}")
        except OSError:
            pass
        return {"ok": False, "error": f"{type(exc).__name__}: {exc}", "traceback": tb,
                "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}  # fmt: skip
    return {"ok": True, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0, "curve": curve}


#: What the worker processes import once (torch._dynamo alone is ~4 s of imports, done lazily by the
#: optimizer's first step otherwise).
PRELOAD = ("torch", "torch._dynamo", "stable_baselines3", "agri_envs", "agri_training.sweep")


def _lost(index: int, message: str) -> dict[str, Any]:
    return {"ok": False, "error": message, "traceback": ""}


def _final(curve: Sequence[Mapping[str, float]], key: str) -> float | None:
    return float(curve[-1][key]) if curve and key in curve[-1] else None


def _interval(values: Sequence[float]) -> dict[str, Any]:
    if not values:
        return {"mean": None, "ci": None}
    lo, hi = bootstrap_ci(values)
    return {"mean": float(np.mean(values)), "ci": [lo, hi] if len(values) > 1 else None}


def summarize(runs: Sequence[SweepRun], results: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Per-run rows and per-point means over seeds (95 % percentile-bootstrap interval of the mean across seeds).

    Returns:
        ``{"interval": ..., "runs": [...], "points": [...]}``.
    """
    rows: list[dict[str, Any]] = []
    for run, res in zip(runs, results, strict=True):
        curve = res.get("curve") or []
        rows.append(
            {
                "run": run.name,
                "seed": run.seed,
                "point": dict(run.point),
                "status": "ok" if res["ok"] else "failed",
                "timesteps": int(curve[-1]["timesteps"]) if curve else None,
                "final_success_rate": _final(curve, "success_rate"),
                "final_mean_return": _final(curve, "mean_return"),
                "best_success_rate": max((r["success_rate"] for r in curve), default=None),
                "wall_time_s": round(float(res.get("wall_s", float("nan"))), 1),
                "cpu_time_s": round(float(res.get("cpu_s", float("nan"))), 1),
                "error": res.get("error"),
            }
        )
    points = []
    for point in dict.fromkeys(json.dumps(r["point"], sort_keys=False, default=repr) for r in rows):
        mine = [r for r in rows if json.dumps(r["point"], sort_keys=False, default=repr) == point]
        ok = [r for r in mine if r["status"] == "ok"]
        points.append(
            {
                "point": json.loads(point),
                "runs": len(mine),
                "ok": len(ok),
                "failed_seeds": [r["seed"] for r in mine if r["status"] != "ok"],
                "final_success_rate": _interval([float(r["final_success_rate"]) for r in ok]),
                "final_mean_return": _interval([float(r["final_mean_return"]) for r in ok]),
            }
        )
    interval = "95 % percentile bootstrap of the mean across seeds (agri_training.stats.bootstrap_ci, 2000 resamples)"
    return {"interval": interval, "runs": rows, "points": points}


def _cell(value: Any, fmt: str) -> str:
    return "-" if value is None or (isinstance(value, float) and not math.isfinite(value)) else fmt.format(value)


def _mean_ci(stat: Mapping[str, Any], fmt: str) -> str:
    return format_interval(stat["mean"], stat["ci"], fmt)


def format_markdown(doc: Mapping[str, Any]) -> str:
    """The sweep's ``summary.md``."""
    lines = [
        f"# Training sweep: {doc['algo']} on {doc['env_id']}",
        "",
        f"`{doc['command']}`",
        "",
        f"{len(doc['summary']['runs'])} runs ({len(doc['seeds'])} seeds x {len(doc['summary']['points'])} grid "
        f"point(s)) on {doc['backend']}, {doc['wall_time_s']:.1f} s wall; load average "
        f"{doc['load_average_start'][0]:.2f} at the start, {doc['load_average_end'][0]:.2f} at the end.",
        "",
        f"Per grid point: mean over its seeds of the final periodic evaluation, with the {doc['summary']['interval']}.",
        "",
        "| grid point | runs ok | final success | final mean return |",
        "|---|---|---|---|",
    ]
    for p in doc["summary"]["points"]:
        label = point_label(p["point"], short=False) or "(defaults)"
        lines.append(
            f"| {label} | {p['ok']}/{p['runs']} | {_mean_ci(p['final_success_rate'], '{:.2f}')} | "
            f"{_mean_ci(p['final_mean_return'], '{:.1f}')} |"
        )
    lines += [
        "",
        "| run | seed | status | timesteps | final success | final mean return | wall [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in doc["summary"]["runs"]:
        lines.append(
            f"| {r['run']} | {r['seed']} | {r['status']} | {_cell(r['timesteps'], '{}')} | "
            f"{_cell(r['final_success_rate'], '{:.2f}')} | {_cell(r['final_mean_return'], '{:.1f}')} | "
            f"{_cell(r['wall_time_s'], '{:.1f}')} |"
        )
    failed = [r for r in doc["summary"]["runs"] if r["status"] != "ok"]
    if failed:
        lines += ["", "Failed runs:", ""]
        lines += [f"- {r['run']} (seed {r['seed']}{_point_note(r['point'])}): {r['error']}" for r in failed]
    return "\n".join(lines) + "\n"


def _point_note(point: Mapping[str, Any]) -> str:
    return f", grid point {point_label(point, short=False)}" if point else ""


def write_summary(out: Path, doc: Mapping[str, Any]) -> None:
    """Write ``sweep.json``, ``summary.md`` and ``summary.csv`` (one row per run) into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / SWEEP_JSON).write_text(json.dumps(doc, indent=1, default=str))
    (out / SUMMARY_MD).write_text(format_markdown(doc))
    keys = ["run", "seed", *doc["grid"], "status", "timesteps", "final_success_rate", "final_mean_return",
            "best_success_rate", "wall_time_s", "cpu_time_s", "error"]  # fmt: skip
    with (out / SUMMARY_CSV).open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        for r in doc["summary"]["runs"]:
            grid_cells = {k: _format(v) for k, v in r["point"].items()}
            writer.writerow({**{k: v for k, v in r.items() if k != "point"}, **grid_cells})


def run_sweep(
    request: SweepRequest,
    workers: int | None = None,
    ray: str | None = None,
    progress: bool = True,
    command: str | None = None,
) -> dict[str, Any]:
    """Plan the sweep, run every run as one task, and write the summary; return the summary document.

    Args:
        request: The sweep.
        workers: Worker processes (None: one per core; 1: the runs one after the other in this process). With
            ``ray``, the CPUs of a ``"local"`` Ray instance (None: all).
        ray: None (local workers), ``"local"``, ``"auto"`` or a Ray cluster address.
        progress: Print a line as each run ends.
        command: The sweep's command line, for the summary (default: this process's ``agri`` command).

    Returns:
        The document written to ``sweep.json`` (``summary.runs`` in plan order, failures included).

    Raises:
        ValueError: For a bad request, grid or ``workers`` (before anything runs), or a missing ``ray`` extra.
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    runs = plan_sweep(request)
    command = command or " ".join(shlex.quote(a) for a in ["agri", *sys.argv[1:]])
    results: list[dict[str, Any] | None] = [None] * len(runs)
    t0 = time.perf_counter()
    load_start = os.getloadavg()

    def on_done(i: int, run: SweepRun, result: dict[str, Any]) -> None:
        results[i] = result
        if progress:
            n_done = sum(r is not None for r in results)
            if result["ok"]:
                final = result["curve"][-1]
                what = f"success {final['success_rate']:.0%}, return {final['mean_return']:.1f}"
            else:
                what = f"FAILED: {result['error']}"
            print(f"[{n_done}/{len(runs)}] {run.name} ({run.describe()}): {what}", file=sys.stderr, flush=True)

    n = min(workers if workers is not None else default_workers(), len(runs))
    if ray is not None:
        backend = f"Ray ({ray}), one CPU per run"
    elif n == 1:
        backend = "1 process (runs one after the other)"
    else:
        backend = f"{n} worker processes, one run each at a time"
    # One run in flight per worker: if a worker dies (a crash, not an exception), only those runs are lost.
    run_items(run_training, runs, lambda i, result: on_done(i, runs[i], result), workers, ray, PRELOAD, _lost)
    done = [r if r is not None else {"ok": False, "error": "not run", "traceback": ""} for r in results]
    doc = {
        "command": command,
        "env_id": request.env_id,
        "algo": request.algo,
        "scenario": request.scenario,
        "timesteps": request.timesteps,
        "seeds": list(request.seeds),
        "grid": {k: list(v) for k, v in request.grid.items()},
        "overrides": dict(request.overrides),
        "backend": backend,
        "wall_time_s": round(time.perf_counter() - t0, 2),
        "load_average_start": [round(x, 2) for x in load_start],
        "load_average_end": [round(x, 2) for x in os.getloadavg()],
        "summary": summarize(runs, done),
        "tracebacks": {run.name: r["traceback"] for run, r in zip(runs, done, strict=True) if not r["ok"]},
    }
    write_summary(Path(request.out), doc)
    return doc
