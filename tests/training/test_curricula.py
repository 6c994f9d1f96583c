"""Training curricula: GreenhouseNav's start_waypoint reset option and the RandomStartWaypoint wrapper."""

import math

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_training.learned.curricula import RandomStartWaypoint, apply_train_wrappers

ENV_ID = "agri_envs/GreenhouseNav-v2"


def test_start_waypoint_places_the_robot_on_the_previous_waypoint():
    env = gym.make(ENV_ID)
    _, info0 = env.reset(seed=3)
    targets = env.unwrapped.task.targets.copy()
    for k in (1, 2, 5, len(targets) - 1):
        _, info = env.reset(seed=3, options={"start_waypoint": k})
        assert info["waypoint_index"] == k and info["waypoints_reached"] == k
        assert np.hypot(info["x"] - targets[k - 1][0], info["y"] - targets[k - 1][1]) < 0.08
        before = targets[k - 2] if k >= 2 else env.unwrapped.layout.start_pose[:2]
        heading = np.arctan2(*(targets[k - 1] - before)[::-1])
        assert abs(np.angle(np.exp(1j * (info["yaw"] - heading)))) <= 0.1 + 1e-9
        assert info["max_episode_steps"] < info0["max_episode_steps"]
    # The default start is unchanged by the option's existence.
    a, ia = env.reset(seed=3)
    b, ib = env.reset(seed=3, options={"start_waypoint": 0})
    assert all(np.array_equal(a[key], b[key]) for key in a) and ia["x"] == ib["x"]


def test_a_late_start_can_finish_the_mission():
    env = gym.make(ENV_ID, n_people=0)
    n = env.reset(seed=0)[1]["n_waypoints"]
    _, info = env.reset(seed=0, options={"start_waypoint": n - 1})
    task = env.unwrapped.task
    assert not task.done
    # Drive straight at the last waypoint: reaching it ends the episode with success.
    for _ in range(400):
        b = info["bearing_to_waypoint"]
        _, _, term, trunc, info = env.step(np.array([1.0 if abs(b) < 0.3 else 0.0, np.clip(2 * b, -1, 1)], np.float32))
        if term or trunc:
            break
    assert info["is_success"] and not info["collision"]


@pytest.mark.parametrize("bad", [-1, 8, 2.5, "1", True])
def test_bad_start_waypoint_leaves_the_episode_intact(bad):
    env = gym.make(ENV_ID, n_people=0)
    env.reset(seed=0)
    base = env.unwrapped
    scene = (base.layout, base.world, base.robot, base.task)
    before = base.robot.pose.copy()
    with pytest.raises(ValueError, match="start_waypoint"):
        env.reset(seed=1, options={"start_waypoint": bad})
    # the episode that was running goes on, in its own scene
    assert (base.layout, base.world, base.robot, base.task) == scene
    _, _, _, _, info = env.step(np.array([0.5, 0.0], np.float32))
    assert not info["collision"] and np.hypot(info["x"] - before[0], info["y"] - before[1]) > 0


def test_random_start_waypoint_is_seeded_and_respects_prob():
    def starts(prob, seed):
        env = RandomStartWaypoint(gym.make(ENV_ID, n_people=0), prob=prob)
        out = [env.reset(seed=seed)[1]["waypoint_index"]]
        out += [env.reset()[1]["waypoint_index"] for _ in range(11)]
        return out

    assert starts(0.0, 0) == [0] * 12
    always = starts(1.0, 0)
    assert all(1 <= k <= 7 for k in always) and len(set(always)) > 2
    assert starts(0.5, 4) == starts(0.5, 4)
    half = starts(0.5, 4)
    assert 0 in half[1:] and any(k > 0 for k in half)


def test_train_wrappers_are_allow_listed():
    env = gym.make(ENV_ID)
    assert isinstance(apply_train_wrappers(env, [{"RandomStartWaypoint": {"prob": 0.3}}]), RandomStartWaypoint)
    with pytest.raises(ValueError, match="not allowed"):
        apply_train_wrappers(env, ["TimeLimit"])
    with pytest.raises(ValueError, match="prob"):
        RandomStartWaypoint(env, prob=1.5)


def test_action_repeat_sums_the_held_steps_and_stops_at_the_end():
    from agri_training.learned.policy import ActionRepeat

    plain = gym.make(ENV_ID, n_people=0)
    held = ActionRepeat(gym.make(ENV_ID, n_people=0), 4)
    plain.reset(seed=2)
    held.reset(seed=2)
    action = np.array([1.0, 0.2], np.float32)
    for _ in range(3):
        rewards = [plain.step(action)[1] for _ in range(4)]
        obs, reward, *_ = held.step(action)
        assert reward == pytest.approx(sum(rewards))
    assert held.unwrapped.task.steps == plain.unwrapped.task.steps == 12
    crash = ActionRepeat(gym.make(ENV_ID, n_rows=1, row_length=3.0, n_people=0), 1000)
    crash.reset(seed=0)
    _, _, term, _, info = crash.step(np.array([1.0, 0.3], np.float32))  # into the row: ends at the contact
    assert term and info["collision"] and crash.unwrapped.task.steps < 1000
    with pytest.raises(ValueError, match="action_repeat"):
        ActionRepeat(plain, 0)


def test_held_actions_ask_every_k_steps_and_restart_with_the_episode():
    from agri_training.learned.policy import HeldActions

    hold = HeldActions(3)
    calls = []

    def decide():
        calls.append(len(calls))
        return np.array([float(len(calls))]), None

    out = [hold(decide, np.array([i == 0]))[0][0] for i in range(7)]
    assert out == [1, 1, 1, 2, 2, 2, 3]
    assert hold(decide, np.array([True]))[0][0] == 4  # a new episode asks at once
    assert HeldActions(1)(decide, None)[0][0] == 5


def test_crash_cost_ramp_refunds_a_shrinking_share_of_the_crash():
    from agri_training.learned.curricula import CrashCostRamp

    def crash(env):
        env.reset(seed=0)
        while True:
            _, reward, term, trunc, info = env.step(np.array([1.0, 0.3], np.float32))  # into the row
            if term or trunc:
                return reward, info

    small = {"n_rows": 1, "row_length": 3.0, "n_people": 0}
    plain_reward, info = crash(gym.make(ENV_ID, **small))
    ramp = CrashCostRamp(gym.make(ENV_ID, **small), start=0.25, ramp_steps=10_000)
    reward, _ = crash(ramp)
    share = 0.25 + 0.75 * ramp.steps / 10_000
    assert ramp.share == pytest.approx(share)
    assert reward == pytest.approx(plain_reward + (1 - share) * -info["reward_collision"])
    done = CrashCostRamp(gym.make(ENV_ID, **small), start=0.25, ramp_steps=1)
    assert crash(done)[0] == pytest.approx(plain_reward)  # after the ramp: the env's own reward
    with pytest.raises(ValueError, match="start"):
        CrashCostRamp(gym.make(ENV_ID, **small), start=2.0)


def test_crash_cost_ramp_refunds_the_coverage_contact_term():
    from agri_training.learned.curricula import CrashCostRamp

    def contact(env):
        env.reset(seed=0)
        while True:
            _, reward, term, trunc, info = env.step(np.array([1.0, -0.6], np.float32))  # into the wall
            if term or trunc:
                return reward, info

    small = {"n_rows": 1, "row_length": 4.0}
    plain, info = contact(gym.make("agri_envs/GreenhouseCoverage-v2", **small))
    assert info["reward_contact"] < 0
    ramp = CrashCostRamp(gym.make("agri_envs/GreenhouseCoverage-v2", **small), 0.5, 10**9, term="reward_contact")
    assert contact(ramp)[0] == pytest.approx(plain + 0.5 * -info["reward_contact"])


def test_random_start_fits_each_drawn_mission():
    # Every episode draws another scene, and its own number of waypoints: the start always lies inside it.
    env = gym.make(ENV_ID, scene_distribution="training")
    lengths, starts = set(), []
    for seed in range(40):
        _, info = env.reset(seed=seed, options={"start_waypoint": "random"})
        assert 1 <= info["waypoint_index"] < info["n_waypoints"]
        lengths.add(info["n_waypoints"])
        starts.append(info["waypoint_index"])
    assert len(lengths) > 3 and len(set(starts)) > 3
    _, again = env.reset(seed=7, options={"start_waypoint": "random"})
    _, first = env.reset(seed=7, options={"start_waypoint": "random"})
    assert again["waypoint_index"] == first["waypoint_index"] and again["x"] == first["x"]


def test_expert_start_hands_over_where_the_baseline_left_off():
    from agri_training.learned.curricula import ExpertStart

    cover = "agri_envs/GreenhouseCoverage-v2"
    small = {"n_rows": 2, "row_length": 4.0}

    def starts(prob, seed):
        env = ExpertStart(gym.make(cover, **small), "gonzalez-pseudo-reactive", prob=prob, extra_steps=30)
        out = []
        for k in range(4):
            obs, info = env.reset(seed=seed if k == 0 else None)
            out.append((info["corridors_covered"], env.unwrapped._steps, float(obs["memory"][:256].sum())))
        return out

    handed = starts(1.0, 3)
    assert handed == starts(1.0, 3)  # seeded
    # After 1 or 2 of the 3 corridors, in real driven states: the memory holds the baseline's trail.
    assert all(1 <= covered <= 2 and steps > 100 and trail > 5 for covered, steps, trail in handed)
    plain = gym.make(cover, **small)
    obs0, info0 = plain.reset(seed=3)
    env = ExpertStart(gym.make(cover, **small), "gonzalez-pseudo-reactive", prob=0.0)
    obs1, info1 = env.reset(seed=3)
    assert all(np.array_equal(obs0[k], obs1[k]) for k in obs0) and info1["corridors_covered"] == 0
    with pytest.raises(ValueError, match="prob"):
        ExpertStart(gym.make(cover, **small), "gonzalez-pseudo-reactive", prob=1.5)


def test_robust_vines_draw_each_episode_from_their_ranges_and_are_seeded():
    from agri_training.learned.curricula import RobustVines

    def draws(seed):
        env = RobustVines(gym.make("agri_envs/GrapeHarvest-v1"), cluster_tilt=[0.3, 0.4], min_clusters=[5, 5])
        env.reset(seed=seed)
        scenes = [env.unwrapped.scene]
        for _ in range(4):
            env.reset()
            scenes.append(env.unwrapped.scene)
        return scenes

    scenes = draws(11)
    assert all(len(s.clusters) == 5 for s in scenes)  # the env alone draws 2-5
    # Oracle: a cluster's lean is the angle between its hanging axis and the vertical, at most the drawn limit.
    leans = [math.acos(min(1.0, abs(float(c.down[2])))) for s in scenes for c in s.clusters]
    assert max(leans) <= 0.4 + 1e-9 and max(leans) > 0.17  # past the env's default 0.17 rad
    again = draws(11)
    assert all(
        np.array_equal(a.clusters[i].cut_point, b.clusters[i].cut_point)
        for a, b in zip(scenes, again, strict=True)
        for i in range(5)
    )
    plain = gym.make("agri_envs/GrapeHarvest-v1")
    with pytest.raises(ValueError, match="cluster_tilt"):
        RobustVines(plain, cluster_tilt=[0.3, 0.6])
    with pytest.raises(ValueError, match="min_clusters"):
        RobustVines(plain, min_clusters=[2, 6])
    with pytest.raises(ValueError, match="GrapeHarvest"):
        RobustVines(gym.make("agri_envs/GreenhouseNav-v2"))
