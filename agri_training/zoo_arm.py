"""The committed GrapeHarvest policy: SAC + HER on the single-goal preset, loaded weights-only."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

#: Registry name of the policy, also its folder under ``agri_training/zoo``.
GRAPE_REACH_SAC = "sac-her-grape-reach"


def make_grape_reach_sac(env: gym.Env[Any, Any]) -> Any:
    """Registry factory: the SAC + HER policy trained on ``reach`` (best of its periodic evaluations)."""
    from agri_training.learned import load_zoo_policy  # torch only when this policy is made

    return load_zoo_policy(env, GRAPE_REACH_SAC)
