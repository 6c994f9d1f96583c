"""GreenhouseCoverage's batched form against single envs: bit for bit in every autoreset mode, options, API, frames.

The oracle and the contact check are :mod:`vector_oracle`'s.
"""

import math

import gymnasium as gym
import numpy as np
import pytest
import vector_oracle
from gymnasium.vector import AutoresetMode
from vector_oracle import assert_contacts_agree, assert_same

import agri_envs  # noqa: F401
from agri_envs.coverage.vector import GreenhouseCoverageVectorEnv

ENV_ID = "agri_envs/GreenhouseCoverage-v2"
#: A small greenhouse the steered sub-envs can cover: one row, two corridors of 3 m, 1 m bins.
SMALL = {"n_rows": 1, "row_length": 3.0, "bin_length": 1.0, "growth": 0.0, "layout_seed": 5}

#: Argument sets (max_episode_steps goes to gym.make / gym.make_vec), with the autoreset mode each runs in.
CASES = {
    "default": ({}, AutoresetMode.NEXT_STEP),
    "ground-truth": ({"localization": "ground_truth", "n_rows": 2, "row_length": 5.0}, AutoresetMode.SAME_STEP),
    "layout-fixed": ({"layout_seed": 3, "max_episode_steps": 40}, AutoresetMode.DISABLED),
    "shaped": (
        {"row_bend": 0.2, "row_incline": 0.02, "corridor_width": 2.0, "corridor_width_jitter": 0.3},
        AutoresetMode.NEXT_STEP,
    ),
    "time-limits": ({"time_limit": 3.0, "n_rows": 1, "max_episode_steps": 20}, AutoresetMode.SAME_STEP),
    "echoes-no-termination": (
        {"terminate_on_contact": False, "vegetation_echo_prob": 0.9, "reward_cross_track": 1.0, "growth": 1.0},
        AutoresetMode.NEXT_STEP,
    ),
    "noise-free": (
        {"sonar_noise_std": 0.0, "vegetation_echo_prob": 0.0, "compass_noise_std": 0.0, "encoder_noise": 0.0},
        AutoresetMode.DISABLED,
    ),
    "quick": ({"max_speed": 1.5, "max_accel": 2.0, "control_period": 0.5, "bin_length": 1.0}, AutoresetMode.NEXT_STEP),
    "small-covered": ({**SMALL, "terminate_on_contact": False}, AutoresetMode.NEXT_STEP),
    # the same at 2 Hz: the serpentine's subgoals are passed within the default run's 60 steps
    "small-quick": ({**SMALL, "terminate_on_contact": False, "control_period": 0.5}, AutoresetMode.SAME_STEP),
    # a greenhouse drawn per episode (sizes, shapes, growth, echoes): the arrays grow as larger ones come
    "distribution": ({"scene_distribution": "training", "max_episode_steps": 25}, AutoresetMode.SAME_STEP),
    # ... and its sensors too (echoes, compass noise and bias, encoder noise and drift): per-world values
    "robust": ({"scene_distribution": "robust", "max_episode_steps": 20}, AutoresetMode.NEXT_STEP),
    "progress-only": (
        {"reward_progress": 1.0, "reward_coverage": 0.0, "localization": "ground_truth", "n_rows": 3},
        AutoresetMode.DISABLED,
    ),
}


def _serpentine(kwargs):
    """Points through both corridors of a SMALL greenhouse and back (from a single env's corridor lines)."""
    env = gym.make(ENV_ID, **kwargs)
    env.reset(seed=0)
    (c0, c1) = env.unwrapped.corridor_lines()
    return np.array([c0[-1] + [0.9, 0.0], [c1[-1, 0] + 0.9, c1[-1, 1]], c1[0] - [0.9, 0.0], c0[0] - [0.5, 0.0]])


def _actions_for(kwargs):
    """Even sub-envs follow the serpentine of SMALL scenes (else wander forward), odd ones act at random."""
    route = _serpentine(kwargs) if kwargs.get("layout_seed") == SMALL["layout_seed"] else None
    progress = {}

    def actions(info, rng, n):
        a = rng.uniform(-1.0, 1.0, (n, 2))
        for i in range(0, n, 2):
            x, y, yaw = info["x"][i], info["y"][i], info["yaw"][i]
            if route is None:
                a[i] = (0.9 + rng.normal(0.0, 0.2), rng.normal(0.0, 0.6) - 0.3 * math.sin(yaw))
                continue
            k = progress.get(i, 0)
            if info["episode_time"][i] == 0.0:
                k = 0
            if math.hypot(route[k][0] - x, route[k][1] - y) < 0.5:
                k = min(k + 1, len(route) - 1)
            progress[i] = k
            bearing = math.atan2(route[k][1] - y, route[k][0] - x) - yaw
            bearing = math.atan2(math.sin(bearing), math.cos(bearing))
            a[i] = (0.9 if abs(bearing) < 0.4 else 0.0, max(-1.0, min(1.0, 3.0 * bearing)))
        return a.astype(np.float32)

    return actions


def run_against_single_envs(kwargs, mode, steps, seed=0):
    return vector_oracle.run_against_single_envs(ENV_ID, kwargs, mode, steps, _actions_for(kwargs), seed=seed)


@pytest.mark.parametrize("case", sorted(CASES))
def test_batched_steps_equal_the_single_envs(case, contacts):
    kwargs, mode = CASES[case]
    seen = run_against_single_envs(kwargs, mode, steps=60)
    assert seen["steps"] == 240
    assert_contacts_agree(contacts)


@pytest.mark.slow
def test_batched_equals_the_single_envs_over_thousands_of_steps(contacts):
    """Every case, longer and on other seeds: over 10,000 env-steps, with contacts, coverage and time limits."""
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


def test_options_seeds_and_masked_resets_equal_single_env_resets():
    vec = gym.make_vec(ENV_ID, num_envs=3, autoreset_mode=AutoresetMode.DISABLED, n_rows=2)
    singles = [gym.make(ENV_ID, n_rows=2) for _ in range(3)]
    obs, info = vec.reset(seed=[4, None, 6], options={"growth": [0.1, 0.5, 0.9], "layout_seed": 2})
    for i, growth in ((0, 0.1), (2, 0.9)):
        expected = singles[i].reset(seed=4 + i, options={"growth": growth, "layout_seed": 2})
        assert_same({k: v[i] for k, v in obs.items()}, expected[0])
        assert info["x"][i] == expected[1]["x"]
    obs, info = vec.reset(seed=[None, 9, None], options={"reset_mask": np.array([False, True, False])})
    assert info["_x"].tolist() == [False, True, False]
    assert_same({k: v[1] for k, v in obs.items()}, singles[1].reset(seed=9)[0])


def test_vector_api_frames_and_bad_arguments():
    envs = gym.make_vec(ENV_ID, num_envs=2, n_rows=2, render_mode="rgb_array", render_width=200)
    assert isinstance(envs, GreenhouseCoverageVectorEnv) and envs.action_space.shape == (2, 2)
    singles = [gym.make(ENV_ID, n_rows=2, render_mode="rgb_array", render_width=200) for _ in range(2)]
    obs, _ = envs.reset(seed=1)
    assert envs.observation_space.contains(obs)
    for i, env in enumerate(singles):
        env.reset(seed=1 + i)
    for a in np.random.default_rng(0).uniform(0.0, 1.0, (15, 2, 2)).astype(np.float32):
        obs, reward, terminated, truncated, info = envs.step(a)
        for i, env in enumerate(singles):
            env.step(a[i])
    assert envs.observation_space.contains(obs) and reward.dtype == np.float64
    for frame, env in zip(envs.render(), singles, strict=True):
        np.testing.assert_array_equal(frame, env.render())
    with pytest.raises(ValueError, match="n_rows"):
        gym.make_vec(ENV_ID, num_envs=2, n_rows=0)
    with pytest.raises(ValueError, match=r"sub-envs \[0\]"):
        envs.step(np.array([[np.inf, 0.0], [0.0, 0.0]]))
    with pytest.raises(ValueError, match="growth"):
        envs.reset(options={"growth": [0.1, 0.2, 0.3]})
    envs.close()
