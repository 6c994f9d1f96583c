"""Joint homing: the arm's last stretch home as a straight line in joint space, not in the clamp's space.

The arm's home configuration (:data:`agri_envs.arm.scene.HOME_Q`) holds joint 2 at its lower limit (-60 deg). A
learned harvester commands the clamp (``control="ee"``), and the env turns each command into joints with its
differential IK (:func:`agri_envs.arm.grape_harvest.end_effector_step`). Coming home, a clamp motion that is not
exactly the one home's joints make asks joint 2 to pass its limit; the IK then locks it there, and the five joints
left cannot make the rest: ``sac-her-grape-vine-shielded-zoom`` stands 7.4-7.8 mm from home until its time limit
(validation seeds 20048 and 20056 of ``grape-stress-precision``'s 5 mm level, every cluster cut), where a 1 cm
tolerance had let it pass. An industrial arm goes home the way :class:`JointHoming` does: once the clamp is within
``position`` of home, and every joint within ``max_joint_offset`` of home's (the same branch of the arm's inverse
kinematics), the action is the clamp motion of a step along the straight joint line to home, as long as the
action's bounds allow. The line stays inside the joint ranges (they are a box), so no joint is locked on the way
and the last step is the exact error.

The rule reads the observation's joints, ``achieved_goal`` and ``desired_goal`` (is the goal home?), and the
robot's own home configuration: nothing a real arm lacks. It counts the steps it drove (``homing_steps``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from agri_baselines.luo_apf import joints_from_observation
from agri_envs.arm.robot_model import goal_vector, tip_pose
from agri_envs.arm.scene import HOME_Q

#: The goal vector of home (float32, as the env's ``desired_goal`` shows it).
_HOME_POSE = tip_pose(HOME_Q)
HOME_GOAL = goal_vector(_HOME_POSE[:3, 3], _HOME_POSE[:3, :3]).astype(np.float32)


@dataclasses.dataclass
class JointHoming:
    """Drive the last stretch home along the joint line to the home configuration (see the module).

    Attributes:
        max_ee_step: The env's ``max_ee_step`` (m of clamp translation at action 1).
        max_ee_rotation: The env's ``max_ee_rotation`` (rad of clamp rotation at action 1).
        position: The rule acts within this distance of home (m).
        max_joint_offset: ... and only while every joint is within this of home's (rad).
    """

    max_ee_step: float
    max_ee_rotation: float
    position: float = 0.02
    max_joint_offset: float = 0.5
    #: Steps of the current episode that the rule drove.
    homing_steps: int = dataclasses.field(default=0, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (self.max_ee_step > 0 and self.max_ee_rotation > 0 and self.position > 0 and self.max_joint_offset > 0):
            raise ValueError(f"JointHoming needs positive step sizes, position and max_joint_offset, got {self}")

    @classmethod
    def for_env(cls, env: Any) -> JointHoming:
        """The rule with the step sizes of ``env``, a GrapeHarvest env under end-effector control.

        Raises:
            ValueError: For another control mode.
        """
        cfg = env.unwrapped.config
        if cfg.control != "ee":
            raise ValueError("JointHoming commands the clamp: make the env with control='ee'")
        return cls(float(cfg.max_ee_step), float(cfg.max_ee_rotation))

    def applies(self, observation: Mapping[str, Any]) -> bool:
        """The goal is home, the clamp within ``position`` of it, every joint within ``max_joint_offset``."""
        desired = np.asarray(observation["desired_goal"], dtype=np.float32)
        if not np.array_equal(desired, HOME_GOAL):
            return False
        gap = float(np.linalg.norm(np.asarray(observation["achieved_goal"][:3], dtype=np.float64) - HOME_GOAL[:3]))
        q = joints_from_observation(observation["observation"])
        return gap < self.position and float(np.max(np.abs(HOME_Q - q))) < self.max_joint_offset

    def action(self, observation: Mapping[str, Any]) -> np.ndarray:
        """The clamp action of the longest step along the joint line home that the action's bounds allow."""
        q = joints_from_observation(observation["observation"])
        here = tip_pose(q)
        scale = np.array([self.max_ee_step] * 3 + [self.max_ee_rotation] * 3)

        def twist(fraction: float) -> np.ndarray:
            there = tip_pose(q + fraction * (HOME_Q - q))
            turn = Rotation.from_matrix(there[:3, :3] @ here[:3, :3].T).as_rotvec()
            return np.concatenate([there[:3, 3] - here[:3, 3], turn]) / scale

        action = twist(1.0)
        largest = float(np.max(np.abs(action)))
        if largest > 1.0:  # the whole line is more than one step: the part of it that one step covers
            action = twist(1.0 / largest)
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def decide(self, observation: Mapping[str, Any], action: np.ndarray, episode_start: bool) -> np.ndarray:
        """The homing action where the rule applies, else ``action`` (the network's) as it is."""
        if episode_start:
            self.homing_steps = 0
        if not self.applies(observation):
            return action
        self.homing_steps += 1
        return self.action(observation)

    def episode_metrics(self) -> dict[str, float]:
        """``homing_steps``: steps of the episode so far that the rule drove."""
        return {"homing_steps": float(self.homing_steps)}
