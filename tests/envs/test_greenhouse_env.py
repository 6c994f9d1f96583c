"""GreenhouseNav-v2: API checkers, determinism, pickling, config strictness, bad actions, rendering."""

import math
import pickle
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from rollouts import assert_same, rollout

import agri_envs  # noqa: F401
from agri_envs.rover.config import GreenhouseNavConfig

ENV_ID = "agri_envs/GreenhouseNav-v2"
SMALL = {"n_rows": 1, "row_length": 3.0}


@pytest.mark.parametrize("kwargs", [{}, {"full_scan": True, "localization": "none"}, {"localization": "odometry"}])
def test_gymnasium_and_sb3_checkers(kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, **kwargs)
    check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)
    env.close()


def test_same_seed_same_actions_identical():
    kw = {"terminate_on_collision": False, "n_people": 3}
    assert_same(rollout(gym.make(ENV_ID, **kw), 7, 300), rollout(gym.make(ENV_ID, **kw), 7, 300))
    a = rollout(gym.make(ENV_ID, **kw), 7, 5)
    b = rollout(gym.make(ENV_ID, **kw), 8, 5)
    assert not np.array_equal(a[1][0]["lidar"], b[1][0]["lidar"])


def test_pickled_env_continues_identically():
    env = gym.make(ENV_ID, terminate_on_collision=False, n_people=3)
    rollout(env, 3, 150)
    clone = pickle.loads(pickle.dumps(env))
    actions = np.random.default_rng(1).uniform(-1, 1, (150, 2))
    for a in actions:
        o1, r1, t1, u1, i1 = env.step(a)
        o2, r2, t2, u2, i2 = clone.step(a)
        assert all(np.array_equal(o1[k], o2[k]) for k in o1) and r1 == r2 and i1["x"] == i2["x"]


def _digest_in_subprocess():
    code = (
        "import gymnasium as gym, numpy as np, hashlib, agri_envs\n"
        "env = gym.make('agri_envs/GreenhouseNav-v2', terminate_on_collision=False)\n"
        "obs, _ = env.reset(seed=11); h = hashlib.sha256()\n"
        "rng = np.random.default_rng(0)\n"
        "for _ in range(200):\n"
        "    obs, r, te, tr, info = env.step(rng.uniform(-1, 1, 2))\n"
        "    h.update(b''.join(v.tobytes() for v in obs.values())); h.update(np.float64(r).tobytes())\n"
        "print(h.hexdigest())\n"
    )
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()


def test_identical_in_another_process():
    assert _digest_in_subprocess() == _digest_in_subprocess()


def test_importing_package_loads_no_physics_engine():
    engines = "('pymunk', 'pybullet', 'numba', 'pygame', 'torch')"
    code = f"import sys, agri_envs; print([m for m in {engines} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"


def test_bad_actions():
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([0.0, np.inf]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    # Out-of-range actions are clipped: same result as the clipped action.
    e1, e2 = gym.make(ENV_ID), gym.make(ENV_ID)
    e1.reset(seed=4)
    e2.reset(seed=4)
    for _ in range(10):
        o1, *_ = e1.step(np.array([7.0, -3.0]))
        o2, *_ = e2.step(np.array([1.0, -1.0]))
        assert all(np.array_equal(o1[k], o2[k]) for k in o1)


def test_config_strictness():
    with pytest.raises(ValueError, match="unknown argument.*'n_row'.*did you mean 'n_rows'"):
        gym.make(ENV_ID, n_row=3)
    with pytest.raises(ValueError, match=r"growth=1.5 is out of range; expected in \[0.0, 1.0\]"):
        gym.make(ENV_ID, growth=1.5)
    with pytest.raises(ValueError, match="n_rows=2.5 must be an integer"):
        gym.make(ENV_ID, n_rows=2.5)
    with pytest.raises(ValueError, match="localization='gps' is invalid"):
        gym.make(ENV_ID, localization="gps")
    with pytest.raises(ValueError, match="corridors keep only"):
        gym.make(ENV_ID, corridor_width=0.8, growth=1.0)
    with pytest.raises(ValueError, match="reset options"):
        gym.make(ENV_ID).reset(seed=0, options={"n_rows": 4})
    assert set(GreenhouseNavConfig.field_names()) >= {
        "n_rows",
        "row_length",
        "corridor_width",
        "plant_spacing",
        "growth",
        "n_people",
    }


def test_the_full_scan_only_adds_an_observation_key():
    # full_scan is declared adds_observation (StrictConfig.differences skips it); the rollouts show it is true.
    plain = gym.make(ENV_ID, n_people=2, max_episode_steps=60)
    scanning = gym.make(ENV_ID, n_people=2, max_episode_steps=60, full_scan=True)
    a, _ = plain.reset(seed=4)
    b, _ = scanning.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(60):
        assert set(b) == set(a) | {"scan"}
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        action = rng.uniform(-1, 1, 2).astype(np.float32)
        a, reward_a, *ends_a, _ = plain.step(action)
        b, reward_b, *ends_b, _ = scanning.step(action)
        assert (reward_a, *ends_a) == (reward_b, *ends_b)
        if any(ends_a):
            break
    config = plain.unwrapped.config
    # the defaults: localization "ground_truth", 3 rows
    assert config.differences({"full_scan": True, "localization": "none", "n_rows": 3}) == ["localization"]
    assert config.differences({"localization": "ground_truth", "no_such_argument": 1}) == ["no_such_argument"]


def test_every_argument_is_documented_with_a_range():
    for name, _default, _unit, valid, doc in GreenhouseNavConfig().describe():
        assert doc and valid != "any value", name


def test_observations_within_bounds_and_reward_terms_add_up():
    env = gym.make(ENV_ID, full_scan=True, n_people=4, growth=0.8, n_trees=4, terminate_on_collision=False)
    obs, info = env.reset(seed=2)
    space = env.observation_space
    rng = np.random.default_rng(0)
    for _ in range(300):
        obs, reward, term, trunc, info = env.step(rng.uniform(-1, 1, 2))
        assert space.contains(obs)
        terms = sum(v for k, v in info.items() if k.startswith("reward_"))
        assert reward == pytest.approx(terms)
        assert {"is_success", "collision", "clearance"} <= info.keys()
        assert 0.05 / 10 - 1e-7 <= obs["scan"].min() and obs["scan"].max() <= 1.0


def test_localization_modes():
    gt = gym.make(ENV_ID, localization="ground_truth", n_people=0)
    odo = gym.make(ENV_ID, localization="odometry", n_people=0, odometry_noise=0.1, odometry_gyro_bias=0.05)
    none = gym.make(ENV_ID, localization="none", n_people=0)
    for env in (gt, odo, none):
        env.reset(seed=5)
    for _ in range(150):
        _, _, _, _, i_gt = gt.step(np.array([0.5, 0.2]))
        _, _, _, _, i_odo = odo.step(np.array([0.5, 0.2]))
        o_none, _, _, _, i_none = none.step(np.array([0.5, 0.2]))
    assert (i_gt["est_x"], i_gt["est_y"]) == (i_gt["x"], i_gt["y"])
    drift = math.hypot(i_odo["est_x"] - i_odo["x"], i_odo["est_y"] - i_odo["y"])
    assert 0.01 < drift < 2.0
    assert "waypoint" not in o_none and "target" in o_none and "est_x" not in i_none
    mission = none.unwrapped.mission_in_start_frame()
    np.testing.assert_allclose(
        o_none["target"], np.clip(mission[i_none["waypoint_index"]] / none.unwrapped.diagonal, -1, 1), atol=1e-6
    )


def test_people_never_walk_into_a_standing_robot():
    env = gym.make(ENV_ID, n_people=8, people_tease_prob=0.5, terminate_on_collision=False, max_episode_steps=3000)
    for seed in range(3):
        env.reset(seed=seed)
        for _ in range(1500):
            _, _, _, _, info = env.step(np.zeros(2))
            assert not info["collision"]


def test_collision_ends_episode_and_robot_never_tunnels():
    env = gym.make(ENV_ID, n_people=0, growth=1.0, corridor_width=1.4)
    env.reset(seed=0)
    terminated = False
    for _ in range(200):  # full speed, turning into the row
        _, r, terminated, _, info = env.step(np.array([1.0, 0.35]))
        assert info["clearance"] > -0.01
        if terminated:
            break
    assert terminated and info["collision"] and info["reward_collision"] < 0 and not info["is_success"]


def test_time_limit_truncates():
    env = gym.make(ENV_ID, max_episode_steps=20)
    env.reset(seed=0)
    for _ in range(20):
        _, _, term, trunc, _ = env.step(np.zeros(2))
    assert trunc and not term


def test_rgb_render_headless():
    env = gym.make(ENV_ID, render_mode="rgb_array", render_width=400, **SMALL)
    env.reset(seed=0)
    env.step(np.array([0.5, 0.0]))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[1] == 400
    robot_blue = np.all(frame == (40, 90, 200), axis=-1)
    assert robot_blue.sum() > 50
    env.close()
    env.close()  # idempotent


def test_reset_options_change_the_scene():
    env = gym.make(ENV_ID, n_people=0)
    env.reset(seed=1)
    kinds0 = env.unwrapped.layout.geometry.circle_kinds.tolist()
    env.reset(seed=1, options={"growth": 1.0, "n_trees": 5})
    g = env.unwrapped.layout.geometry
    assert 4 in g.circle_kinds.tolist() and 4 not in kinds0  # trees appeared (Kind.TREE)
    assert (g.capsule_kinds == 3).sum() > 20  # leaves (Kind.LEAF)


def test_map_scene_from_ros_map():
    from agri_envs.scenes import EXAMPLE_MAP

    wps = [[1.0, 0.6], [8.6, 0.6], [8.6, 2.2], [1.0, 2.2]]
    env = gym.make(ENV_ID, scene="map", map_yaml=str(EXAMPLE_MAP), waypoints=wps, n_people=1)
    obs, info = env.reset(seed=0)
    assert info["clearance"] > 0.2 and len(env.unwrapped.layout.geometry.polygons) > 20
    assert env.observation_space.contains(obs)
    with pytest.raises(ValueError, match="needs map_yaml"):
        gym.make(ENV_ID, scene="map", map_yaml="/nonexistent.yaml", waypoints=wps)
    with pytest.raises(ValueError, match=">= 2"):
        gym.make(ENV_ID, scene="map", map_yaml=str(EXAMPLE_MAP), waypoints=[[1.0, 1.0]])
    with pytest.raises(ValueError, match="only to scene='map'"):
        gym.make(ENV_ID, waypoints=wps)


def test_the_example_map_ships_its_waypoints(tmp_path):
    """scene='map' on EXAMPLE_MAP needs no invented waypoints (tests/baselines: harik-apf-gt drives them)."""
    from agri_envs.scenes import EXAMPLE_MAP, EXAMPLE_WAYPOINTS

    assert len(EXAMPLE_WAYPOINTS) == 8
    env = gym.make(ENV_ID, scene="map", map_yaml=str(EXAMPLE_MAP), n_people=0)
    env.reset(seed=0)
    assert np.allclose(env.unwrapped.layout.waypoints, EXAMPLE_WAYPOINTS)
    # A map without its own waypoints still needs them, and the message says where they can come from.
    text = EXAMPLE_MAP.read_text().split("# Not read")[0]
    bare = tmp_path / "bare.yaml"
    bare.write_text(text.replace("example_greenhouse.pgm", str(EXAMPLE_MAP.with_suffix(".pgm"))))
    with pytest.raises(ValueError, match="names its own under 'waypoints'"):
        gym.make(ENV_ID, scene="map", map_yaml=str(bare))
    broken = tmp_path / "broken.yaml"
    broken.write_text(bare.read_text() + "waypoints: [[1.0, 2.0]]\n")
    with pytest.raises(ValueError, match="'waypoints' must be a list of >= 2"):
        gym.make(ENV_ID, scene="map", map_yaml=str(broken))


def test_docstring_documents_every_argument():
    from agri_envs.rover.greenhouse_nav import GreenhouseNavEnv

    doc = GreenhouseNavEnv.__doc__
    for name in GreenhouseNavConfig.field_names():
        assert f"| ``{name}`` |" in doc, name


def test_human_render_headless():
    env = gym.make(ENV_ID, render_mode="human", render_width=300, **SMALL)
    env.reset(seed=0)
    env.step(np.zeros(2))
    assert env.render() is None
    env.close()


def test_occupancy_grid_of_the_scene():
    env = gym.make(ENV_ID, n_people=0)
    env.reset(seed=0)
    grid = env.unwrapped.occupancy_grid(0.05)
    start = env.unwrapped.layout.start_pose
    i, j = grid.world_to_cell(np.array(start[:2]))
    assert grid.data[i, j] == 0 and (grid.data == 100).mean() > 0.02


def test_episodes_equal_the_digests_recorded_before_resets_were_made_fast():
    """Seeded rollouts over 17 argument sets (people, growth, corridor, map, localization, frame_skip, limits)."""
    from greenhouse_reference import NAV_ID, digests, recorded

    assert digests(NAV_ID) == recorded(NAV_ID)


def test_lidar_sector_angles_are_the_pooled_sectors_centres():
    """Each pooled ``lidar`` value's sector: its centre angle lies within it; unpooled, it is the beam's angle."""
    full = gym.make("agri_envs/GreenhouseNav-v2", lidar_beams=811).unwrapped
    assert np.array_equal(full.lidar_sector_angles, full.lidar.spec.beam_angles)
    pooled = gym.make("agri_envs/GreenhouseNav-v2", lidar_beams=90).unwrapped
    angles, beams = pooled.lidar_sector_angles, pooled.lidar.spec.beam_angles
    assert angles.shape == (90,) and np.all(np.diff(angles) > 0)
    step = beams[1] - beams[0]
    assert beams[0] < angles[0] < beams[0] + 9 * step  # the first of 9-beam sectors starts at the first beam
    assert np.all(np.abs(np.diff(angles) - 270 / 90 * np.pi / 180) < 1.1 * step)  # 3 deg apart, give or take a beam
