"""agri_envs: Gymnasium / PettingZoo environments for agricultural robots.

Importing the package registers every env with string entry points, so no physics engine is imported
until an env is made::

    import gymnasium as gym
    import agri_envs  # noqa: F401

    env = gym.make("agri_envs/GreenhouseNav-v1", n_rows=4, growth=0.5)
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

__all__ = ["__version__", "register_envs"]


def register_envs() -> None:
    """Register all agri_envs ids with Gymnasium (idempotent)."""
    if "agri_envs/GreenhouseNav-v1" not in registry:
        register(
            id="agri_envs/GreenhouseNav-v1",
            entry_point="agri_envs.rover.greenhouse_nav:GreenhouseNavEnv",
            max_episode_steps=2250,
        )
    if "agri_envs/GrapeHarvest-v1" not in registry:
        register(
            id="agri_envs/GrapeHarvest-v1",
            entry_point="agri_envs.arm.grape_harvest:GrapeHarvestEnv",
            max_episode_steps=1000,
        )
    if "agri_envs/GreenhouseCoverage-v0" not in registry:  # the env truncates itself at its mission-sized limit
        register(
            id="agri_envs/GreenhouseCoverage-v0",
            entry_point="agri_envs.coverage.greenhouse_coverage:GreenhouseCoverageEnv",
        )


register_envs()
