"""GreenhouseNav's batched form against single envs: bit for bit in every autoreset mode, options, API, frames.

The oracle and the contact check are :mod:`vector_oracle`'s.
"""

import gymnasium as gym
import numpy as np
import pytest
import vector_oracle
from gymnasium.vector import AutoresetMode
from vector_oracle import assert_contacts_agree, assert_same

import agri_envs  # noqa: F401
from agri_envs.rover.vector import GreenhouseNavVectorEnv
from agri_envs.scenes import EXAMPLE_MAP

ENV_ID = "agri_envs/GreenhouseNav-v2"
MAP = {"scene": "map", "map_yaml": str(EXAMPLE_MAP), "waypoints": [[1.0, 0.6], [8.6, 0.6], [8.6, 2.2], [1.0, 2.2]]}

#: Argument sets (max_episode_steps goes to gym.make / gym.make_vec), with the autoreset mode each runs in.
CASES = {
    "default": ({}, AutoresetMode.NEXT_STEP),
    "people-tease-skip": (
        {"n_people": 5, "people_tease_prob": 0.8, "frame_skip": 4, "max_episode_steps": 60},
        AutoresetMode.NEXT_STEP,
    ),
    "growth-trees": ({"n_rows": 4, "growth": 0.8, "n_trees": 6, "corridor_width": 1.4}, AutoresetMode.SAME_STEP),
    "corridor-odometry": (
        {"scene": "corridor", "localization": "odometry", "max_episode_steps": 70},
        AutoresetMode.NEXT_STEP,
    ),
    "map": ({**MAP, "n_people": 1, "mission_cycles": 2, "max_episode_steps": 90}, AutoresetMode.DISABLED),
    "none-full-scan": (
        {"localization": "none", "full_scan": True, "lidar_beams": 811, "max_episode_steps": 45},
        AutoresetMode.SAME_STEP,
    ),
    "noisy-fast": (
        {"lidar_noise_std": 0.3, "lidar_dropout": 0.3, "sonar_noise_std": 0.2, "max_speed": 2.0, "max_accel": 10.0},
        AutoresetMode.NEXT_STEP,
    ),
    "small-mission-skip": (
        {"frame_skip": 4, "n_rows": 1, "row_length": 3.0, "terminate_on_collision": False, "n_people": 2},
        AutoresetMode.NEXT_STEP,
    ),
    "noise-free-no-termination": (
        {
            "lidar_noise_std": 0.0,
            "lidar_dropout": 0.0,
            "sonar_noise_std": 0.0,
            "terminate_on_collision": False,
            "layout_seed": 3,
            "max_episode_steps": 80,
        },
        AutoresetMode.DISABLED,
    ),
}


def _actions(info, rng, n):
    """Even sub-envs drive noisily toward their waypoint, odd ones act at random."""
    a = rng.uniform(-1.0, 1.0, (n, 2))
    bearing = info["bearing_to_waypoint"][::2]
    a[::2, 0] = np.where(np.abs(bearing) < 0.6, 0.8, 0.1) + rng.normal(0.0, 0.2, len(bearing))
    a[::2, 1] = np.clip(2.0 * bearing, -1.0, 1.0) + rng.normal(0.0, 0.3, len(bearing))
    return a.astype(np.float32)


def run_against_single_envs(kwargs, mode, steps, seed=0):
    return vector_oracle.run_against_single_envs(ENV_ID, kwargs, mode, steps, _actions, seed=seed)


@pytest.mark.parametrize("case", sorted(CASES))
def test_batched_steps_equal_the_single_envs(case, contacts):
    kwargs, mode = CASES[case]
    seen = run_against_single_envs(kwargs, mode, steps=60)
    assert seen["steps"] == 240
    assert_contacts_agree(contacts)


@pytest.mark.slow
def test_batched_equals_the_single_envs_over_thousands_of_steps(contacts):
    """Every case, longer and on other seeds: over 10,000 env-steps, with crashes, successes and time limits."""
    total = {"steps": 0, "terminated": 0, "truncated": 0, "collision": 0, "success": 0}
    for k, case in enumerate(sorted(CASES)):
        kwargs, mode = CASES[case]
        for key, value in run_against_single_envs(kwargs, mode, steps=300, seed=100 + 10 * k).items():
            total[key] += value
    print("env-steps and episode ends of the batched runs:", total, "contact questions:", len(contacts))
    assert total["steps"] >= 10_000
    assert total["collision"] > 10 and total["success"] > 0 and total["truncated"] > 50
    assert len(contacts) > 500  # the contact rule was exercised (and never disagreed, below)
    assert_contacts_agree(contacts)


def test_seeds_options_and_masked_resets_equal_single_env_resets():
    """Per-sub-env seeds and option arrays reach the sub-envs; a masked reset leaves the others alone."""
    n = 3
    vec = gym.make_vec(ENV_ID, num_envs=n, autoreset_mode=AutoresetMode.DISABLED, n_people=2)
    singles = [gym.make(ENV_ID, n_people=2) for _ in range(n)]
    obs, info = vec.reset(seed=[5, None, 7], options={"start_waypoint": [0, 3, 5], "growth": 0.4})
    assert info["waypoints_reached"].tolist() == [0, 3, 5]
    expected = singles[0].reset(seed=5, options={"start_waypoint": 0, "growth": 0.4})
    assert_same({k: v[0] for k, v in obs.items()}, expected[0])
    expected = singles[2].reset(seed=7, options={"start_waypoint": 5, "growth": 0.4})
    assert_same({k: v[2] for k, v in obs.items()}, expected[0])
    before = {k: v.copy() for k, v in obs.items()}
    obs, info = vec.reset(seed=[None, 11, None], options={"reset_mask": np.array([False, True, False])})
    assert info["_x"].tolist() == [False, True, False] and info["x"][0] == 0.0
    assert_same({k: v[1] for k, v in obs.items()}, singles[1].reset(seed=11)[0])
    for k in obs:
        np.testing.assert_array_equal(obs[k][[0, 2]], before[k][[0, 2]])
    # reset(seed=S) seeds sub-env i with S + i, as SyncVectorEnv does
    obs, _ = vec.reset(seed=20)
    for i, env in enumerate(singles):
        assert_same({k: v[i] for k, v in obs.items()}, env.reset(seed=20 + i)[0])


def test_same_seed_same_episodes_and_returned_arrays_are_fresh():
    a = gym.make_vec(ENV_ID, num_envs=2)
    b = gym.make_vec(ENV_ID, num_envs=2)
    obs_a, _ = a.reset(seed=3)
    obs_b, _ = b.reset(seed=3)
    assert_same(obs_a, obs_b)
    rng = np.random.default_rng(0)
    for _ in range(20):
        actions = rng.uniform(-1, 1, (2, 2))
        out_a, out_b = a.step(actions), b.step(actions)
        assert_same(out_a, out_b)
        out_a[0]["lidar"][:] = -1.0  # a caller's changes to returned arrays reach nothing
        out_a[4]["x"][:] = np.nan
    assert_same(a.step(np.zeros((2, 2))), b.step(np.zeros((2, 2))))
    other, _ = gym.make_vec(ENV_ID, num_envs=2).reset(seed=4)
    assert not np.array_equal(other["lidar"], obs_a["lidar"])


def test_vector_api_spaces_and_gymnasium_wrappers():
    envs = gym.make_vec(ENV_ID, num_envs=3, n_people=1, max_episode_steps=5)
    assert isinstance(envs, GreenhouseNavVectorEnv) and envs.num_envs == 3
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    single = gym.make(ENV_ID, n_people=1)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space and envs.action_space.shape == (3, 2)
    obs, _ = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    wrapped = gym.wrappers.vector.DictInfoToList(gym.wrappers.vector.RecordEpisodeStatistics(envs))
    wrapped.reset(seed=0)
    lengths = []
    for _ in range(6):
        obs, reward, terminated, truncated, infos = wrapped.step(wrapped.action_space.sample())
        assert envs.observation_space.contains(obs) and reward.dtype == np.float64
        assert isinstance(infos, list) and "is_success" in infos[0]
        lengths += [info["episode"]["l"] for info in infos if "episode" in info]
    assert lengths == [5, 5, 5]  # every sub-env truncated at its explicit limit
    assert all(
        info["truncation_reason"].startswith("time limit: 5 steps") for info in infos if "truncation_reason" in info
    )
    wrapped.close()


def test_rgb_frames_are_the_single_envs_frames():
    kwargs = {"n_people": 2, "frame_skip": 2, "render_width": 240}
    envs = gym.make_vec(ENV_ID, num_envs=2, render_mode="rgb_array", **kwargs)
    singles = [gym.make(ENV_ID, render_mode="rgb_array", **kwargs) for _ in range(2)]
    envs.reset(seed=4)
    for i, env in enumerate(singles):
        env.reset(seed=4 + i)
    actions = np.random.default_rng(2).uniform(-0.3, 1.0, (12, 2, 2)).astype(np.float32)
    for a in actions:
        envs.step(a)
        for i, env in enumerate(singles):
            env.step(a[i])
    frames = envs.render()
    assert len(frames) == 2 and frames[0].ndim == 3
    for frame, env in zip(frames, singles, strict=True):
        np.testing.assert_array_equal(frame, env.render())
    assert gym.make_vec(ENV_ID, num_envs=1).render() is None
    envs.close()
    envs.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        envs.step(np.zeros((2, 2)))


def test_bad_arguments_and_actions_are_refused_by_name():
    with pytest.raises(ValueError, match="num_envs"):
        GreenhouseNavVectorEnv(0)
    with pytest.raises(ValueError, match="autoreset_mode"):
        GreenhouseNavVectorEnv(2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="max_episode_steps"):
        GreenhouseNavVectorEnv(2, max_episode_steps=0)
    with pytest.raises(ValueError, match="render_mode"):
        GreenhouseNavVectorEnv(2, render_mode="human")
    with pytest.raises(ValueError, match="n_rows"):
        gym.make_vec(ENV_ID, num_envs=2, n_rows=0)
    with pytest.raises(ValueError, match="unknown argument"):
        gym.make_vec(ENV_ID, num_envs=2, n_robots=3)
    envs = gym.make_vec(ENV_ID, num_envs=3, autoreset_mode=AutoresetMode.DISABLED, max_episode_steps=2)
    with pytest.raises(RuntimeError, match="reset"):
        envs.step(np.zeros((3, 2)))
    obs, _ = envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(3, 2\)"):
        envs.step(np.zeros((2, 2)))
    with pytest.raises(ValueError, match=r"sub-envs \[1\]"):
        envs.step(np.array([[0.0, 0.0], [np.nan, 0.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="one per sub-env"):
        envs.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="reset_mask"):
        envs.reset(options={"reset_mask": [True, False, True]})
    with pytest.raises(ValueError, match="at least one"):
        envs.reset(options={"reset_mask": np.zeros(3, dtype=bool)})
    with pytest.raises(ValueError, match="start_waypoint"):
        envs.reset(options={"start_waypoint": [1, 2]})
    with pytest.raises(ValueError, match="start_waypoint"):
        envs.reset(options={"start_waypoint": 99})
    after, _ = envs.reset(seed=0)  # nothing was corrupted: the same seed gives the same episodes
    assert_same(after, obs)
    envs.step(np.zeros((3, 2)))
    envs.step(np.zeros((3, 2)))  # every sub-env is at its limit now
    with pytest.raises(RuntimeError, match=r"sub-envs \[0, 1, 2\] finished"):
        envs.step(np.zeros((3, 2)))
