"""ObservationHistory: stacked frames in training, and the same frames replayed by a loaded policy."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_training.learned.policy import (
    ActionRepeat,
    HeldActions,
    ObservationHistory,
    ObservationReplay,
    apply_wrappers,
    decide_held,
    observation_chain,
)

ENV_ID = "agri_envs/GreenhouseNav-v2"
SMALL = {"n_rows": 1, "row_length": 3.0, "n_people": 1, "max_episode_steps": 30}
WRAPPERS = ["FlattenObservation", {"ObservationHistory": {"frames": 3}}]


def _flat(env, obs):
    return gym.spaces.flatten(env.observation_space, obs)


def test_history_stacks_oldest_first_and_refills_on_reset():
    raw = gym.make(ENV_ID, **SMALL)
    stacked = apply_wrappers(gym.make(ENV_ID, **SMALL), WRAPPERS)
    n = gym.spaces.flatdim(raw.observation_space)
    assert stacked.observation_space.shape == (3 * n,)
    first, _ = raw.reset(seed=4)
    obs, _ = stacked.reset(seed=4)
    np.testing.assert_array_equal(obs, np.tile(_flat(raw, first), 3))
    frames = [_flat(raw, first)] * 3
    action = np.array([0.8, 0.3], np.float32)
    for _ in range(4):
        frames = [*frames[1:], _flat(raw, raw.step(action)[0])]
        obs = stacked.step(action)[0]
        np.testing.assert_array_equal(obs, np.concatenate(frames))
        assert stacked.observation_space.contains(obs)
    again, _ = raw.reset(seed=9)
    np.testing.assert_array_equal(stacked.reset(seed=9)[0], np.tile(_flat(raw, again), 3))


def test_history_refuses_what_it_cannot_stack():
    with pytest.raises(ValueError, match="flat Box"):
        ObservationHistory(gym.make(ENV_ID, **SMALL))  # a Dict observation: flatten first
    with pytest.raises(ValueError, match="frames"):
        ObservationHistory(gym.wrappers.FlattenObservation(gym.make(ENV_ID, **SMALL)), frames=0)


class _RecordingModel:
    """Stands in for an SB3 model: records what it is shown, acts as a fixed function of it."""

    def __init__(self) -> None:
        self.seen: list[np.ndarray] = []

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        self.seen.append(np.array(observation))
        x = float(np.tanh(np.asarray(observation)[:20].mean()))
        return np.array([0.5 + 0.4 * x, x], np.float32), state


def test_a_loaded_policy_sees_the_frames_training_saw():
    """Training: ActionRepeat inside the history. Evaluation: raw env, replayed once per held action."""
    repeat, episodes = 3, (11, 12)
    train_env = apply_wrappers(ActionRepeat(gym.make(ENV_ID, **SMALL), repeat), WRAPPERS)
    trained = _RecordingModel()
    for seed in episodes:
        obs, _ = train_env.reset(seed=seed)
        done = False
        while not done:
            action, _ = trained.predict(obs)
            obs, _, term, trunc, _ = train_env.step(action)
            done = term or trunc

    eval_env = gym.make(ENV_ID, **SMALL)
    replay = ObservationReplay(observation_chain(eval_env, WRAPPERS)[1])
    loaded, hold = _RecordingModel(), HeldActions(repeat)
    for seed in episodes:
        obs, _ = eval_env.reset(seed=seed)
        start, done = True, False
        while not done:
            action, _ = decide_held(hold, replay, loaded, obs, None, np.array([start]), True)
            obs, _, term, trunc, _ = eval_env.step(action)
            start, done = False, term or trunc

    assert len(loaded.seen) == len(trained.seen) > 2 * len(episodes)
    for k, (a, b) in enumerate(zip(trained.seen, loaded.seen, strict=True)):
        np.testing.assert_array_equal(a, b, err_msg=f"decision {k}")
