"""The arm's boxes as a goal-conditioned learner can use them: the nearest ones, seen from the clamp.

GrapeHarvest-v1 lists its anti-collision boxes in fixed slots (the designated cluster, the other clusters,
then stems and leaves) in the base frame, and their number and the observation's length follow the scene
arguments. :class:`NearestBoxes` rewrites the ``observation`` key into a fixed-length vector that reads the
same in every scene, so one network drives the single-goal preset and the whole vine alike:

| part | count | meaning |
|---|---|---|
| joints | 6 | the env's joint values, mapped to [-1, 1] over their ranges |
| box k (k < ``k``) | 7 each | present flag, then box minimum and maximum minus the clamp position (m) |

Boxes are taken nearest first (by the distance from the clamp to the box); empty slots are zeros. In the
env's collisions it is the tool that meets a box (its jaws and pallet lead the arm into the canopy), so the
clamp is where the boxes are seen from. ``achieved_goal`` and ``desired_goal`` pass unchanged: HER relabels
the desired goal, so nothing here may depend on it (the goal error is the network's input, see
:mod:`agri_training.learned.goal_features`). Only element-wise arithmetic and a stable sort, so the
observation is a function of the env's alone on every CPU.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

#: Bound of a box coordinate relative to the clamp (m): the env's positions lie in [-2, 2].
RELATIVE_BOUND = 4.0
#: Box slot width: present flag, minimum (3), maximum (3).
BOX_SLOT = 7
#: Joint values at the start of the env's observation.
N_JOINTS = 6


class NearestBoxes(gym.ObservationWrapper[dict[str, np.ndarray], Any, dict[str, np.ndarray]]):
    """GrapeHarvest-v1's ``observation`` as joints and the ``k`` nearest boxes relative to the clamp.

    Args:
        env: A GrapeHarvest-v1 env (anything whose unwrapped env has its ``layout``).
        k: Box slots, >= 1.

    Raises:
        ValueError: For ``k`` < 1 or an env without the GrapeHarvest observation layout.
    """

    def __init__(self, env: gym.Env[Any, Any], k: int = 6) -> None:
        if int(k) < 1:
            raise ValueError(f"NearestBoxes: k must be >= 1, got {k}")
        layout = getattr(env.unwrapped, "layout", None)
        space = env.observation_space
        if not isinstance(layout, dict) or not isinstance(space, gym.spaces.Dict) or "observation" not in space.spaces:
            raise ValueError("NearestBoxes needs a GrapeHarvest-v1 env (a Dict observation with the env's layout)")
        super().__init__(env)
        self.k = int(k)
        n = int(np.prod(space.spaces["observation"].shape or (0,)))
        goal = int(np.prod(space.spaces["desired_goal"].shape or (0,)))
        # Where each box slot's flag starts: the designated cluster, the others (box, then cut goal), stems, leaves.
        starts = [layout["target_box"].start]
        o0, o1, _ = layout["others"].indices(n)
        starts += list(range(o0, o1, BOX_SLOT + goal))
        b0, b1, _ = layout["obstacles"].indices(n)
        starts += list(range(b0, b1, BOX_SLOT))
        self._slots = np.array(starts, dtype=np.int64)
        low = np.concatenate([-np.ones(N_JOINTS), np.tile([0.0] + [-RELATIVE_BOUND] * 6, self.k)])
        high = np.concatenate([np.ones(N_JOINTS), np.tile([1.0] + [RELATIVE_BOUND] * 6, self.k)])
        box = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32))
        self.observation_space = gym.spaces.Dict({**space.spaces, "observation": box})  # type: ignore[assignment]

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The env's observation with its ``observation`` key rewritten (see the module docstring)."""
        raw = np.asarray(observation["observation"], dtype=np.float64)
        clamp = np.asarray(observation["achieved_goal"], dtype=np.float64)[:3]
        rows = raw[self._slots[:, None] + np.arange(BOX_SLOT)[None, :]]  # (slots, 7)
        rows = rows[rows[:, 0] > 0.5]
        lo, hi = rows[:, 1:4] - clamp, rows[:, 4:7] - clamp  # relative to the clamp
        gap = np.maximum(np.maximum(lo, -hi), 0.0)  # per axis: how far the clamp is outside the box
        dist2 = (gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1]) + gap[:, 2] * gap[:, 2]
        nearest = np.argsort(dist2, kind="stable")[: self.k]
        boxes = np.zeros((self.k, BOX_SLOT))
        boxes[: len(nearest), 0] = 1.0
        boxes[: len(nearest), 1:4] = lo[nearest]
        boxes[: len(nearest), 4:7] = hi[nearest]
        out = np.concatenate([raw[:N_JOINTS], np.clip(boxes, -RELATIVE_BOUND, RELATIVE_BOUND).ravel()])
        return {**observation, "observation": out.astype(np.float32)}
