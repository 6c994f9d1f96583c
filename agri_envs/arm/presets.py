"""Kwargs presets of GrapeHarvest-v1 (pure data: importing this pulls in no physics engine)."""

from __future__ import annotations

from typing import Any

#: The single-goal preset (``agri_envs/GrapeHarvestReach-v1``, scenario ``reach``): reach and cut one cluster in a
#: scene where the cut can be reached (its box, the trunk and the cordon; no leaves or canes), with end-effector
#: actions of 4 cm and 0.2 rad (the straight move takes about 8 steps, so a goal lies within the horizon of a
#: discount of 0.95), no return home, and the learner's tolerances. 3 cm is within the clamp's jaw opening
#: (``TOOL_HALF_Y`` = 3.5 cm: the peduncle still lands between the fingers) and 0.35 rad (20 deg) keeps the pallet
#: under the berries; the evaluation presets keep the env's default 1 cm / 0.2 rad.
REACH_PRESET: dict[str, Any] = {
    "min_clusters": 1,
    "max_clusters": 1,
    "n_leaves": 0,
    "n_canes": 0,
    "feasible_scenes": True,
    "return_home": False,
    "control": "ee",
    "max_ee_step": 0.04,
    "max_ee_rotation": 0.2,
    "position_tolerance": 0.03,
    "orientation_tolerance": 0.35,
}
