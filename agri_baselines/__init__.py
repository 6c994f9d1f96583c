"""Scripted baseline policies from the papers, evaluable exactly like trained SB3 models.

Every baseline implements SB3's ``predict(observation, state=None, episode_start=None,
deterministic=False) -> (actions, state)`` on batched observations, so
``stable_baselines3.common.evaluation.evaluate_policy`` accepts it unchanged. Policies are registered
here by name with the env they drive, the env arguments they need (for example the full-resolution
scan) and whether they use privileged information (ground-truth pose, the true scene).

    >>> from agri_baselines import make_policy
    >>> policy = make_policy("harik-apf-gt", env)  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:  # the pure algorithms in this package (SLAM, kinematics) must not pull in Gymnasium
    import gymnasium as gym


class Policy(Protocol):
    """What the evaluator needs of a policy: SB3's ``predict`` signature."""

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Any]:
        """Return batched actions (and an opaque recurrent state, unused here)."""
        ...


@dataclasses.dataclass(frozen=True)
class PolicySpec:
    """A registered baseline.

    Attributes:
        name: Registry name used by ``agri evaluate --policy NAME``.
        env_id: The env the policy drives.
        entry_point: ``"module:callable"``; the callable takes the (unwrapped-able) env and returns a policy.
        env_kwargs: Env arguments the policy requires (merged into the user's, conflicts are errors).
        privileged: True when the policy uses information a real robot would not have.
        description: One line for tables and reports.
        learned: True for a trained policy (its weights ship in ``agri_training/zoo/NAME``).
        algo: The training algorithm of a learned policy (``ppo``, ``sac``, ``td3``, ``tqc``).
        train_command: The ``agri train`` command that reproduces a learned policy.
    """

    name: str
    env_id: str
    entry_point: str
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    privileged: bool = False
    description: str = ""
    learned: bool = False
    algo: str = ""
    train_command: str = ""


_REGISTRY: dict[str, PolicySpec] = {}


def register_policy(spec: PolicySpec) -> None:
    """Add a baseline to the registry (names are unique)."""
    if spec.name in _REGISTRY and _REGISTRY[spec.name] != spec:
        raise ValueError(f"policy {spec.name!r} is already registered")
    _REGISTRY[spec.name] = spec


def policy_spec(name: str) -> PolicySpec:
    """Look up a registered baseline by name.

    Raises:
        ValueError: If the name is unknown (the message lists the registered ones).
    """
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown policy {name!r}; registered: {', '.join(sorted(_REGISTRY))}") from None


def list_policies(env_id: str | None = None) -> list[PolicySpec]:
    """Registered baselines, optionally only those for one env id."""
    return [s for s in _REGISTRY.values() if env_id is None or s.env_id == env_id]


def make_policy(name: str, env: gym.Env[Any, Any]) -> Any:
    """Build a registered baseline for an env made with (at least) the spec's ``env_kwargs``."""
    spec = policy_spec(name)
    module_name, attr = spec.entry_point.split(":")
    factory = getattr(importlib.import_module(module_name), attr)
    return factory(env, spec.name) if spec.learned else factory(env)


register_policy(
    PolicySpec(
        name="harik-apf-gt",
        env_id="agri_envs/GreenhouseNav-v1",
        entry_point="agri_baselines.harik_apf:make_harik_apf_gt",
        env_kwargs={"localization": "ground_truth", "full_scan": True},
        privileged=True,
        description="Harik 2018 APF controller (eqs. 12-14, passive safety stop) on the ground-truth pose",
    )
)
register_policy(
    PolicySpec(
        name="harik-apf",
        env_id="agri_envs/GreenhouseNav-v1",
        entry_point="agri_baselines.harik_apf:make_harik_apf_slam",
        env_kwargs={"localization": "none", "full_scan": True},
        privileged=False,
        description="Harik 2018 APF controller on a Hector SLAM pose from the LIDAR alone (no odometry)",
    )
)
register_policy(
    PolicySpec(
        name="harik-apf-hector-plain",
        env_id="agri_envs/GreenhouseNav-v1",
        entry_point="agri_baselines.harik_apf:make_harik_apf_hector_plain",
        env_kwargs={"localization": "none", "full_scan": True},
        privileged=False,
        description="harik-apf on plain Hector SLAM, as ROS hector_mapping (no guard against people, no step check)",
    )
)
register_policy(
    PolicySpec(
        name="luo-apf",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_baselines.luo_apf:make_luo_apf",
        env_kwargs={"control": "joint"},
        description="Luo 2018: energy-optimal harvesting order (eq. 11) and APF sampling path points (Alg. 1)",
    )
)
