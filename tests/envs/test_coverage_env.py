"""GreenhouseCoverage-v0: API checkers, determinism, pickling, config strictness, bad input, rendering, task."""

import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from rollouts import assert_same, rollout

import agri_envs  # noqa: F401
from agri_envs.coverage.config import GreenhouseCoverageConfig
from agri_envs.coverage.task import CoverageTask, CoverageWeights

ENV_ID = "agri_envs/GreenhouseCoverage-v0"
SMALL = {"n_rows": 1, "row_length": 4.0}


@pytest.mark.parametrize("kwargs", [SMALL, {**SMALL, "localization": "ground_truth"}])
def test_gymnasium_and_sb3_checkers(kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, **kwargs)
    check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)
    env.close()


def test_same_seed_same_actions_identical_and_seeds_differ():
    kw = {**SMALL, "terminate_on_contact": False}
    assert_same(rollout(gym.make(ENV_ID, **kw), 5, 200), rollout(gym.make(ENV_ID, **kw), 5, 200))
    a = rollout(gym.make(ENV_ID, **kw), 5, 3)
    b = rollout(gym.make(ENV_ID, **kw), 6, 3)
    assert not np.array_equal(a[1][0]["sonar"], b[1][0]["sonar"])


def test_pickled_env_continues_identically():
    env = gym.make(ENV_ID, **SMALL, terminate_on_contact=False)
    rollout(env, 3, 50)
    clone = pickle.loads(pickle.dumps(env))
    for a in np.random.default_rng(1).uniform(-1, 1, (60, 2)):
        o1, r1, _, _, i1 = env.step(a)
        o2, r2, _, _, i2 = clone.step(a)
        assert all(np.array_equal(o1[k], o2[k]) for k in o1) and r1 == r2 and i1["x"] == i2["x"]


def test_observations_normalised_and_info_keys():
    env = gym.make(ENV_ID)
    obs, info = env.reset(seed=0)
    for _ in range(30):
        obs, _, _, _, info = env.step(np.array([1.0, 0.1]))
        for k, v in obs.items():
            assert v.dtype == np.float32 and np.all((v >= 0) & (v <= 1)), k
    for key in ("coverage", "cross_track", "max_cross_track", "crop_contacts", "is_success", "n_corridors"):
        assert key in info
    assert obs["coverage"].shape == (5,)


def test_bad_actions_and_config():
    env = gym.make(ENV_ID, **SMALL)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    env.step(np.array([5.0, -5.0]))  # clipped, no error
    with pytest.raises(ValueError, match="corridor_widht"):
        gym.make(ENV_ID, corridor_widht=1.5)
    with pytest.raises(ValueError, match="vegetation_echo_prob"):
        gym.make(ENV_ID, vegetation_echo_prob=1.5)
    with pytest.raises(ValueError, match="narrowest corridor"):
        gym.make(ENV_ID, corridor_width=1.0, row_bend=0.3)
    with pytest.raises(ValueError, match="reset options"):
        env.reset(options={"n_rows": 3})


def test_step_before_reset_and_render():
    env = gym.make(ENV_ID, **SMALL, render_mode="rgb_array")
    with pytest.raises(RuntimeError):
        env.unwrapped.step(np.zeros(2))
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
    env.close()
    env.close()


def test_driving_into_the_crop_ends_the_episode_with_a_crop_contact():
    env = gym.make(ENV_ID, **SMALL)
    env.reset(seed=0)
    # Into the first corridor, then curve left into the first row: the first thing touched is the crop.
    for _ in range(50):
        _, _, term, _, info = env.step(np.array([1.0, 0.0]))
    assert info["corridor"] == 0 and not term
    for _ in range(200):
        _, _, term, _, info = env.step(np.array([0.6, 1.0]))
        if term:
            break
    assert term and info["crop_contacts"] == 1 and not info["is_success"]


def test_time_limit_truncates():
    env = gym.make(ENV_ID, **SMALL, time_limit=2.0)
    env.reset(seed=0)
    truncations = []
    for _ in range(20):
        _, _, term, trunc, _ = env.step(np.zeros(2))
        assert not term
        truncations.append(trunc)
    assert truncations == [False] * 19 + [True]


def test_coverage_task_bins_cross_track_and_success():
    lines = (np.array([[0.0, 1.0], [10.0, 1.0]]), np.array([[0.0, 3.0], [5.0, 3.5], [10.0, 3.0]]))
    task = CoverageTask(lines, 0.5, CoverageWeights())
    assert task.n_bins.tolist() == [20, 20]
    k, d = task.locate(5.0, 3.4)
    assert k == 1 and d == pytest.approx(0.1 * math.cos(math.atan2(0.5, 5.0)))
    assert task.locate(-1.0, 1.0) == (-1, 0.0)
    for x in np.linspace(0.0, 10.0, 200):
        out = task.evaluate(np.array([x, 1.05, 0.0]), False, False)
    assert task.corridor_fractions().tolist() == [1.0, 0.0] and not out["is_success"]
    assert out["max_cross_track"] == pytest.approx(0.05)
    for x in np.linspace(10.0, 0.0, 200):
        out = task.evaluate(np.array([x, 3.0 + 0.5 * (1 - abs(x - 5) / 5), 0.0]), False, False)
    assert out["is_success"] and out["coverage"] == 1.0


def test_config_describe_lists_every_argument():
    rows = GreenhouseCoverageConfig().describe()
    assert {r[0] for r in rows} == set(GreenhouseCoverageConfig.field_names())


@pytest.mark.parametrize("kwargs", [{"row_bend": 0.15}, {"row_incline": 0.03}, {"corridor_width_jitter": 0.3}])
def test_a_corridor_with_exactly_the_margin_is_accepted(kwargs):
    """Each leaves 0.9 m (0.899997 m after tan()) of the 1.4 m corridor: the 0.2 m margin, to the millimetre."""
    env = gym.make(ENV_ID, **kwargs)
    env.reset(seed=0)
    env.close()
    with pytest.raises(ValueError, match="narrowest corridor"):
        gym.make(ENV_ID, **{k: v * 1.05 for k, v in kwargs.items()})


def test_episodes_equal_the_digests_recorded_before_resets_were_made_fast():
    """Seeded rollouts over 8 argument sets (shaped rows, limits, noise, echoes, localization)."""
    from greenhouse_reference import COVERAGE_ID, digests, recorded

    assert digests(COVERAGE_ID) == recorded(COVERAGE_ID)
