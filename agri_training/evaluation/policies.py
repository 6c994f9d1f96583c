"""What to evaluate: the request, its policy resolved once, and the env arguments the episodes run with.

A policy is named as :mod:`.reference` says (a registered name, an ``agri train`` run folder, an ONNX or SB3
``.zip`` file, ``module:attribute``, or a live object in Python). :class:`EvalRequest` resolves it when it is
made, into one :class:`~.reference.PolicyRef` that every layer below uses; nothing looks it up again.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import gymnasium as gym

from agri_baselines import list_policies
from agri_envs import env_version
from agri_envs.scenarios import scenario as get_scenario
from agri_training.evaluation.reference import PolicyRef, build_policy, merge_env_kwargs, resolve_policy


@dataclasses.dataclass(frozen=True)
class EvalRequest:
    """What to evaluate.

    Attributes:
        env_id: Registered env id.
        policy: The policy: a :class:`~.reference.PolicyRef`, or anything :func:`~.reference.resolve_policy`
            takes (a name, a path, ``module:attribute``, an object), resolved when the request is made.
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
        env_kwargs_from: Where ``env_kwargs`` come from, for messages (``--env-kwargs``, ``suite NAME``).
    """

    env_id: str
    policy: PolicyRef | str | Any
    episodes: int = 20
    seed: int = 0
    scenario: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    record_traces: int = 1
    label: str | None = None
    campaign_runs: int = 1
    env_kwargs_from: str = "the request's env_kwargs"

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.campaign_runs < 1 or self.episodes % self.campaign_runs:
            raise ValueError(
                f"campaign_runs must be >= 1 and divide episodes ({self.episodes}), got {self.campaign_runs}"
            )
        if not isinstance(self.policy, PolicyRef):  # resolved here, once, for every layer below
            object.__setattr__(self, "policy", resolve_policy(self.policy))

    @property
    def ref(self) -> PolicyRef:
        """The resolved policy."""
        assert isinstance(self.policy, PolicyRef)
        return self.policy


def resolve_env_kwargs(request: EvalRequest, base: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], bool]:
    """Env arguments = scenario preset + user arguments + what the policy needs; and whether it is privileged.

    Args:
        request: The evaluation.
        base: Preset arguments (one level of the scenario); defaults to the scenario's own.

    Raises:
        ValueError: For an unknown env id (listing the known ones), when the policy drives another env, or
            needs an argument that contradicts the scenario's or the request's (both values named; see
            :func:`~.reference.merge_env_kwargs`).
    """
    env_version(request.env_id)  # a misspelled env id is named as such before anything else
    asked: list[tuple[str, Mapping[str, Any]]] = []
    if base is not None:
        asked.append((f"scenario {request.scenario}" if request.scenario else "the level", base))
    elif request.scenario:
        asked.append((f"scenario {request.scenario}", get_scenario(request.env_id, request.scenario).env_kwargs))
    asked.append((request.env_kwargs_from, request.env_kwargs))
    return merge_env_kwargs(request.env_id, request.ref, asked), request.ref.privileged


def load_policy(name_or_path: str | PolicyRef | Any, env: gym.Env[Any, Any]) -> Any:
    """A policy in any format, built on ``env``: SB3's ``predict`` on the env's raw observations.

    Args:
        name_or_path: A registered name, an ``agri train`` run folder, a ``.onnx`` or SB3 ``.zip`` file,
            ``module:attribute``, a :class:`~.reference.PolicyRef`, or a live policy object.
        env: The env it will drive (made with the arguments it needs).

    Raises:
        ValueError: For an unknown name, a refused file (unsupported operator, pickled content, wrong widths),
            a module that does not import; :class:`agri_training.learned.UnsafeCheckpointError` for pickles.
    """
    return build_policy(resolve_policy(name_or_path), env)


def all_baselines() -> list[str]:
    """Names of every registered baseline."""
    return [p.name for p in list_policies()]
