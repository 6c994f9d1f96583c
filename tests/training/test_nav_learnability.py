"""GreenhouseNav-v2's learnability changes: mission-sized time limits and honest crash costs."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_envs.rover.task import RewardWeights, mission_time_limit
from agri_training.evaluation.episode import run_episode
from agri_training.evaluation.policies import load_policy

ENV_ID = "agri_envs/GreenhouseNav-v2"
SMALL = {"n_rows": 1, "row_length": 3.0, "n_people": 0}


def _drive(env, action, seed=0):
    env.reset(seed=seed)
    total = 0.0
    while True:
        _, r, term, trunc, info = env.step(np.asarray(action, np.float32))
        total += r
        if term or trunc:
            return total, term, trunc, info


def test_crash_costs_more_than_stopping_and_waiting_out_the_limit():
    env = gym.make(ENV_ID, **SMALL)
    idle_return, _, idle_trunc, idle_info = _drive(env, [0.0, 0.0])
    crash_return, crash_term, _, crash_info = _drive(env, [1.0, 0.3])  # full speed, curving into the row on the left
    assert idle_trunc and crash_term and crash_info["collision"]
    assert crash_return < idle_return
    limit = crash_info["max_episode_steps"]
    steps = round(crash_info["episode_time"] * 15)
    w = RewardWeights()
    # The crash costs its fixed part plus the time penalty of every step it leaves unused.
    assert -crash_info["reward_collision"] == pytest.approx(w.collision + (limit - steps) * w.time)
    assert -crash_info["reward_collision"] > (limit - steps) * w.time + 0.5 * w.collision
    assert idle_info["max_episode_steps"] == limit


def test_crash_cost_covers_a_longer_time_limit():
    a = gym.make(ENV_ID, **SMALL)
    b = gym.make(ENV_ID, **SMALL, max_episode_steps=20_000)
    costs = [-_drive(e, [1.0, 0.3])[3]["reward_collision"] for e in (a, b)]
    w = RewardWeights()
    assert costs[1] - costs[0] == pytest.approx((20_000 - a.unwrapped.max_episode_steps) * w.time)


def test_clearance_penalty_is_paid_per_metre_driven_inside_the_margin():
    w = RewardWeights()
    env = gym.make(ENV_ID, **SMALL, safety_margin=1.0)  # every pose is inside a 1 m margin
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(2, np.float32))
    assert info["reward_clearance"] == 0.0  # standing still costs time only
    for _ in range(10):
        _, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    before = info["path_length"]
    _, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    shortfall = 1.0 - info["clearance"]
    assert 0 < shortfall < 1
    assert info["reward_clearance"] == pytest.approx(-w.clearance * shortfall * (info["path_length"] - before))


def test_default_limit_follows_the_mission():
    limits = []
    for kw in ({}, {"n_rows": 5}, {"n_rows": 6, "row_length": 12.0}):
        env = gym.make(ENV_ID, **kw)
        _, info = env.reset(seed=0)
        limits.append(info["max_episode_steps"])
    assert limits[0] < limits[1] < limits[2]
    assert env.spec is not None and env.spec.max_episode_steps is None


def test_explicit_limit_wins_and_info_says_why():
    for n in (15, 4000):  # below and above the mission's own limit
        env = gym.make(ENV_ID, **SMALL, max_episode_steps=n)
        _, info = env.reset(seed=0)
        assert info["max_episode_steps"] == n
        steps = 0
        while True:
            _, _, term, trunc, info = env.step(np.zeros(2, np.float32))
            steps += 1
            if term or trunc:
                break
        assert trunc and not term and steps == n
        assert info["truncated"] and "explicit max_episode_steps" in info["truncation_reason"]


def test_default_truncation_info():
    env = gym.make(ENV_ID, **SMALL)
    _, _, trunc, info = _drive(env, [0.0, 0.0])
    assert trunc and info["truncated"]
    assert "time limit" in info["truncation_reason"] and "of the speed limits" in info["truncation_reason"]
    assert info["episode_time"] == pytest.approx(info["max_episode_steps"] / 15)


def test_mission_time_limit_oracle():
    # 10 m straight ahead, then a 90 deg left turn and 5 m: at half of 1 m/s and 1 rad/s.
    steps = mission_time_limit(np.zeros(3), np.array([[10.0, 0.0], [10.0, 5.0]]), 1.0, 1.0, 0.1, 0.5)
    assert steps == int(np.ceil((15 / 0.5 + (np.pi / 2) / 0.5) / 0.1 - 1e-9))
    with pytest.raises(ValueError, match="speed_fraction"):
        mission_time_limit(np.zeros(3), np.ones((1, 2)), 1.0, 1.0, 0.1, 0.0)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"n_rows": 4, "growth": 0.8, "n_people": 4, "people_tease_prob": 0.6},
        pytest.param({"n_rows": 5}, marks=pytest.mark.slow),
        pytest.param({"n_rows": 6, "row_length": 10.0, "growth": 0.5, "n_people": 4}, marks=pytest.mark.slow),
    ],
)
def test_harik_apf_gt_meets_the_default_limit_on_held_out_scenes(kwargs):
    env = gym.make(ENV_ID, localization="ground_truth", full_scan=True, **kwargs)
    policy = load_policy("harik-apf-gt", env)
    record = run_episode(env, policy, 100_000, None)["record"]
    assert record["is_success"], record
    assert not record["truncated"]


def test_turning_counts_as_progress_on_the_distance_to_go():
    w = RewardWeights()
    env = gym.make(ENV_ID, **SMALL)
    _, info0 = env.reset(seed=0)
    turn_distance = env.unwrapped.config.max_speed / env.unwrapped.config.max_turn_rate

    def to_go(info):
        return info["distance_to_waypoint"] + turn_distance * abs(info["bearing_to_waypoint"])

    earned = 0.0
    for _ in range(15):  # turn in place, away from the waypoint
        _, _, _, _, info = env.step(np.array([0.0, 1.0], np.float32))
        earned += info["reward_progress"]
    assert abs(info["bearing_to_waypoint"]) - abs(info0["bearing_to_waypoint"]) > 0.3
    assert earned == pytest.approx(w.progress * (to_go(info0) - to_go(info)), rel=1e-6)
    assert earned < -0.3 * w.progress * turn_distance
    back = 0.0
    for _ in range(15):  # and back toward it
        _, _, _, _, info = env.step(np.array([0.0, -1.0], np.float32))
        back += info["reward_progress"]
    assert back > 0.0
