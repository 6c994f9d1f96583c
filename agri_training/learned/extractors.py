"""SB3 features extractors that a config may name in ``policy_kwargs.features_extractor_class`` (training side).

Each has a numpy twin in :mod:`agri_training.learned.inference` that acting uses (the same features, the same
bits on every CPU); this module needs torch and is imported only where a policy is built for training.
"""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from agri_training.learned.goal_features import GOAL_ERROR, GOAL_LENGTH, N_GOAL_ERROR_FEATURES, goal_error_columns


class GoalErrorExtractor(BaseFeaturesExtractor):  # type: ignore[misc]
    """The dict observation flattened as SB3's ``CombinedExtractor`` does, plus the goal-error features.

    The keys are concatenated in the space's order (``achieved_goal``, ``desired_goal``, ``observation``),
    then :func:`~agri_training.learned.goal_features.goal_error_columns` of the two goals. No parameters.

    Args:
        observation_space: A ``Dict`` with 9-number ``achieved_goal`` and ``desired_goal`` boxes.

    Raises:
        ValueError: For another space.
    """

    def __init__(self, observation_space: spaces.Dict) -> None:
        keys = list(getattr(observation_space, "spaces", {}))
        if not {"achieved_goal", "desired_goal"} <= set(keys) or any(
            get_flattened_obs_dim(observation_space.spaces[k]) != GOAL_LENGTH for k in ("achieved_goal", "desired_goal")
        ):
            raise ValueError(
                f"{GOAL_ERROR} needs a Dict observation with {GOAL_LENGTH}-number achieved_goal and desired_goal, "
                f"got {observation_space}"
            )
        flat = sum(get_flattened_obs_dim(s) for s in observation_space.spaces.values())
        super().__init__(observation_space, features_dim=flat + N_GOAL_ERROR_FEATURES)
        self.keys = keys

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        """Flattened keys, then the goal-error features."""
        a, d = observations["achieved_goal"], observations["desired_goal"]
        columns = goal_error_columns(
            [a[:, i] for i in range(GOAL_LENGTH)],
            [d[:, i] for i in range(GOAL_LENGTH)],
            lambda x: torch.clamp(x, -1.0, 1.0),
        )
        parts = [observations[k].flatten(1) for k in self.keys] + [torch.stack(columns, dim=1)]
        return torch.cat(parts, dim=1)


#: Features extractors a config may name (nothing is imported from a string).
EXTRACTORS: dict[str, Any] = {GOAL_ERROR: GoalErrorExtractor}
