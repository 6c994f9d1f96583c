"""RobotLimits: the limits of the robot that drives the episode, as an observation key."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_training.learned.robot_limits import RobotLimits

NAV = "agri_envs/GreenhouseNav-v2"


def test_limits_follow_the_robot_each_episode_draws():
    env = RobotLimits(gym.make(NAV, scene_distribution="robust"))
    seen = set()
    for seed in range(6):
        obs, _ = env.reset(seed=seed)
        cfg = env.unwrapped.episode_config
        want = np.array([cfg.max_speed / 2.0, cfg.max_turn_rate / 4.0, cfg.max_accel / 10.0], np.float32)
        np.testing.assert_array_equal(obs["limits"], want)
        assert env.observation_space.contains(obs)
        obs, *_ = env.step(env.action_space.sample())
        np.testing.assert_array_equal(obs["limits"], want)
        seen.add(float(obs["limits"][0]))
    assert len(seen) == 6
    fixed = RobotLimits(gym.make(NAV, max_speed=1.5, max_turn_rate=2.0, max_accel=0.5))
    np.testing.assert_array_equal(fixed.reset(seed=0)[0]["limits"], np.float32([0.75, 0.5, 0.05]))


def test_needs_a_robot_and_a_dict_observation():
    with pytest.raises(ValueError, match="robot_spec and a Dict observation"):
        RobotLimits(gym.wrappers.FlattenObservation(gym.make(NAV)))
