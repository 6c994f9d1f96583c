"""What to evaluate: the request, the policy by name or path, and the env arguments the episodes run with.

A policy is a registered name (a scripted baseline of :mod:`agri_baselines`, or a trained policy of the
zoo, :mod:`agri_training.learned.zoo`) or an ``agri train`` run directory, loaded weights-only.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym

from agri_baselines import list_policies, make_policy, policy_spec
from agri_envs import env_version
from agri_envs.scenarios import scenario as get_scenario
from agri_training.learned import zoo  # noqa: F401  (registers the trained policies by name)
from agri_training.learned.policy import LearnedPolicy, is_run_path, read_config, refuse_pickled


@dataclasses.dataclass(frozen=True)
class EvalRequest:
    """What to evaluate.

    Attributes:
        env_id: Registered env id.
        policy: Registered policy name (a baseline or a zoo policy) or an ``agri train`` run directory.
        episodes: Number of episodes (seeds ``seed`` .. ``seed + episodes - 1``).
        seed: First seed.
        scenario: Name of an env-argument preset (``agri_envs.scenarios``), or None.
        env_kwargs: Extra env arguments (override the scenario's; must not contradict the policy's needs).
        record_traces: How many episodes record per-step traces (campaigns: how many campaigns).
        label: Name of the evaluation in progress displays and in the result (default: the scenario's).
        campaign_runs: Runs per campaign: the episodes are driven in campaigns of this many consecutive seeds,
            each by one policy that keeps its state between runs, in one world held fixed by the env's
            ``layout_seed`` (the campaign's first seed, unless the arguments fix it). 1: every episode is a
            fresh policy's first.
    """

    env_id: str
    policy: str
    episodes: int = 20
    seed: int = 0
    scenario: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    record_traces: int = 1
    label: str | None = None
    campaign_runs: int = 1

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.campaign_runs < 1 or self.episodes % self.campaign_runs:
            raise ValueError(
                f"campaign_runs must be >= 1 and divide episodes ({self.episodes}), got {self.campaign_runs}"
            )


def resolve_env_kwargs(request: EvalRequest, base: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], bool]:
    """Env arguments = scenario preset + user arguments + what the policy needs; and whether it is privileged.

    Args:
        request: The evaluation.
        base: Preset arguments (one level of the scenario); defaults to the scenario's own.

    Raises:
        ValueError: For an unknown env id (listing the known ones), when a user argument contradicts what the
            policy needs, or the policy drives another env.
    """
    env_version(request.env_id)  # a misspelled env id is named as such before anything else
    kwargs: dict[str, Any] = {}
    if base is not None:
        kwargs.update(base)
    elif request.scenario:
        kwargs.update(get_scenario(request.env_id, request.scenario).env_kwargs)
    kwargs.update(request.env_kwargs)
    privileged = False
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
    refuse_pickled(name_or_path)
    if is_run_path(name_or_path):
        return LearnedPolicy(name_or_path, env)
    return make_policy(name_or_path, env)


def all_baselines() -> list[str]:
    """Names of every registered baseline."""
    return [p.name for p in list_policies()]

