"""The oracle of the batched 2D envs: Gymnasium's SyncVectorEnv over gym.make single envs, compared to the bit.

Gymnasium's own ``SyncVectorEnv`` over ``gym.make`` single envs (the pymunk reference), stepped with the same
actions, resets finished sub-envs the way each autoreset mode says and lays ``info`` out as Gymnasium defines,
so observations, rewards, flags and every ``info`` array and mask of a batched env must equal its to the bit.

Contact is the one place where the two compute differently: the single env asks pymunk whether the robot's
box overlaps anything, the batched env whether the exact footprint distance is <= 0. Both are exact
geometry, so they can disagree only for a pose that touches an obstacle exactly, to within rounding. The
``contacts`` fixture (``tests/envs/conftest.py``) records each contact question the single envs ask, and
:func:`assert_contacts_agree` checks that the two answers never differed and that no question came within
1e-12 m of an exact touch.
"""

import math

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import agri_envs  # noqa: F401


def assert_contacts_agree(asked):
    """pymunk and the exact footprint distance gave the same answers, never near an exact touch."""
    assert all(hit == (clearance <= 0.0) for hit, clearance in asked), "pymunk and the footprint distance disagree"
    assert min((abs(c) for _, c in asked), default=1.0) > 1e-12


def assert_same(a, b, where=""):
    """Equal to the bit: same keys, dtypes and bytes (signed zeros too); object arrays element by element."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), (where, set(a) ^ set(b))
        for key in a:
            assert_same(a[key], b[key], f"{where}/{key}")
    elif isinstance(a, tuple):
        assert len(a) == len(b)
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{k}]")
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert b.dtype == object and a.shape == b.shape, where
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert (x is None) == (y is None), (where, k)
            if x is not None:
                assert_same(x, y, f"{where}[{k}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, (where, a.dtype, b.dtype)
        assert a.tobytes() == b.tobytes(), (where, a, b)
    else:
        assert type(a) is type(b) and (a == b or (a != a and b != b)), (where, a, b)
        if isinstance(a, float):
            assert math.copysign(1.0, a) == math.copysign(1.0, b), where


def run_against_single_envs(env_id, kwargs, mode, steps, actions, num_envs=4, seed=0):
    """Step ``gym.make_vec(env_id)`` and a SyncVectorEnv of ``gym.make(env_id)`` side by side, asserting equality.

    Args:
        env_id: The env id.
        kwargs: Its arguments (``max_episode_steps`` too).
        mode: The autoreset mode of both.
        steps: Steps to take.
        actions: ``actions(info, rng, num_envs)``: the next actions, from the last info dict of arrays.
        num_envs: Sub-envs of each.
        seed: Seed of the first reset (sub-env i gets seed + i) and of the actions.

    Returns:
        Counts of what happened: env-steps, terminations, truncations, steps in contact, successes.
    """
    vec = gym.make_vec(env_id, num_envs=num_envs, autoreset_mode=mode, **kwargs)
    ref = gym.vector.SyncVectorEnv([lambda: gym.make(env_id, **kwargs)] * num_envs, autoreset_mode=mode)
    first = vec.reset(seed=seed)
    assert_same(first, ref.reset(seed=seed), "reset")
    info = first[1]
    rng = np.random.default_rng(seed + 1)
    seen = {"steps": 0, "terminated": 0, "truncated": 0, "collision": 0, "success": 0}
    for t in range(steps):
        a = actions(info, rng, num_envs)
        out = vec.step(a)
        assert_same(out, ref.step(a), f"step {t}")
        _, _, terminated, truncated, info = out
        seen["steps"] += num_envs
        seen["terminated"] += int(terminated.sum())
        seen["truncated"] += int(truncated.sum())
        seen["collision"] += int(info["collision"].sum())
        seen["success"] += int((info["is_success"] & terminated).sum())
        if mode == AutoresetMode.DISABLED and (terminated | truncated).any():
            mask = terminated | truncated
            again = vec.reset(options={"reset_mask": mask})
            assert_same(again, ref.reset(options={"reset_mask": mask.copy()}), f"reset {t}")
            info = {key: np.where(mask, again[1][key], value) for key, value in info.items() if key in again[1]}
    vec.close()
    ref.close()
    return seen
