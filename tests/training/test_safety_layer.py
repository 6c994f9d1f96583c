"""Safety layers: the passive safety keeps a reckless policy out of obstacles, counts what it does, refuses misuse."""

import shutil

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401  (registers the envs)
from agri_training.evaluation.episode import run_episode
from agri_training.learned.policy import LearnedPolicy, guarded
from agri_training.learned.safety import HarikPassiveSafety, LuoBoxCheck, check_safety_layer, make_safety_layer
from agri_training.learned.zoo import ZOO_DIR
from agri_training.train import TrainRequest, resolve_config

NAV = "agri_envs/GreenhouseNav-v2"
#: One straight corridor, nobody else in it: driving ahead at full speed ends in the far wall.
CORRIDOR = {"scene": "corridor", "office_length": 8.0, "n_people": 0, "localization": "ground_truth"}


def _drive_ahead(layer, steps=400, seed=3):
    """Full speed ahead, slightly turning, for ``steps`` steps (or until the episode ends): the last info."""
    env = gym.make(NAV, **CORRIDOR)
    obs, info = env.reset(seed=seed)
    action = np.array([1.0, 0.05], dtype=np.float32)
    for step in range(steps):
        a = action if layer is None else layer.apply(obs, action, step == 0)
        if layer is not None:
            assert a[1] == action[1]  # the steering is the policy's
        obs, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            break
    env.close()
    return info


def test_passive_safety_stops_a_policy_that_drives_into_the_wall():
    alone = _drive_ahead(None)
    assert alone["collision"]
    layer = HarikPassiveSafety(gym.make(NAV, **CORRIDOR))
    guarded_info = _drive_ahead(layer)
    assert not guarded_info["collision"]
    m = layer.episode_metrics()
    assert m["safety_stops"] >= 1 and m["safety_interventions"] >= 1 and m["safety_blocked_time"] > 0


def test_clear_view_leaves_the_action_alone():
    env = gym.make(NAV, **CORRIDOR)
    obs, _ = env.reset(seed=0)
    clear = {k: np.ones_like(v) for k, v in obs.items()}
    layer = HarikPassiveSafety(env)
    action = np.array([0.7, -0.3], dtype=np.float32)
    assert np.array_equal(layer.apply(clear, action, True), action)
    assert layer.episode_metrics()["safety_interventions"] == 0
    blocked = dict(clear, lidar=np.full_like(clear["lidar"], 0.02))  # 20 cm all around
    out = layer.apply(blocked, action, False)
    assert out[0] <= 0.0 and out[1] == action[1]
    assert layer.episode_metrics()["safety_interventions"] == 1
    layer.apply(clear, action, True)  # a new episode clears the counts
    assert layer.episode_metrics()["safety_interventions"] == 0


def test_bad_layers_are_refused(tmp_path):
    tmp_path_for_refusal = tmp_path / "run"
    check_safety_layer(None, NAV)
    check_safety_layer("harik-passive-safety", NAV)
    with pytest.raises(ValueError, match="must be one of harik-passive-safety"):
        check_safety_layer("airbag", NAV)
    with pytest.raises(ValueError, match="guards agri_envs/GreenhouseNav-v2, not robot_chain_v1"):
        check_safety_layer("harik-passive-safety", "robot_chain_v1")
    with pytest.raises(ValueError, match="must be one of"):
        resolve_config(TrainRequest(NAV, "ppo", tmp_path_for_refusal, overrides={"safety_layer": "airbag"}))
    assert make_safety_layer(None, None, NAV) is None
    with pytest.raises(ValueError, match="must be one of"):
        make_safety_layer("airbag", gym.make(NAV, **CORRIDOR), NAV)
    with pytest.raises(ValueError, match="not agri_envs/GreenhouseCoverage-v2"):
        coverage = "agri_envs/GreenhouseCoverage-v2"
        make_safety_layer("harik-passive-safety", gym.make(coverage), coverage)
    layer = HarikPassiveSafety(gym.make(NAV, **CORRIDOR))
    with pytest.raises(ValueError, match="one env at a time"):
        guarded(layer, {}, np.zeros((2, 2), dtype=np.float32), np.array([True, True]))


def test_a_run_with_a_layer_acts_through_it_and_reports_it(tmp_path):
    """The same weights with ``safety_layer`` in their config: the records carry the layer's counts, and where the
    layer never acts (an empty greenhouse) the episode is the network's own, number for number."""
    run = tmp_path / "shielded"
    shutil.copytree(ZOO_DIR / "ppo-greenhouse-nav-general", run)
    with open(run / "config.yaml", "a") as f:
        f.write("safety_layer: harik-passive-safety\n")

    def both(kwargs, last_step):
        env = gym.make(NAV, **kwargs)
        plain = LearnedPolicy(ZOO_DIR / "ppo-greenhouse-nav-general", env)
        return [
            run_episode(env, p, 1, None, lambda step: step >= last_step)["record"]
            for p in (plain, LearnedPolicy(run, env))
        ]

    plain, shielded = both(CORRIDOR, 2000)  # the whole mission: its turns face the corridor's walls
    assert "safety_interventions" not in plain
    assert {"safety_interventions", "safety_stops", "safety_blocked_time"} <= set(shielded)
    assert shielded["safety_interventions"] > 0
    plain, shielded = both({"n_people": 0, "localization": "ground_truth"}, 300)  # 20 s among the first rows
    assert shielded["safety_interventions"] == 0
    assert {k: v for k, v in shielded.items() if k in plain and k != "wall_time_s"} == {
        k: v for k, v in plain.items() if k != "wall_time_s"
    }


GRAPE = "agri_envs/GrapeHarvest-v1"
GRAPE_EE = {"control": "ee", "max_ee_step": 0.04, "max_ee_rotation": 0.2, "min_clusters": 2, "max_clusters": 3}


def _push_into_the_target_box(layer, seed=5, steps=60):
    """Drive the clamp straight at the target cluster's box centre: the last info and the layer's counts."""
    env = gym.make(GRAPE, **GRAPE_EE)
    obs, info = env.reset(seed=seed)
    box = env.unwrapped.layout["target_box"]
    for step in range(steps):
        lo_hi = obs["observation"][box]
        toward = 0.5 * (lo_hi[1:4] + lo_hi[4:7]) - obs["achieved_goal"][:3]
        action = np.concatenate([toward / max(np.linalg.norm(toward), 1e-9), np.zeros(3)]).astype(np.float32)
        if layer is not None:
            action = layer.apply(obs, action, step == 0)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    return info


def test_luo_box_check_keeps_the_arm_out_of_the_boxes():
    assert _push_into_the_target_box(None)["collision"]
    layer = LuoBoxCheck(gym.make(GRAPE, **GRAPE_EE))
    assert not _push_into_the_target_box(layer)["collision"]
    assert layer.episode_metrics()["safety_interventions"] >= 1
    with pytest.raises(ValueError, match="control='ee'"):
        LuoBoxCheck(gym.make(GRAPE))


def test_luo_box_check_leaves_clear_actions_alone():
    env = gym.make(GRAPE, **GRAPE_EE)
    obs, _ = env.reset(seed=2)
    layer = LuoBoxCheck(env)
    still = np.zeros(6, dtype=np.float32)
    assert np.array_equal(layer.apply(obs, still, True), still)
    assert layer.episode_metrics() == {"safety_interventions": 0.0, "safety_stops": 0.0}
