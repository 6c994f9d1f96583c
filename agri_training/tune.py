r"""``agri tune``: a hyperparameter search with Ray Tune, each trial one ``agri train`` run on one CPU.

For example::

    agri tune --env agri_envs/GreenhouseNav-v2 --algo ppo --timesteps 100000 --samples 16 \
        --param algo_kwargs.learning_rate=loguniform:1e-5:1e-3 algo_kwargs.n_epochs=choice:5,10,20 \
        --out runs/nav-tune --ray local            # or --space space.yaml, --ray auto, --ray HOST:PORT

The space is declared on the command line (``--param KEY=KIND:ARGS``) or in YAML (``--space FILE``)::

    algo_kwargs.learning_rate: {loguniform: [1.0e-5, 1.0e-3]}
    algo_kwargs.gamma: {uniform: [0.95, 0.999]}
    algo_kwargs.n_epochs: {randint: [3, 20]}          # integers in [3, 20)
    policy_kwargs.activation_fn: [ReLU, Tanh]         # a list is a choice

``KEY`` is a dotted hyperparameter path as in ``agri train --grid``; ``KIND`` is ``uniform``, ``loguniform``,
``randint`` or ``choice`` (Ray Tune's ``tune.uniform`` ... ``tune.choice``). The search algorithm is Optuna's
TPE through ``ray.tune.search.optuna.OptunaSearch`` (``--search optuna``, the default; the ``ray`` extra
installs optuna) or Ray Tune's random search (``--search random``, ``BasicVariantGenerator``). Every trial
trains with the same training seed (``--seed``), so trials differ by their hyperparameters only.

Each trial is a Ray Tune trial of one CPU (``tune.with_resources(..., {"cpu": 1})``) that calls
:func:`agri_training.train.train` with ``torch_threads: 1`` and reports every periodic evaluation (the rows of
``curve.csv``: ``success_rate``, ``mean_return``, ``timesteps``, ...) with ``tune.report``; the search ranks
trials by the last report of ``--metric`` (the final evaluation). Each trial writes a normal run directory,
``OUT/trials/<trial id>/``; the search writes ``OUT/trials.csv`` (one row per trial), ``OUT/best.yaml`` (the
best hyperparameters, their scores, the run folder and the ``agri train`` command that reproduces it) and
Ray Tune's own records under ``OUT/tune/``. On a cluster, ``OUT`` must be a folder every node sees.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from agri_training.core.pool import RAY_EXTRA_HINT, import_ray, init_ray
from agri_training.sweep import check_key, merge, nested, parse_value, split_top_level, train_command
from agri_training.train import TrainRequest, resolve_config, train

DISTRIBUTIONS = ("uniform", "loguniform", "randint", "choice")
SEARCHERS = ("optuna", "random")
METRICS = ("success_rate", "mean_return")
BEST_FILE, TRIALS_CSV, TRIALS_DIR = "best.yaml", "trials.csv", "trials"


@dataclasses.dataclass(frozen=True)
class Param:
    """One dimension of the search space.

    Attributes:
        kind: ``uniform`` / ``loguniform`` (floats in [low, high]), ``randint`` (ints in [low, high)) or
            ``choice`` (one of the values).
        args: ``(low, high)``, or the choices.
    """

    kind: str
    args: tuple[Any, ...]

    def __post_init__(self) -> None:
        if self.kind not in DISTRIBUTIONS:
            raise ValueError(f"a search dimension's kind must be one of {', '.join(DISTRIBUTIONS)}, got {self.kind!r}")
        if self.kind == "choice":
            if not self.args:
                raise ValueError("choice needs one value at least")
            return
        if len(self.args) != 2 or not all(_is_number(a) for a in self.args):
            raise ValueError(f"{self.kind} needs two numbers low and high, got {list(self.args)}")
        low, high = self.args
        if not low < high:
            raise ValueError(f"{self.kind} needs low < high, got low={low}, high={high}")
        if self.kind == "loguniform" and low <= 0:
            raise ValueError(f"loguniform needs low > 0, got {low}")
        if self.kind == "randint" and not all(isinstance(a, int) for a in self.args):
            raise ValueError(f"randint needs integer bounds, got {list(self.args)}")

    def to_tune(self) -> Any:
        """The Ray Tune search-space object (``tune.loguniform(low, high)``, ...)."""
        from ray import tune

        if self.kind == "choice":
            return tune.choice(list(self.args))
        factory = {"uniform": tune.uniform, "loguniform": tune.loguniform, "randint": tune.randint}[self.kind]
        return factory(*self.args)

    def example(self) -> Any:
        """A value inside the dimension (its lower bound or first choice), to check the config resolves."""
        return self.args[0]


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def parse_param(item: str) -> tuple[str, Param]:
    """``KEY=KIND:LOW:HIGH`` or ``KEY=choice:V1,V2,...`` (values as YAML) to ``(key, Param)``.

    Raises:
        ValueError: For a malformed item, an unknown key or kind, or bad bounds.
    """
    if "=" not in item or ":" not in item.split("=", 1)[1]:
        raise ValueError(
            f"--param expects KEY=KIND:LOW:HIGH or KEY=choice:V1,V2 (e.g. algo_kwargs.learning_rate="
            f"loguniform:1e-5:1e-3), got {item!r}"
        )
    key, spec = (s.strip() for s in item.split("=", 1))
    check_key(key, "--param")
    kind, rest = spec.split(":", 1)
    kind = kind.strip()
    if kind == "choice":
        values = tuple(parse_value(v.strip()) for v in split_top_level(rest))
    else:
        values = tuple(parse_value(v.strip()) for v in rest.split(":"))
    try:
        return key, Param(kind, values)
    except ValueError as exc:
        raise ValueError(f"--param {key}: {exc}") from None


def load_space(path: Path) -> dict[str, Param]:
    """A search space from YAML: ``KEY: {KIND: [LOW, HIGH]}`` or ``KEY: {choice: [...]}`` or ``KEY: [choices]``.

    Raises:
        ValueError: For a file that is not such a mapping, or a bad dimension (naming its key).
    """
    data = yaml.safe_load(Path(path).read_text())
    if not isinstance(data, Mapping) or not data:
        raise ValueError(f"{path}: a search space is a mapping KEY: {{KIND: [ARGS]}}, got {type(data).__name__}")
    space = {}
    for key, spec in data.items():
        check_key(str(key), f"{path}")
        if isinstance(spec, list):
            spec = {"choice": spec}
        if not isinstance(spec, Mapping) or len(spec) != 1:
            raise ValueError(f"{path}: {key} needs one KIND: [ARGS] entry (kinds: {', '.join(DISTRIBUTIONS)})")
        ((kind, args),) = spec.items()
        args = [parse_value(a) if isinstance(a, str) else a for a in (args if isinstance(args, list) else [args])]
        try:
            space[str(key)] = Param(str(kind), tuple(args))
        except ValueError as exc:
            raise ValueError(f"{path}: {key}: {exc}") from None
    return space


@dataclasses.dataclass(frozen=True)
class TuneRequest:
    """A hyperparameter search.

    Attributes:
        env_id: Registered env id.
        algo: ``ppo``, ``sac``, ``td3`` or ``tqc``.
        out: Search folder.
        space: ``{dotted hyperparameter: Param}``, one entry at least.
        samples: Trials, >= 1.
        search: ``optuna`` (TPE) or ``random``.
        metric: What the search maximises, from the last periodic evaluation: ``success_rate`` or ``mean_return``.
        seed: Training seed of every trial.
        search_seed: Seed of the search algorithm's sampler.
        timesteps: Training steps per trial (None: the YAML's).
        scenario: Env-argument preset, or None.
        her: ``HerReplayBuffer``.
        overrides: Hyperparameters every trial shares (as ``agri train --hp``).
        hyperparams_file: YAML to read instead of ``hyperparams/<algo>.yml``.
    """

    env_id: str
    algo: str
    out: Path
    space: Mapping[str, Param]
    samples: int = 8
    search: str = "optuna"
    metric: str = "mean_return"
    seed: int = 0
    search_seed: int = 0
    timesteps: int | None = None
    scenario: str | None = None
    her: bool = False
    overrides: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    hyperparams_file: Path | None = None

    def __post_init__(self) -> None:
        if not self.space:
            raise ValueError("the search space is empty: give --param KEY=KIND:ARGS or --space FILE")
        for key in self.space:
            check_key(key, "space")
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or self.samples < 1:
            raise ValueError(f"samples must be an int >= 1, got {self.samples!r}")
        if self.search not in SEARCHERS:
            raise ValueError(f"search must be one of {', '.join(SEARCHERS)}, got {self.search!r}")
        if self.metric not in METRICS:
            raise ValueError(f"metric must be one of {', '.join(METRICS)}, got {self.metric!r}")

    def trial_request(self, point: Mapping[str, Any], out: Path) -> TrainRequest:
        """The single run of one trial: the shared overrides, the sampled point, one torch thread."""
        return TrainRequest(
            env_id=self.env_id,
            algo=self.algo,
            out=out,
            seed=self.seed,
            timesteps=self.timesteps,
            scenario=self.scenario,
            her=self.her,
            overrides=merge(merge(self.overrides, nested(point)), {"torch_threads": 1, "update_threads": 1}),
            hyperparams_file=None if self.hyperparams_file is None else Path(self.hyperparams_file).resolve(),
            progress=False,
        )


def _plain(value: Any) -> Any:
    """Numpy scalars from the samplers as Python numbers (so that ``config.yaml`` stays plain YAML)."""
    return value.item() if hasattr(value, "item") else value


def _trial(config: dict[str, Any], request: TuneRequest, trials_dir: str) -> None:
    """A Ray Tune trial: train with the sampled hyperparameters, report each periodic evaluation."""
    import torch
    from ray import tune

    torch.set_num_threads(1)
    trial_id = tune.get_context().get_trial_id()
    point = {key: _plain(config[key]) for key in request.space}
    run = request.trial_request(point, Path(trials_dir) / trial_id)

    def report(row: dict[str, Any]) -> None:
        tune.report(row)

    train(run, train_command(run), on_eval=report)


def _searcher(request: TuneRequest) -> Any:
    if request.search == "random":
        from ray.tune.search import BasicVariantGenerator

        return BasicVariantGenerator(random_state=request.search_seed)
    try:
        import optuna  # noqa: F401
        from ray.tune.search.optuna import OptunaSearch
    except ImportError:
        raise ValueError(f"--search optuna needs optuna, part of the 'ray' extra: {RAY_EXTRA_HINT}") from None
    return OptunaSearch(metric=request.metric, mode="max", seed=request.search_seed)


def run_tune(
    request: TuneRequest, ray: str = "local", workers: int | None = None, progress: bool = True
) -> dict[str, Any]:
    """Run the search on Ray Tune and write ``trials.csv`` and ``best.yaml``; return the best trial's record.

    Args:
        request: The search.
        ray: ``"local"`` (a private Ray instance, shut down at the end), ``"auto"`` or a cluster address.
        workers: CPUs of a ``"local"`` Ray instance (None: all); trials run one per CPU.
        progress: Ray Tune's progress table.

    Returns:
        The ``best.yaml`` document.

    Raises:
        ValueError: For a space or hyperparameters that do not resolve (before anything runs), a missing
            extra, an ``out`` that holds a search already, or a search in which every trial failed.
    """
    out = Path(request.out).resolve()
    if (out / BEST_FILE).exists() or (out / TRIALS_DIR).exists():
        raise ValueError(f"{out} already holds a search; pass another --out")
    example = {key: p.example() for key, p in request.space.items()}
    try:
        config = resolve_config(request.trial_request(example, out / TRIALS_DIR / "check"))
    except (ValueError, TypeError) as exc:
        raise ValueError(f"the search space's first point does not resolve: {exc}") from None
    if config["vec_env"] == "subproc":
        raise ValueError(
            "vec_env 'subproc' starts n_envs processes per trial; a trial gets one CPU: use dummy or vector"
        )
    searcher = _searcher(request)
    import_ray()
    from ray import tune

    started = init_ray(ray, workers)
    try:
        trainable = tune.with_resources(
            tune.with_parameters(_trial, request=request, trials_dir=str(out / TRIALS_DIR)), {"cpu": 1}
        )
        tuner = tune.Tuner(
            trainable,
            param_space={key: p.to_tune() for key, p in request.space.items()},
            tune_config=tune.TuneConfig(
                metric=request.metric, mode="max", search_alg=searcher, num_samples=request.samples
            ),
            run_config=tune.RunConfig(name="tune", storage_path=str(out), verbose=1 if progress else 0),
        )
        grid = tuner.fit()
    finally:
        if started:
            import ray as ray_module

            ray_module.shutdown()
    return _write_results(request, out, grid)


def _write_results(request: TuneRequest, out: Path, grid: Any) -> dict[str, Any]:
    rows = []
    for result in grid:
        metrics = result.metrics or {}
        trial_id = metrics.get("trial_id") or Path(result.path).name
        point = {key: _plain(result.config.get(key)) for key in request.space}
        rows.append(
            {
                "trial_id": trial_id,
                **point,
                "status": "failed" if result.error else "ok",
                "timesteps": metrics.get("timesteps"),
                "final_success_rate": metrics.get("success_rate"),
                "final_mean_return": metrics.get("mean_return"),
                "run_dir": str(out / TRIALS_DIR / trial_id),
                "error": f"{type(result.error).__name__}: {result.error}" if result.error else None,
            }
        )
    with (out / TRIALS_CSV).open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]) if rows else ["trial_id"])
        writer.writeheader()
        writer.writerows(rows)
    ok = [r for r in rows if r["status"] == "ok" and r[f"final_{request.metric}"] is not None]
    if not ok:
        errors = "; ".join(str(r["error"]) for r in rows[:3])
        raise ValueError(f"every trial of the search failed (first errors: {errors}); see {out / TRIALS_CSV}")
    best = grid.get_best_result(metric=request.metric, mode="max", scope="last")
    best_id = best.metrics.get("trial_id") or Path(best.path).name
    point = {key: _plain(best.config[key]) for key in request.space}
    doc = {
        "metric": request.metric,
        "value": float(best.metrics[request.metric]),
        "final_success_rate": float(best.metrics["success_rate"]),
        "final_mean_return": float(best.metrics["mean_return"]),
        "hyperparameters": point,
        "trial_id": best_id,
        "run_dir": str(out / TRIALS_DIR / best_id),
        "command": train_command(request.trial_request(point, Path("RUN_DIR"))),
        "search": request.search,
        "samples": request.samples,
        "trials_ok": len(ok),
        "trials_failed": len(rows) - len(ok),
    }
    (out / BEST_FILE).write_text(yaml.safe_dump(doc, sort_keys=False))
    return doc


def format_best(doc: Mapping[str, Any]) -> str:
    """The best trial as a few lines for the terminal."""
    params = ", ".join(f"{k}={v!r}" for k, v in doc["hyperparameters"].items())
    return (
        f"best of {doc['trials_ok']} trials ({doc['trials_failed']} failed), by final {doc['metric']}: {params}\n"
        f"  final success {doc['final_success_rate']:.2f}, final mean return {doc['final_mean_return']:.2f}\n"
        f"  run {doc['run_dir']}\n  reproduce: {doc['command']}"
    )


def parse_space(params: Sequence[str], space_file: str | None) -> dict[str, Param]:
    """The space from ``--space FILE`` and ``--param`` items (an item overrides the file's key).

    Raises:
        ValueError: For a malformed item or file.
    """
    space = load_space(Path(space_file)) if space_file else {}
    for item in params:
        key, param = parse_param(item)
        space[key] = param
    return space
