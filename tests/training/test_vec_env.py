"""Gymnasium vector envs under SB3: the VecEnv adapter against DummyVecEnv, and the training's vector wrappers.

The oracle is SB3's own ``DummyVecEnv`` of the same single envs: for the same seeds and actions the adapter
must hand SB3 the same observations, rewards, dones, infos and terminal observations, with the training's
observation wrappers, curricula, ``Monitor`` statistics and ``VecNormalize`` on top.
"""

import dataclasses
import functools
import os
import types

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

import agri_envs  # noqa: F401
from agri_training.learned.curricula import (
    TRAIN_WRAPPERS,
    VECTOR_TRAIN_WRAPPERS,
    RandomStartWaypoint,
    VectorCrashCostRamp,
    VectorRandomStartWaypoint,
)
from agri_training.learned.policy import WRAPPERS, apply_wrappers
from agri_training.learned.vec_env import VectorVecEnv
from agri_training.learned.vector import (
    VECTOR_WRAPPERS,
    OptionsSyncVectorEnv,
    apply_vector_wrappers,
    make_sync_vector_env,
    split_info,
)
from agri_training.train import (
    TrainRequest,
    idle_cores,
    make_vec_env,
    make_vector_train_env,
    resolve_config,
    train,
    with_update_threads,
)

ENV_ID = "agri_envs/GreenhouseNav-v2"
#: Short episodes (truncations), people who stand in the way (collisions), and the recipe's wrappers.
SMALL = {"n_rows": 2, "row_length": 4.0, "n_people": 2, "people_tease_prob": 0.6, "max_episode_steps": 25}
RECIPE = {
    "n_envs": 4,
    "env_kwargs": SMALL,
    # the recipe's own envs draw scenes from the training distribution: here SMALL ones
    "train_env_kwargs": {"scene_distribution": "off"},
    "eval_env_kwargs": {"scene_distribution": "off"},
    "pretrain": None,
    "train_wrappers": [{"RandomStartWaypoint": {"prob": 0.5}}, {"CrashCostRamp": {"start": 0.1, "ramp_steps": 40}}],
}


def _pair(seed=7, **overrides):
    """The same training envs through DummyVecEnv (today's path) and through the adapter (vec_env: vector)."""
    venvs = []
    for kind in ("dummy", "vector"):
        hp = {**RECIPE, **overrides, "vec_env": kind}
        venvs.append(make_vec_env(resolve_config(TrainRequest(ENV_ID, "ppo", "unused", seed=seed, overrides=hp))))
    return venvs


def _assert_same_info(a, b, where):
    assert set(a) == set(b), (where, set(a) ^ set(b))
    for key, value in a.items():
        other = b[key]
        if key == "episode":  # Monitor rounds its float64 sum to 1e-6, VecMonitor sums float32 rewards
            assert value["l"] == other["l"] and value["is_success"] == other["is_success"], where
            assert abs(value["r"] - other["r"]) <= 1e-4 * max(1.0, abs(value["r"])), where
        elif isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, other, err_msg=f"{where} {key}")
        else:
            assert value == other and type(value) is type(other), (where, key, value, other)


def test_the_adapter_gives_sb3_what_dummy_vec_env_gives():
    old, new = _pair()
    np.testing.assert_array_equal(old.reset(), new.reset())
    rng = np.random.default_rng(0)
    seen = {"terminated": 0, "truncated": 0, "crash": 0, "late_start": 0}
    for step in range(160):
        actions = rng.uniform(-1, 1, (4, 2)).astype(np.float32)
        obs_a, rew_a, done_a, infos_a = old.step(actions)
        obs_b, rew_b, done_b, infos_b = new.step(actions)
        np.testing.assert_array_equal(obs_a, obs_b, err_msg=f"step {step}")
        np.testing.assert_array_equal(rew_a, rew_b, err_msg=f"step {step}")
        np.testing.assert_array_equal(done_a, done_b, err_msg=f"step {step}")
        np.testing.assert_array_equal(old.get_original_obs(), new.get_original_obs())
        np.testing.assert_array_equal(old.get_original_reward(), new.get_original_reward())
        for i, (a, b) in enumerate(zip(infos_a, infos_b, strict=True)):
            _assert_same_info(a, b, f"step {step} env {i}")
            if done_a[i]:
                seen["truncated" if a["TimeLimit.truncated"] else "terminated"] += 1
            seen["crash"] += a["reward_collision"] != 0
        seen["late_start"] += sum(info.get("waypoint_index", 0) > 0 for info in new.unwrapped.reset_infos)
    # The window saw every case: episodes ending both ways, crashes under the cost ramp, starts on the way.
    assert all(seen.values()), seen
    # VecNormalize's statistics (saved to normalize.json) come out the same.
    np.testing.assert_array_equal(old.obs_rms.mean, new.obs_rms.mean)
    np.testing.assert_array_equal(old.obs_rms.var, new.obs_rms.var)
    np.testing.assert_array_equal(old.ret_rms.var, new.ret_rms.var)


class _DictEnv(gym.Env):
    """A small seeded env with Dict observations, random episode ends and a time limit (for the adapter alone)."""

    observation_space = gym.spaces.Dict(
        {"a": gym.spaces.Box(-10, 10, (3,), np.float32), "b": gym.spaces.Box(0, 5, (2, 2), np.float32)}
    )
    action_space = gym.spaces.Box(-1, 1, (2,), np.float32)

    def _obs(self):
        return {"a": self.state[:3].copy(), "b": self.state[3:].reshape(2, 2).copy()}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = self.np_random.uniform(0, 1, 7).astype(np.float32) + float((options or {}).get("offset", 0))
        return self._obs(), {"start": float(self.state[0]), "vector": self.state[:2].copy()}

    def step(self, action):
        self.state = self.state + np.float32(0.1) * action.sum() + self.np_random.normal(0, 0.1, 7).astype(np.float32)
        done = bool(self.np_random.random() < 0.08)
        info = {"value": float(self.state.sum()), "is_success": done}
        if done:
            info["only_at_the_end"] = 1
        return self._obs(), float(self.state[0]), done, False, info


def _dict_env():
    return gym.wrappers.TimeLimit(_DictEnv(), 12)


def test_the_adapter_on_dict_observations_seeds_options_and_infos():
    dummy = VecMonitor(DummyVecEnv([_dict_env] * 3), info_keywords=("is_success",))
    adapter = VecMonitor(VectorVecEnv(make_sync_vector_env([_dict_env] * 3)), info_keywords=("is_success",))
    for venv in (dummy, adapter):
        venv.seed(11)
        venv.set_options([{"offset": 2.0}, {"offset": 3.0}, {"offset": 2.0}])  # one sub-env differs
    a, b = dummy.reset(), adapter.reset()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert dummy.venv.reset_infos[1]["start"] == adapter.venv.reset_infos[1]["start"] > 3.0
    rng = np.random.default_rng(1)
    ends = 0
    for step in range(60):
        actions = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        (oa, ra, da, ia), (ob, rb, db, ib) = dummy.step(actions), adapter.step(actions)
        for key in oa:
            np.testing.assert_array_equal(oa[key], ob[key])
        np.testing.assert_array_equal(ra, rb)
        np.testing.assert_array_equal(da, db)
        for i in range(3):
            assert set(ia[i]) == set(ib[i]), (step, i)
            for key, value in ia[i].items():
                if key == "terminal_observation":
                    for part in value:
                        np.testing.assert_array_equal(value[part], ib[i][key][part])
                elif key != "episode":
                    assert value == ib[i][key], (step, i, key)
            if da[i]:
                ends += 1
                assert ia[i]["episode"]["l"] == ib[i]["episode"]["l"]
                for part in ("start", "vector"):  # the reset info of the new episode
                    np.testing.assert_array_equal(dummy.venv.reset_infos[i][part], adapter.venv.reset_infos[i][part])
    assert ends >= 5


def test_the_adapter_refuses_a_vector_env_that_resets_itself():
    env = gym.vector.SyncVectorEnv([_dict_env] * 2, autoreset_mode=AutoresetMode.NEXT_STEP)
    with pytest.raises(ValueError, match="AutoresetMode.DISABLED"):
        VectorVecEnv(env)


def test_history_restarts_only_in_the_sub_env_whose_episode_ended():
    frames = 3
    kwargs = [{**SMALL, "max_episode_steps": 11 + 7 * i} for i in range(3)]  # episodes end at different steps
    single = [apply_wrappers(gym.make(ENV_ID, **kw), ["FlattenObservation"]) for kw in kwargs]
    venv = VectorVecEnv(
        apply_vector_wrappers(
            make_sync_vector_env([functools.partial(gym.make, ENV_ID, **kw) for kw in kwargs]),
            ["FlattenObservation", {"ObservationHistory": {"frames": frames}}],
        )
    )
    venv.seed(5)
    obs = venv.reset()
    history = [[env.reset(seed=5 + i)[0]] * frames for i, env in enumerate(single)]
    np.testing.assert_array_equal(obs, np.stack([np.concatenate(h) for h in history]))
    rng = np.random.default_rng(2)
    lone_restarts = 0
    for _ in range(60):
        actions = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        obs, _, dones, infos = venv.step(actions)
        for i, env in enumerate(single):
            flat, _, term, trunc, _ = env.step(actions[i])
            history[i] = [*history[i][1:], flat]
            assert dones[i] == (term or trunc)
            if dones[i]:
                # the final observation holds the ended episode's frames; the new one only its first frame
                np.testing.assert_array_equal(infos[i]["terminal_observation"], np.concatenate(history[i]))
                history[i] = [env.reset()[0]] * frames
            np.testing.assert_array_equal(obs[i], np.concatenate(history[i]))
        lone_restarts += 0 < dones.sum() < 3
    assert lone_restarts >= 3


@pytest.mark.parametrize(
    "kwargs, batched",
    [(SMALL, False), ({"scene_distribution": "training", "max_episode_steps": 25}, True)],
    ids=["sync", "batched-distribution"],
)
def test_random_start_waypoint_draws_per_sub_env_as_the_single_wrapper_does(kwargs, batched):
    n = 4
    if batched:  # the recipe's training envs: the batched env, a scene (and mission) drawn per episode
        envs = gym.make_vec(
            ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=AutoresetMode.DISABLED, **kwargs
        )
    else:
        envs = make_sync_vector_env([lambda: gym.make(ENV_ID, **kwargs)] * n)
    vector = VectorRandomStartWaypoint(envs, prob=0.7)
    singles = [RandomStartWaypoint(gym.make(ENV_ID, **kwargs), prob=0.7) for _ in range(n)]
    _, info = vector.reset(seed=20)
    for i, env in enumerate(singles):
        assert env.reset(seed=20 + i)[1]["waypoint_index"] == info["waypoint_index"][i]
    starts = set()
    for _ in range(6):  # masked resets: only the chosen sub-envs draw (and advance their own generators)
        mask = np.array([True, False, True, True])
        _, info = vector.reset(options={"reset_mask": mask})
        for i in np.flatnonzero(mask):
            expected = singles[i].reset()[1]["waypoint_index"]
            assert info["waypoint_index"][i] == expected and info["_waypoint_index"][i]
            starts.add(expected)
        assert not info["_waypoint_index"][1]
    assert len(starts) >= 3  # the sub-envs start at different waypoints


def test_crash_cost_ramp_refunds_only_the_sub_env_that_crashed():
    class Crashes(gym.vector.VectorEnv):
        metadata = {"autoreset_mode": AutoresetMode.DISABLED}
        num_envs = 3

        def step(self, actions):
            info = {"reward_collision": np.array([0.0, -20.0, -50.0]), "_reward_collision": np.array([1, 1, 0], bool)}
            return np.zeros((3, 1)), np.array([1.0, -19.0, -49.0]), np.zeros(3, bool), np.zeros(3, bool), info

    ramp = VectorCrashCostRamp(Crashes(), start=0.25, ramp_steps=2)
    np.testing.assert_allclose(ramp.step(None)[1], [1.0, -19.0 + (1 - 0.625) * 20, -49.0])
    np.testing.assert_allclose(ramp.step(None)[1], [1.0, -19.0, -49.0])  # ramp over: the env's own reward


def test_per_sub_env_reset_options_reach_their_sub_env():
    venv = OptionsSyncVectorEnv([lambda: gym.make(ENV_ID, **SMALL)] * 3, autoreset_mode=AutoresetMode.DISABLED)
    _, info = venv.reset(seed=1, options={"start_waypoint": np.array([0, 2, 3])})
    assert info["waypoint_index"].tolist() == [0, 2, 3]
    _, info = venv.reset(options={"start_waypoint": np.array([1, 1, 2]), "reset_mask": np.array([0, 0, 1], bool)})
    assert info["_waypoint_index"].tolist() == [False, False, True] and info["waypoint_index"][2] == 2


def test_split_info_keeps_masks_and_gives_python_scalars():
    info = {
        "x": np.array([1.5, 2.5]),
        "_x": np.array([True, True]),
        "end": np.array([0, 7]),
        "_end": np.array([False, True]),
        "nested": {"r": np.array([1.0, 2.0]), "_r": np.array([True, False])},
        "_nested": np.array([True, False]),
    }
    out = split_info(info, 2)
    assert out == [{"x": 1.5, "nested": {"r": 1.0}}, {"x": 2.5, "end": 7}]
    assert type(out[1]["end"]) is int


def test_wrappers_without_a_vector_form_are_refused_on_the_vector_path(tmp_path):
    # the arm's wrappers (RobustVines, HarvestLegs, NearestBoxes) serve GrapeHarvest, which has no batched form;
    # ExpertStart lets a baseline drive one env
    # alone before the episode; SlamWaypoint and RobotLimits read their single env (its scan geometry and scene,
    # its robot). None has a vector form, and the vector path refuses each up front.
    assert set(VECTOR_WRAPPERS) == set(WRAPPERS) - {"NearestBoxes", "SlamWaypoint", "RobotLimits"}
    assert set(VECTOR_TRAIN_WRAPPERS) == set(TRAIN_WRAPPERS) - {"ExpertStart", "HarvestLegs", "RobustVines"}
    vector = {"vec_env": "vector"}
    grape = TrainRequest("agri_envs/GrapeHarvest-v1", "sac", tmp_path, scenario="table2", her=True, overrides=vector)
    with pytest.raises(ValueError, match="wrappers: NearestBoxes has no vector form"):
        resolve_config(grape)
    hp = {"vec_env": "vector", "train_wrappers": [{"ExpertStart": {"policy": "gonzalez-pseudo-reactive"}}]}
    with pytest.raises(ValueError, match="ExpertStart has no vector form.*vec_env: dummy"):
        resolve_config(TrainRequest("agri_envs/GreenhouseCoverage-v2", "ppo", tmp_path, overrides=hp))


def test_update_threads_take_the_idle_cores_at_most(tmp_path):
    recorded = []

    class Algorithm:
        logger = types.SimpleNamespace(record=lambda key, value: recorded.append((key, value)))

        def train(self):
            return torch.get_num_threads()

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        assert with_update_threads(Algorithm, 2, idle=lambda: 2)().train() == 2
        assert torch.get_num_threads() == 1  # the rollout's threads again
        assert with_update_threads(Algorithm, 2, idle=lambda: 1)().train() == 1  # the other core is taken
        assert with_update_threads(Algorithm, 2, idle=lambda: 8)().train() == 2
        assert recorded == [("train/update_threads", 2), ("train/update_threads", 1), ("train/update_threads", 2)]
    finally:
        torch.set_num_threads(before)
    cores = len(os.sched_getaffinity(0))
    loadavg = tmp_path / "loadavg"
    loadavg.write_text("0.50 0.40 0.30 1/200 4242\n")  # only the caller runs
    assert idle_cores(loadavg) == cores
    loadavg.write_text(f"3.00 2.00 1.00 {cores + 5}/200 4242\n")
    assert idle_cores(loadavg) == 1
    assert idle_cores(tmp_path / "missing") == cores


def test_monitor_and_vec_monitor_count_the_same_episodes():
    """The vector path replaces each env's Monitor by one VecMonitor: episode lengths and successes agree."""
    dummy = DummyVecEnv([lambda: Monitor(_dict_env(), info_keywords=("is_success",))] * 2)
    adapter = VecMonitor(VectorVecEnv(make_sync_vector_env([_dict_env] * 2)), info_keywords=("is_success",))
    dummy.seed(3)
    adapter.seed(3)
    dummy.reset()
    adapter.reset()
    episodes = [[], []]
    for _ in range(50):
        action = np.zeros((2, 2), np.float32)
        for venv, out in zip((dummy, adapter), episodes, strict=True):
            _, _, dones, infos = venv.step(action)
            out += [(i, infos[i]["episode"]["l"], infos[i]["is_success"]) for i in np.flatnonzero(dones)]
    assert episodes[0] == episodes[1] and len(episodes[0]) >= 4


def test_a_run_on_the_vector_path_is_the_run_on_the_dummy_path(tmp_path):
    """Same seed, same envs: the trained weights and the saved normalisation statistics agree bit for bit."""
    hp = {
        **RECIPE,
        "n_envs": 3,
        "algo_kwargs": {"n_steps": 32, "batch_size": 48, "n_epochs": 2},
        "policy_kwargs": {"net_arch": {"pi": [16], "vf": [16]}},
        "update_threads": 1,
        "eval_freq": 10**6,
        "eval_episodes": 1,
        "checkpoint_freq": 0,
    }
    runs = {}
    for kind in ("dummy", "vector"):
        out = tmp_path / kind
        request = TrainRequest(ENV_ID, "ppo", out, seed=2, timesteps=192, overrides={**hp, "vec_env": kind})
        train(dataclasses.replace(request, progress=False))
        runs[kind] = out
    old = torch.load(runs["dummy"] / "policy.pt", weights_only=True)
    new = torch.load(runs["vector"] / "policy.pt", weights_only=True)
    assert old.keys() == new.keys()
    for key in old:
        assert torch.equal(old[key], new[key]), key
    assert (runs["dummy"] / "normalize.json").read_text() == (runs["vector"] / "normalize.json").read_text()


def test_vector_path_refusals_name_the_fix(tmp_path):
    config = resolve_config(
        TrainRequest(ENV_ID, "ppo", tmp_path, overrides={"vec_env": "vector", "env_kwargs": {"frame_skip": 4}})
    )
    with pytest.raises(ValueError, match="set action_repeat, not env_kwargs.frame_skip"):
        make_vector_train_env(config)
    with pytest.raises(ValueError, match="vec_env 'vector' applies to Gymnasium envs only"):
        resolve_config(TrainRequest("robot_chain_v1", "ppo", tmp_path, overrides={"vec_env": "vector"}))
