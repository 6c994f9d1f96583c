"""Kwargs presets of GrapeHarvest-v1 (pure data: importing this pulls in no physics engine)."""

from __future__ import annotations

from typing import Any

#: The single-goal preset (``agri_envs/GrapeHarvestReach-v1``, scenario ``reach``): reach and cut one
#: cluster in a scene where the cut can be reached, with end-effector actions, no return home, and the
#: learner's tolerances. 3 cm is within the clamp's jaw opening (``TOOL_HALF_Y`` = 3.5 cm: the peduncle
#: still lands between the fingers) and 0.35 rad (20 deg) keeps the pallet under the berries; the
#: evaluation presets keep the env's default 1 cm / 0.2 rad.
REACH_PRESET: dict[str, Any] = {
    "min_clusters": 1,
    "max_clusters": 1,
    "n_leaves": 2,
    "n_canes": 1,
    "feasible_scenes": True,
    "return_home": False,
    "control": "ee",
    "position_tolerance": 0.03,
    "orientation_tolerance": 0.35,
}
