"""Goal zoom: a fixed rule that lets a goal-conditioned arm policy resolve errors finer than it was trained to.

A reach skill trained to cut within 1 cm and 0.2 rad stops short of a 1 mm cut: near its goal its network asks
for (almost) nothing, because every error it was trained on below about a centimetre already counted as reached
(``sac-her-grape-vine-shielded`` settles 3.2 mm from the goal and swings 0.012-0.024 rad about it, seed 20000 of
``grape-stress-precision``'s 2 mm level). :class:`GoalZoom` sits between the env and the network. Where the clamp is
closer to the goal than ``position`` (m), the network is shown a goal moved out along the same error, to
``position`` away, and the translation it asks for is divided by the same factor; the orientation likewise (the
rotation from the clamp's axes to the goal's, scaled up to ``angle`` rad, and the action's rotation scaled back).
Far from the goal nothing changes; close to it the network's own answer to a larger error, scaled down, drives
the arm there: a gain schedule, as a servo's fine mode. The factors stop at ``max_factor``, which sets the finest
error still magnified (``position / max_factor``).

The rule reads the observation's ``achieved_goal`` and ``desired_goal`` (the clamp's position and two axes, the
goal's; :data:`agri_envs.arm.task.GOAL_DIM`), nothing else. A policy with a zoom says so in its name and counts
the steps it acted in (``zoomed_steps``, one per-episode metric in its entries).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from agri_envs.arm.task import GOAL_DIM


def _frame(goal: np.ndarray) -> np.ndarray:
    """The rotation matrix whose first two columns are a goal's two axes (orthonormalised, the first kept)."""
    u = goal[3:6] / np.linalg.norm(goal[3:6])
    v = goal[6:9] - u * float(u @ goal[6:9])
    v = v / np.linalg.norm(v)
    return np.stack([u, v, np.cross(u, v)], axis=1)


@dataclasses.dataclass
class GoalZoom:
    """Magnify small goal errors for the network and shrink its action by the same factors (see the module).

    Attributes:
        position: Position errors below this (m) are shown at this size.
        angle: Orientation errors below this (rad) are shown at this size.
        max_factor: The largest magnification, >= 1.
    """

    position: float = 0.02
    angle: float = 0.2
    max_factor: float = 20.0
    #: Steps of the current episode in which an error was magnified.
    zoomed_steps: int = dataclasses.field(default=0, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (self.position > 0 and self.angle > 0 and self.max_factor >= 1):
            raise ValueError(f"GoalZoom needs position > 0, angle > 0 and max_factor >= 1, got {self}")

    def factors(self, achieved: np.ndarray, desired: np.ndarray) -> tuple[float, float, np.ndarray]:
        """``(position factor, angle factor, the goal the network is shown)`` for one observation's goals."""
        a = np.asarray(achieved, dtype=np.float64).reshape(GOAL_DIM)
        d = np.asarray(desired, dtype=np.float64).reshape(GOAL_DIM)
        error = d[:3] - a[:3]
        k = float(np.clip(self.position / max(float(np.linalg.norm(error)), 1e-12), 1.0, self.max_factor))
        turn = Rotation.from_matrix(_frame(d) @ _frame(a).T).as_rotvec()
        kr = float(np.clip(self.angle / max(float(np.linalg.norm(turn)), 1e-12), 1.0, self.max_factor))
        shown = d.copy()
        shown[:3] = a[:3] + k * error
        axes = Rotation.from_rotvec(kr * turn).as_matrix() @ _frame(a)
        shown[3:6] = axes[:, 0] * np.linalg.norm(d[3:6])
        shown[6:9] = axes[:, 1] * np.linalg.norm(d[6:9])
        return k, kr, shown

    def observe(
        self, observation: Mapping[str, Any], episode_start: bool
    ) -> tuple[dict[str, Any], tuple[float, float]]:
        """The observation the network is shown, and the factors to divide its action by."""
        if episode_start:
            self.zoomed_steps = 0
        k, kr, shown = self.factors(observation["achieved_goal"], observation["desired_goal"])
        self.zoomed_steps += int(k > 1.0 or kr > 1.0)
        seen = dict(observation)
        seen["desired_goal"] = shown.astype(np.asarray(observation["desired_goal"]).dtype)
        return seen, (k, kr)

    @staticmethod
    def act(action: np.ndarray, factors: tuple[float, float]) -> np.ndarray:
        """The network's end-effector action with its translation and rotation divided by the factors."""
        out = np.array(action, dtype=np.float32, copy=True)
        out[:3] /= factors[0]
        out[3:] /= factors[1]
        return out

    def episode_metrics(self) -> dict[str, float]:
        """``zoomed_steps``: steps of the episode so far in which the zoom magnified an error."""
        return {"zoomed_steps": float(self.zoomed_steps)}
