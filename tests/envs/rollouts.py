"""Helpers shared by the env tests: seeded random rollouts and their bit-for-bit comparison."""

import json

import numpy as np


def rollout(env, seed, n, action_seed=0):
    """``n`` uniformly random actions from ``reset(seed=seed)``, resetting on episode end.

    Returns:
        ``[(obs, reward, info), ...]``, the reset included.
    """
    rng = np.random.default_rng(action_seed)
    shape = env.action_space.shape
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for _ in range(n):
        obs, r, te, tr, info = env.step(rng.uniform(-1, 1, shape).astype(np.float32))
        out.append((obs, r, info))
        if te or tr:
            obs, info = env.reset()
            out.append((obs, 0.0, info))
    return out


def assert_same(a, b):
    """Two rollouts are identical: same observation keys and arrays, rewards and infos."""
    assert len(a) == len(b)
    for (o1, r1, i1), (o2, r2, i2) in zip(a, b, strict=True):
        assert o1.keys() == o2.keys()
        for k in o1:
            assert np.array_equal(o1[k], o2[k]), k
        assert r1 == r2
        assert json.dumps(i1, sort_keys=True, default=str) == json.dumps(i2, sort_keys=True, default=str)
