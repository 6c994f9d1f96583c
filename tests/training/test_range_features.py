"""Differences and Ramp: width-free readings of range keys, the same bits on one env and on a batch."""

import gymnasium as gym
import numpy as np
import pytest
from batch_forms import assert_batch_matches_single_envs

import agri_envs  # noqa: F401
from agri_training.learned.policy import ObservationReplay, observation_chain
from agri_training.learned.range_features import Differences, Ramp

ENV_ID = "agri_envs/GreenhouseCoverage-v2"
SMALL = {"n_rows": 1, "row_length": 4.0, "max_episode_steps": 40}
PAIRS = {"sonar": [[1, 4], [2, 5], [3, 6]]}  # left minus right: front, middle, rear
BOUNDS = {"sonar": {"low": [0.0] + [0.25] * 6, "high": [1.0] + [0.75] * 6}}
WRAPPERS = [
    {"Differences": PAIRS},
    {"Ramp": BOUNDS},
    {"FilterObservation": {"filter_keys": ["sonar_difference", "sonar_ramp", "compass"]}},
    "FlattenObservation",
]


def _drive(env, seed, steps=25):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        out.append(env.step(np.array([1.0, 0.3], np.float32))[0])
    return out


def test_differences_are_left_minus_right_and_leave_the_ranges_alone():
    raw = _drive(gym.make(ENV_ID, **SMALL), 4)
    env = Differences(gym.make(ENV_ID, **SMALL), **PAIRS)
    for first, obs in zip(raw, _drive(env, 4), strict=True):
        np.testing.assert_array_equal(obs["sonar"], first["sonar"])
        x = first["sonar"].astype(np.float64)  # the float64 difference of two float32 is exact: one rounding
        expected = np.float32([x[1] - x[4], x[2] - x[5], x[3] - x[6]])
        np.testing.assert_array_equal(obs["sonar_difference"], expected)
        assert env.observation_space.contains(obs)
    box = env.observation_space["sonar_difference"]
    np.testing.assert_array_equal([box.low.min(), box.high.max()], [-1.0, 1.0])


def test_a_centred_robot_reads_zero_difference_in_any_corridor_width():
    readings = {width: np.float32([1.0, width, width, width, width, width, width]) for width in (0.1, 0.125)}
    env = Differences(gym.make(ENV_ID, **SMALL), **PAIRS)
    obs, _ = gym.make(ENV_ID, **SMALL).reset(seed=0)
    for sonar in readings.values():
        np.testing.assert_array_equal(env.observation({**obs, "sonar": sonar})["sonar_difference"], 0.0)
    offset = env.observation({**obs, "sonar": np.float32([1, 0.05, 0.05, 0.05, 0.2, 0.2, 0.2])})
    np.testing.assert_allclose(offset["sonar_difference"], -0.15, rtol=1e-6)  # nearer the left row


def test_a_group_reads_its_nearest_range_so_one_long_echo_does_not_swing_it():
    env = Differences(gym.make(ENV_ID, **SMALL), sonar=[[[1, 2, 3], [4, 5, 6]], [0, [1, 4]]])
    obs, _ = gym.make(ENV_ID, **SMALL).reset(seed=0)
    slipped = np.float32([0.9, 0.05, 0.06, 0.05, 0.2, 0.95, 0.21])  # the right middle echo slipped long
    diff = env.observation({**obs, "sonar": slipped})["sonar_difference"]
    np.testing.assert_array_equal(diff, [np.float32(0.05) - np.float32(0.2), np.float32(0.9) - np.float32(0.05)])
    box = env.observation_space["sonar_difference"]
    np.testing.assert_array_equal([box.low, box.high], [[-1.0, -1.0], [1.0, 1.0]])
    for obs in _drive(env, 6):
        assert env.observation_space.contains(obs)
        x = obs["sonar"]
        assert obs["sonar_difference"][0] == x[1:4].min() - x[4:7].min()


def test_the_ramp_is_flat_below_low_and_above_high_and_linear_between():
    env = Ramp(gym.make(ENV_ID, **SMALL), **BOUNDS)
    obs, _ = gym.make(ENV_ID, **SMALL).reset(seed=0)
    sides = np.float32([0.1, 0.25, 0.3, 0.5, 0.7, 0.75, 1.0])
    ramp = env.observation({**obs, "sonar": sides})["sonar_ramp"]
    assert ramp[0] == np.float32(0.1)  # the front's ramp spans its whole range: the reading itself
    np.testing.assert_allclose(ramp[1:], [0.0, 0.1, 0.5, 0.9, 1.0, 1.0], rtol=1e-6)
    for obs in _drive(env, 2):
        assert env.observation_space.contains(obs)
        assert obs["sonar_ramp"].dtype == np.float32


def test_a_list_of_ramps_reads_the_key_through_each_end_to_end():
    near, far = {"low": 0.025, "high": 0.1125}, {"low": 0.25, "high": 0.75}
    env = Ramp(gym.make(ENV_ID, **SMALL), sonar=[near, far])
    assert env.observation_space["sonar_ramp"].shape == (14,)
    obs, _ = gym.make(ENV_ID, **SMALL).reset(seed=0)
    sonar = np.float32([1.0, 0.05, 0.1125, 0.3, 0.025, 0.5, 0.75])
    ramp = env.observation({**obs, "sonar": sonar})["sonar_ramp"]
    alone = [Ramp(gym.make(ENV_ID, **SMALL), sonar=r).observation({**obs, "sonar": sonar}) for r in (near, far)]
    np.testing.assert_array_equal(ramp, np.concatenate([a["sonar_ramp"] for a in alone]))
    np.testing.assert_allclose(ramp[7:], [1.0, 0.0, 0.0, 0.1, 0.0, 0.5, 1.0], rtol=1e-6)


def test_one_number_bounds_every_element():
    env = Ramp(gym.make(ENV_ID, **SMALL), sonar={"low": 0.25, "high": 0.75})
    obs, _ = gym.make(ENV_ID, **SMALL).reset(seed=0)
    ramp = env.observation({**obs, "sonar": np.full(7, 0.5, np.float32)})["sonar_ramp"]
    np.testing.assert_array_equal(ramp, np.full(7, 0.5, np.float32))


def test_the_batch_forms_give_each_sub_env_the_single_envs_bits():
    kwargs = [{**SMALL, "max_episode_steps": 15 + 9 * i} for i in range(3)]
    assert_batch_matches_single_envs(ENV_ID, kwargs, WRAPPERS)


def test_a_loaded_policy_replays_the_features():
    env = gym.make(ENV_ID, **SMALL)
    wrapped, chain = observation_chain(gym.make(ENV_ID, **SMALL), WRAPPERS)
    raw, _ = env.reset(seed=8)
    np.testing.assert_array_equal(ObservationReplay(chain)(raw, new_episode=True), wrapped.reset(seed=8)[0])


@pytest.mark.parametrize(
    "wrapper, kwargs, match",
    [
        (Differences, {}, "at least one key"),
        (Differences, {"camera": [[0, 1]]}, "'camera' must be a 1-D Box"),
        (Differences, {"sonar": [[1, 1]]}, "two different members"),
        (Differences, {"sonar": [[[1, 2], [2, 1]]]}, "two different members"),
        (Differences, {"sonar": [[1, 7]]}, "two different members"),
        (Differences, {"sonar": [[1, []]]}, "two different members"),
        (Differences, {"sonar": [1, 4]}, "list of pairs"),
        (Differences, {"sonar": [[1, 2, 3]]}, "list of pairs"),
        (Ramp, {}, "at least one key"),
        (Ramp, {"sonar": {"low": 0.5}}, "needs {low: ..., high: ...}"),
        (Ramp, {"sonar": {"low": 0.5, "high": 0.5}}, "above its low"),
        (Ramp, {"sonar": {"low": [0.1, 0.2], "high": 0.9}}, "one number or 7"),
        (Ramp, {"sonar": []}, "or a list of them"),
        (Ramp, {"sonar": [{"low": 0.1, "high": 0.2}, {"low": 0.1}]}, "or a list of them"),
    ],
)
def test_the_features_refuse_what_they_cannot_read(wrapper, kwargs, match):
    with pytest.raises(ValueError, match=match):
        wrapper(gym.make(ENV_ID, **SMALL), **kwargs)


@pytest.mark.parametrize("wrapper, kwargs", [(Differences, PAIRS), (Ramp, BOUNDS)])
def test_the_features_need_a_dict_observation(wrapper, kwargs):
    with pytest.raises(ValueError, match="Dict observation"):
        wrapper(gym.wrappers.FlattenObservation(gym.make(ENV_ID, **SMALL)), **kwargs)
