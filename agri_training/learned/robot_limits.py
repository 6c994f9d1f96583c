"""The robot's own limits as an observation: what a policy needs to drive robots of several speeds.

GreenhouseNav scales its action and its ``velocity`` observation by the robot's limits (``max_speed``,
``max_turn_rate``), so a policy that sees only those keys cannot tell a 0.6 m/s robot from a 1.4 m/s one until
it has driven it; a stopping distance four times longer looks the same. :class:`RobotLimits` adds the limits of
the robot driving the current episode (``scene_distribution="robust"`` draws ``max_speed`` per episode) as
``limits``: speed, turn rate and acceleration, each over the largest value the env accepts. A real robot knows
its own limits: nothing privileged.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

#: The limits read, and the largest value of each that GreenhouseNav's config accepts (the scale).
LIMITS = (("max_speed", 2.0), ("max_turn_rate", 4.0), ("max_accel", 10.0))


class RobotLimits(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """Add ``limits``: the episode's robot speed, turn-rate and acceleration limits over their largest values.

    Reads ``env.unwrapped.robot_spec`` at each observation (the robot of the current episode). Put it before
    ``FlattenObservation``; in a config: ``RobotLimits``.

    Raises:
        ValueError: For an env without a ``robot_spec`` or a Dict observation.
    """

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        space = env.observation_space
        if not isinstance(space, gym.spaces.Dict) or not hasattr(env.unwrapped, "robot_spec"):
            raise ValueError(f"RobotLimits needs an env with a robot_spec and a Dict observation, got {env}")
        super().__init__(env)
        box = gym.spaces.Box(0.0, 1.0, (len(LIMITS),), np.float32)
        self.observation_space = gym.spaces.Dict({**space.spaces, "limits": box})

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with the current robot's ``limits``."""
        unwrapped: Any = self.env.unwrapped
        spec = unwrapped.robot_spec
        limits = np.array([getattr(spec, name) / scale for name, scale in LIMITS], np.float32)
        return {**observation, "limits": limits}
