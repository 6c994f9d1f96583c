"""The ``agri`` command line: train and evaluate policies, build the baseline report, list what is registered."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

import agri_envs
from agri_baselines import list_policies
from agri_envs.scenarios import list_scenarios
from agri_training import leaderboard as lb
from agri_training.core.yaml_values import load_yaml
from agri_training.datasets import DatasetRequest, default_dataset_id, default_env, make_dataset
from agri_training.evaluation.batched import BATCH_SIZE
from agri_training.evaluation.evaluate import EvalRequest, evaluate, format_summary
from agri_training.evaluation.parallel import EpisodeError
from agri_training.evaluation.reference import resolve_policy
from agri_training.evaluation.validation import VALIDATION_SEED, candidates, validate
from agri_training.evaluation.video import ClipRequest, record
from agri_training.learned.zoo import zoo_training
from agri_training.report.page import build_report
from agri_training.sweep import SUMMARY_MD, SweepRequest, parse_grid, run_sweep
from agri_training.train import TrainRequest, train
from agri_training.tune import TuneRequest, format_best, parse_space, run_tune


def parse_env_kwargs(items: list[str]) -> dict[str, Any]:
    """``key=value`` strings to a dict, values parsed as YAML scalars (``3``, ``0.5``, ``true``, ``odometry``).

    Raises:
        ValueError: For an item without ``=``.
    """
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--env-kwargs expects key=value, got {item!r}")
        key, value = item.split("=", 1)
        out[key.strip()] = load_yaml(value)
    return out


def _cmd_evaluate(args: argparse.Namespace) -> int:
    request = EvalRequest(
        env_id=args.env,
        policy=args.policy,
        episodes=args.episodes,
        seed=args.seed,
        scenario=args.scenario,
        env_kwargs=parse_env_kwargs(args.env_kwargs or []),
        record_traces=args.traces,
        campaign_runs=args.campaign_runs,
        env_kwargs_from="--env-kwargs",
    )
    result = evaluate(request, progress=not args.quiet, workers=args.workers, ray=args.ray, batch=args.batch)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    print(format_summary(result))
    print(f"wrote {out}")
    return 0


def _cmd_dataset(args: argparse.Namespace) -> int:
    env_id = args.env or default_env(args.policy)
    request = DatasetRequest(
        env_id=env_id,
        policy=args.policy,
        dataset_id=args.dataset_id or default_dataset_id(env_id, args.policy),
        episodes=args.episodes,
        seed=args.seed,
        scenario=args.scenario,
        env_kwargs=parse_env_kwargs(args.env_kwargs or []),
        training_distribution=args.training_distribution,
        overwrite=args.overwrite,
    )
    done = make_dataset(request, workers=args.workers, ray=args.ray, progress=not args.quiet)
    print(
        f"wrote {done['dataset_id']} ({done['path']}): {done['episodes']} episodes, {done['trajectories']} Minari "
        f"episodes, {done['steps']} steps, {done['successes']} successes, {done['size_mb']:.1f} MB in "
        f"{done['seconds']:.0f} s; load it with minari.load_dataset({done['dataset_id']!r})"
    )
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    paths = [c for run in args.runs for c in (candidates(Path(run)) if args.checkpoints else [Path(run)])]
    given = parse_env_kwargs(args.env_kwargs or [])
    doc = validate(paths, args.episodes, args.seed, args.workers, not args.quiet, ray=args.ray, env_kwargs=given)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1))
    best = set(doc["best_per_run"].values())
    for row in doc["candidates"]:
        s = row["summary"]
        mark = " <- chosen" if row["path"] == doc["chosen"] else (" <- best of its run" if row["path"] in best else "")
        print(
            f"{row['path']}: success {s['success_rate']:.2f}, collisions {s.get('collision_rate', 0.0):.2f}, "
            f"mean return {s['mean_return']:.1f}{mark}"
        )
    print(f"wrote {out}")
    return 0


def _clip_request(args: argparse.Namespace, out: str | None) -> ClipRequest:
    return ClipRequest(
        env_id=args.env,
        policy=args.policy,
        seed=args.seed,
        out=Path(out) if out else None,
        scenario=args.scenario,
        env_kwargs=parse_env_kwargs(args.env_kwargs or []),
        episodes=args.episodes,
        max_steps=args.max_steps,
        every=args.every,
        fps=args.fps,
        scale=args.scale,
    )


def _cmd_record(args: argparse.Namespace) -> int:
    clip = record(_clip_request(args, args.out), progress_s=5.0)
    outcomes = ", ".join(
        f"seed {r['seed']}: {'success' if r['is_success'] else 'no success'} after {r['steps']} steps"
        for r in clip["records"]
    )
    w, h = clip["size"] if clip["size"] else (0, 0)
    print(f"wrote {clip['out']}: {clip['frames']} frames of {w}x{h} at {clip['fps']:g} fps ({outcomes})")
    return 0


def _cmd_watch(args: argparse.Namespace) -> int:
    clip = record(_clip_request(args, args.out))
    for r in clip["records"]:
        print(f"seed {r['seed']}: {'success' if r['is_success'] else 'no success'} after {r['steps']} steps")
    if clip["out"]:
        print(f"wrote {clip['out']}: {clip['frames']} frames")
    return 0


def _add_clip_arguments(parser: argparse.ArgumentParser, out_required: bool) -> None:
    parser.add_argument("--env", required=True, help="env id, e.g. agri_envs/GreenhouseNav-v2 or robot_chain_v1")
    parser.add_argument(
        "--policy",
        required=True,
        help="registered policy name (agri list), an `agri train` run, a .onnx or SB3 .zip file, or module:attribute",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    parser.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    parser.add_argument("--env-kwargs", nargs="*", action="extend", metavar="KEY=VALUE", help="extra env arguments")
    parser.add_argument("--episodes", type=int, default=1, help="episodes, one after another (default 1)")
    parser.add_argument("--max-steps", type=int, default=None, help="stop each episode after N steps (a short clip)")
    parser.add_argument("--every", type=int, default=1, help="keep every k-th frame (default 1: all)")
    parser.add_argument("--fps", type=float, default=None, help="clip frame rate (default: the env's, / --every)")
    parser.add_argument("--scale", type=float, default=1.0, help="shrink frames by this factor in (0, 1]")
    parser.add_argument(
        "--out",
        required=out_required,
        default=None,
        help="clip file: .gif (Pillow) or .mp4 (the 'video' extra)"
        + ("" if out_required else "; without it a window opens"),
    )


def _cmd_train(args: argparse.Namespace) -> int:
    if args.seeds is not None or args.grid is not None:
        return _cmd_sweep(args)
    if args.workers is not None or args.ray is not None:
        raise ValueError("--workers and --ray spread the runs of a sweep: add --seeds S1 S2 ... and/or --grid")
    request = TrainRequest(
        env_id=args.env,
        algo=args.algo,
        out=Path(args.out),
        seed=args.seed if args.seed is not None else 0,
        timesteps=args.timesteps,
        scenario=args.scenario,
        her=args.her,
        overrides=parse_env_kwargs(args.hp or []),
        hyperparams_file=Path(args.hyperparams) if args.hyperparams else None,
        progress=not args.quiet,
    )
    run_dir = train(request)
    print(f"wrote {run_dir}; evaluate it with: agri evaluate --env {args.env} --policy {run_dir} --out RESULT.json")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    if args.seed is not None:
        raise ValueError("give either --seed (one run) or --seeds (a sweep), not both")
    request = SweepRequest(
        env_id=args.env,
        algo=args.algo,
        out=Path(args.out),
        seeds=tuple(args.seeds if args.seeds is not None else [0]),
        grid=parse_grid(args.grid or []),
        timesteps=args.timesteps,
        scenario=args.scenario,
        her=args.her,
        overrides=parse_env_kwargs(args.hp or []),
        hyperparams_file=Path(args.hyperparams) if args.hyperparams else None,
    )
    doc = run_sweep(request, workers=args.workers, ray=args.ray, progress=not args.quiet)
    print((Path(args.out) / SUMMARY_MD).read_text())
    failed = [r for r in doc["summary"]["runs"] if r["status"] != "ok"]
    print(f"wrote {len(doc['summary']['runs'])} run folders, {SUMMARY_MD}, summary.csv and sweep.json under {args.out}")
    if failed:
        for r in failed:
            where = "".join(f", {k}={v!r}" for k, v in r["point"].items())
            print(f"run {r['run']} (seed {r['seed']}{where}) failed: {r['error']}", file=sys.stderr)
        print(f"agri: error: {len(failed)} of {len(doc['summary']['runs'])} runs failed", file=sys.stderr)
        return 1
    return 0


def _cmd_tune(args: argparse.Namespace) -> int:
    request = TuneRequest(
        env_id=args.env,
        algo=args.algo,
        out=Path(args.out),
        space=parse_space(args.param or [], args.space),
        samples=args.samples,
        search=args.search,
        metric=args.metric,
        seed=args.seed,
        search_seed=args.search_seed,
        timesteps=args.timesteps,
        scenario=args.scenario,
        her=args.her,
        overrides=parse_env_kwargs(args.hp or []),
        hyperparams_file=Path(args.hyperparams) if args.hyperparams else None,
    )
    best = run_tune(request, ray=args.ray, workers=args.workers, progress=not args.quiet)
    print(format_best(best))
    print(f"wrote {Path(args.out) / 'best.yaml'} and {Path(args.out) / 'trials.csv'}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    path = build_report(
        Path(args.out),
        suites_dir=Path(args.suites),
        entries_dir=Path(args.entries),
        runs_dir=Path(args.runs),
        only_env=args.env,
        episodes=args.episodes,
        workers=args.workers,
        ray=args.ray,
        progress=not args.quiet,
    )
    print(f"wrote {path} and {path.with_suffix('.html')}")
    return 0


def _cmd_leaderboard(args: argparse.Namespace) -> int:
    suites_dir = Path(args.suites)
    entries_dir = Path(args.entries)
    md = Path(args.markdown)
    if args.action == "suites":
        for s in lb.load_suites(suites_dir):
            levels = len(s.levels())
            print(f"{s.name} v{s.version}  {s.env_id}  seeds {s.seed_start}+{s.episodes} x {levels} level(s)")
        return 0
    if args.action == "render":
        lb.write_markdown(md, entries_dir, suites_dir)
        print(f"wrote {md}")
        return 0
    if args.action == "submit":
        suites = lb.load_suites(suites_dir)
        pairs: list[tuple[lb.Suite, Any]]  # (suite, a resolved policy or an entry's policy record)
        if args.all:  # optionally only the suites named (every registered policy on each)
            named = set(args.suite or [])
            unknown = named - {s.name for s in suites}
            if unknown:
                raise ValueError(f"unknown suites {sorted(unknown)}; `agri leaderboard suites` lists them")
            pairs = lb.all_baseline_pairs(
                s for s in suites if (not args.env or s.env_id == args.env) and (not named or s.name in named)
            )
        else:
            if not args.suite or not args.policy:
                raise ValueError("submit needs --suite and --policy (or --all for every baseline on every suite)")
            names = args.suite
            chosen = [lb.find_suite(n, suites_dir) for n in names] if names != ["all"] else suites
            policy = resolve_policy(args.policy, args.name, lb.ROOT)  # resolved once, here
            if names == ["all"]:
                if policy.env_id is None:
                    raise ValueError(
                        f"{args.policy} does not say which env it drives: name the suites (--suite NAME ...), "
                        "or give env_id in its sidecar"
                    )
                # the suites of its env; a suite that names its policies runs only those
                chosen = [s for s in chosen if s.env_id == policy.env_id]
                chosen = [s for s in chosen if s.policies is None or policy.name in s.policies]
            pairs = [(s, policy) for s in chosen]
        command = "agri leaderboard " + " ".join(sys.argv[2:] if len(sys.argv) > 2 else [])
        entries, seconds = lb.timed(
            lb.evaluate_entries, pairs, args.workers, not args.quiet, command, args.ray, batch=args.batch
        )
        for entry in entries:
            print(f"wrote {lb.write_entry(entry, entries_dir)}")
        lb.write_markdown(md, entries_dir, suites_dir)
        print(f"wrote {md} ({len(entries)} entries evaluated in {seconds:.0f} s with {args.workers} worker(s))")
        return 0
    # verify
    entries = lb.load_entries(entries_dir)
    if args.entries_named:
        wanted = {str(Path(e).resolve()) for e in args.entries_named}
        entries = [e for e in entries if str(Path(e["_path"]).resolve()) in wanted]
        if len(entries) != len(wanted):
            raise ValueError(f"not an entry under {entries_dir}: {sorted(wanted)}")
    if args.sample is not None:
        problems, seconds = lb.timed(
            lb.verify_sample, entries, args.sample, suites_dir, args.workers, args.rtol, not args.quiet, args.ray,
            args.batch,
        )
    else:
        problems, seconds = lb.timed(
            lb.verify_entries, entries, suites_dir, args.workers, args.rtol, not args.quiet, args.ray, args.batch
        )
    if not args.no_markdown and not lb.leaderboard_is_current(md, entries_dir, suites_dir):
        problems.append(f"{md} is stale: run `agri leaderboard render` and commit it")
    if problems:
        print(f"agri leaderboard verify: {len(problems)} problem(s) in {len(entries)} entries:", file=sys.stderr)
        lb.print_problems(problems)
        return 1
    tol = "exactly" if args.rtol == 0 else f"within rtol {args.rtol:g}"
    if args.sample is not None:
        tol += f" (a sample: {args.sample} episode(s) per level re-run, every summary recomputed)"
    print(f"verified {len(entries)} entries {tol} in {seconds:.0f} s ({args.workers} worker(s)); {md.name} is current")
    return 0


def _cmd_list(args: argparse.Namespace) -> int:
    print("envs:")
    for env_id in agri_envs.env_ids():
        parallel = agri_envs.is_parallel_id(env_id)
        print(f"  {env_id}" + (f" (PettingZoo parallel env: {agri_envs.PARALLEL_ENVS[env_id]})" if parallel else ""))
    print("scenarios:")
    for sc in list_scenarios():
        print(f"  {sc.env_id} {sc.name}: {sc.description}")
    print("policies:")
    for p in list_policies():
        flag = " (privileged)" if p.privileged else ""
        flag += f" (learned: {zoo_training(p.name)})" if p.learned else ""
        print(f"  {p.name} [{p.env_id}]{flag}: {p.description}")
    print("training teachers (pretrain may clone them; no leaderboard entries):")
    for p in list_policies(teachers=True):
        if p.teacher:
            print(f"  {p.name} [{p.env_id}]{' (privileged)' if p.privileged else ''}: {p.description}")
    return 0


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expects an integer >= 1, got {text!r}")
    return n


def add_scale_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--workers N`` (default: one per core) and ``--ray ADDRESS`` to a subcommand that runs episodes."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    parser.add_argument(
        "--workers",
        type=_workers,
        default=max(1, cores),
        help=f"worker processes running episodes (default: one per core, here {cores}); 1 runs in this process",
    )
    parser.add_argument(
        "--ray",
        default=None,
        metavar="ADDRESS",
        help="run episodes as Ray tasks: 'local' (a private Ray instance for this run), 'auto' (the cluster "
        "started here with 'ray start') or a cluster address HOST:PORT; needs the 'ray' extra",
    )


def add_batch_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--batch N``: most episodes stepped together in an env's batched form (1: the reference loop only)."""
    parser.add_argument(
        "--batch",
        type=_workers,
        default=BATCH_SIZE,
        metavar="N",
        help=f"step up to N episodes together in the env's batched form where it has one and the policy acts on "
        f"its observations alone (default {BATCH_SIZE}); 1 runs every episode in the single-env loop. The "
        "records are the same",
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``agri``."""
    parser = argparse.ArgumentParser(prog="agri", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    ev = sub.add_parser("evaluate", help="run a policy over seeds S, S+1, ... and write a JSON result")
    ev.add_argument("--env", required=True, help="env id, e.g. agri_envs/GreenhouseNav-v2")
    ev.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    ev.add_argument(
        "--policy",
        required=True,
        help="registered policy name (baseline or shipped learned policy: agri list), an `agri train` run "
        "directory (or its best/ folder), an ONNX file, an SB3 model.zip (read without unpickling) or "
        "module:attribute (a factory taking the env)",
    )
    ev.add_argument("--episodes", type=int, default=20, help="episodes to run (default 20)")
    ev.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the first episode; episode i runs seed S+i (default 0; held-out suites use 100000 and up)",
    )
    ev.add_argument("--env-kwargs", nargs="*", action="extend", metavar="KEY=VALUE", help="extra env arguments")
    ev.add_argument("--traces", type=int, default=1, help="episodes (campaigns) that record per-step traces")
    ev.add_argument(
        "--campaign-runs",
        type=int,
        default=1,
        metavar="R",
        help="drive the episodes in campaigns of R consecutive seeds, each in one world (layout_seed = its first "
        "seed) by one policy that keeps what it learned between runs (e.g. gonzalez-hybrid's sensory map); "
        "R must divide --episodes (default 1: a fresh policy per episode)",
    )
    ev.add_argument("--out", required=True, help="output JSON file")
    ev.add_argument("--quiet", action="store_true", help="no progress bar or progress lines (the summary still prints)")
    add_scale_arguments(ev)
    add_batch_argument(ev)
    ev.set_defaults(func=_cmd_evaluate)
    ds = sub.add_parser(
        "dataset",
        help="run a policy over seeds S, S+1, ... and write its episodes as a Minari dataset (MINARI_DATASETS_PATH)",
    )
    ds.add_argument("--policy", required=True, help="registered policy name (agri list) or an `agri train` run")
    ds.add_argument("--env", default=None, help="env id (default: the registered policy's env)")
    ds.add_argument(
        "--dataset-id",
        default=None,
        help="Minari id (default agri/ENV/POLICY-v0, e.g. agri/GreenhouseNav-v2/harik-apf-gt-v0)",
    )
    ds.add_argument("--episodes", type=int, default=100, help="episodes to record (default 100)")
    ds.add_argument(
        "--seed", type=int, default=0, help="seed of the first episode; episode i runs seed S+i, all below 100000"
    )
    ds.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    ds.add_argument("--env-kwargs", nargs="*", action="extend", metavar="KEY=VALUE", help="extra env arguments")
    ds.add_argument(
        "--training-distribution",
        action="store_true",
        help="draw each episode's scene from the env's training distribution (scene_distribution=training)",
    )
    ds.add_argument("--overwrite", action="store_true", help="replace a dataset already under the id")
    ds.add_argument("--quiet", action="store_true", help="no progress bar or progress lines")
    add_scale_arguments(ds)
    ds.set_defaults(func=_cmd_dataset)
    va = sub.add_parser(
        "validate",
        help="choose a learned policy's weights: evaluate runs (and their checkpoints) on validation seeds of "
        "their training distribution",
    )
    va.add_argument("runs", nargs="+", help="`agri train` run directories (or their best/ or checkpoint folders)")
    va.add_argument("--checkpoints", action="store_true", help="also every run's best/ and checkpoints/step_N folders")
    va.add_argument("--episodes", type=int, default=100, help="episodes per candidate (default 100)")
    va.add_argument(
        "--seed",
        type=int,
        default=VALIDATION_SEED,
        help=f"first validation seed (default {VALIDATION_SEED}: above training's, below the held-out 100000)",
    )
    va.add_argument(
        "--env-kwargs",
        nargs="*",
        action="extend",
        metavar="KEY=VALUE",
        help="env arguments over the runs' periodic evaluation's (e.g. their training distribution: "
        "n_robots=16 scene_distribution=robust); never one a run's weights need changed",
    )
    va.add_argument("--out", required=True, help="output JSON file (e.g. agri_training/zoo/NAME/validation.json)")
    va.add_argument("--quiet", action="store_true", help="no progress bar")
    add_scale_arguments(va)
    va.set_defaults(func=_cmd_validate)
    rc = sub.add_parser("record", help="record a policy's episode headless as a GIF or MP4 clip")
    _add_clip_arguments(rc, out_required=True)
    rc.set_defaults(func=_cmd_record)
    wa = sub.add_parser("watch", help="watch a policy in a window (render_mode='human'), or --out a clip")
    _add_clip_arguments(wa, out_required=False)
    wa.set_defaults(func=_cmd_watch)
    tr = sub.add_parser("train", help="train an SB3 policy; writes a weights-only run directory")
    tr.add_argument("--env", required=True, help="env id, e.g. agri_envs/GreenhouseNav-v2")
    tr.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    tr.add_argument("--algo", required=True, choices=("ppo", "sac", "td3", "tqc"))
    tr.add_argument("--her", action="store_true", help="HerReplayBuffer (goal-conditioned Dict envs; sac/td3/tqc)")
    tr.add_argument("--timesteps", type=int, default=None, help="training steps (default: the YAML's n_timesteps)")
    tr.add_argument("--seed", type=int, default=None, help="training seed, below 100000 (default 0)")
    tr.add_argument("--out", required=True, help="run directory to create")
    tr.add_argument("--hyperparams", default=None, help="YAML to use instead of agri_training/hyperparams/ALGO.yml")
    tr.add_argument(
        "--hp", nargs="*", action="extend", metavar="KEY=VALUE", help="override hyperparameters (YAML values)"
    )
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    sw = tr.add_argument_group("sweep", "many runs, each one CPU: OUT/<run>/ per run, OUT/summary.md|csv, sweep.json")
    sw.add_argument("--seeds", type=int, nargs="+", default=None, metavar="S", help="train once per seed")
    sw.add_argument(
        "--grid",
        nargs="+",
        default=None,
        metavar="KEY=V1,V2",
        help="hyperparameter grid axes (dotted keys, YAML values), e.g. algo_kwargs.learning_rate=1e-4,3e-4",
    )
    sw.add_argument("--workers", type=_workers, default=None, help="runs at a time (default: one per core)")
    sw.add_argument("--ray", default=None, metavar="ADDRESS", help="runs as Ray tasks: 'local', 'auto' or HOST:PORT")
    tr.set_defaults(func=_cmd_train)
    tu = sub.add_parser("tune", help="hyperparameter search with Ray Tune (Optuna or random), one CPU per trial")
    tu.add_argument("--env", required=True, help="env id, e.g. agri_envs/GreenhouseNav-v2")
    tu.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    tu.add_argument("--algo", required=True, choices=("ppo", "sac", "td3", "tqc"))
    tu.add_argument("--her", action="store_true", help="HerReplayBuffer (goal-conditioned Dict envs; sac/td3/tqc)")
    tu.add_argument("--timesteps", type=int, default=None, help="training steps per trial (default: the YAML's)")
    tu.add_argument("--seed", type=int, default=0, help="training seed of every trial, below 100000")
    tu.add_argument(
        "--param",
        nargs="+",
        metavar="KEY=KIND:ARGS",
        help="a search dimension: KEY=uniform|loguniform|randint:LOW:HIGH or KEY=choice:V1,V2 "
        "(e.g. algo_kwargs.learning_rate=loguniform:1e-5:1e-3)",
    )
    tu.add_argument("--space", default=None, help="YAML search space: KEY: {loguniform: [LOW, HIGH]}, KEY: [choices]")
    tu.add_argument("--samples", type=int, default=8, help="trials (default 8)")
    tu.add_argument("--search", default="optuna", choices=("optuna", "random"), help="Optuna TPE or random search")
    tu.add_argument(
        "--metric",
        default="mean_return",
        choices=("success_rate", "mean_return"),
        help="what the search maximises: the final periodic evaluation's (default mean_return)",
    )
    tu.add_argument("--search-seed", type=int, default=0, help="seed of the search algorithm")
    tu.add_argument(
        "--hp", nargs="*", action="extend", metavar="KEY=VALUE", help="hyperparameters every trial shares (YAML values)"
    )
    tu.add_argument("--hyperparams", default=None, help="YAML to use instead of agri_training/hyperparams/ALGO.yml")
    tu.add_argument("--out", required=True, help="search folder: trials/<id>/ run folders, best.yaml, trials.csv")
    tu.add_argument("--workers", type=_workers, default=None, help="CPUs of a --ray local instance (default: all)")
    tu.add_argument(
        "--ray", default="local", metavar="ADDRESS", help="'local' (default: a private Ray instance), 'auto', HOST:PORT"
    )
    tu.add_argument("--quiet", action="store_true", help="no Ray Tune progress table")
    tu.set_defaults(func=_cmd_tune)
    rp = sub.add_parser(
        "report",
        help="one Markdown + HTML page over the leaderboard entries (fresh runs where stale) and training runs",
    )
    rp.add_argument("--out", default="reports/latest", help="output folder")
    rp.add_argument("--suites", default="leaderboard/suites", help="folder of suite YAML files")
    rp.add_argument("--entries", default="leaderboard/entries", help="folder of leaderboard entries")
    rp.add_argument("--runs", default="runs", help="folder of training runs (learning curves)")
    rp.add_argument("--episodes", type=int, default=None, help="quick look: override every suite's episodes")
    rp.add_argument("--env", default=None, help="only this env id")
    rp.add_argument("--quiet", action="store_true")
    add_scale_arguments(rp)
    rp.set_defaults(func=_cmd_report)
    board = sub.add_parser(
        "leaderboard", help="pinned suites, leaderboard entries, LEADERBOARD.md (docs/leaderboard.md)"
    )
    board.add_argument("--suites", default="leaderboard/suites", help="folder of suite YAML files")
    board.add_argument("--entries", default="leaderboard/entries", help="folder of entry JSON files")
    board.add_argument("--markdown", default="LEADERBOARD.md", help="the generated leaderboard page")
    lbsub = board.add_subparsers(dest="action", required=True)
    lbsub.add_parser("suites", help="list the pinned suites")
    lbsub.add_parser("render", help="regenerate LEADERBOARD.md from the entries")
    su = lbsub.add_parser("submit", help="evaluate a policy on suites and write its entries (and LEADERBOARD.md)")
    su.add_argument("--suite", nargs="+", help="suite names, or 'all' (every suite of the policy's env)")
    su.add_argument(
        "--policy",
        help="registered policy name, an `agri train` run folder, a .onnx or SB3 .zip file, or module:attribute",
    )
    su.add_argument("--name", default=None, help="display name of a learned, ONNX, SB3 or Python policy")
    su.add_argument(
        "--all", action="store_true", help="every registered policy on every suite of its env (or on the --suite named)"
    )
    su.add_argument("--env", default=None, help="with --all: only this env id")
    add_scale_arguments(su)
    add_batch_argument(su)
    su.add_argument("--quiet", action="store_true")
    ve = lbsub.add_parser("verify", help="re-evaluate entries on their pinned seeds; fail on any difference")
    ve.add_argument("entries_named", nargs="*", metavar="ENTRY", help="entry JSON files (default: all)")
    add_scale_arguments(ve)
    add_batch_argument(ve)
    ve.add_argument("--rtol", type=float, default=0.0, help="relative tolerance for floats (default 0: exact)")
    ve.add_argument("--no-markdown", action="store_true", help="do not check that LEADERBOARD.md is current")
    ve.add_argument(
        "--sample",
        type=int,
        default=None,
        metavar="N",
        help="re-run only N evenly spaced episodes (whole campaigns) of every level of every entry, and recompute "
        "every summary from the committed records (make test: 2; default: every episode)",
    )
    ve.add_argument("--quiet", action="store_true")
    board.set_defaults(func=_cmd_leaderboard)
    ls = sub.add_parser("list", help="registered envs, scenarios and baselines")
    ls.set_defaults(func=_cmd_list)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``agri`` command."""
    args = build_parser().parse_args(argv)
    if "" not in sys.path and os.getcwd() not in sys.path:  # module:attribute policies of the working folder,
        sys.path.insert(0, os.getcwd())  # as `python -m` finds them
    try:
        return int(args.func(args))
    except ValueError as exc:  # users' mistakes: a clear message, no traceback
        print(f"agri: error: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        if not isinstance(exc, EpisodeError):
            raise
        # A failing episode: where it failed (the worker's traceback), then which seed and why.
        print(exc.remote_traceback, file=sys.stderr)
        print(f"agri: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
