"""agri_envs: Gymnasium / PettingZoo environments for agricultural robots.

Importing the package registers every env with string entry points, so no physics engine is imported
until an env is made::

    import gymnasium as gym
    import agri_envs  # noqa: F401

    env = gym.make("agri_envs/GreenhouseNav-v2", n_rows=4, growth=0.5)
"""

from __future__ import annotations

from gymnasium.envs.registration import WrapperSpec, register, registry

from agri_envs.arm.presets import REACH_PRESET  # pure data: no pybullet

__version__ = "0.1.0"

__all__ = ["__version__", "register_envs"]


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
    if "agri_envs/GreenhouseCoverage-v0" not in registry:  # the env truncates itself at its mission-sized limit
        register(
            id="agri_envs/GreenhouseCoverage-v0",
            entry_point="agri_envs.coverage.greenhouse_coverage:GreenhouseCoverageEnv",
        )


register_envs()
