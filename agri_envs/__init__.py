"""agri_envs: Gymnasium / PettingZoo environments for agricultural robots.

Every env of the package, of either kind, is registered here: the Gymnasium ids with Gymnasium's
registry (string entry points, so no physics engine is imported until an env is made), the PettingZoo
ones in :data:`PARALLEL_ENVS`. :func:`make` builds any of them by id::

    import gymnasium as gym
    import agri_envs

    env = gym.make("agri_envs/GreenhouseNav-v2", n_rows=4, growth=0.5)   # or agri_envs.make(...)
    chain = agri_envs.make("robot_chain_v1", n_robots=8)                  # a PettingZoo ParallelEnv

Package map: ``sim2d`` (the shared 2D engine), ``scenes`` (scene generators shared by the 2D envs),
``rover`` (GreenhouseNav), ``coverage`` (GreenhouseCoverage), ``chain`` (robot_chain), ``arm``
(GrapeHarvest); ``scenarios`` holds the named presets of env arguments.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec, WrapperSpec, register, registry

from agri_envs.arm.presets import REACH_PRESET  # pure data: no pybullet
from agri_envs.errors import SetupError

__version__ = "0.1.0"

__all__ = [
    "PARALLEL_ENVS",
    "SetupError",
    "__version__",
    "env_ids",
    "env_version",
    "is_parallel_env",
    "is_parallel_id",
    "make",
    "register_envs",
    "training_distribution",
]

# ---------------------------------------------------------------- PettingZoo envs

#: PettingZoo env ids -> the versioned module that provides ``parallel_env``, ``env`` and ``raw_env``.
PARALLEL_ENVS: dict[str, str] = {
    "robot_chain_v1": "agri_envs.chain.robot_chain_v1",
}

# ---------------------------------------------------------------- Gymnasium envs


class _SpecWithVectorForm(EnvSpec):
    """A spec whose single env needs a wrapper (``gym.make``) and that has a native vector env (``gym.make_vec``).

    Gymnasium's ``make_vec`` refuses a ``vector_entry_point`` beside ``additional_wrappers``, which it could not
    apply to a vector env. GreenhouseNav's one additional wrapper, ``SyncTimeLimit``, tells a single env about
    ``gym.make(..., max_episode_steps=N)``; its vector env takes ``max_episode_steps`` itself and needs no wrapper.
    ``make_vec`` works on a deep copy of the spec, and the copy leaves the wrappers out. (So
    ``gym.make_vec(..., vectorization_mode="sync")`` with an explicit ``max_episode_steps`` would build sub-envs
    that truncate through ``TimeLimit`` alone, their crash penalty and ``info`` sized to the mission: build such
    sub-envs with ``gym.make``, or use the native vector env.)
    """

    def __deepcopy__(self, memo: dict[int, Any]) -> EnvSpec:
        fields = {f.name: copy.deepcopy(getattr(self, f.name), memo) for f in dataclasses.fields(EnvSpec) if f.init}
        fields["additional_wrappers"] = ()
        return EnvSpec(**fields)

    def __eq__(self, other: object) -> bool:
        """Equal to any ``EnvSpec`` with the same fields: the subclass only changes how ``make_vec`` copies it.

        So a spec that went through ``EnvSpec.to_json`` / ``from_json`` (a plain ``EnvSpec``) equals it, either
        way round, as Gymnasium's own specs do.
        """
        if not isinstance(other, EnvSpec):
            return NotImplemented
        return all(getattr(self, f.name) == getattr(other, f.name) for f in dataclasses.fields(EnvSpec) if f.compare)

    __hash__ = None  # type: ignore[assignment]  # as EnvSpec's (a mutable dataclass)


def register_envs() -> None:
    """Register all agri_envs ids with Gymnasium (idempotent)."""
    if "agri_envs/GreenhouseNav-v2" not in registry:
        register(
            id="agri_envs/GreenhouseNav-v2",
            entry_point="agri_envs.rover.greenhouse_nav:GreenhouseNavEnv",
            # No fixed limit: the env sizes it to the mission; gym.make(..., max_episode_steps=N) still wins.
            max_episode_steps=None,
            additional_wrappers=(
                WrapperSpec("SyncTimeLimit", "agri_envs.rover.greenhouse_nav:SyncTimeLimit", kwargs={}),
            ),
            vector_entry_point="agri_envs.rover.vector:GreenhouseNavVectorEnv",
        )
        spec = registry["agri_envs/GreenhouseNav-v2"]
        registry[spec.id] = _SpecWithVectorForm(
            **{f.name: getattr(spec, f.name) for f in dataclasses.fields(EnvSpec) if f.init}
        )
    # GrapeHarvest truncates itself at a time limit that follows the scene (its info["time_limit"]).
    if "agri_envs/GrapeHarvest-v1" not in registry:
        register(id="agri_envs/GrapeHarvest-v1", entry_point="agri_envs.arm.grape_harvest:GrapeHarvestEnv")
    if "agri_envs/GrapeHarvestReach-v1" not in registry:
        register(
            id="agri_envs/GrapeHarvestReach-v1",
            entry_point="agri_envs.arm.grape_harvest:GrapeHarvestEnv",
            kwargs=dict(REACH_PRESET),
        )
    if "agri_envs/GreenhouseCoverage-v2" not in registry:  # the env truncates itself at its mission-sized limit
        register(
            id="agri_envs/GreenhouseCoverage-v2",
            entry_point="agri_envs.coverage.greenhouse_coverage:GreenhouseCoverageEnv",
            vector_entry_point="agri_envs.coverage.vector:GreenhouseCoverageVectorEnv",
        )


register_envs()


# ---------------------------------------------------------------- one door for both kinds


def env_ids() -> list[str]:
    """Every env id of the package: the Gymnasium ``agri_envs/...`` ids, then the PettingZoo ones."""
    return sorted(i for i in registry if i.startswith("agri_envs/")) + sorted(PARALLEL_ENVS)


def is_parallel_id(env_id: str) -> bool:
    """Whether ``env_id`` names a PettingZoo (parallel, multi-agent) env of the package."""
    return env_id in PARALLEL_ENVS


def is_parallel_env(env: Any) -> bool:
    """Whether ``env`` is a PettingZoo parallel env (per-agent dicts) rather than a Gymnasium one."""
    return hasattr(env, "possible_agents") and hasattr(env, "state")


def env_version(env_id: str) -> str:
    """The version tag of an env id: ``v2`` for ``agri_envs/GreenhouseNav-v2``, ``v1`` for ``robot_chain_v1``.

    Raises:
        ValueError: For an id that is not the package's.
    """
    if env_id in PARALLEL_ENVS:
        return env_id.rsplit("_", 1)[-1]
    if env_id in registry and env_id.startswith("agri_envs/"):
        return env_id.rsplit("-", 1)[-1]
    raise ValueError(f"unknown env id {env_id!r}; known: {', '.join(env_ids())}")


# ---------------------------------------------------------------- training distributions

#: Gymnasium ids whose env declares a training distribution -> its config class (``module:Class``).
_DISTRIBUTION_CONFIGS: dict[str, str] = {
    "agri_envs/GreenhouseNav-v2": "agri_envs.rover.config:GreenhouseNavConfig",
    "agri_envs/GreenhouseCoverage-v2": "agri_envs.coverage.config:GreenhouseCoverageConfig",
}


def training_distribution(env_id: str) -> tuple[Any, dict[str, Any]] | None:
    """``(distribution, default arguments)`` of an env that declares a training distribution, else None.

    The distribution is the :class:`~agri_envs.scenes.distribution.SceneDistribution` that
    ``scene_distribution="training"`` draws each episode's scene from; the defaults fill in the arguments a
    suite leaves out when asking whether it lies outside (:meth:`~agri_envs.scenes.distribution.
    SceneDistribution.lies_outside`).
    """
    if env_id not in _DISTRIBUTION_CONFIGS:
        return None
    module, name = _DISTRIBUTION_CONFIGS[env_id].split(":")
    config = getattr(importlib.import_module(module), name)
    return config(scene_distribution="training").distribution(), config().to_dict()


def make(env_id: str, **kwargs: Any) -> Any:
    """Any env of the package by id: ``gym.make`` for a Gymnasium id, the native ``ParallelEnv`` otherwise.

    Raises:
        ValueError: For an unknown id (the message lists the known ones), or a bad env argument.
    """
    if env_id in PARALLEL_ENVS:
        return importlib.import_module(PARALLEL_ENVS[env_id]).parallel_env(**kwargs)
    if not (env_id in registry and env_id.startswith("agri_envs/")):
        raise ValueError(f"unknown env id {env_id!r}; known: {', '.join(env_ids())}")
    return gym.make(env_id, **kwargs)
