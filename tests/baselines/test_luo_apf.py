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
from agri_training.evaluation.episode import run_episode

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
    np.testing.assert_allclose(JOINT_WEIGHTS, [0.32, 0.32, 0.16, 0.08, 0.08, 0.04])


def test_eq11_weights_change_the_order():
    """Scenes where the power-weighted and the uniformly weighted tours differ: the order must be the former."""
    rng = np.random.default_rng(11)
    uniform = np.full(6, 1 / 6)

    def best(weights, q):
        costs = {
            perm: float(np.sum(weights * np.abs(np.diff(np.vstack([HOME_Q, q[list(perm)], HOME_Q]), axis=0))))
            for perm in itertools.permutations(range(len(q)))
        }
        return min(costs, key=costs.get)

    differing = 0
    for _ in range(40):
        q = rng.uniform(-2, 2, (4, 6))
        power, flat = best(JOINT_WEIGHTS, q), best(uniform, q)
        if flat in (power, power[::-1]):
            continue
        differing += 1
        assert harvest_order(HOME_Q, q)[0] in (power, power[::-1])
    assert differing >= 5


def test_potential_is_eq13_plus_eq15():
    from agri_baselines.luo_apf import ApfPlanner

    p = LuoApfParams(k_att=2.0, eta=1e-3, rho=0.1)
    lo, hi = np.array([[0.0, 0.0, 0.0]]), np.array([[0.1, 0.1, 0.1]])
    planner = ApfPlanner(lo, hi, np.random.default_rng(0), p)
    goal = np.array([0.5, 0.05, 0.05])
    x = np.array(
        [
            [0.5, 0.05, 0.05],  # at the goal, far from the box: U = 0 (condition 1)
            [0.4, 0.05, 0.05],  # 0.1 from the goal, 0.3 from the box: attraction only
            [0.15, 0.05, 0.05],  # 0.05 from the box face: both terms
            [0.13, 0.05, 0.05],  # closer to the box: the repulsion grows
        ]
    )
    u = planner.potential(x, goal)
    att = 0.5 * 2.0 * np.sum((x - goal) ** 2, axis=1)
    rep = np.array([0.0, 0.0, 0.5e-3 * (1 / 0.05 - 1 / 0.1) ** 2, 0.5e-3 * (1 / 0.03 - 1 / 0.1) ** 2])
    np.testing.assert_allclose(u, att + rep, rtol=1e-12)
    assert u[0] == 0.0 and u[3] - att[3] > u[2] - att[2] > 0.0
    # No repulsion without eta: the attract-only ablation.
    flat = ApfPlanner(lo, hi, np.random.default_rng(0), LuoApfParams(k_att=2.0, eta=0.0, rho=0.1))
    np.testing.assert_allclose(flat.potential(x, goal), att, rtol=1e-12)


def test_fallback_backtracks_out_of_a_dead_end_and_counts_it(monkeypatch):
    from agri_baselines.luo_apf import ApfPlanner

    env = gym.make(ENV_ID, min_clusters=1, max_clusters=1, n_leaves=0, feasible_scenes=True)
    obs, _ = env.reset(seed=0)
    targets, lo, hi = targets_from_observation(obs, env.unwrapped.layout)
    planner = ApfPlanner(lo, hi, np.random.default_rng(0), LuoApfParams(max_resample=2))
    real = planner.reachable
    calls = {"n": 0}

    def flaky(poses, q):
        calls["n"] += 1
        q_best, ok = real(poses, q)
        if 5 <= calls["n"] < 7:  # the 3rd path point runs out of samples once
            ok[:] = False
        return q_best, ok

    monkeypatch.setattr(planner, "reachable", flaky)
    from agri_envs.arm.scene import PRE_CUT

    seg = planner.segment(HOME_Q, targets[0].tip_pose(PRE_CUT))
    assert seg is not None and planner.fallbacks == 1
    no_fallback = ApfPlanner(lo, hi, np.random.default_rng(0), LuoApfParams(max_resample=2, max_backtracks=0))
    calls["n"] = 0
    real = no_fallback.reachable
    monkeypatch.setattr(no_fallback, "reachable", flaky)
    assert no_fallback.segment(HOME_Q, targets[0].tip_pose(PRE_CUT)) is None


def test_attract_only_ablation_is_registered_and_repulsion_keeps_path_points_farther():
    spec = policy_spec("luo-apf-attract-only")
    env = gym.make(ENV_ID, min_clusters=3, max_clusters=3)
    assert make_policy("luo-apf-attract-only", env).params.eta == 0.0 and spec.env_kwargs == {"control": "joint"}
    full, ablation = [], []
    for seed in range(4):
        for params, out in ((LuoApfParams(), full), (LuoApfParams(eta=0.0), ablation)):
            plan, *_ = plan_for(env, seed, params)
            assert plan.success
            out.append(plan.min_box_clearance)
    assert np.mean(full) > 1.1 * np.mean(ablation)


def plan_for(env, seed, params=None):
    obs, _ = env.reset(seed=seed)
    targets, lo, hi = targets_from_observation(obs, env.unwrapped.layout)
    q0 = joints_from_observation(obs["observation"])
    # The env's cluster index of each target, to take the right box out of pybullet after a cut.
    cuts = [c.cut_point.astype(np.float32) for c in env.unwrapped.scene.clusters]
    slots = [int(np.argmin([np.linalg.norm(t.cut_point - c) for c in cuts])) for t in targets]
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
    env = gym.make(ENV_ID, min_clusters=2, max_clusters=5, feasible_scenes=True)
    policy = make_policy("luo-apf", env)
    success = [run(env, policy, seed)["is_success"] for seed in range(100)]
    assert np.mean(success) >= 0.95, np.flatnonzero(~np.array(success))
