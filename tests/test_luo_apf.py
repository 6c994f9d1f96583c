"""Luo APF planner: eq. 11 order vs brute force, collision-free path points by pybullet, solving the env."""

import itertools

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_baselines import make_policy, policy_spec
from agri_baselines.luo_apf import (
    JOINT_WEIGHTS,
    LuoApfParams,
    cut_configurations,
    harvest_order,
    joints_from_observation,
    plan_harvest,
    targets_from_observation,
)
from agri_envs.arm.robot_model import tip_pose
from agri_envs.arm.scene import HOME_Q
from agri_training.evaluate import run_episode

ENV_ID = "agri_envs/GrapeHarvest-v1"


def tour_cost(q_home, q_clusters, perm):
    tour = [q_home] + [q_clusters[i] for i in perm] + [q_home]
    return sum(JOINT_WEIGHTS[j] * abs(tour[k][j] - tour[k + 1][j]) for k in range(len(tour) - 1) for j in range(6))


def brute_force_order(q_home, q_clusters):
    costs = {perm: tour_cost(q_home, q_clusters, perm) for perm in itertools.permutations(range(len(q_clusters)))}
    best = min(costs, key=costs.get)
    return best, costs[best]


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_order_equals_brute_force_over_permutations(n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        q = rng.uniform(-2, 2, (n, 6))
        order, cost = harvest_order(HOME_Q, q)
        ref, ref_cost = brute_force_order(HOME_Q, q)
        # The tour cost is symmetric: an order and its reverse tie, and either may come first.
        assert order in (ref, ref[::-1]) and cost == pytest.approx(ref_cost, abs=1e-12)
        assert tour_cost(HOME_Q, q, order) == pytest.approx(ref_cost, abs=1e-12)


def test_weights_are_power_shares():
    assert JOINT_WEIGHTS.sum() == pytest.approx(1.0) and np.all(np.diff(JOINT_WEIGHTS) <= 0)


def plan_for(env, seed, params=None):
    obs, _ = env.reset(seed=seed)
    targets, slots, lo, hi = targets_from_observation(obs["observation"])
    q0 = joints_from_observation(obs["observation"])
    return plan_harvest(q0, targets, lo, hi, np.random.default_rng(seed), params), targets, slots


def test_plan_uses_the_eq11_order_and_reaches_every_cut():
    env = gym.make(ENV_ID, min_clusters=4, max_clusters=4)
    plan, targets, slots = plan_for(env, 5)
    assert plan.success and len(plan.cuts) == 4
    q_cut = cut_configurations(HOME_Q, targets)
    assert plan.order == harvest_order(HOME_Q, q_cut)[0]
    for k, i in enumerate(plan.order):
        np.testing.assert_allclose(plan.points[plan.cuts[k]], targets[i].cut_point, atol=1e-9)
        np.testing.assert_allclose(tip_pose(plan.waypoints[plan.cuts[k]]), targets[i].tip_pose(), atol=1e-9)
    np.testing.assert_allclose(tip_pose(plan.waypoints[-1]), tip_pose(HOME_Q), atol=1e-9)
    steps = np.linalg.norm(np.diff(plan.points, axis=0), axis=1)
    assert steps.max() <= LuoApfParams().step + 1e-9
    assert np.max(np.abs(np.diff(plan.waypoints, axis=0))) <= LuoApfParams().max_joint_jump + 1e-9
    assert plan.path_length == pytest.approx(steps.sum())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_planned_path_points_are_collision_free_in_pybullet(seed):
    """Independent check: pybullet's closest points between the arm's real shapes and every box."""
    env = gym.make(ENV_ID)
    plan, targets, slots = plan_for(env, seed)
    assert plan.success
    sim = env.unwrapped.sim
    cut_at = {plan.cuts[k]: slots[i] for k, i in enumerate(plan.order)}
    clearances = []
    for index, q in enumerate(plan.waypoints):
        sim.set_joints(q)
        assert sim.collisions() == [], (index, sim.collisions())
        clearances.append(sim.min_distance(0.2))
        if index in cut_at:
            sim.remove_cluster(cut_at[index])  # the cut cluster leaves with the clamp
    assert min(clearances) > 0.0


def run(env, policy, seed):
    """The evaluator's record of one episode (final info keys plus the policy's own metrics)."""
    return run_episode(env, policy, seed, None)["record"]


def test_policy_solves_the_easy_preset():
    env = gym.make(ENV_ID, min_clusters=2, max_clusters=2, n_leaves=0, n_canes=0)
    policy = make_policy("luo-apf", env)
    for seed in range(3):
        info = run(env, policy, seed)
        assert info["is_success"] and not info["collision"] and info["harvested"] == 2
        metrics = policy.episode_metrics(0)
        assert metrics["plan_success"] and metrics["path_points"] > 10 and metrics["planning_time_ms"] > 0
        assert sorted(metrics["order"].split("->")) == ["1", "2"]


def test_policy_spec_and_ee_control_is_refused():
    spec = policy_spec("luo-apf")
    assert not spec.privileged and spec.env_kwargs == {"control": "joint"}
    with pytest.raises(ValueError, match="control='joint'"):
        make_policy("luo-apf", gym.make(ENV_ID, control="ee"))


def test_sb3_evaluate_policy_accepts_it_unchanged():
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.vec_env import DummyVecEnv

    kwargs = {"min_clusters": 2, "max_clusters": 2, "n_leaves": 0}
    venv = DummyVecEnv([lambda: gym.make(ENV_ID, **kwargs) for _ in range(2)])
    policy = make_policy("luo-apf", venv.envs[0])
    mean, _ = evaluate_policy(policy, venv, n_eval_episodes=2, deterministic=True)
    assert mean > -300.0  # sparse reward: -1 per step until each goal is reached; a stuck arm gets -1000


@pytest.mark.slow
def test_table2_success_at_least_95_percent_over_100_seeds():
    env = gym.make(ENV_ID, min_clusters=2, max_clusters=5)
    policy = make_policy("luo-apf", env)
    success = [run(env, policy, seed)["is_success"] for seed in range(100)]
    assert np.mean(success) >= 0.95, np.flatnonzero(~np.array(success))
