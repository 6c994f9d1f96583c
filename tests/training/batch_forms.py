"""A check shared by the observation wrappers' tests: their batch forms give each sub-env the single env's bits."""

import functools

import gymnasium as gym
import numpy as np

from agri_training.learned.policy import apply_wrappers
from agri_training.learned.vector import apply_vector_wrappers, make_sync_vector_env


def assert_batch_matches_single_envs(env_id, kwargs, wrappers, steps=40):
    """Step ``wrappers``' vector forms over sub-envs ``kwargs`` and the single wrappers over one env each, with the
    same seeds and random actions, through masked resets; every observation must be the same bits."""
    single = [apply_wrappers(gym.make(env_id, **kw), wrappers) for kw in kwargs]
    batch = apply_vector_wrappers(
        make_sync_vector_env([functools.partial(gym.make, env_id, **kw) for kw in kwargs]), wrappers
    )
    assert batch.single_observation_space == single[0].observation_space
    n = len(kwargs)
    obs, _ = batch.reset(seed=[5 + i for i in range(n)])
    rows = [env.reset(seed=5 + i)[0] for i, env in enumerate(single)]
    rng = np.random.default_rng(1)
    for step in range(steps):
        np.testing.assert_array_equal(obs, np.stack(rows), err_msg=f"step {step}")
        actions = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
        obs, _, term, trunc, _ = batch.step(actions)
        rows = []
        for i, env in enumerate(single):
            row, _, t, u, _ = env.step(actions[i])
            if t or u:
                row = env.reset()[0]
            rows.append(row)
        done = term | trunc
        if done.any():
            obs, _ = batch.reset(options={"reset_mask": done})
