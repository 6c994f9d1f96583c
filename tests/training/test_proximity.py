"""Proximity: range keys read again as length / (length + range), the same bits on one env and on a batch."""

import gymnasium as gym
import numpy as np
import pytest
from batch_forms import assert_batch_matches_single_envs

import agri_envs  # noqa: F401
from agri_training.learned.policy import ObservationReplay, Proximity, observation_chain

ENV_ID = "agri_envs/GreenhouseNav-v2"
SMALL = {"n_rows": 2, "row_length": 4.0, "n_people": 2, "people_tease_prob": 0.6, "max_episode_steps": 40}
LENGTHS = {"lidar": 0.05, "sonar": 0.1}
WRAPPERS = [{"Proximity": LENGTHS}, "FlattenObservation"]


def test_proximity_keys_sit_beside_the_ranges_and_follow_the_formula():
    raw = gym.make(ENV_ID, **SMALL)
    env = Proximity(gym.make(ENV_ID, **SMALL), **LENGTHS)
    assert set(env.observation_space.spaces) == set(raw.observation_space.spaces) | {
        "lidar_proximity",
        "sonar_proximity",
    }
    first, _ = raw.reset(seed=3)
    obs, _ = env.reset(seed=3)
    action = np.array([0.7, -0.2], np.float32)
    for _ in range(20):
        for key, length in LENGTHS.items():
            np.testing.assert_array_equal(obs[key], first[key])  # the ranges stay as they were
            expected = length / (length + first[key].astype(np.float64))  # one rounding, float64
            np.testing.assert_allclose(obs[f"{key}_proximity"], expected, rtol=2e-7)
            assert obs[f"{key}_proximity"].dtype == np.float32
        assert env.observation_space.contains(obs)
        first, obs = raw.step(action)[0], env.step(action)[0]


def test_proximity_halves_at_its_length_and_reaches_one_at_contact():
    env = Proximity(gym.make(ENV_ID, **SMALL), lidar=0.05)
    obs, _ = gym.make(ENV_ID, **SMALL).reset(seed=0)
    ranges = np.array([0.0, 0.05, 0.5, 1.0], np.float32)
    near = env.observation({**obs, "lidar": ranges})["lidar_proximity"]
    np.testing.assert_allclose(near, [1.0, 0.5, 0.05 / 0.55, 0.05 / 1.05], rtol=1e-6)
    assert np.all(np.diff(near) < 0)  # nearer reads higher
    box = env.observation_space["lidar_proximity"]
    np.testing.assert_allclose([box.low.min(), box.high.max()], [0.05 / 1.05, 1.0], rtol=1e-6)


def test_the_batch_form_gives_each_sub_env_the_single_envs_bits():
    kwargs = [{**SMALL, "max_episode_steps": 15 + 9 * i} for i in range(3)]
    assert_batch_matches_single_envs(ENV_ID, kwargs, WRAPPERS)


def test_a_loaded_policy_replays_the_proximity_keys():
    env = gym.make(ENV_ID, **SMALL)
    wrapped, chain = observation_chain(gym.make(ENV_ID, **SMALL), WRAPPERS)
    replay = ObservationReplay(chain)
    raw, _ = env.reset(seed=8)
    np.testing.assert_array_equal(replay(raw, new_episode=True), wrapped.reset(seed=8)[0])


@pytest.mark.parametrize(
    "wrap, lengths, match",
    [
        (False, {"lidar": 0.0}, "must be > 0"),
        (False, {"camera": 0.1}, "'camera' must be a Box of ranges"),
        (False, {"velocity": 0.1}, "'velocity' must be a Box of ranges"),  # velocity reaches -1: not a range
        (False, {}, "at least one key"),
        (True, {"lidar": 0.05}, "Dict observation"),  # after FlattenObservation: nothing to name
    ],
)
def test_proximity_refuses_what_it_cannot_read(wrap, lengths, match):
    env = gym.make(ENV_ID, **SMALL)
    with pytest.raises(ValueError, match=match):
        Proximity(gym.wrappers.FlattenObservation(env) if wrap else env, **lengths)
