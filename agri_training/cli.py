"""The ``agri`` command line: train and evaluate policies, build the baseline report, list what is registered."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import yaml


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
        out[key.strip()] = yaml.safe_load(value)
    return out


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from agri_training.evaluate import EvalRequest, evaluate, format_summary

    request = EvalRequest(
        env_id=args.env,
        policy=args.policy,
        episodes=args.episodes,
        seed=args.seed,
        scenario=args.scenario,
        env_kwargs=parse_env_kwargs(args.env_kwargs or []),
        record_traces=args.traces,
    )
    result = evaluate(request, progress=not args.quiet)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    print(format_summary(result))
    print(f"wrote {out}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from agri_training.train import TrainRequest, train

    request = TrainRequest(
        env_id=args.env,
        algo=args.algo,
        out=Path(args.out),
        seed=args.seed,
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


def _cmd_report(args: argparse.Namespace) -> int:
    from agri_training.report import build_report, default_suite

    suite = default_suite(episodes=args.episodes, only_env=args.env)
    path = build_report(suite, Path(args.out), progress=not args.quiet)
    print(f"wrote {path} and {path.with_suffix('.html')}")
    return 0


def _cmd_list(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import agri_envs  # noqa: F401
    from agri_baselines import list_policies
    from agri_envs.scenarios import list_scenarios

    print("envs:")
    for env_id in sorted(k for k in gym.registry if k.startswith("agri_envs/")):
        print(f"  {env_id}")
    print("scenarios:")
    for sc in list_scenarios():
        print(f"  {sc.env_id} {sc.name}: {sc.description}")
    print("policies:")
    for p in list_policies():
        flag = " (privileged)" if p.privileged else ""
        flag += f" (learned, {p.algo})" if p.learned else ""
        print(f"  {p.name} [{p.env_id}]{flag}: {p.description}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``agri``."""
    parser = argparse.ArgumentParser(prog="agri", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    ev = sub.add_parser("evaluate", help="run a policy over seeds S, S+1, ... and write a JSON result")
    ev.add_argument("--env", required=True, help="env id, e.g. agri_envs/GreenhouseNav-v1")
    ev.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    ev.add_argument("--policy", required=True, help="baseline name (agri list) or SB3 checkpoint .zip")
    ev.add_argument("--episodes", type=int, default=20)
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument("--env-kwargs", nargs="*", metavar="KEY=VALUE", help="extra env arguments")
    ev.add_argument("--traces", type=int, default=1, help="episodes that record per-step traces")
    ev.add_argument("--out", required=True, help="output JSON file")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    ev.set_defaults(func=_cmd_evaluate)
    tr = sub.add_parser("train", help="train an SB3 policy; writes a weights-only run directory")
    tr.add_argument("--env", required=True, help="env id, e.g. agri_envs/GreenhouseNav-v1")
    tr.add_argument("--scenario", default=None, help="named preset of env arguments (agri list)")
    tr.add_argument("--algo", required=True, choices=("ppo", "sac", "td3", "tqc"))
    tr.add_argument("--her", action="store_true", help="HerReplayBuffer (goal-conditioned Dict envs; sac/td3/tqc)")
    tr.add_argument("--timesteps", type=int, default=None, help="training steps (default: the YAML's n_timesteps)")
    tr.add_argument("--seed", type=int, default=0, help="training seed, below 100000")
    tr.add_argument("--out", required=True, help="run directory to create")
    tr.add_argument("--hyperparams", default=None, help="YAML to use instead of agri_training/hyperparams/ALGO.yml")
    tr.add_argument("--hp", nargs="*", metavar="KEY=VALUE", help="override hyperparameters (YAML values)")
    tr.add_argument("--quiet", action="store_true", help="no progress bar")
    tr.set_defaults(func=_cmd_train)
    rp = sub.add_parser("report", help="evaluate every registered baseline and write a Markdown + HTML report")
    rp.add_argument("--out", default="reports/baselines", help="output folder")
    rp.add_argument("--episodes", type=int, default=None, help="override the episodes of every suite entry")
    rp.add_argument("--env", default=None, help="only this env id")
    rp.add_argument("--quiet", action="store_true")
    rp.set_defaults(func=_cmd_report)
    ls = sub.add_parser("list", help="registered envs, scenarios and baselines")
    ls.set_defaults(func=_cmd_list)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``agri`` command."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except ValueError as exc:  # users' mistakes: a clear message, no traceback
        print(f"agri: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
