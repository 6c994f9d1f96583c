"""Evaluation of PettingZoo (multi-agent) envs: the robot chain.

:func:`make_env` builds a registered multi-agent env by its id (the chain is not a Gymnasium id), and
:func:`run_chain_episode` plays one episode with a multi-agent policy whose ``predict`` takes and returns
per-agent dicts, producing the same record as :func:`agri_training.evaluate.run_episode` does for one
agent. The team's metrics come from the leader's final ``info`` (they are shared by every agent).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np

#: Multi-agent env ids and the module that provides ``parallel_env``.
MULTIAGENT_ENVS = {"robot_chain_v0": "agri_envs.chain.robot_chain_v0"}


def is_multiagent(env_id: str) -> bool:
    """Whether ``env_id`` names a PettingZoo env of this package."""
    return env_id in MULTIAGENT_ENVS


def make_env(env_id: str, kwargs: Mapping[str, Any]) -> Any:
    """The native parallel env of a multi-agent id.

    Raises:
        ValueError: For an id that is not a multi-agent env.
    """
    import importlib

    if env_id not in MULTIAGENT_ENVS:
        raise ValueError(f"{env_id!r} is not a multi-agent env; known: {', '.join(MULTIAGENT_ENVS)}")
    return importlib.import_module(MULTIAGENT_ENVS[env_id]).parallel_env(**dict(kwargs))


def is_parallel_env(env: Any) -> bool:
    """Whether ``env`` is a PettingZoo parallel env (per-agent dicts) rather than a Gymnasium one."""
    return hasattr(env, "possible_agents") and hasattr(env, "state")


def run_chain_episode(env: Any, policy: Any, seed: int, trace_keys: tuple[str, ...] | None) -> dict[str, Any]:
    """One episode of a parallel env from ``reset(seed=seed)``.

    Args:
        env: A PettingZoo parallel env (e.g. ``robot_chain_v0.parallel_env()``).
        policy: ``predict(observations: dict, state, episode_start, deterministic) -> (actions: dict, state)``.
        seed: Reset seed.
        trace_keys: When given, record per step every robot's position (``positions``) and the shared info
            keys among these; plus the A* path (``astar_path``) once.

    Returns:
        ``{"record": metrics, "trace": per-step data or None}`` like the single-agent ``run_episode``.
    """
    from agri_training.evaluate import _jsonable

    obs, infos = env.reset(seed=seed)
    first = env.possible_agents[0]
    state = None
    start = True
    total = 0.0
    steps = 0
    trace: dict[str, list[Any]] = {}
    if trace_keys:
        trace = {k: [] for k in trace_keys}

    def record_step(infos: Mapping[str, Mapping[str, Any]]) -> None:
        if not trace:
            return
        lead = infos[first]
        for k in trace:
            if k == "positions":
                trace[k].append([[round(i["x"], 4), round(i["y"], 4)] for i in infos.values()])
            else:
                trace[k].append(lead.get(k))

    record_step(infos)
    info = infos[first]
    truncated = False
    t0 = time.perf_counter()
    while env.agents:
        actions, state = policy.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        start = False
        obs, rewards, terms, truncs, infos = env.step(actions)
        total += float(rewards[first])
        steps += 1
        record_step(infos)
        info = infos[first]
        truncated = bool(truncs[first]) and not bool(terms[first])
    wall = time.perf_counter() - t0
    record: dict[str, Any] = {
        "seed": seed,
        "return": total,
        "steps": steps,
        "truncated": truncated,
        "is_success": bool(info.get("is_success", False)),
        "wall_time_s": wall,
    }
    for key in env.unwrapped.metadata.get("episode_metric_keys", ()):
        record[key] = info.get(key)
    record["collision"] = bool(info.get("collisions", 0))
    if trace:
        raw = env.unwrapped
        if hasattr(raw, "path"):
            trace["astar_path"] = np.round(raw.path.points, 4).tolist()
        if getattr(raw, "world", None) is not None:  # obstacles dropped during the episode
            movers = raw.world.mover_circles
            trace["obstacles"] = movers[np.abs(movers[:, 0]) < 1e5].tolist()
    return {"record": _jsonable(record), "trace": _jsonable(trace) if trace else None}
