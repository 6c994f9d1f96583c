"""Harik APF: eqs. 12-14 worked values, repulsion, passive safety, SB3 compatibility, solving the env."""

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_baselines import make_policy, policy_spec
from agri_baselines.harik_apf import (
    HarikApfController,
    HarikApfParams,
    RobotGeometry,
    scan_zones,
    scan_zones_reference,
)
from agri_envs.rover import robot as rover
from agri_envs.rover.distribution import ROBUST
from agri_envs.sim2d.sensors import tim561
from agri_training.evaluation.episode import run_episode

ENV_ID = "agri_envs/GreenhouseNav-v2"


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


def wall_scan(controller, y, x0, x1, ranges=None):
    """Full LIDAR scan (m) with a wall along the body axis at body-frame ``y`` from ``x0`` to ``x1``.

    The ranges are exact ray-segment intersections from the LIDAR mount, so the points the controller
    reconstructs lie on the wall.
    """
    mx, my, myaw = controller.robot.lidar_mount
    ang = myaw + controller.robot.beam_angles
    out = np.full(len(ang), 10.0) if ranges is None else ranges
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (y - my) / np.sin(ang)
    x_hit = mx + t * np.cos(ang)
    hit = (t > 0) & (x_hit >= x0) & (x_hit <= x1)
    out[hit] = np.minimum(out[hit], t[hit])
    return out


def cross_wall_scan(controller, x, y0, y1):
    """Full LIDAR scan (m) with a wall across the robot's path at body-frame ``x``, from ``y0`` to ``y1``."""
    mx, my, myaw = controller.robot.lidar_mount
    ang = myaw + controller.robot.beam_angles
    out = np.full(len(ang), 10.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (x - mx) / np.cos(ang)
    y_hit = my + t * np.sin(ang)
    hit = (t > 0) & (y_hit >= y0) & (y_hit <= y1)
    out[hit] = t[hit]
    return out


def test_lidar_side_obstacles_repel_to_the_other_side(controller):
    # Only the LIDAR sees the obstacle (sonars free): a wall alongside the body, 15 cm from its left side.
    half_w, half_l = 0.5 * rover.WIDTH, 0.5 * rover.LENGTH
    _, sonar = free_scan()
    gap = 0.15
    ranges = wall_scan(controller, half_w + gap, -half_l, half_l)
    front, left, right = controller.obstacle_zones(ranges, sonar)
    assert left == pytest.approx(gap) and right == math.inf and front == math.inf
    _, r = controller.command(5.0, 0.0, ranges, sonar)
    assert r == pytest.approx(-controller.p.k_rep / gap)  # obstacle on the left: turn right (r < 0)
    controller.reset()
    ranges = wall_scan(controller, -(half_w + 0.2), -half_l, half_l)
    front, left, right = controller.obstacle_zones(ranges, sonar)
    assert right == pytest.approx(0.2) and left == math.inf
    _, r = controller.command(5.0, 0.0, ranges, sonar)
    assert r == pytest.approx(controller.p.k_rep / 0.2)  # obstacle on the right: turn left (r > 0)


def test_lidar_front_zone_triggers_the_safety_stop(controller):
    # An obstacle 20 cm ahead of the front edge, off the front sonar's axis: only the LIDAR sees it.
    half_l = 0.5 * rover.LENGTH
    _, sonar = free_scan()
    ranges = cross_wall_scan(controller, half_l + 0.2, 0.1, 0.25)
    front, left, right = controller.obstacle_zones(ranges, sonar)
    assert front == pytest.approx(0.2)
    u, _ = controller.command(5.0, 0.0, ranges, sonar)
    assert u < 0.0 and controller.stops == 1  # stop and step back
    # The same obstacle 1 m ahead is no reason to stop.
    controller.reset()
    u, _ = controller.command(5.0, 0.0, cross_wall_scan(controller, half_l + 1.0, 0.1, 0.25), sonar)
    assert u > 0.0 and controller.stops == 0


def test_safety_stop_acts_in_a_turn_on_the_spot(controller):
    # Sec. 3.4: halfway through a 180 deg turn the robot faces the wall; it steps back and keeps turning.
    half_l = 0.5 * rover.LENGTH
    p = controller.p
    _, sonar = free_scan()
    ranges = cross_wall_scan(controller, half_l + 0.2, -1.0, 1.0)
    alpha = 2.5  # waypoint behind: |alpha| > alpha_max, eq. 14 turns on the spot with u = 0
    assert controller.attractive(5.0, alpha) == (0.0, p.r_max)
    commands = [controller.command(5.0, alpha, ranges, sonar) for _ in range(20)]
    backing = [u for u, _ in commands if u < 0]
    assert backing and commands[0][0] < 0  # steps back at once
    assert sum(-u / 15 for u in backing) == pytest.approx(p.step_back_distance, abs=0.01)
    assert all(r == p.r_max for _, r in commands)  # and keeps turning toward the waypoint
    assert controller.stops == 1 and controller.turn_stops == 1


def test_repulsion_is_what_keeps_the_robot_in_narrow_grown_rows():
    # Leaves reach into 1.05 m corridors (growth 1): the robot enters each corridor off-centre after the
    # turn at the headland (d_min = 0.3 m lets it leave the waypoint off the centre line). With the
    # side repulsion it gets through; with attraction alone it ends up blocked or touching the plants.
    kwargs = {"n_rows": 2, "corridor_width": 1.05, "growth": 1.0, "n_people": 0}
    env = gym.make(ENV_ID, full_scan=True, localization="ground_truth", **kwargs)
    results = {}
    for k_rep in (None, 0.0):
        infos = []
        for seed in range(3):
            policy = make_policy("harik-apf-gt", env)
            if k_rep is not None:
                policy.params = dataclasses.replace(policy.params, k_rep=k_rep)
            infos.append(run_episode(env, policy, seed, None)["record"])
        results[k_rep] = infos
    assert all(i["is_success"] and not i["collision"] for i in results[None])
    assert not any(i["is_success"] for i in results[0.0])


def test_it_reads_each_drawn_scenes_distance_scale():
    # With scene_distribution the distance scale (the scene's diagonal) changes per episode. Read once,
    # at construction, it made the controller believe every waypoint within d_min: it stopped short of
    # the first one (0 waypoints) in these corridor missions, larger than the default greenhouse.
    env = gym.make(ENV_ID, full_scan=True, localization="ground_truth", scene_distribution="training")
    policy = make_policy("harik-apf-gt", env)
    base_diagonal = env.unwrapped.diagonal
    records = [run_episode(env, policy, seed, None)["record"] for seed in (20000, 20001)]
    assert env.unwrapped.diagonal > 1.1 * base_diagonal
    assert all(r["is_success"] and not r["collision"] for r in records), records


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


def scenario_run(name, policy_name, seeds):
    from agri_envs.scenarios import scenario

    kwargs = dict(scenario(ENV_ID, name).env_kwargs)
    kwargs.update(policy_spec(policy_name).env_kwargs)
    env = gym.make(ENV_ID, **kwargs)
    policy = make_policy(policy_name, env)
    return [run_episode(env, policy, seed, None)["record"] for seed in seeds]


def test_paper_scenarios_have_no_people_and_variants_do():
    from agri_envs.scenarios import scenario

    for name in ("sim-loop", "plant-development", "corridor", "repeatability"):
        assert scenario(ENV_ID, name).env_kwargs["n_people"] == 0, name
    for name in ("sim-loop-people", "corridor-people", "repeatability-people"):
        assert scenario(ENV_ID, name).env_kwargs["n_people"] > 0, name
    rep = scenario(ENV_ID, "repeatability").env_kwargs
    assert rep["scene"] == "corridor" and rep["office_route"] == "repeatability" and rep["mission_cycles"] == 10
    env = gym.make(ENV_ID, **{k: v for k, v in rep.items() if k != "max_episode_steps"})
    env.reset(seed=0)
    assert env.unwrapped.layout.mission.tolist() == [2, 3, 4, 0]  # Harik sec. 3.5: 0 -> 2 -> 3 -> 4 -> 0
    assert env.unwrapped.task.targets.shape == (40, 2)


def test_corridor_turns_make_safety_stops_and_succeed():
    # Sec. 3.4: in each 180 deg turn the front detection triggers; the robot steps back, keeps turning, goes on.
    from agri_envs.scenarios import scenario

    kwargs = {**scenario(ENV_ID, "corridor").env_kwargs, **policy_spec("harik-apf-gt").env_kwargs}
    env = gym.make(ENV_ID, **kwargs)
    policy = make_policy("harik-apf-gt", env)
    keys = ("distance_to_waypoint", "bearing_to_waypoint", "waypoint_index")
    for seed in range(3):
        out = run_episode(env, policy, seed, keys)
        info, trace = out["record"], out["trace"]
        assert info["is_success"] and not info["collision"]
        assert info["turn_safety_stops"] >= 1
        d = np.array(trace["distance_to_waypoint"])
        alpha = np.abs(np.array(trace["bearing_to_waypoint"]))
        index = np.array(trace["waypoint_index"])
        # Figs. 14-15: after waypoints 1 and 3 (and 2 on the way back) the next one is behind the robot;
        # while it turns around, d stays almost constant and alpha decreases.
        for k in (1, 3, 4):
            i0 = int(np.flatnonzero(index == k)[0])
            i1 = i0 + int(np.flatnonzero(alpha[i0:] < policy.params.alpha_max)[0])
            assert alpha[i0] > 2.5
            assert np.ptp(d[i0 : i1 + 1]) < 0.1, (seed, k)


@pytest.mark.slow
def test_corridor_must_reach_20_seeds():
    infos = scenario_run("corridor", "harik-apf-gt", range(20))
    assert all(i["is_success"] and not i["collision"] for i in infos)
    assert all(i["turn_safety_stops"] >= 1 for i in infos)


@pytest.mark.slow
def test_repeatability_in_the_office_corridor_completed_by_harik_apf():
    infos = scenario_run("repeatability", "harik-apf", range(2))
    assert all(i["is_success"] and i["waypoints_reached"] == 40 for i in infos)


def test_harik_apf_gt_drives_the_example_maps_own_waypoints():
    """scene='map' on the shipped example map with no waypoints given: the map's loop 0 -> ... -> 7 -> 0."""
    from agri_envs.scenes import EXAMPLE_MAP

    env = gym.make("agri_envs/GreenhouseNav-v2", scene="map", map_yaml=str(EXAMPLE_MAP), n_people=0, full_scan=True)
    for seed in (0, 1):
        record = run_episode(env, make_policy("harik-apf-gt", env), seed, None)["record"]
        assert record["is_success"] and not record["collision"] and record["waypoints_reached"] == 8, record
    env.close()


def test_compiled_scan_zones_are_the_numpy_statement_bit_for_bit(controller):
    """Random scans (echoes near and far, no-echo beams) and scans the env took in a corridor and a greenhouse."""
    rb, p = controller.robot, controller.p
    rng = np.random.default_rng(4)
    scans = [rng.uniform(0.05, 10.0, 811) for _ in range(40)] + [rng.uniform(0.05, 1.2, 811) for _ in range(40)]
    for scan in scans[:20]:
        scan[rng.random(811) < 0.3] = rb.lidar_max_range  # no echo
    for kwargs in ({"scene": "corridor", "office_width": 1.2}, {"n_people": 3}):
        env = gym.make(ENV_ID, full_scan=True, **kwargs)
        env.reset(seed=1)
        for _ in range(150):
            obs, *_ = env.step(np.array([0.8, 0.3], np.float32))
            scans.append(obs["scan"].astype(np.float64) * rb.lidar_max_range)
    for scan in scans + [np.full(811, rb.lidar_max_range)]:
        args = (scan, controller._cos, controller._sin, *controller._mount, rb.lidar_max_range - 1e-6)
        geometry = (0.5 * rb.length, 0.5 * rb.width, p.front_margin, p.side_lookahead)
        assert scan_zones(*args, *geometry) == scan_zones_reference(*args, *geometry)


def test_gains_follow_the_robots_limits_and_are_the_papers_at_the_default():
    assert HarikApfParams().for_robot(0.6, 1.2, 1.0, 1 / 15) == HarikApfParams()  # bit for bit
    fast = HarikApfParams().for_robot(1.2, 2.4, 0.5, 1 / 15)
    assert fast.u_max == pytest.approx(1.0) and fast.r_max == pytest.approx(1.6) and fast.braking_accel == 0.5
    paper = HarikApfParams()
    # the speed cap never binds at the paper's speeds (the safety stop acts below 0.35 m)
    for u in np.linspace(0.0, paper.u_max, 11):
        for front in (0.35, 0.4, 1.0, math.inf):
            assert paper.governed_speed(float(u), front) == u
    # a fast robot slows so that it can stop before the paper's stop distance
    for front in (0.4, 0.8, 1.2):
        u = fast.governed_speed(fast.u_max, front)
        braking = u * u / (2 * fast.braking_accel) + u * fast.reaction_time
        assert u < fast.u_max and braking == pytest.approx(0.5**2 / 2 + 0.5 / 15 + front - 0.35)


@pytest.mark.parametrize("kwargs", [{"max_speed": 1.0}, {"max_speed": 2.0, "max_turn_rate": 2.0}, {"max_accel": 0.1}])
def test_drives_any_valid_robot_within_the_time_limit(kwargs):
    # the time limit scales with the robot's limits; Harik's fixed u_max = 0.5 timed out every episode at 1 m/s
    infos = run({"n_rows": 2, "row_length": 5.0, "n_people": 0, **kwargs}, range(2))
    assert all(i["is_success"] and not i["collision"] for i in infos), infos


def test_front_zone_fits_narrow_corridors_and_is_the_papers_from_0_9_m():
    paper = HarikApfParams()
    for width in (0.9, 1.0, 1.2, 3.0):
        assert paper.for_corridor(width - rover.WIDTH) == paper  # bit for bit
    margins = [paper.for_corridor(w - rover.WIDTH).front_margin for w in (0.8, 0.85, 0.9)]
    assert margins[0] == pytest.approx(0.0, abs=1e-12) and 0.0 < margins[1] < margins[2] == 0.05
    # Two held-out episodes of greenhouse-stress-narrow-rows at 0.8 m: with the paper's 5 cm margin the plants
    # keep entering the front zone (about 50 safety stops, then the time limit); with the fitted margin both arrive.
    env = gym.make(ENV_ID, full_scan=True, localization="ground_truth", corridor_width=0.8, n_people=0)
    for margin, arrives in ((None, True), (0.05, False)):
        policy = make_policy("harik-apf-gt", env)
        if margin is not None:
            policy.params = dataclasses.replace(policy.params, front_margin=margin)
        records = [run_episode(env, policy, seed, None)["record"] for seed in (100007, 100011)]
        assert all(r["is_success"] == arrives and not r["collision"] for r in records), (margin, records)


@pytest.mark.parametrize("name", ["harik-apf-gt", "harik-apf"])
def test_takes_each_drawn_episodes_robot_and_corridor(name):
    # scene_distribution="robust" draws the robot's speed and the corridor's width per episode: the controller's
    # gains and limits are the episode's, as for an env made with those arguments.
    localization = "ground_truth" if name == "harik-apf-gt" else "none"
    env = gym.make(ENV_ID, full_scan=True, localization=localization, scene_distribution="robust")
    policy = make_policy(name, env)
    seen = set()
    for seed in range(8):
        obs, _ = env.reset(seed=seed)
        policy.predict(obs, episode_start=np.array([True]))
        cfg = env.unwrapped.episode_config
        fixed = make_policy(name, gym.make(ENV_ID, full_scan=True, localization=localization,
                                           **{k: getattr(cfg, k) for k in ROBUST.arguments}))
        assert policy.controllers[0].p == fixed.params
        assert (policy.max_speed, policy.max_turn_rate) == (fixed.max_speed, fixed.max_turn_rate) == (
            cfg.max_speed, cfg.max_turn_rate)
        seen.add((round(cfg.max_speed, 3), policy.controllers[0].p.front_margin))
    assert len({speed for speed, _ in seen}) == 8 and len({margin for _, margin in seen}) >= 2
