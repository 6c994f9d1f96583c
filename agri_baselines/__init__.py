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
    """A registered policy: a scripted baseline, or a trained policy that a training package registers.

    Attributes:
        name: Registry name used by ``agri evaluate --policy NAME``.
        env_id: The env the policy drives.
        entry_point: ``"module:callable"``; the callable takes the (unwrapped-able) env and returns a policy.
        env_kwargs: Env arguments the policy requires (merged into the user's, conflicts are errors).
        privileged: True when the policy uses information a real robot would not have.
        description: One line for tables and reports.
        learned: True for a trained policy (registered by the package that ships its weights; the
            entry point is then called with the env and the policy's name).
        algo: The training algorithm of a learned policy (``ppo``, ``sac``, ``td3``, ``tqc``).
        train_command: The ``agri train`` command that reproduces a learned policy.
        observation_only: Once built, the policy acts on its observations alone: it reads nothing of the
            env during an episode. The evaluator may then step several of its episodes together in the env's
            batched form (``gym.make_vec``), whose sub-envs it could not read (learned policies always may).
        teacher: A training teacher, not a baseline: a scripted controller that is no paper's, written to label
            demonstrations (``pretrain: {policy: NAME}``). ``make_policy`` builds it and ``agri evaluate`` runs
            it, but :func:`list_policies` leaves it out unless asked, so it has no leaderboard entries: the
            leaderboard compares learned policies with the papers' controllers. A policy cloned from it says so.
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
    observation_only: bool = False
    teacher: bool = False


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


def list_policies(env_id: str | None = None, teachers: bool = False) -> list[PolicySpec]:
    """Registered baselines and learned policies, optionally those of one env id only.

    Training teachers (``PolicySpec.teacher``) only with ``teachers=True``.
    """
    return [s for s in _REGISTRY.values() if (env_id is None or s.env_id == env_id) and (teachers or not s.teacher)]


def make_policy(name: str, env: gym.Env[Any, Any]) -> Any:
    """Build a registered baseline for an env made with (at least) the spec's ``env_kwargs``."""
    spec = policy_spec(name)
    module_name, attr = spec.entry_point.split(":")
    factory = getattr(importlib.import_module(module_name), attr)
    return factory(env, spec.name) if spec.learned else factory(env)


register_policy(
    PolicySpec(
        name="harik-apf-gt",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_baselines.harik_apf:make_harik_apf_gt",
        env_kwargs={"localization": "ground_truth", "full_scan": True},
        privileged=True,
        description="Harik 2018 APF controller (eqs. 12-14, passive safety stop) on the ground-truth pose",
        observation_only=True,
    )
)
register_policy(
    PolicySpec(
        name="harik-apf",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_baselines.harik_apf:make_harik_apf_slam",
        env_kwargs={"localization": "none", "full_scan": True},
        privileged=False,
        description="Harik 2018 APF controller on a Hector SLAM pose from the LIDAR alone (no odometry)",
        observation_only=True,
    )
)
register_policy(
    PolicySpec(
        name="harik-apf-hector-plain",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_baselines.harik_apf:make_harik_apf_hector_plain",
        env_kwargs={"localization": "none", "full_scan": True},
        privileged=False,
        description="harik-apf on plain Hector SLAM, as ROS hector_mapping (no guard against people, no step check)",
        observation_only=True,
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
register_policy(
    PolicySpec(
        name="luo-apf-attract-only",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_baselines.luo_apf:make_luo_apf_attract_only",
        env_kwargs={"control": "joint"},
        description="Ablation of luo-apf: attraction only (eta = 0, no repulsion of eq. 15); collisions still rejected",
    )
)


def astar(occupancy: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]] | None:
    """8-connected grid A* (Apoorva 2018, Alg. 1); see :func:`agri_envs.sim2d.astar.astar`.

    Args:
        occupancy: ``(H, W)`` boolean array, True = blocked.
        start: ``(row, col)`` start cell.
        goal: ``(row, col)`` goal cell.

    Returns:
        The cells from start to goal, or None when there is no path.
    """
    from agri_envs.sim2d.astar import astar as _astar  # numba is compiled only when A* is used

    return _astar(occupancy, start, goal)


def __getattr__(name: str) -> Any:
    """``agri_baselines.coverage_path`` (González's planner), imported on first use (it loads scikit-image)."""
    if name == "coverage_path":
        from agri_baselines.gonzalez_planner import coverage_path

        return coverage_path
    raise AttributeError(f"module 'agri_baselines' has no attribute {name!r}")


register_policy(
    PolicySpec(
        name="apoorva-chain",
        env_id="robot_chain_v1",
        entry_point="agri_baselines.apoorva_chain:make_apoorva_chain",
        description=(
            "Apoorva 2018: A* + ghost robot, sonar potential field, leader/follower chain, elastic strip laid "
            "along the leader's trail (a departure from Alg. 6's straight line, which crosses walls)"
        ),
    )
)
register_policy(
    PolicySpec(
        name="apoorva-chain-alg6",
        env_id="robot_chain_v1",
        entry_point="agri_baselines.apoorva_chain:make_apoorva_chain_alg6",
        description="Ablation of apoorva-chain: the printed Alg. 6 strip (the straight line from first to last robot)",
    )
)
register_policy(
    PolicySpec(
        name="apoorva-chain-no-strip",
        env_id="robot_chain_v1",
        entry_point="agri_baselines.apoorva_chain:make_apoorva_chain_no_strip",
        description="apoorva-chain without the elastic strip (Alg. 6 off)",
    )
)
register_policy(
    PolicySpec(
        name="gonzalez-deliberative",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_baselines.gonzalez_policies:make_gonzalez_deliberative",
        env_kwargs={"localization": "ground_truth"},
        privileged=True,
        description="González 2009: Voronoi diagram of the true map, corridor-covering search, Pure Pursuit (1 m)",
    )
)
register_policy(
    PolicySpec(
        name="gonzalez-pseudo-reactive",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_baselines.gonzalez_policies:make_gonzalez_pseudo_reactive",
        env_kwargs={"localization": "odometry"},
        description="González 2009: behaviours, 2+2 turn rule, centering, peak filter (eq. 1), sensory map (eq. 2)",
    )
)
register_policy(
    PolicySpec(
        name="gonzalez-hybrid",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_baselines.gonzalez_policies:make_gonzalez_hybrid",
        env_kwargs={"localization": "odometry"},
        description="González 2009, Fig. 2: first run pseudo-reactive, later runs deliberative on its sensory map",
    )
)
register_policy(
    PolicySpec(
        name="coverage-half-circle",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_baselines.coverage_teacher:make_half_circle_teacher",
        env_kwargs={"localization": "ground_truth"},
        privileged=True,
        description="Training teacher, no paper's: true corridor lines, half circles at the row ends, Pure Pursuit",
        teacher=True,
    )
)
