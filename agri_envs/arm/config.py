"""GrapeHarvest-v1's arguments and the layout of its observation vector."""

from __future__ import annotations

import dataclasses
import numbers
from typing import Any

import numpy as np

from agri_envs._config import StrictConfig, param
from agri_envs.arm.scene import SceneParams

ARM_FEATURES = 15  # joints normalised (6), clamp position (3), approach axis (3), pallet axis (3)
BOX_FEATURES = 7  # present, lo (3), hi (3)
GOAL_FEATURES = 9  # cut point (3), approach axis (3), pallet axis (3)
OTHER_FEATURES = BOX_FEATURES + GOAL_FEATURES  # a cluster besides the designated one: its box and its cut
#: Stems besides the canes: the cordon and the trunk.
FIXED_STEMS = 2


@dataclasses.dataclass(frozen=True)
class GrapeHarvestConfig(StrictConfig):
    """Arguments of ``agri_envs/GrapeHarvest-v1`` (each one a ``gym.make`` keyword)."""

    min_clusters: int = param(2, "fewest grape clusters in an episode (the count is drawn uniformly)", low=1, high=5)
    max_clusters: int = param(5, "most grape clusters in an episode", low=1, high=5)
    n_leaves: int = param(4, "leaves placed around the clusters (fewer when no free place is found)", low=0, high=8)
    n_canes: int = param(2, "vertical canes in the row plane, besides trunk and cordon", low=0, high=4)
    cluster_tilt: float = param(0.17, "largest lean of a cluster's hanging axis", unit="rad", low=0.0, high=0.5)
    feasible_scenes: bool = param(
        False, "draw only scenes whose every cut is reachable along a free approach (False: at random, as Luo)"
    )
    return_home: bool = param(True, "after the last cut the clamp must return home (False: the last cut ends it)")
    position_tolerance: float = param(
        0.01,
        "a cutting point (or home) is reached within this distance of the clamp centre",
        unit="m",
        low=0.001,
        high=0.1,
    )
    orientation_tolerance: float = param(
        0.2,
        "largest angle between the clamp's and the goal's approach and pallet axes",
        unit="rad",
        low=0.01,
        high=3.15,
    )
    control: str = param("joint", "action type: joint-position deltas or end-effector deltas", choices=("joint", "ee"))
    max_joint_step: float = param(
        0.05, "joint change per step at action 1 (control='joint')", unit="rad", low=0.001, high=0.5
    )
    max_ee_step: float = param(
        0.02, "clamp translation per step at action 1 (control='ee')", unit="m", low=0.001, high=0.1
    )
    max_ee_rotation: float = param(
        0.1, "clamp rotation per step at action 1 (control='ee')", unit="rad", low=0.001, high=0.5
    )
    time_slack: float = param(
        4.0, "time limit: this many times the steps of the straight tour between the goals", low=1.0, high=100.0
    )
    reward_type: str = param("sparse", "sparse (0 / -1) or dense (minus the goal error)", choices=("sparse", "dense"))
    orientation_weight: float = param(
        0.1, "dense reward: metres of penalty per radian of axis error", low=0.0, high=10.0
    )
    terminate_on_collision: bool = param(True, "end the episode when any link touches a box")
    show_boxes: bool = param(True, "draw the clusters' anti-collision boxes in rendered frames")
    render_width: int = param(480, "width of rendered frames", unit="px", low=64, high=4000)
    render_height: int = param(360, "height of rendered frames", unit="px", low=64, high=4000)

    @classmethod
    def _check_field(cls, f: dataclasses.Field[Any], value: Any) -> None:
        """The base checks, after making sure a numeric argument got a number (not a string or None)."""
        default = f.default
        if isinstance(default, float) and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise ValueError(
                f"{cls.__name__}: {f.name}={value!r} must be a number (float in "
                f"[{f.metadata['low']}, {f.metadata['high']}]), got {type(value).__name__}."
            )
        super()._check_field(f, value)

    def validate(self) -> None:
        """Check the cluster counts fit together."""
        if self.min_clusters > self.max_clusters:
            raise ValueError(
                f"GrapeHarvestConfig: min_clusters={self.min_clusters} exceeds max_clusters={self.max_clusters}; "
                "expected min_clusters <= max_clusters."
            )

    def scene_params(self) -> SceneParams:
        """The scene part of the config."""
        return SceneParams(
            self.min_clusters, self.max_clusters, self.n_leaves, self.n_canes, self.cluster_tilt, self.feasible_scenes
        )

    @property
    def n_obstacle_slots(self) -> int:
        """Obstacle slots of the observation: cordon, trunk, the canes and the leaves."""
        return FIXED_STEMS + self.n_canes + self.n_leaves

    @property
    def obs_dim(self) -> int:
        """Length of the ``observation`` vector."""
        others = (self.max_clusters - 1) * OTHER_FEATURES
        return ARM_FEATURES + BOX_FEATURES + others + self.n_obstacle_slots * BOX_FEATURES


def observation_bounds(cfg: GrapeHarvestConfig) -> tuple[np.ndarray, np.ndarray]:
    """Observation bounds: joints in [-1, 1], positions in [-2, 2] m, axes in [-1, 1], flags in [0, 1]."""
    box = ([0.0] + [-2.0] * 6, [1.0] + [2.0] * 6)
    goal = ([-2.0] * 3 + [-1.0] * 6, [2.0] * 3 + [1.0] * 6)
    low = [-1.0] * 6 + goal[0] + box[0] + (box[0] + goal[0]) * (cfg.max_clusters - 1) + box[0] * cfg.n_obstacle_slots
    high = [1.0] * 6 + goal[1] + box[1] + (box[1] + goal[1]) * (cfg.max_clusters - 1) + box[1] * cfg.n_obstacle_slots
    return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)


def observation_layout(cfg: GrapeHarvestConfig) -> dict[str, slice]:
    """Where each part of the ``observation`` vector sits (for policies that read it)."""
    k0 = ARM_FEATURES
    k1 = k0 + BOX_FEATURES
    k2 = k1 + (cfg.max_clusters - 1) * OTHER_FEATURES
    return {"arm": slice(0, k0), "target_box": slice(k0, k1), "others": slice(k1, k2), "obstacles": slice(k2, None)}
