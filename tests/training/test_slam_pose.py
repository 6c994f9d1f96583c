"""SlamWaypoint: a learned policy's own Hector SLAM, checked against harik-apf's and replayed as training saw it."""

import math

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_baselines import make_policy
from agri_training.learned.policy import (
    ActionRepeat,
    HeldActions,
    ObservationReplay,
    apply_wrappers,
    decide_held,
    observation_chain,
    with_wrapper_settings,
)
from agri_training.learned.slam_pose import SlamWaypoint

ENV_ID = "agri_envs/GreenhouseNav-v2"
BLIND = {"localization": "none", "full_scan": True, "n_rows": 2, "row_length": 4.0, "n_people": 1}
WRAPPERS = [
    "SlamWaypoint",
    {"FilterObservation": {"filter_keys": ["lidar", "sonar", "velocity", "waypoint"]}},
    "FlattenObservation",
]


def _act(k):
    """The k-th decision of an episode: slow ahead, weaving (the same in training and evaluation)."""
    return np.array([0.3, 0.5 * math.sin(k / 5)], np.float32)


def test_waypoint_is_harik_apfs_distance_and_bearing_on_the_same_slam():
    # The oracle: harik-apf runs the same Hector SLAM on every scan and computes d and alpha its own way.
    env = SlamWaypoint(gym.make(ENV_ID, **BLIND))
    harik = make_policy("harik-apf", env)
    diagonal = env.unwrapped.diagonal
    for seed in (3, 4):
        obs, _ = env.reset(seed=seed)
        start, done, steps, far = True, False, 0, 0.0
        while not done and steps < 200:
            scan = obs["scan"] * harik.robot.lidar_max_range
            if start:
                harik.start_episode(0)
            d, alpha = harik.waypoint_error(0, obs, scan)  # its SLAM update on this scan, then eqs. 2-4
            np.testing.assert_allclose(obs["waypoint"][0], min(1.0, d / diagonal), rtol=1e-6, atol=1e-7)
            np.testing.assert_allclose(obs["waypoint"][1:], [math.sin(alpha), math.cos(alpha)], atol=1e-6)
            far = max(far, d)
            obs, _, terminated, truncated, _ = env.step(_act(steps))
            start, done, steps = False, terminated or truncated, steps + 1
        assert far > 1.0 and steps > 50


def test_a_loaded_policy_replays_the_slam_training_saw():
    """Training: the wrappers outside ActionRepeat. Evaluation: raw env, replayed once per held action, the
    SLAM map started afresh with each episode."""
    repeat, episodes, decisions = 4, (11, 12), 40
    train_env = apply_wrappers(ActionRepeat(gym.make(ENV_ID, **BLIND), repeat), WRAPPERS)
    trained = []
    for seed in episodes:
        obs, _ = train_env.reset(seed=seed)
        for k in range(decisions):
            trained.append(obs)
            obs, _, terminated, truncated, _ = train_env.step(_act(k))
            if terminated or truncated:
                break

    class Recorder:
        """Records what it is shown; acts by its decision count in the episode."""

        def __init__(self):
            self.seen, self.k = [], 0

        def predict(self, observation, state=None, episode_start=None, deterministic=True):
            self.k = 0 if episode_start[0] else self.k + 1
            self.seen.append(np.array(observation))
            return _act(self.k), state

    eval_env = gym.make(ENV_ID, **BLIND)
    replay = ObservationReplay(observation_chain(eval_env, WRAPPERS)[1])
    hold, loaded = HeldActions(repeat), Recorder()
    for seed in episodes:
        obs, _ = eval_env.reset(seed=seed)
        for step in range(decisions * repeat):
            action, _ = decide_held(hold, replay, loaded, obs, None, np.array([step == 0]), True)
            obs, _, terminated, truncated, _ = eval_env.step(action)
            if terminated or truncated:
                break
    assert len(loaded.seen) == len(trained) > 20
    for k, (a, b) in enumerate(zip(trained, loaded.seen, strict=True)):
        np.testing.assert_array_equal(a, b, err_msg=f"decision {k}")


@pytest.mark.parametrize("kwargs", [{}, {"localization": "none"}, {"full_scan": True}])
def test_needs_an_env_without_pose_and_with_the_scan(kwargs):
    with pytest.raises(ValueError, match="localization='none' and full_scan=True"):
        SlamWaypoint(gym.make(ENV_ID, **kwargs))


def test_aim_inside_adds_its_margin_to_the_distance_only():
    plain, aimed = (SlamWaypoint(gym.make(ENV_ID, **BLIND), aim_inside=m) for m in (0.0, 0.1))
    a, _ = plain.reset(seed=5)
    b, _ = aimed.reset(seed=5)
    for k in range(30):
        diagonal = plain.unwrapped.diagonal
        assert b["waypoint"][0] * diagonal == pytest.approx(a["waypoint"][0] * diagonal + 0.1, abs=1e-5)
        np.testing.assert_array_equal(a["waypoint"][1:], b["waypoint"][1:])
        a, *_ = plain.step(_act(k))
        b, *_ = aimed.step(_act(k))
    with pytest.raises(ValueError, match="aim_inside must be in"):
        SlamWaypoint(gym.make(ENV_ID, **BLIND), aim_inside=-0.1)


def test_every_scan_feeds_the_held_steps_scans_to_the_slam_wherever_the_weights_act_or_learn():
    """Oracle: the wrapper on an env stepped every control period (its SLAM sees every scan), read at the
    decisions. Both the evaluation path (decide_held) and imitation's recording (pretrain) must match it, and
    differ from the once-per-decision SLAM."""
    from agri_training.learned.pretrain import _Decisions

    repeat, steps, seed = 4, 160, 21
    every = [{"SlamWaypoint": {"every_scan": True}}, *WRAPPERS[1:]]
    oracle_env = apply_wrappers(gym.make(ENV_ID, **BLIND), WRAPPERS)
    obs, _ = oracle_env.reset(seed=seed)
    oracle = []
    for step in range(steps):
        if step % repeat == 0:
            oracle.append(obs)
        obs, *_ = oracle_env.step(_act(step // repeat))

    def decisions_seen(wrappers):
        env = gym.make(ENV_ID, **BLIND)
        replay, hold = ObservationReplay(observation_chain(env, wrappers)[1]), HeldActions(repeat)
        seen = []

        class Recorder:
            def predict(self, observation, state=None, episode_start=None, deterministic=True):
                seen.append(np.array(observation))
                return _act(len(seen) - 1), state

        obs, _ = env.reset(seed=seed)
        for step in range(steps):
            action, _ = decide_held(hold, replay, Recorder(), obs, None, np.array([step == 0]), True)
            obs, *_ = env.step(action)
        return seen

    def recorded_by_imitation(wrappers):
        env = gym.make(ENV_ID, **BLIND)
        decisions = _Decisions(env, {"wrappers": wrappers, "action_repeat": repeat})
        obs, _ = env.reset(seed=seed)
        for step in range(steps):
            decisions.decide(step, obs, _act(step // repeat))
            obs, *_ = env.step(_act(step // repeat))
        return decisions.observations

    for seen in (decisions_seen(every), recorded_by_imitation(every)):
        assert len(seen) == len(oracle) == steps // repeat
        for k, (a, b) in enumerate(zip(oracle, seen, strict=True)):
            np.testing.assert_array_equal(a, b, err_msg=f"decision {k}")
    once = decisions_seen(WRAPPERS)
    assert max(np.abs(a - b).max() for a, b in zip(oracle, once, strict=True)) > 1e-4  # half the scans: another pose


def test_every_scan_is_a_bool_and_ppo_rollouts_refuse_it(tmp_path):
    from agri_training.train import TrainRequest, resolve_config

    with pytest.raises(ValueError, match="every_scan must be true or false"):
        SlamWaypoint(gym.make(ENV_ID, **BLIND), every_scan="yes")
    recipe = tmp_path / "slam.yml"
    recipe.write_text(
        "default:\n  policy: MultiInputPolicy\n  action_repeat: 2\n  n_timesteps: 4096\n"
        "  env_kwargs: {localization: none, full_scan: true}\n"
        "  wrappers: [{SlamWaypoint: {every_scan: true}}]\n"
        "  pretrain: {policy: harik-apf-gt, episodes: 2}\n"
    )
    with pytest.raises(ValueError, match="imitation-only run"):
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "r", hyperparams_file=recipe))
    imitation = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "r", hyperparams_file=recipe, timesteps=0))
    assert imitation["wrappers"][0] == {"SlamWaypoint": {"every_scan": True}}


def test_the_odometry_is_the_motion_of_the_last_control_period():
    """Oracle: the true pose's change over each step, in the robot's frame (the env's info)."""
    env = SlamWaypoint(gym.make(ENV_ID, **BLIND), every_scan=True, odometry=True)
    obs, info = env.reset(seed=7)
    worst = np.zeros(3)
    for k in range(60):
        before = np.array([info["x"], info["y"], info["yaw"]])
        obs, _, terminated, truncated, info = env.step(_act(k))
        c, s = math.cos(before[2]), math.sin(before[2])
        dx, dy = info["x"] - before[0], info["y"] - before[1]
        turn = math.atan2(math.sin(info["yaw"] - before[2]), math.cos(info["yaw"] - before[2]))
        truth = np.array([c * dx + s * dy, -s * dx + c * dy, turn])
        worst = np.maximum(worst, np.abs(np.array(env._odometry(obs)) - truth))
        assert not (terminated or truncated)
    assert worst[0] < 0.005 and worst[1] < 0.002 and worst[2] < 0.01, worst  # m, m, rad per 1/15 s


def test_odometry_is_a_bool_and_needs_every_scan():
    blind = gym.make(ENV_ID, **BLIND)
    with pytest.raises(ValueError, match="odometry must be true or false"):
        SlamWaypoint(blind, every_scan=True, odometry=1)
    with pytest.raises(ValueError, match="odometry needs every_scan"):
        SlamWaypoint(blind, odometry=True)
    assert SlamWaypoint(blind, every_scan=True)._odometry({"velocity": np.ones(2, np.float32)}) is None


def test_wrapper_settings_change_only_the_named_wrappers_arguments():
    wrappers = [{"SlamWaypoint": {"every_scan": True}}, "RobotLimits", {"ObservationHistory": {"frames": 3}}]
    changed = with_wrapper_settings(wrappers, {"SlamWaypoint": {"odometry": True}, "RobotLimits": {}})
    assert changed == [{"SlamWaypoint": {"every_scan": True, "odometry": True}}, {"RobotLimits": {}}, wrappers[2]]
    assert wrappers[0] == {"SlamWaypoint": {"every_scan": True}}  # the run's config is left as it was
    with pytest.raises(ValueError, match="does not use"):
        with_wrapper_settings(wrappers, {"Proximity": {"lidar": 0.1}})


def test_the_odometry_policy_is_the_every_scan_network_with_odometry_in_its_slam():
    from agri_training.learned import zoo

    env = gym.make(ENV_ID, **BLIND)
    every = make_policy("dagger-greenhouse-nav-slam-every-scan-shielded", env)
    odometry = make_policy("dagger-greenhouse-nav-slam-odometry-shielded", env)
    assert zoo.zoo_path("dagger-greenhouse-nav-slam-odometry-shielded") == every.folder
    slams = [next(w for w in p._replay.chain if isinstance(w, SlamWaypoint)) for p in (every, odometry)]
    assert [s.odometry for s in slams] == [False, True] and all(s.every_scan for s in slams)
    for a, b in zip(odometry.network.hidden, every.network.hidden, strict=True):  # one set of weights
        np.testing.assert_array_equal(a[0], b[0])
