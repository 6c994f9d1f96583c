"""GreenhouseNav's frame_skip: k held periods per step, the same trajectory as k plain steps, one observation."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_training.learned.policy import ActionRepeat
from agri_training.train import make_repeating

ENV_ID = "agri_envs/GreenhouseNav-v2"
# Without sensor noise the env draws random numbers only for the people, so skipped observations change nothing.
QUIET = {"lidar_noise_std": 0.0, "lidar_dropout": 0.0, "sonar_noise_std": 0.0, "n_people": 2}


def _actions(n, seed=0):
    rng = np.random.default_rng(seed)
    return [np.array([rng.uniform(0.2, 1.0), rng.uniform(-0.6, 0.6)], np.float32) for _ in range(n)]


def test_a_skipped_step_is_k_plain_steps():
    k = 3
    plain = gym.make(ENV_ID, **QUIET)
    skip = gym.make(ENV_ID, frame_skip=k, **QUIET)
    plain.reset(seed=7)
    skip.reset(seed=7)
    for action in _actions(40):
        obs, reward, term, trunc, info = skip.step(action)
        total, terms = 0.0, {}
        for _ in range(k):
            p_obs, p_reward, p_term, p_trunc, p_info = plain.step(action)
            total += p_reward
            for key in p_info:
                if key.startswith("reward_"):
                    terms[key] = terms.get(key, 0.0) + p_info[key]
            if p_term or p_trunc:
                break
        for key in obs:
            np.testing.assert_array_equal(obs[key], p_obs[key], err_msg=key)
        assert reward == pytest.approx(total, abs=1e-12)
        for key, value in terms.items():
            assert info[key] == pytest.approx(value, abs=1e-12), key
        assert (term, trunc) == (p_term, p_trunc)
        assert (info["x"], info["y"], info["min_clearance"]) == (p_info["x"], p_info["y"], p_info["min_clearance"])
        if term or trunc:
            break
    assert skip.unwrapped.task.steps == plain.unwrapped.task.steps > 40


def test_a_skipped_step_stops_at_the_period_that_ends_the_episode():
    env = gym.make(ENV_ID, n_rows=1, row_length=3.0, n_people=0, frame_skip=16)
    env.reset(seed=0)
    done, steps = False, 0
    while not done:
        *_, term, trunc, info = env.step(np.array([1.0, 0.3], np.float32))  # into the row
        done, steps = term or trunc, steps + 1
    assert term and info["collision"] and info["reward_collision"] < 0
    assert env.unwrapped.task.steps % 16 != 0  # the crash came mid-step and ended it there


def test_explicit_time_limit_counts_steps_of_k_periods():
    env = gym.make(ENV_ID, n_people=0, frame_skip=4, max_episode_steps=5)
    _, info = env.reset(seed=1)
    assert info["max_episode_steps"] == 20
    for i in range(5):
        *_, term, trunc, info = env.step(np.zeros(2, np.float32))
        assert trunc == (i == 4) and not term
    assert info["truncated"] and env.unwrapped.task.steps == 20


def test_training_uses_the_envs_own_frame_skip():
    env = make_repeating(ENV_ID, {"n_people": 0}, 4)
    assert env.unwrapped.config.frame_skip == 4 and not isinstance(env, ActionRepeat)
    assert make_repeating(ENV_ID, {"n_people": 0}, 1).unwrapped.config.frame_skip == 1
    with pytest.raises(ValueError, match="action_repeat"):
        make_repeating(ENV_ID, {"frame_skip": 2}, 4)
    with pytest.raises(ValueError, match="frame_skip"):
        gym.make(ENV_ID, frame_skip=0)
