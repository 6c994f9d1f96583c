"""The learned harvest's parts: the boxes seen from the clamp, eq. 11's order, the legs training sees."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401  (registers the env ids)
from agri_baselines.luo_apf import joints_from_observation, plan_harvest, targets_from_observation
from agri_envs.arm.collision import box_distance
from agri_envs.scenarios import scenario
from agri_training.learned.arm_observation import NearestBoxes
from agri_training.learned.curricula import apply_train_wrappers
from agri_training.learned.harvest import HarvestLegs, HarvestOrder

ENV_ID = "agri_envs/GrapeHarvest-v1"
EE = {"control": "ee", "max_ee_step": 0.04, "max_ee_rotation": 0.2}


def _rotation_error(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    return 0.5 * (np.cross(a[3:6], d[3:6]) + np.cross(a[6:9], d[6:9]))


def drive(obs: dict, waypoint_first: bool = True) -> np.ndarray:
    """A scripted end-effector action toward the observation's desired goal, via a point 10 cm in front of it."""
    a, d = obs["achieved_goal"].astype(float), obs["desired_goal"].astype(float)
    pre = d[:3] - 0.1 * d[3:6]
    far = np.linalg.norm(d[:3] - a[:3]) > 0.09 and np.linalg.norm(a[:3] - pre) > 0.01
    target = pre if waypoint_first and far and abs(d[5]) < 0.5 else d[:3]
    return np.clip(np.concatenate([(target - a[:3]) / 0.04, _rotation_error(a, d) / 0.2]), -1, 1).astype(np.float32)


# ---- NearestBoxes -------------------------------------------------------------------------------------------


def oracle_nearest(env, clamp: np.ndarray, k: int) -> np.ndarray:
    """The k boxes nearest the clamp, straight from the scene (not from the observation), relative to it.

    The boxes the env's observation lists: those still in the scene, and the designated cluster's (the env
    keeps it for the one step after its cut, when its designated target switches).
    """
    raw = env.unwrapped
    shown = raw.task.harvested.copy()
    if raw.task.target >= 0:
        shown[raw.task.target] = False
    lo, hi = raw.scene.boxes(shown)
    dist = box_distance(clamp[None], lo, hi)[0]
    order = np.argsort(dist, kind="stable")[:k]
    out = np.zeros((k, 7))
    out[: len(order), 0] = 1.0
    out[: len(order), 1:4] = lo[order] - clamp
    out[: len(order), 4:7] = hi[order] - clamp
    return out


@pytest.mark.parametrize(
    "kwargs",
    [{}, {"min_clusters": 1, "max_clusters": 1, "n_leaves": 0, "n_canes": 0}, {"max_clusters": 3, "n_leaves": 8}],
)
def test_nearest_boxes_are_the_scene_boxes_nearest_the_clamp_in_every_scene(kwargs):
    k = 6
    env = NearestBoxes(gym.make(ENV_ID, **EE, **kwargs), k=k)
    assert env.observation_space["observation"].shape == (6 + 7 * k,)  # the same in every scene
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        for _ in range(60):
            assert env.observation_space.contains(obs)
            clamp = obs["achieved_goal"].astype(np.float64)[:3]
            got = obs["observation"][6:].reshape(k, 7)
            want = oracle_nearest(env, clamp, k)
            np.testing.assert_allclose(got, want, atol=2e-6)  # the env's float32 boxes against the scene's
            np.testing.assert_array_equal(
                obs["observation"][:6], env.unwrapped._observe(obs["achieved_goal"])["observation"][:6]
            )
            obs, _, term, trunc, _ = env.step(drive(obs))
            if term or trunc:
                break


def test_nearest_boxes_keep_the_goals_and_refuse_other_envs():
    env = NearestBoxes(gym.make(ENV_ID, **EE), k=3)
    raw_obs, _ = env.env.reset(seed=1)
    obs = env.observation(raw_obs)
    assert obs["desired_goal"] is raw_obs["desired_goal"] and obs["achieved_goal"] is raw_obs["achieved_goal"]
    with pytest.raises(ValueError, match="k must be"):
        NearestBoxes(gym.make(ENV_ID), k=0)
    with pytest.raises(ValueError, match="GrapeHarvest"):
        NearestBoxes(gym.make("CartPole-v1"))


# ---- HarvestOrder --------------------------------------------------------------------------------------------


def harvest_order(env, obs) -> HarvestOrder:
    cfg = env.unwrapped.config
    return HarvestOrder(obs, env.unwrapped.layout, cfg.position_tolerance, cfg.orientation_tolerance)


@pytest.mark.parametrize("seed", [0, 3, 7, 11])
def test_the_order_is_luo_apf_s_eq_11_order(seed):
    env = gym.make(ENV_ID, **scenario(ENV_ID, "table2").env_kwargs)
    obs, _ = env.reset(seed=seed)
    layout = env.unwrapped.layout
    targets, lo, hi = targets_from_observation(obs, layout)
    plan = plan_harvest(joints_from_observation(obs["observation"]), targets, lo, hi, np.random.default_rng(0))
    order = harvest_order(env, obs)
    assert order.order == plan.order and order.energy == pytest.approx(plan.energy)
    seen, index = order.see(obs)
    assert index == plan.order[0]
    np.testing.assert_array_equal(seen["desired_goal"][:3], targets[index].cut_point.astype(np.float32))
    np.testing.assert_array_equal(seen["observation"], obs["observation"])


def test_the_goal_moves_on_as_clusters_are_cut_and_ends_home():
    env = gym.make(ENV_ID, **EE, min_clusters=3, max_clusters=3, feasible_scenes=True)
    obs, _ = env.reset(seed=4)
    order = harvest_order(env, obs)
    raw = env.unwrapped
    seen_goals, hidden = [], 0
    for _ in range(400):
        seen, index = order.see(obs)
        np.testing.assert_array_equal(order.harvested, raw.task.harvested)  # the env's own harvest rule
        box = raw.layout["target_box"]
        if raw.task.target >= 0 and raw.task.harvested[raw.task.target]:  # the step after a cut: box hidden
            assert obs["observation"][box.start] == 1.0 and seen["observation"][box.start] == 0.0
            hidden += 1
        else:
            np.testing.assert_array_equal(seen["observation"], obs["observation"])
        if not seen_goals or seen_goals[-1] != index:
            seen_goals.append(index)
        obs, _, term, trunc, info = env.step(drive(seen))
        if term or trunc:
            break
    assert info["is_success"], info
    assert seen_goals == [*order.order, -1] and hidden >= 1


# ---- HarvestLegs ---------------------------------------------------------------------------------------------


def test_legs_follow_the_order_each_is_one_goal_and_the_episode_runs_on():
    env = apply_train_wrappers(gym.make(ENV_ID, **EE, min_clusters=3, max_clusters=3), [{"HarvestLegs": {}}])
    assert isinstance(env, HarvestLegs)
    obs, _ = env.reset(seed=2)
    raw = env.unwrapped
    order = harvest_order(raw, obs)
    goals = [order.goals[i] for i in order.order]
    legs, resets = 0, 0
    while legs < 4:
        goal = goals[legs] if legs < 3 else raw.home_goal
        np.testing.assert_allclose(obs["desired_goal"], goal.astype(np.float32), atol=1e-6)
        for _ in range(60):
            obs, reward, term, trunc, info = env.step(drive(obs))
            assert reward == env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)  # what HER recomputes
            if term or trunc:
                break
        assert term and info["is_success"] and not info["collision"]
        legs += 1
        assert raw.task.harvested.sum() == min(legs, 3)
        before = raw.elapsed_steps
        obs, _ = env.reset()
        resets += raw.elapsed_steps == 0
        if legs < 4:
            assert raw.elapsed_steps == before  # the next leg goes on in the same episode
    assert info["time_limit"] > 0 and resets == 1  # the fourth leg (home) ended the env's episode: a new one began


def test_a_collision_ends_the_leg_and_the_episode_and_a_slow_leg_is_cut():
    env = HarvestLegs(gym.make(ENV_ID, **EE), max_leg_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        _, _, term, trunc, info = env.step(np.zeros(6, np.float32))
    assert trunc and not term and not info["is_success"]
    env.reset()
    assert env.unwrapped.elapsed_steps == 5  # truncated leg: the same episode goes on
    crash = HarvestLegs(gym.make(ENV_ID, **EE), max_leg_steps=200)
    obs, _ = crash.reset(seed=0)
    box = obs["observation"][crash.unwrapped.layout["target_box"]]
    centre = 0.5 * (box[1:4] + box[4:7])
    for _ in range(200):  # into the middle of the designated cluster's box
        move = np.clip((centre - obs["achieved_goal"][:3]) / 0.04, -1, 1)
        obs, reward, term, trunc, info = crash.step(np.concatenate([move, np.zeros(3)]).astype(np.float32))
        if term or trunc:
            break
    assert term and info["collision"] and reward == -1.0 - 201.0  # the goal term and (max_leg_steps + 1) worst steps
    crash.reset()
    assert crash.unwrapped.elapsed_steps == 0
    with pytest.raises(ValueError, match="max_leg_steps"):
        HarvestLegs(gym.make(ENV_ID), max_leg_steps=0)


def test_the_leg_reward_is_her_s_batched_reward_and_the_tolerance_shrinks():
    env = HarvestLegs(gym.make(ENV_ID, **EE), max_leg_steps=10, tolerance_start=[0.05, 0.5], tolerance_steps=4)
    np.testing.assert_allclose(env.tolerances, [0.05, 0.5])
    obs, _ = env.reset(seed=3)
    achieved, infos = [], []
    for step in range(6):
        obs, reward, *_, info = env.step(drive(obs))
        achieved.append(obs["achieved_goal"])
        infos.append(info)
        np.testing.assert_allclose(
            env.tolerances, [0.01, 0.2] if step >= 3 else [0.05 - 0.01 * (step + 1), 0.5 - 0.075 * (step + 1)]
        )
    # HER's call: arrays of goals and an array of info dicts; one goal within 3 cm / 0.3 rad, one far, one crash.
    a = np.array(achieved[:3], dtype=np.float64)
    d = a.copy()
    d[0, :3] += 0.005
    d[1, :3] += 0.02
    batch = np.array([{"collision": False}, {"collision": False}, {"collision": True}])
    np.testing.assert_array_equal(env.compute_reward(a, d, batch), [0.0, -1.0, -11.0])
    for k in range(3):
        assert env.compute_reward(a[k], d[k], batch[k]) == env.compute_reward(a, d, batch)[k]
    dense = HarvestLegs(gym.make(ENV_ID, **EE, reward_type="dense"), max_leg_steps=10)
    worst = 2.0 + 0.1 * np.pi
    assert dense.collision_cost == pytest.approx(11 * worst)
    crash = dense.compute_reward(a[1], d[1], {"collision": True})
    assert crash == pytest.approx(-0.02 * np.sqrt(3) - 11 * worst, abs=1e-6)
    with pytest.raises(ValueError, match="tolerance_start"):
        HarvestLegs(gym.make(ENV_ID), tolerance_start=[0.005, 0.3])
    with pytest.raises(ValueError, match="tolerance_steps"):
        HarvestLegs(gym.make(ENV_ID), tolerance_steps=0)


def test_a_goal_reached_only_within_the_curriculum_tolerance_is_passed_over():
    env = HarvestLegs(
        gym.make(ENV_ID, **EE, min_clusters=2, max_clusters=2, feasible_scenes=True),
        tolerance_start=[0.04, 3.0],
        tolerance_steps=10**6,
    )
    obs, _ = env.reset(seed=6)
    raw = env.unwrapped
    order = harvest_order(raw, obs)
    goals = [order.goals[i] for i in (*order.order, None) if i is not None] + [raw.home_goal]
    for leg in range(3):
        np.testing.assert_allclose(obs["desired_goal"], goals[leg].astype(np.float32), atol=1e-6)
        for _ in range(40):
            obs, _, term, trunc, info = env.step(drive(obs))
            if term or trunc:
                break
        assert term and info["is_success"] and raw.task.harvested.sum() == 0  # within 4 cm: nothing cut
        obs, _ = env.reset()
    assert raw.elapsed_steps == 0  # home passed over too: a new episode
