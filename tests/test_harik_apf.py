"""Harik APF: eqs. 12-14 worked values, repulsion, passive safety, SB3 compatibility, solving the env."""

import math

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_baselines import make_policy, policy_spec
from agri_baselines.harik_apf import HarikApfController, HarikApfParams, RobotGeometry
from agri_envs.rover import robot as rover
from agri_envs.sim2d.sensors import tim561
from agri_training.evaluate import run_episode

ENV_ID = "agri_envs/GreenhouseNav-v1"


@pytest.fixture
def controller():
    spec = tim561(mount=rover.LIDAR_MOUNT)
    geo = RobotGeometry(
        rover.LENGTH, rover.WIDTH, rover.LIDAR_MOUNT, spec.beam_angles, spec.max_range, rover.SONAR_MOUNTS, 4.0, 1 / 15
    )
    return HarikApfController(HarikApfParams(), geo)


def free_scan():
    return np.full(811, 10.0), np.full(6, 4.0)


def test_eq13_eq14_piecewise(controller):
    p = controller.p
    assert p.k_att == pytest.approx(2 * p.u_max / p.d_max**2)
    assert controller.attractive(0.2, 0.1) == (0.0, pytest.approx(p.k_a * 0.1))  # d < d_min: u = 0
    u, r = controller.attractive(0.8, -0.2)
    assert u == pytest.approx(0.5 * p.k_att * 0.64) and r == pytest.approx(-0.2 * p.k_a)  # eq. 12
    assert controller.attractive(3.0, 0.0)[0] == p.u_max  # d >= d_max: saturated
    assert controller.attractive(3.0, 2.0) == (0.0, p.r_max)  # |alpha| > alpha_max: turn on the spot
    assert controller.attractive(3.0, -2.0) == (0.0, -p.r_max)
    # continuity of eq. 13 at d_max
    assert controller.attractive(p.d_max - 1e-9, 0.0)[0] == pytest.approx(p.u_max)


def test_side_repulsion_pushes_away(controller):
    ranges, sonar = free_scan()
    sonar[1] = 0.15  # left-front sonar: obstacle 15 cm from the left side
    _, r_left = controller.command(5.0, 0.0, ranges, sonar)
    assert r_left == pytest.approx(-controller.p.k_rep / 0.15)  # turn right, eq. 12
    controller.reset()
    ranges, sonar = free_scan()
    sonar[5] = 0.2
    _, r_right = controller.command(5.0, 0.0, ranges, sonar)
    assert r_right == pytest.approx(controller.p.k_rep / 0.2)
    ranges, sonar = free_scan()
    sonar[1] = 1.0  # beyond d_obs_threshold: ignored (eq. 11)
    assert controller.command(5.0, 0.0, ranges, sonar)[1] == 0.0


def test_passive_safety_stop_steps_back_then_waits(controller):
    ranges, sonar = free_scan()
    sonar[0] = 0.2  # something 20 cm in front
    commands = [controller.command(5.0, 0.0, ranges, sonar) for _ in range(30)]
    backing = [u for u, _ in commands if u < 0]
    dt = 1 / 15
    assert sum(-u * dt for u in backing) == pytest.approx(controller.p.step_back_distance, abs=0.01)
    assert all(u == 0.0 for u, _ in commands[len(backing) :])
    assert controller.stops == 1
    ranges, sonar = free_scan()
    assert controller.command(5.0, 0.0, ranges, sonar)[0] > 0  # path free: drive on
    # No stepping back into something behind.
    controller.reset()
    ranges, sonar = free_scan()
    sonar[0], sonar[3] = 0.2, 0.1
    assert all(controller.command(5.0, 0.0, ranges, sonar)[0] == 0.0 for _ in range(5))


def test_policy_spec_is_privileged_and_requires_full_scan():
    spec = policy_spec("harik-apf-gt")
    assert spec.privileged and spec.env_kwargs == {"localization": "ground_truth", "full_scan": True}
    with pytest.raises(ValueError, match="full_scan=True"):
        make_policy("harik-apf-gt", gym.make(ENV_ID))


def test_sb3_evaluate_policy_accepts_it_unchanged():
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import DummyVecEnv

    kwargs = {"full_scan": True, "localization": "ground_truth", "n_rows": 1, "row_length": 3.0, "n_people": 0}
    venv = DummyVecEnv([lambda: gym.make(ENV_ID, **kwargs) for _ in range(2)])
    policy = make_policy("harik-apf-gt", venv.envs[0])
    mean, std = evaluate_policy(policy, venv, n_eval_episodes=2, deterministic=True)
    assert mean > 5.0  # waypoint and success bonuses were collected


def run(kwargs, seeds):
    env = gym.make(ENV_ID, full_scan=True, localization="ground_truth", **kwargs)
    policy = make_policy("harik-apf-gt", env)
    return [run_episode(env, policy, seed, None)["record"] for seed in seeds]


def test_solves_the_easy_preset():
    infos = run({"n_rows": 1, "row_length": 4.0, "n_people": 0}, range(3))
    assert all(i["is_success"] and not i["collision"] for i in infos)


def test_default_scene_with_people_at_least_95_percent():
    infos = run({}, range(20))
    success = np.mean([i["is_success"] and not i["collision"] for i in infos])
    assert success >= 0.95, [(k, i["collision"], i["waypoints_reached"]) for k, i in enumerate(infos)]
    assert all(math.isfinite(i["min_clearance"]) for i in infos)
