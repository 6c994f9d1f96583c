"""GrapeHarvest-v1: API checkers, HER reward, determinism, pickling, strictness, collisions, rendering."""

import pickle
import resource

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from rollouts import assert_same, rollout

import agri_envs  # noqa: F401
from agri_envs.arm.config import GrapeHarvestConfig
from agri_envs.arm.grape_harvest import GrapeHarvestEnv
from agri_envs.arm.kinematics import nearest_ik
from agri_envs.arm.robot_model import flange_pose_for_tip, tip_pose
from agri_envs.arm.scene import HOME_Q, harvest_configurations

ENV_ID = "agri_envs/GrapeHarvest-v1"


def drive_to(env, q_target, max_steps=200):
    """Joint-delta actions toward q_target until reached or the episode ends; returns the last step."""
    out = None
    for _ in range(max_steps):
        delta = (q_target - env.unwrapped.q) / env.unwrapped.config.max_joint_step
        out = env.step(np.clip(delta, -1, 1))
        if out[2] or out[3] or np.max(np.abs(env.unwrapped.q - q_target)) < 1e-9:
            break
    return out


@pytest.mark.parametrize(
    "kwargs", [{}, {"control": "ee", "reward_type": "dense"}, {"min_clusters": 5, "n_leaves": 8, "n_canes": 4}]
)
def test_gymnasium_and_sb3_checkers(kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, **kwargs)
    check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("reward_type", ["sparse", "dense"])
def test_compute_reward_batched_equals_per_sample_and_step_reward(reward_type):
    env = gym.make(ENV_ID, reward_type=reward_type, terminate_on_collision=False)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    achieved, desired, infos, rewards = [], [], [], []
    for _ in range(40):
        obs, r, _, _, info = env.step(rng.uniform(-1, 1, 6))
        assert r == env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
        achieved.append(obs["achieved_goal"])
        desired.append(obs["desired_goal"])
        infos.append(info)
        rewards.append(r)
    infos[0] = dict(infos[0], collision=True)  # a collision step is penalised in the batch too
    batch = env.unwrapped.compute_reward(np.array(achieved), np.array(desired), np.array(infos))
    single = [env.unwrapped.compute_reward(a, d, i) for a, d, i in zip(achieved, desired, infos, strict=True)]
    assert batch.shape == (40,)
    np.testing.assert_array_equal(batch, single)
    assert single[0] == pytest.approx(rewards[0] - (infos[0]["time_limit"] + 1.0) * env.unwrapped.task.worst_step)
    # A goal relabelled to the achieved one is reached (HER's premise).
    reached = env.unwrapped.compute_reward(np.array(achieved), np.array(achieved), np.array(infos[1:] + infos[:1]))
    np.testing.assert_allclose(reached[:-1], 0.0, atol=1e-6)
    assert reached[-1] <= -1.0


def test_same_seed_same_actions_identical_and_seeds_differ():
    assert_same(rollout(gym.make(ENV_ID), 7, 150), rollout(gym.make(ENV_ID), 7, 150))
    a = rollout(gym.make(ENV_ID), 7, 1)
    b = rollout(gym.make(ENV_ID), 8, 1)
    assert not np.array_equal(a[0][0]["observation"], b[0][0]["observation"])


def test_pickled_env_continues_identically():
    env = gym.make(ENV_ID, terminate_on_collision=False)
    rollout(env, 3, 20)
    clone = pickle.loads(pickle.dumps(env))
    assert clone.unwrapped.sim.client != env.unwrapped.sim.client
    for a in np.random.default_rng(1).uniform(-1, 1, (60, 6)):
        o1, r1, t1, u1, i1 = env.step(a)
        o2, r2, t2, u2, i2 = clone.step(a)
        assert all(np.array_equal(o1[k], o2[k]) for k in o1) and r1 == r2 and i1 == i2
    clone.close()


def test_bad_actions_and_clipping():
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([np.nan, 0, 0, 0, 0, 0]))
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([0, 0, 0, np.inf, 0, 0]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    e1, e2 = gym.make(ENV_ID), gym.make(ENV_ID)
    e1.reset(seed=4)
    e2.reset(seed=4)
    o1, *_ = e1.step(np.array([5.0, -3.0, 0.5, 0, 0, 9.0]))
    o2, *_ = e2.step(np.array([1.0, -1.0, 0.5, 0, 0, 1.0]))
    assert all(np.array_equal(o1[k], o2[k]) for k in o1)


def test_config_strictness():
    with pytest.raises(ValueError, match="unknown argument.*'n_leaf'.*did you mean 'n_leaves'"):
        gym.make(ENV_ID, n_leaf=3)
    with pytest.raises(ValueError, match=r"max_clusters=6 is out of range; expected in \[1, 5\]"):
        gym.make(ENV_ID, max_clusters=6)
    with pytest.raises(ValueError, match=r"position_tolerance=0.0 m is out of range"):
        gym.make(ENV_ID, position_tolerance=0.0)
    with pytest.raises(ValueError, match="control='torque' is invalid"):
        gym.make(ENV_ID, control="torque")
    with pytest.raises(ValueError, match="min_clusters=4 exceeds max_clusters=3"):
        gym.make(ENV_ID, min_clusters=4, max_clusters=3)
    with pytest.raises(ValueError, match="reset options"):
        gym.make(ENV_ID).reset(seed=0, options={"n_clusters": 4})


def test_docstring_documents_every_argument():
    for name, _default, _unit, valid, doc in GrapeHarvestConfig().describe():
        assert doc and valid != "any value", name
        assert f"| ``{name}`` |" in GrapeHarvestEnv.__doc__, name


def test_cluster_count_and_workspace():
    env = gym.make(ENV_ID, min_clusters=3, max_clusters=3)
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        assert info["n_clusters"] == 3 and env.observation_space.contains(obs)
        for c in env.unwrapped.scene.clusters:
            assert harvest_configurations(c) is not None  # reachable (Fig. 3)
            assert c.cut_point[2] > c.box_hi[2]  # the cutting point is above the box


def test_several_envs_have_separate_clients_and_close_is_idempotent():
    envs = [gym.make(ENV_ID) for _ in range(3)]
    clients = {e.unwrapped.sim.client for e in envs}
    assert len(clients) == 3
    for i, e in enumerate(envs):
        e.reset(seed=i)
    envs[0].close()
    envs[0].close()
    obs, *_ = envs[1].step(np.zeros(6))  # the others keep working
    assert obs["observation"].shape == (142,)
    with pytest.raises(RuntimeError, match="closed"):
        envs[0].unwrapped.sim.set_joints(HOME_Q)
    for e in envs[1:]:
        e.close()


def peak_rss_growth_kb(warmup, cycles):
    """Growth of the process's peak RSS over ``cycles`` make/reset/close cycles, after ``warmup`` of them."""

    def cycle(n):
        for _ in range(n):
            env = gym.make(ENV_ID)
            env.reset(seed=0)
            env.close()

    cycle(warmup)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    cycle(cycles)
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before


def test_make_close_cycles_do_not_grow_memory():
    assert peak_rss_growth_kb(20, 60) < 20_000


@pytest.mark.slow
def test_thousand_make_close_cycles_do_not_grow_memory():
    assert peak_rss_growth_kb(50, 1000) < 20_000


def test_touching_a_box_is_a_collision_that_ends_the_episode():
    env = gym.make(ENV_ID, min_clusters=2, max_clusters=2)
    env.reset(seed=1)
    cluster = env.unwrapped.scene.clusters[0]
    inside = cluster.tip_pose()
    inside[:3, 3] = 0.5 * (cluster.box_lo + cluster.box_hi)  # the clamp in the middle of the berries
    q = nearest_ik(flange_pose_for_tip(inside), harvest_configurations(cluster)[1])
    assert q is not None
    obs, reward, terminated, truncated, info = drive_to(env, q)
    assert terminated and info["collision"] and not info["is_success"]
    # A crash costs more than the worst return of a whole episode without one.
    assert reward == -1.0 - (info["time_limit"] + 1.0)
    assert reward < -info["time_limit"]


def test_reaching_a_cutting_point_harvests_the_cluster():
    env = gym.make(ENV_ID, min_clusters=2, max_clusters=2, n_leaves=0)
    obs, info = env.reset(seed=2)
    target = info["target_index"]
    pre, cut = harvest_configurations(env.unwrapped.scene.clusters[target])
    drive_to(env, pre)
    _, reward, terminated, _, info = drive_to(env, cut)
    assert info["harvested"] == 1 and reward == 0.0 and not info["collision"] and not terminated
    assert info["distance"] < 1e-6
    obs, *_, info = env.step(np.zeros(6))  # the designated goal moves on one step later
    assert info["target_index"] != target
    layout = env.unwrapped.layout
    others = obs["observation"][layout["others"]].reshape(-1, 16)
    assert others[:, 0].sum() == 0.0  # one cluster left: it is the designated one, no other slot is used
    np.testing.assert_allclose(
        obs["desired_goal"], env.unwrapped.scene.clusters[info["target_index"]].goal().astype(np.float32)
    )
    assert env.unwrapped.sim.collisions(margin=0.5).count(target) == 0  # its box left the scene


def test_end_effector_control_moves_the_clamp():
    env = gym.make(ENV_ID, control="ee")
    obs, _ = env.reset(seed=0)
    start = obs["achieved_goal"][:3].astype(float)
    obs, *_ = env.step(np.array([1.0, 0, 0, 0, 0, 0]))
    np.testing.assert_allclose(obs["achieved_goal"][:3] - start, [0.02, 0, 0], atol=5e-4)  # damped IK
    np.testing.assert_allclose(tip_pose(env.unwrapped.q)[:3, 3], obs["achieved_goal"][:3], atol=1e-6)


def test_rgb_render_headless_and_human():
    env = gym.make(ENV_ID, render_mode="rgb_array", render_width=160, render_height=120)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8
    assert frame.std() > 10  # a scene, not a blank image
    arm_orange = (frame[..., 0] > 180) & (frame[..., 1] > 90) & (frame[..., 1] < 170) & (frame[..., 2] < 80)
    assert arm_orange.sum() > 50
    env.close()
    env.close()
    human = gym.make(ENV_ID, render_mode="human", render_width=120, render_height=90)
    human.reset(seed=0)
    human.step(np.zeros(6))
    assert human.render() is None
    human.close()


def test_desired_goal_is_nowhere_in_the_observation():
    """HER relabels desired_goal only: the designated cut must not also sit in the observation."""
    for kwargs in ({}, {"min_clusters": 1, "max_clusters": 1}):
        env = gym.make(ENV_ID, **kwargs)
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            o, g = obs["observation"], obs["desired_goal"]
            windows = np.lib.stride_tricks.sliding_window_view(o, 3)
            assert not np.any(np.all(np.isclose(windows, g[:3], atol=1e-6), axis=1)), seed
            targets = env.unwrapped.scene.clusters
            others = o[env.unwrapped.layout["others"]].reshape(-1, 16)
            assert int(others[:, 0].sum()) == len(targets) - 1  # every other cluster is listed


def test_reach_preset_single_goal_ends_at_the_cut_and_time_limit_follows_the_task():
    env = gym.make("agri_envs/GrapeHarvestReach-v1")
    obs, info = env.reset(seed=5)
    assert obs["observation"].shape == (36,) and info["n_clusters"] == 1 and info["final_target"]
    assert 15 <= info["time_limit"] <= 100  # a few times the ~8 steps of the straight move, not 1000
    goal = obs["desired_goal"].copy()
    for _ in range(info["time_limit"]):
        obs, r, te, tr, info = env.step(np.zeros(6))
        np.testing.assert_array_equal(obs["desired_goal"], goal)  # the goal never switches
        if te or tr:
            break
    assert tr and not te and info["time_limit_reached"] and info["elapsed_steps"] == info["time_limit"]


def straight_to_goal(env, goal):
    """End-effector action moving the clamp straight toward the goal pose (a proportional controller)."""
    from agri_baselines.luo_apf import _log_rotation

    cfg, tip = env.unwrapped.config, tip_pose(env.unwrapped.q)
    g = np.asarray(goal, dtype=float)
    rot = np.stack([g[6:9], np.cross(g[3:6], g[6:9]), g[3:6]], axis=1)
    a = np.concatenate(
        [(g[:3] - tip[:3, 3]) / cfg.max_ee_step, _log_rotation(rot @ tip[:3, :3].T) / cfg.max_ee_rotation]
    )
    return np.clip(a, -1.0, 1.0)


@pytest.mark.parametrize("reward_type", ["sparse", "dense"])
def test_compute_terminated_and_truncated_batched_agree_with_step(reward_type):
    env = gym.make("agri_envs/GrapeHarvestReach-v1", reward_type=reward_type)
    u = env.unwrapped
    rng = np.random.default_rng(1)
    rows = []
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            goal = obs["desired_goal"]
            # Seeds 0-1 steer straight to the goal (they end reached), 2-3 wobble about home (they time out).
            action = straight_to_goal(env, goal) if seed < 2 else 0.2 * rng.uniform(-1, 1, 6)
            obs, r, te, tr, info = env.step(action)
            rows.append((obs["achieved_goal"], goal, info, te, tr))
            assert te == u.compute_terminated(obs["achieved_goal"], goal, info)
            assert tr == u.compute_truncated(obs["achieved_goal"], goal, info)
            done = te or tr
    a, d, infos = (np.array([row[k] for row in rows]) for k in range(3))
    np.testing.assert_array_equal(u.compute_terminated(a, d, infos), [row[3] for row in rows])
    np.testing.assert_array_equal(u.compute_truncated(a, d, infos), [row[4] for row in rows])
    assert any(row[3] for row in rows) and any(row[4] for row in rows)
    # Relabelled to the achieved goal, the final target counts as reached: terminated unless it collided.
    reached = u.compute_terminated(a, a, infos)
    assert reached.shape == (len(rows),) and reached.all()


def test_crashing_early_is_never_the_best_return():
    for reward_type in ("sparse", "dense"):
        env = gym.make(ENV_ID, reward_type=reward_type)
        _, info = env.reset(seed=0)
        u = env.unwrapped
        worst_uncrashed = -info["time_limit"] * u.task.worst_step
        g = np.zeros(9)
        crash = u.compute_reward(g, g + 1.0, dict(info, collision=True))
        assert crash < worst_uncrashed


def test_reset_after_close_and_render_without_mode_warns():
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    env.close()
    obs, _ = env.reset(seed=0)  # Gymnasium's and SB3's checkers do this
    env.step(np.zeros(6))
    with pytest.warns(UserWarning, match="render_mode=None"):
        assert env.unwrapped.render() is None
    env.close()


def test_luo_random_scenes_are_not_pre_filtered_but_feasible_ones_are():
    from agri_envs.arm.scene import SceneParams, corridor, sample_scene

    def blocked(scene):
        cors = [corridor(c, grow=0.0) for c in scene.clusters]
        return any(
            i != j and np.all(lo <= c.box_hi) and np.all(c.box_lo <= hi)
            for i, (lo, hi) in enumerate(cors)
            for j, c in enumerate(scene.clusters)
        )

    rng = np.random.default_rng(0)
    random = [sample_scene(rng, SceneParams(5, 5, 4, 2, 0.17, False)) for _ in range(30)]
    feasible = [sample_scene(rng, SceneParams(5, 5, 4, 2, 0.17, True)) for _ in range(30)]
    assert any(blocked(s) for s in random)  # a cluster's box across another's approach happens
    assert not any(blocked(s) for s in feasible)


def test_importing_the_sim_prints_nothing():
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", "import agri_envs.arm.sim"], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout == "" and out.stderr == ""


@pytest.mark.parametrize(
    ("name", "value", "expected"),
    [
        ("cluster_tilt", "0.1", "must be a number"),
        ("position_tolerance", None, "must be a number"),
        ("time_slack", True, "must be a number"),
        ("orientation_weight", [0.1], "must be a number"),
        ("min_clusters", "2", "must be an integer"),
        ("n_leaves", None, "must be an integer"),
        ("n_canes", 1.5, "must be an integer"),
        ("feasible_scenes", "yes", "must be a bool"),
        ("return_home", None, "must be a bool"),
        ("control", None, "is invalid; expected one of 'joint', 'ee'"),
        ("reward_type", 1, "is invalid; expected one of 'sparse', 'dense'"),
    ],
)
def test_wrong_argument_types_are_named(name, value, expected):
    with pytest.raises(ValueError, match=rf"{name}=.*{expected}"):
        gym.make(ENV_ID, **{name: value})
    env = gym.make(ENV_ID, cluster_tilt=0.2)  # numbers of either kind still pass
    env.reset(seed=0)
    env.step(np.zeros(6))
    env.close()


def test_wrong_reset_options_are_named_and_leave_the_env_usable():
    env = gym.make(ENV_ID)
    obs, _ = env.reset(seed=5)
    for bad in (3, "scene", [1, 2], env.unwrapped.scene.clusters):
        with pytest.raises(TypeError, match=r"reset option 'scene' must be an agri_envs.arm.scene.Scene"):
            env.reset(options={"scene": bad})
    with pytest.raises(TypeError, match="reset options must be a dict"):
        env.reset(options="scene")
    with pytest.raises(ValueError, match=r"reset options \['n_clusters'\] unknown"):
        env.reset(options={"n_clusters": 2})
    big = gym.make(ENV_ID, min_clusters=5, max_clusters=5)
    big.reset(seed=0)
    small = gym.make(ENV_ID, max_clusters=3)
    with pytest.raises(ValueError, match=r"'scene' has 5 clusters.*max_clusters >= 5"):
        small.reset(options={"scene": big.unwrapped.scene})
    # The env is still usable: the same seed gives the same episode, and a fitting scene is placed.
    again, _ = env.reset(seed=5)
    assert all(np.array_equal(obs[k], again[k]) for k in obs)
    env.step(np.zeros(6))
    two = gym.make(ENV_ID, min_clusters=2, max_clusters=2)
    two.reset(seed=1)
    placed, info = small.reset(options={"scene": two.unwrapped.scene})
    assert small.observation_space.contains(placed) and info["n_clusters"] == 2
    for e in (env, big, small, two):
        e.close()


def test_episodes_equal_the_digests_recorded_before_resets_were_made_fast():
    import json
    from pathlib import Path

    from grape_reference import digests

    recorded = json.loads((Path(__file__).parents[1] / "data" / "grape_harvest_digests.json").read_text())
    assert digests() == recorded


@pytest.mark.parametrize("kwargs", [{}, {"min_clusters": 5, "n_leaves": 8, "n_canes": 4, "control": "ee"}])
def test_a_long_lived_env_equals_a_fresh_one_for_every_seed(kwargs):
    """The reused pybullet client (bodies replaced, reconnected when shapes pile up) is a fresh env's."""
    env = gym.make(ENV_ID, **kwargs)
    env.unwrapped.sim.SHAPES_PER_CLIENT = 40  # reconnect every few resets
    actions = np.random.default_rng(0).uniform(-1, 1, (5, 6)).astype(np.float32)
    for seed in range(12):
        fresh = gym.make(ENV_ID, **kwargs)
        a = [env.reset(seed=seed)] + [env.step(x) for x in actions]
        b = [fresh.reset(seed=seed)] + [fresh.step(x) for x in actions]
        assert_same(
            [(o[0], 0.0 if len(o) == 2 else o[1], o[-1]) for o in a],
            [(o[0], 0.0 if len(o) == 2 else o[1], o[-1]) for o in b],
        )
        assert env.unwrapped.sim.min_distance(0.3) == fresh.unwrapped.sim.min_distance(0.3)
        assert env.unwrapped.sim.collisions(0.1) == fresh.unwrapped.sim.collisions(0.1)
        fresh.close()
    env.close()


def _numpy_make_cluster(rng, cut, tilt_max):
    """make_cluster as first written, in numpy: the reference for the scalar version."""
    import math

    from agri_envs.arm.scene import BOX_MARGIN, PEDUNCLE_GAP, Cluster

    def rotate(v, axis, angle):
        c, s = math.cos(angle), math.sin(angle)
        return v * c + np.cross(axis, v) * s + axis * np.dot(axis, v) * (1 - c)

    yaw = math.atan2(cut[1], cut[0]) + rng.uniform(-math.radians(12.0), math.radians(12.0))
    approach = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    down = rotate(np.array([0.0, 0.0, -1.0]), approach, rng.uniform(-tilt_max, tilt_max))
    length, radius = rng.uniform(0.10, 0.16), rng.uniform(0.035, 0.05)
    side = np.cross(down, approach)
    berries = []
    berry = 0.013
    for level in np.linspace(0.0, 1.0, 5):
        ring_r = (radius - berry) * (1.0 - 0.7 * level)
        centre = cut + (PEDUNCLE_GAP + berry + level * (length - 2 * berry)) * down
        n = 5 - int(round(4 * level))
        phase = rng.uniform(0, 2 * math.pi)
        for k in range(n):
            a = phase + 2 * math.pi * k / n
            offset = ring_r * (math.cos(a) * approach + math.sin(a) * side)
            berries.append(np.concatenate([centre + offset, [berry]]))
    b = np.array(berries)
    lo = np.min(b[:, :3] - b[:, 3:], axis=0) - BOX_MARGIN
    hi = np.max(b[:, :3] + b[:, 3:], axis=0) + BOX_MARGIN
    return Cluster(cut.copy(), approach, down, b, lo, hi)


def test_scalar_cluster_builder_equals_the_numpy_one_bit_for_bit():
    from agri_envs.arm.scene import CUT_HIGH, CUT_LOW, make_cluster

    r1, r2 = np.random.default_rng(11), np.random.default_rng(11)
    for i in range(3000):
        tilt = (0.0, 0.17, 0.5)[i % 3]
        a = make_cluster(r1, r1.uniform(CUT_LOW, CUT_HIGH), tilt)
        b = _numpy_make_cluster(r2, r2.uniform(CUT_LOW, CUT_HIGH), tilt)
        for field in ("cut_point", "approach", "down", "berries", "box_lo", "box_hi"):
            x, y = getattr(a, field), getattr(b, field)
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), (i, field)
    assert r1.random() == r2.random()  # the same draws were consumed


def _same_scene(a, b):
    assert len(a.clusters) == len(b.clusters) and len(a.obstacles) == len(b.obstacles)
    for x, y in zip(a.clusters, b.clusters, strict=True):
        for field in ("cut_point", "approach", "down", "berries", "box_lo", "box_hi"):
            assert getattr(x, field).tobytes() == getattr(y, field).tobytes(), field
    for x, y in zip(a.obstacles, b.obstacles, strict=True):
        assert x.kind == y.kind and x.lo.tobytes() == y.lo.tobytes() and x.hi.tobytes() == y.hi.tobytes()


@pytest.mark.parametrize("unsure", [0.0, 0.3, 1.0])
@pytest.mark.parametrize(
    "params", [(2, 5, 4, 2, 0.17, False), (2, 5, 4, 2, 0.17, True), (5, 5, 8, 4, 0.5, False), (1, 1, 0, 0, 0.0, True)]
)
def test_fast_scene_sampler_equals_the_numpy_reference(params, unsure, monkeypatch):
    """The certified kernels' answers, numpy's fallbacks (forced at random here) and the reference agree."""
    from agri_envs.arm import _kernels
    from agri_envs.arm.scene import (
        SceneParams,
        harvest_configurations,
        sample_scene_and_configurations,
        sample_scene_reference,
    )

    coin = np.random.default_rng(0)
    for name in ("overlap", "collides", "too_close", "harvest_configurations"):
        real = getattr(_kernels, name)

        def shaky(*args, _real=real, _name=name):
            out = _real(*args)
            if coin.random() >= unsure:
                return out
            return (out[0], out[1], _kernels.UNCERTAIN) if _name == "harvest_configurations" else _kernels.UNCERTAIN

        monkeypatch.setattr(_kernels, name, shaky)
    p = SceneParams(*params)
    for seed in range(12):
        r1, r2 = np.random.default_rng(seed), np.random.default_rng(seed)
        scene, configs = sample_scene_and_configurations(r1, p)
        _same_scene(scene, sample_scene_reference(r2, p))
        assert r1.random() == r2.random()  # the same draws
        for c, (pre, cut) in zip(scene.clusters, configs, strict=True):
            exact = harvest_configurations(c)
            np.testing.assert_allclose(pre, exact[0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(cut, exact[1], rtol=0, atol=1e-12)


def test_frames_show_the_scene_not_the_collision_boxes():
    """Visual shapes are made at the first frame of a scene; the boxes' collision links stay invisible."""
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=3)
    first = env.render()
    for seed in range(6):  # resets without frames make no visual shapes
        env.reset(seed=seed)
    env.reset(seed=3)
    assert np.array_equal(env.render(), first)
    # Berries are drawn in their purple (the bare collision boxes would hide them in white).
    purple = (first[..., 2] > first[..., 1] + 40) & (first[..., 0] > first[..., 1] + 20)
    assert purple.sum() > 200
    env.close()


def test_tool_rotation_equals_the_numpy_cross_version_bit_for_bit():
    from agri_envs.arm.scene import tool_rotation

    rng = np.random.default_rng(4)
    for _ in range(2000):
        approach, down = rng.normal(size=3), rng.normal(size=3)
        z = approach / np.linalg.norm(approach)
        x = down - np.dot(down, z) * z
        x /= np.linalg.norm(x)
        assert tool_rotation(approach, down).tobytes() == np.stack([x, np.cross(z, x), z], axis=1).tobytes()


@pytest.mark.parametrize("kwargs", [{}, {"max_joint_step": 0.001, "time_slack": 100.0}])
def test_time_limit_from_the_samplers_configurations_equals_numpys(kwargs):
    env = gym.make(ENV_ID, **kwargs).unwrapped
    for seed in range(40):
        env.reset(seed=seed)
        assert env.time_limit == env._time_limit(env.scene)  # configurations from harvest_configurations
