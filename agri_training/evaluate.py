"""Evaluate any policy (a registered baseline or an SB3 checkpoint) on an env over a range of seeds.

Episode ``i`` is reset with seed ``seed + i``. The env's final ``info`` supplies the keys listed in its
``metadata["episode_metric_keys"]``; a policy may add its own through ``episode_metrics(index)``. The
first ``record_traces`` episodes also record the ``metadata["trace_keys"]`` of every step, for plots.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import agri_envs
from agri_baselines import list_policies, make_policy, policy_spec
from agri_envs.scenarios import scenario as get_scenario
from agri_training.stats import bootstrap_ci


@dataclasses.dataclass(frozen=True)
class EvalRequest:
    """What to evaluate.

    Attributes:
        env_id: Registered env id.
        policy: Baseline name (see ``agri_baselines``) or path to an SB3 ``.zip`` checkpoint.
        episodes: Number of episodes (seeds ``seed`` .. ``seed + episodes - 1``).
        seed: First seed.
        scenario: Name of an env-argument preset (``agri_envs.scenarios``), or None.
        env_kwargs: Extra env arguments (override the scenario's; must not contradict the policy's needs).
        record_traces: How many episodes record per-step traces.
    """

    env_id: str
    policy: str
    episodes: int = 20
    seed: int = 0
    scenario: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    record_traces: int = 1


def resolve_env_kwargs(request: EvalRequest, base: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], bool]:
    """Env arguments = scenario preset + user arguments + what the policy needs; and whether it is privileged.

    Args:
        request: The evaluation.
        base: Preset arguments (one level of the scenario); defaults to the scenario's own.

    Raises:
        ValueError: When a user argument contradicts what the policy needs, or the policy drives another env.
    """
    kwargs: dict[str, Any] = {}
    if base is not None:
        kwargs.update(base)
    elif request.scenario:
        kwargs.update(get_scenario(request.env_id, request.scenario).env_kwargs)
    kwargs.update(request.env_kwargs)
    privileged = False
    from agri_training.learned import is_run_path, read_config, refuse_pickled

    refuse_pickled(request.policy)
    if is_run_path(request.policy):  # a training run: its env id and env arguments, like a baseline's needs
        config = read_config(Path(request.policy))
        if config["env_id"] != request.env_id:
            raise ValueError(f"run {request.policy} was trained on {config['env_id']}, not {request.env_id}")
        for key, value in config["env_kwargs"].items():
            if key in request.env_kwargs and request.env_kwargs[key] != value:
                raise ValueError(
                    f"run {request.policy} was trained with {key}={value!r}, got {request.env_kwargs[key]!r}"
                )
            kwargs[key] = value
        privileged = bool(config.get("privileged", False))
    else:
        spec = policy_spec(request.policy)
        if spec.env_id != request.env_id:
            raise ValueError(f"policy {spec.name!r} drives {spec.env_id}, not {request.env_id}")
        for key, value in spec.env_kwargs.items():
            if key in request.env_kwargs and request.env_kwargs[key] != value:
                raise ValueError(f"policy {spec.name!r} needs {key}={value!r}, got {request.env_kwargs[key]!r}")
            kwargs[key] = value
        privileged = spec.privileged
    return kwargs, privileged


def load_policy(name_or_path: str, env: gym.Env[Any, Any]) -> Any:
    """A registered policy by name (baseline or trained), or an ``agri train`` run directory, weights-only.

    Raises:
        ValueError: For an unknown name; :class:`agri_training.learned.UnsafeCheckpointError` for checkpoints
            that need unpickling (SB3 ``.zip`` files).
    """
    from agri_training.learned import LearnedPolicy, is_run_path, refuse_pickled

    refuse_pickled(name_or_path)
    if is_run_path(name_or_path):
        return LearnedPolicy(name_or_path, env)
    return make_policy(name_or_path, env)


def git_commit() -> str:
    """Current git commit of the working tree, or ``"unknown"``."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, cwd=Path(__file__).resolve().parent
        )
        return out.stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _jsonable(v: Any) -> Any:
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    return v


def run_episode(env: gym.Env[Any, Any], policy: Any, seed: int, trace_keys: tuple[str, ...] | None) -> dict[str, Any]:
    """One episode from ``reset(seed=seed)``: return, steps, final info and optionally the trace."""
    obs, info = env.reset(seed=seed)
    start = True
    state = None
    total = 0.0
    steps = 0
    trace: dict[str, list[Any]] = {k: [info.get(k)] for k in trace_keys} if trace_keys else {}
    localizes = hasattr(policy, "pose_estimate") and "x" in info
    truth: list[tuple[float, float, float]] = []
    estimate: list[np.ndarray] = []
    t0 = time.perf_counter()
    while True:
        action, state = policy.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        start = False
        if localizes:  # the estimate for this observation, paired with the true pose it was taken at
            truth.append((info["x"], info["y"], info["yaw"]))
            estimate.append(np.asarray(policy.pose_estimate(0), dtype=np.float64))
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        steps += 1
        for k in trace:
            trace[k].append(info.get(k))
        if terminated or truncated:
            break
    wall = time.perf_counter() - t0
    record: dict[str, Any] = {
        "seed": seed,
        "return": total,
        "steps": steps,
        "truncated": bool(truncated),
        "is_success": bool(info.get("is_success", False)),
        "wall_time_s": wall,
    }
    for key in env.unwrapped.metadata.get("episode_metric_keys", ()):
        record[key] = info.get(key)
    if hasattr(policy, "episode_metrics"):
        record.update(policy.episode_metrics(0))
    if localizes and truth:
        world_est = start_frame_to_world(np.array(truth[0]), np.array(estimate))
        record.update(localization_errors(np.array(truth), world_est))
        if trace:
            trace.update(
                slam_x=world_est[:, 0].tolist(), slam_y=world_est[:, 1].tolist(), slam_yaw=world_est[:, 2].tolist()
            )
    return {"record": _jsonable(record), "trace": _jsonable(trace) if trace else None}


def start_frame_to_world(start: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses ``(n, 3)`` given in the frame of the robot's start pose, expressed in the world frame."""
    c, s = np.cos(start[2]), np.sin(start[2])
    out = np.empty_like(poses)
    out[:, 0] = start[0] + c * poses[:, 0] - s * poses[:, 1]
    out[:, 1] = start[1] + s * poses[:, 0] + c * poses[:, 1]
    out[:, 2] = np.arctan2(np.sin(poses[:, 2] + start[2]), np.cos(poses[:, 2] + start[2]))
    return out


def localization_errors(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """Absolute trajectory error and final-pose error of a pose estimate against the ground truth.

    Both trajectories share the start pose (the estimate's map frame is anchored there, as on the robot),
    so no alignment is fitted: the ATE is what the controller actually drove on.

    Returns:
        ``ate_rmse`` (m), ``ate_max`` (m), ``final_position_error`` (m), ``final_heading_error`` (rad).
    """
    err = np.hypot(estimate[:, 0] - truth[:, 0], estimate[:, 1] - truth[:, 1])
    dyaw = np.arctan2(np.sin(estimate[-1, 2] - truth[-1, 2]), np.cos(estimate[-1, 2] - truth[-1, 2]))
    return {
        "ate_rmse": float(np.sqrt(np.mean(err**2))),
        "ate_max": float(err.max()),
        "final_position_error": float(err[-1]),
        "final_heading_error": float(abs(dyaw)),
    }


def summarize(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """Success and collision rates, means of every numeric metric, with 95 % bootstrap intervals."""
    summary: dict[str, Any] = {"episodes": len(episodes)}
    if not episodes:
        return summary
    success = np.array([e["is_success"] for e in episodes], dtype=float)
    summary["success_rate"] = float(success.mean())
    summary["success_rate_ci"] = bootstrap_ci(success)
    if "collision" in episodes[0]:
        col = np.array([bool(e["collision"]) for e in episodes], dtype=float)
        summary["collision_rate"] = float(col.mean())
        summary["collision_rate_ci"] = bootstrap_ci(col)
    skip = {"seed", "is_success", "collision", "truncated"}
    for key, value in episodes[0].items():
        if key in skip or isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        vals = np.array([e[key] if e.get(key) is not None else np.nan for e in episodes], dtype=float)
        summary[f"mean_{key}"] = float(np.nanmean(vals)) if np.any(np.isfinite(vals)) else None
        summary[f"mean_{key}_ci"] = bootstrap_ci(vals)
    if "episode_time" in episodes[0]:
        ok = [e["episode_time"] for e in episodes if e["is_success"]]
        summary["mean_time"] = summary["mean_episode_time"]
        summary["mean_time_successful"] = float(np.mean(ok)) if ok else None
    if "ate_rmse" in episodes[0]:
        summary["ate_rmse"] = summary["mean_ate_rmse"]
    if "min_clearance" in episodes[0]:
        clearances = [e["min_clearance"] for e in episodes if e.get("min_clearance") is not None]
        summary["min_clearance"] = float(np.min(clearances)) if clearances else None
    return summary


def evaluate(request: EvalRequest, progress: bool = True) -> dict[str, Any]:
    """Run the request and return the result document.

    For a scenario that sweeps an argument the document holds one result per value under ``levels`` (and
    the ``summary`` of all levels pooled); otherwise it is a single result.
    """
    sc = get_scenario(request.env_id, request.scenario) if request.scenario else None
    if sc is None or sc.sweep is None:
        return evaluate_level(request, None, progress)
    levels = [evaluate_level(request, kwargs, progress, label) for label, kwargs in sc.levels()]
    pooled = [e for level in levels for e in level["episodes"]]
    doc = {k: v for k, v in levels[0].items() if k not in ("episodes", "traces", "summary", "env_kwargs", "label")}
    doc.update(
        sweep={"parameter": sc.sweep[0], "values": list(sc.sweep[1])},
        levels=levels,
        summary=_jsonable(summarize(pooled)),
    )
    return doc


def evaluate_level(
    request: EvalRequest, base: Mapping[str, Any] | None, progress: bool = True, label: str | None = None
) -> dict[str, Any]:
    """Evaluate one set of env arguments (one level of a scenario)."""
    kwargs, privileged = resolve_env_kwargs(request, base)
    env = gym.make(request.env_id, **kwargs)
    try:
        policy = load_policy(request.policy, env)
        trace_keys = tuple(env.unwrapped.metadata.get("trace_keys", ()))
        episodes: list[dict[str, Any]] = []
        traces: list[dict[str, Any]] = []
        bar = _progress(request.episodes, f"{request.policy} on {request.env_id}", progress)
        if progress:
            _print_row(bar, None)
        for i in range(request.episodes):
            seed = request.seed + i
            out = run_episode(env, policy, seed, trace_keys if i < request.record_traces else None)
            episodes.append(out["record"])
            if out["trace"] is not None:
                traces.append({"seed": seed, "data": out["trace"]})
            if progress:
                _print_row(bar, out["record"])
            if bar is not None:
                rate = np.mean([e["is_success"] for e in episodes])
                bar.set_postfix(success=f"{rate:.0%}")
                bar.update(1)
        if bar is not None:
            bar.close()
    finally:
        env.close()
    return {
        "env_id": request.env_id,
        "scenario": request.scenario,
        "label": label or request.scenario,
        "policy": request.policy,
        "privileged": privileged,
        "seed": request.seed,
        "env_kwargs": _jsonable(kwargs),
        "package_version": agri_envs.__version__,
        "git_commit": git_commit(),
        "command": " ".join(sys.argv),
        "summary": _jsonable(summarize(episodes)),
        "episodes": episodes,
        "traces": traces,
    }


def _progress(total: int, desc: str, enabled: bool) -> Any:
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=total, desc=desc, unit="ep", leave=False, file=sys.stderr)


_COLUMNS = (
    ("seed", "{:>5}"),
    ("is_success", "{!s:>7}"),
    ("collision", "{!s:>9}"),
    ("steps", "{:>6}"),
    ("episode_time", "{:>8.1f}"),
    ("path_length", "{:>8.2f}"),
    ("min_clearance", "{:>9.3f}"),
)


def _print_row(bar: Any, record: dict[str, Any] | None) -> None:
    if record is None:
        line = f"{'seed':>5} {'success':>7} {'collision':>9} {'steps':>6} {'time[s]':>8} {'path[m]':>8} {'clear[m]':>9}"
    else:
        cells = []
        for name, fmt in _COLUMNS:
            v = record.get(name)
            width = len(fmt.format(0)) if "f" in fmt or ":>" in fmt else 8
            cells.append(fmt.format(v) if v is not None else f"{'-':>{width}}")
        line = " ".join(cells)
    (bar.write if bar is not None else print)(line)


def format_summary(result: dict[str, Any]) -> str:
    """Human-readable summary lines of a result document."""
    s = result["summary"]
    lines = [
        f"{result['policy']} on {result['env_id']}"
        + (f" [{result['scenario']}]" if result["scenario"] else "")
        + (" (privileged)" if result["privileged"] else "")
    ]
    for key in ("success_rate", "collision_rate"):
        if key in s:
            lo, hi = s[f"{key}_ci"]
            lines.append(f"  {key:<22} {s[key]:.2f}  [{lo:.2f}, {hi:.2f}]")
    for key, value in s.items():
        if key.startswith("mean_") and not key.endswith("_ci") and isinstance(value, float):
            lines.append(f"  {key:<22} {value:.3f}")
    if s.get("min_clearance") is not None:
        lines.append(f"  {'min_clearance':<22} {s['min_clearance']:.3f}")
    return "\n".join(lines)


def all_baselines() -> list[str]:
    """Names of every registered baseline."""
    return [p.name for p in list_policies()]
