"""The peers' own env tests over every env of the package: Gymnasium's for the Gymnasium ids (written after its
``tests/envs/test_envs.py``), PettingZoo's for the parallel envs (its ``pettingzoo.test`` suite).

The ids come from ``gym.registry`` (every ``agri_envs/`` id), so an env added later is covered without
editing this file; each runs with its defaults and, where listed in ``EXTRA_KWARGS``, with more argument
sets. Checks: the env checkers of Gymnasium and SB3 with the render check on, the determinism rollout
(two envs, same seed, same actions), pickling (the copy continues identically), every declared render
mode, ``render()`` warning under ``render_mode=None``, reset after ``close()``, a clean interpreter
exit for a script that never closes its env, Gymnasium's conventions on the made env (``gym.make(spec)``,
``check_env`` on the wrapped env), frames of one shape across episodes, pickling an env that has
rendered, and bad inputs (wrong types for every argument and reset option, malformed actions) refused
with errors that name them, leaving the env working.
"""

from __future__ import annotations

import dataclasses
import importlib
import pickle
import subprocess
import sys
import textwrap
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, parallel_seed_test, render_test, seed_test

import agri_envs
from agri_envs.scenes import EXAMPLE_MAP

ENV_IDS = sorted(env_id for env_id in gym.registry if env_id.startswith("agri_envs/"))

#: Argument sets beyond the defaults, per env id (short episodes, other scenes and modes).
EXTRA_KWARGS: dict[str, list[dict[str, Any]]] = {
    "agri_envs/GreenhouseNav-v2": [
        {"scene": "corridor", "n_people": 1, "full_scan": True, "localization": "none"},
        {"localization": "odometry", "lidar_beams": 30, "growth": 0.6, "n_trees": 3, "n_rows": 2},
    ],
    "agri_envs/GrapeHarvest-v1": [{"control": "ee", "reward_type": "dense"}],
    "agri_envs/GreenhouseCoverage-v2": [
        {"row_bend": 0.15, "corridor_width": 1.6, "corridor_width_jitter": 0.1, "vegetation_echo_prob": 0.2}
    ],
}

#: ``reset(options=...)`` keys that override config fields, per env id (wrong types must be named).
RESET_OPTIONS: dict[str, tuple[str, ...]] = {
    "agri_envs/GreenhouseNav-v2": ("growth", "n_trees", "layout_seed", "start_waypoint"),
    "agri_envs/GreenhouseCoverage-v2": ("growth", "layout_seed"),
}

#: Known failures that another branch fixes; strict, so the merge that fixes them flips the mark.
KNOWN_FAILURES: dict[tuple[str, str], str] = {}

CASES = [(env_id, kwargs) for env_id in ENV_IDS for kwargs in [{}, *EXTRA_KWARGS.get(env_id, [])]]
SEED = 0
NUM_STEPS = 40


def case_id(case: tuple[str, dict[str, Any]]) -> str:
    env_id, kwargs = case
    return env_id.split("/")[-1] + ("-" + "-".join(f"{k}={v}" for k, v in kwargs.items()) if kwargs else "")


def cases(check: str) -> list[Any]:
    """The (env id, kwargs) cases, with the known failures of ``check`` marked ``xfail(strict=True)``."""
    out = []
    for case in CASES:
        reason = KNOWN_FAILURES.get((case[0], check))
        marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
        out.append(pytest.param(*case, id=case_id(case), marks=marks))
    return out


def env_ids(check: str) -> list[Any]:
    """Every env id once, with the known failures of ``check`` marked ``xfail(strict=True)``."""
    out = []
    for env_id in ENV_IDS:
        reason = KNOWN_FAILURES.get((env_id, check))
        marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
        out.append(pytest.param(env_id, id=env_id.split("/")[-1], marks=marks))
    return out


def test_every_env_of_the_package_is_covered():
    assert {"agri_envs/GreenhouseNav-v2", "agri_envs/GrapeHarvest-v1"} <= set(ENV_IDS)
    assert set(EXTRA_KWARGS) <= set(ENV_IDS), "EXTRA_KWARGS names an env that is not registered"
    assert set(RESET_OPTIONS) <= set(ENV_IDS), "RESET_OPTIONS names an env that is not registered"


@pytest.mark.parametrize(("env_id", "kwargs"), cases("checkers"))
def test_env_checkers_with_render_check(env_id, kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=False)
    assert not [str(w.message) for w in caught], "Gymnasium's checker warned"
    env.close()
    # SB3's checker closes the env at the end of its render check. It warns about spaces its learners cannot
    # take as they are (a float box of image shape: GreenhouseCoverage-v1's memory): none may warn.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(gym.make(env_id, render_mode="rgb_array", **kwargs).unwrapped, skip_render_check=False)
    assert not [str(w.message) for w in caught], "SB3's checker warned"


@pytest.mark.parametrize(("env_id", "kwargs"), cases("determinism"))
def test_env_determinism_rollout(env_id, kwargs):
    """Two envs, same seed, same actions: identical observations, rewards, terminations and infos."""
    env_1 = gym.make(env_id, disable_env_checker=True, **kwargs)
    env_2 = gym.make(env_id, disable_env_checker=True, **kwargs)
    obs_1, info_1 = env_1.reset(seed=SEED)
    obs_2, info_2 = env_2.reset(seed=SEED)
    assert data_equivalence(obs_1, obs_2, exact=True)
    assert data_equivalence(info_1, info_2, exact=True)
    env_1.action_space.seed(SEED)
    for t in range(NUM_STEPS):
        action = env_1.action_space.sample()
        obs_1, rew_1, term_1, trunc_1, info_1 = env_1.step(action)
        obs_2, rew_2, term_2, trunc_2, info_2 = env_2.step(action)
        assert data_equivalence(obs_1, obs_2, exact=True), f"[{t}] observations differ"
        assert env_1.observation_space.contains(obs_1), f"[{t}] observation outside the space"
        assert rew_1 == rew_2 and term_1 == term_2 and trunc_1 == trunc_2, f"[{t}]"
        assert data_equivalence(info_1, info_2, exact=True), f"[{t}] infos differ"
        if term_1 or trunc_1:
            env_1.reset(seed=SEED)
            env_2.reset(seed=SEED)
    env_1.close()
    env_2.close()


@pytest.mark.parametrize(("env_id", "kwargs"), cases("pickle"))
def test_pickle_env(env_id, kwargs):
    """A pickled copy resets and steps like the original, and a copy taken mid-episode continues identically."""
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(SEED)
    action = env.action_space.sample()
    env_reset = env.reset(seed=123)
    env_step = env.step(action)
    copy = pickle.loads(pickle.dumps(env))
    assert data_equivalence(env_reset, copy.reset(seed=123))
    assert data_equivalence(env_step, copy.step(action))
    # Mid-episode: both continue with the same actions.
    for _ in range(5):
        env.step(env.action_space.sample())
    copy = pickle.loads(pickle.dumps(env))
    for t in range(10):
        action = env.action_space.sample()
        assert data_equivalence(env.step(action), copy.step(action), exact=True), f"[{t}] the copy diverged"
    env.close()
    copy.close()


@pytest.mark.parametrize(("env_id", "kwargs"), cases("render_modes"))
def test_render_modes(env_id, kwargs):
    """Every declared mode renders after reset: ``rgb_array`` an RGB frame, ``human`` a window (None)."""
    modes = gym.make(env_id, **kwargs).metadata["render_modes"]
    assert "rgb_array" in modes
    for mode in modes:
        env = gym.make(env_id, render_mode=mode, **kwargs)
        env.reset(seed=SEED)
        env.step(env.action_space.sample())
        frame = env.render()
        if mode == "rgb_array":
            assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
            assert frame.ndim == 3 and frame.shape[2] == 3 and frame.shape[0] > 0 and frame.shape[1] > 0
            assert frame.std() > 0, "blank frame"
        else:
            assert frame is None
        env.close()
        env.close()  # idempotent


@pytest.mark.parametrize("env_id", env_ids("render_none_warns"))
def test_render_without_render_mode_warns(env_id):
    env = gym.make(env_id).unwrapped  # the raw env: the passive checker wrapper would warn on its own
    env.reset(seed=SEED)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    env.close()


@pytest.mark.parametrize(("env_id", "kwargs"), cases("reset_after_close"))
def test_reset_after_close(env_id, kwargs):
    """``close()`` then ``reset()`` gives a working env, the same as a fresh one for the same seed."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=SEED)
    env.step(env.action_space.sample())
    env.close()
    obs, info = env.reset(seed=SEED)
    fresh = gym.make(env_id, **kwargs)
    assert data_equivalence((obs, info), fresh.reset(seed=SEED), exact=True)
    action = env.action_space.sample()
    assert data_equivalence(env.step(action), fresh.step(action), exact=True)
    env.close()
    fresh.close()


@pytest.mark.parametrize("env_id", env_ids("clean_exit"))
def test_script_that_never_closes_its_env_exits_cleanly(env_id):
    """No "Exception ignored ..." noise at interpreter exit when a script leaves its env open.

    The env is kept alive into the interpreter's final phase, where it wipes module globals (here
    through ``sys``, which is wiped last; in real scripts a long-lived module or object does the same).
    An engine object freed after its module's globals are gone fails in its finalizer; pymunk's Space
    did (``spacefree ... 'NoneType' object has no attribute 'new_handle'``).
    """
    script = textwrap.dedent(
        f"""
        import sys
        import gymnasium as gym
        import agri_envs
        env = gym.make({env_id!r})
        env.reset(seed=0)
        for _ in range(3):
            env.step(env.action_space.sample())
        modules = [m for name, m in sys.modules.items() if name.startswith(("pymunk", "pybullet"))]
        sys._agri_test_keep_alive = (env, modules)
        print("ok")
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr
    # pybullet announces itself on stderr at import; anything else is noise.
    noise = [line for line in out.stderr.splitlines() if line.strip() and not line.startswith("pybullet build time")]
    assert not noise, out.stderr


@pytest.mark.parametrize(("env_id", "kwargs"), cases("make_from_spec"))
def test_make_from_spec(env_id, kwargs):
    """``gym.make(env.spec)`` rebuilds the same env, wrappers and explicit time limit included."""
    for extra in ({}, {"max_episode_steps": 7}):
        env = gym.make(env_id, **kwargs, **extra)
        again = gym.make(env.spec)
        assert again.spec == env.spec
        assert str(again) == str(env)
        assert data_equivalence(env.reset(seed=SEED), again.reset(seed=SEED), exact=True)
        action = env.action_space.sample()
        assert data_equivalence(env.step(action), again.step(action), exact=True)
        env.close()
        again.close()


@pytest.mark.parametrize(("env_id", "kwargs"), cases("check_made_env"))
def test_check_env_on_the_made_env(env_id, kwargs):
    """Gymnasium's checker accepts the env as ``gym.make`` returns it (wrappers and all), not only unwrapped."""
    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=False)
    # The only expected warning is the checker's advice to pass the unwrapped env.
    other = [str(w.message) for w in caught if "different from the unwrapped version" not in str(w.message)]
    assert not other, "Gymnasium's checker warned"
    env.close()


@pytest.mark.parametrize(("env_id", "kwargs"), cases("fixed_frame_size"))
def test_frames_keep_one_shape_across_episodes(env_id, kwargs):
    """Every episode's frame has the env's one shape (vector-env tiling and video writers need it)."""
    env = gym.make(env_id, render_mode="rgb_array", **kwargs)
    shapes = set()
    for seed in range(4):
        env.reset(seed=seed)
        shapes.add(env.render().shape)
        env.step(env.action_space.sample())
        shapes.add(env.render().shape)
    env.close()
    assert len(shapes) == 1, f"frame shapes differ between episodes: {sorted(shapes)}"


@pytest.mark.parametrize("env_id", env_ids("pickle_rendering"))
def test_pickle_a_rendering_env(env_id):
    """An env that has rendered pickles (the copy makes its own renderer) and draws frames of the same shape."""
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=SEED)
    frame = env.render()
    copy = pickle.loads(pickle.dumps(env))
    assert copy.render().shape == frame.shape
    env.close()
    copy.close()


def _numeric_fields(env_id):
    """``(name, expected type word)`` of every int, float and bool argument of ``env_id``'s config."""
    config = gym.make(env_id, disable_env_checker=True).unwrapped.config
    out = []
    for f in dataclasses.fields(config):
        if isinstance(f.default, bool):
            out.append((f.name, "bool"))
        elif isinstance(f.default, int):
            out.append((f.name, "integer"))
        elif isinstance(f.default, float):
            out.append((f.name, "number"))
    return out


@pytest.mark.parametrize("env_id", env_ids("bad_argument_types"))
def test_wrong_argument_types_are_named(env_id):
    """A string or None for any numeric ``gym.make`` argument: a ValueError naming it and the expected type."""
    fields = _numeric_fields(env_id)
    assert fields
    for name, expected in fields:
        for bad in ("a", None, [1.0]):
            with pytest.raises(ValueError, match=rf"{name}=.*must be (a|an) {expected}"):
                gym.make(env_id, disable_env_checker=True, **{name: bad})


@pytest.mark.parametrize("env_id", sorted(RESET_OPTIONS))
def test_wrong_reset_option_types_are_named_and_leave_the_env_working(env_id):
    env = gym.make(env_id, disable_env_checker=True)
    fresh = gym.make(env_id, disable_env_checker=True)
    env.reset(seed=SEED)
    for name in RESET_OPTIONS[env_id]:
        for bad in ("a", None, 0.5j):
            with pytest.raises(ValueError, match=rf"reset option.*{name}=.*must be (a|an) (number|integer)"):
                env.reset(seed=SEED + 1, options={name: bad})
    # Nothing was corrupted: the env goes on exactly like a fresh one.
    assert data_equivalence(env.reset(seed=SEED), fresh.reset(seed=SEED), exact=True)
    for _ in range(3):
        action = env.action_space.sample()
        assert data_equivalence(env.step(action), fresh.step(action), exact=True)


@pytest.mark.parametrize("env_id", env_ids("bad_actions"))
def test_malformed_actions_are_named_and_leave_the_env_working(env_id):
    """A dict, a string, a wrong shape or NaN as the action: a ValueError saying what was expected."""
    env = gym.make(env_id, disable_env_checker=True)
    fresh = gym.make(env_id, disable_env_checker=True)
    env.reset(seed=SEED)
    fresh.reset(seed=SEED)
    size = env.action_space.shape[0]
    for bad in ({"v": 0.0}, "ab", np.zeros(size + 1), np.zeros((size, 1)), np.full(size, np.nan)):
        with pytest.raises(ValueError, match=rf"action (must|contains).*(\({size},\)|NaN)"):
            env.step(bad)
    for _ in range(3):
        action = env.action_space.sample()
        assert data_equivalence(env.step(action), fresh.step(action), exact=True)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_registered_spec_equals_its_json_round_trip(env_id):
    # GreenhouseNav-v2's spec (a subclass that make_vec copies without its wrapper) did not equal its own
    # to_json/from_json round trip, a plain EnvSpec.
    from gymnasium.envs.registration import EnvSpec

    spec = gym.spec(env_id)
    back = EnvSpec.from_json(spec.to_json())
    assert back == spec and spec == back and not back != spec


@pytest.mark.xfail(
    strict=True,
    reason="Gymnasium 1.4's make_vec refuses a vector_entry_point beside additional_wrappers and builds sync/async "
    "sub-envs from the same copy of the spec, so they cannot get SyncTimeLimit while the native vector env stays "
    "make_vec's default (agri_envs._SpecWithVectorForm)",
)
@pytest.mark.parametrize("mode", ["sync", "async"])
def test_sync_and_async_sub_envs_keep_an_explicit_step_limit(mode):
    envs = gym.make_vec("agri_envs/GreenhouseNav-v2", num_envs=2, vectorization_mode=mode, max_episode_steps=20)
    try:
        envs.reset(seed=0)
        info = envs.step(envs.action_space.sample())[-1]
        assert list(info["max_episode_steps"]) == [20, 20]
    finally:
        envs.close()


VECTOR_IDS = sorted(env_id for env_id in ENV_IDS if gym.spec(env_id).vector_entry_point is not None)


@pytest.mark.parametrize("env_id", VECTOR_IDS)
def test_batched_form_reports_its_seeds_as_sync_vector_env_does(env_id):
    # SyncVectorEnv (the oracle) reports its sub-envs' seeds; the batched forms reported a random 128-bit number.
    native = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    sync = gym.make_vec(env_id, num_envs=3, vectorization_mode="sync")
    assert not isinstance(native.unwrapped, gym.vector.SyncVectorEnv)
    try:
        # An unseeded reset keeps each sub-env's seed.
        for seed, seeds in ((42, (42, 43, 44)), ([7, 8, 9], (7, 8, 9)), (None, (7, 8, 9))):
            native.reset(seed=seed)
            sync.reset(seed=seed)
            assert native.np_random_seed == sync.np_random_seed == seeds
            assert all(type(s) is int for s in native.np_random_seed)
            assert [g.bit_generator.state for g in native.np_random] == [
                g.bit_generator.state for g in sync.np_random
            ]
        native.step(native.action_space.sample())
        assert native.np_random_seed == (7, 8, 9)
    finally:
        native.close()
        sync.close()


def test_one_registry_builds_every_env_of_both_kinds():
    ids = agri_envs.env_ids()
    assert "robot_chain_v1" in ids and set(ENV_IDS) <= set(ids)
    for env_id in ids:
        env = agri_envs.make(env_id)
        try:
            assert agri_envs.env_version(env_id) in {"v0", "v1", "v2"}
            assert hasattr(env, "possible_agents") == agri_envs.is_parallel_id(env_id)
        finally:
            env.close()
    with pytest.raises(ValueError, match="unknown env id 'CartPole-v1'.*robot_chain_v1"):
        agri_envs.make("CartPole-v1")


# ---------------------------------------------------------------- PettingZoo envs (agri_envs.PARALLEL_ENVS)

PARALLEL_IDS = sorted(agri_envs.PARALLEL_ENVS)

#: Argument sets beyond the defaults, per PettingZoo id (robot counts, scenes, a loaded map).
PARALLEL_EXTRA_KWARGS: dict[str, list[dict[str, Any]]] = {
    "robot_chain_v1": [
        {"n_robots": 1},
        {"n_robots": 2, "n_dynamic_obstacles": 0},
        {"n_robots": 16, "office_width": 18.0, "office_height": 12.0, "min_goal_distance": 3.0},
        {"n_robots": 4, "scene": "greenhouse", "n_rows": 2},
        {"n_robots": 3, "scene": "map", "map_yaml": str(EXAMPLE_MAP), "min_goal_distance": 2.0},
        {"n_robots": 8, "scene_distribution": "robust"},
    ],
}
PARALLEL_CASES = [
    pytest.param(env_id, kwargs, id=env_id + "".join(f"-{k}={v}" for k, v in kwargs.items() if k != "map_yaml"))
    for env_id in PARALLEL_IDS
    for kwargs in [{}, *PARALLEL_EXTRA_KWARGS.get(env_id, [])]
]


def versioned_module(env_id: str) -> Any:
    """The env's versioned PettingZoo module (``parallel_env``, ``env``, ``raw_env``)."""
    return importlib.import_module(agri_envs.PARALLEL_ENVS[env_id])


@pytest.mark.parametrize(("env_id", "kwargs"), PARALLEL_CASES)
def test_pettingzoo_parallel_and_aec_api(env_id, kwargs):
    module = versioned_module(env_id)
    parallel_api_test(module.parallel_env(terminate_on_collision=False, **kwargs), num_cycles=60)
    api_test(module.env(terminate_on_collision=False, **kwargs), num_cycles=20)


@pytest.mark.parametrize("env_id", PARALLEL_IDS)
def test_pettingzoo_seeding_max_cycles_and_render(env_id):
    module = versioned_module(env_id)
    seed_test(lambda: module.env(sonar_noise_std=0.05), num_cycles=30)
    parallel_seed_test(lambda: module.parallel_env(sonar_noise_std=0.05), num_cycles=30)
    max_cycles_test(module)
    render_test(lambda render_mode=None: module.env(render_mode=render_mode, render_width=200))


@pytest.mark.parametrize(("env_id", "kwargs"), PARALLEL_CASES[:1] + PARALLEL_CASES[4:5] + PARALLEL_CASES[-1:])
def test_pettingzoo_frames_keep_one_shape_across_episodes(env_id, kwargs):
    env = agri_envs.make(env_id, render_mode="rgb_array", render_width=200, **kwargs)
    shapes = set()
    for seed in range(3):
        env.reset(seed=seed)
        shapes.add(env.render().shape)
    env.close()
    assert len(shapes) == 1, shapes
