"""GreenhouseCoverage-v2: API checkers, determinism, pickling, config strictness, bad input, rendering, task."""

import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from rollouts import assert_same, rollout

import agri_envs  # noqa: F401
from agri_baselines import make_policy
from agri_envs.coverage.config import GreenhouseCoverageConfig
from agri_envs.coverage.greenhouse_coverage import ROUTE_AHEAD
from agri_envs.coverage.task import CoverageTask, CoverageWeights, serpentine_subgoals
from agri_envs.scenarios import list_scenarios

ENV_ID = "agri_envs/GreenhouseCoverage-v2"
SMALL = {"n_rows": 1, "row_length": 4.0}


@pytest.mark.parametrize(
    "kwargs", [SMALL, {**SMALL, "localization": "ground_truth"}, {**SMALL, "route_observation": True}]
)
def test_gymnasium_and_sb3_checkers(kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(ENV_ID, **kwargs)
    check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)
    env.close()


def test_same_seed_same_actions_identical_and_seeds_differ():
    kw = {**SMALL, "terminate_on_contact": False}
    assert_same(rollout(gym.make(ENV_ID, **kw), 5, 200), rollout(gym.make(ENV_ID, **kw), 5, 200))
    a = rollout(gym.make(ENV_ID, **kw), 5, 3)
    b = rollout(gym.make(ENV_ID, **kw), 6, 3)
    assert not np.array_equal(a[1][0]["sonar"], b[1][0]["sonar"])


def test_pickled_env_continues_identically():
    env = gym.make(ENV_ID, **SMALL, terminate_on_contact=False)
    rollout(env, 3, 50)
    clone = pickle.loads(pickle.dumps(env))
    for a in np.random.default_rng(1).uniform(-1, 1, (60, 2)):
        o1, r1, _, _, i1 = env.step(a)
        o2, r2, _, _, i2 = clone.step(a)
        assert all(np.array_equal(o1[k], o2[k]) for k in o1) and r1 == r2 and i1["x"] == i2["x"]


def test_observations_normalised_and_info_keys():
    env = gym.make(ENV_ID)
    obs, info = env.reset(seed=0)
    for _ in range(30):
        obs, _, _, _, info = env.step(np.array([1.0, 0.1]))
        for k, v in obs.items():
            assert v.dtype == np.float32 and np.all((v >= 0) & (v <= 1)), k
    for key in ("coverage", "cross_track", "max_cross_track", "crop_contacts", "is_success", "n_corridors"):
        assert key in info
    assert set(obs) == {"sonar", "compass", "velocity", "pose", "memory"} and obs["memory"].shape == (512,)


@pytest.mark.parametrize(
    "kwargs",
    [{}, {"scene_distribution": "training"}, *(dict(sc.env_kwargs) for sc in list_scenarios(ENV_ID))],
    ids=lambda kw: "-".join(f"{k}={v}" for k, v in kw.items()) or "default",
)
def test_sb3_check_env_takes_every_coverage_id_without_a_warning(kwargs):
    # v1's memory was a float32 (2, 16, 16) box: SB3 read it as an image that should be uint8 and warned.
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    coverage_ids = [i for i in gym.registry if i.startswith("agri_envs/GreenhouseCoverage")]
    assert coverage_ids == [ENV_ID]  # the project keeps only the current version
    for env_id in coverage_ids:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sb3_check_env(gym.make(env_id, **kwargs).unwrapped, warn=True, skip_render_check=True)
        assert not [str(w.message) for w in caught], "SB3's checker warned"


def test_memory_is_the_flat_view_in_c_order_in_both_forms():
    env = gym.make(ENV_ID, **SMALL)
    obs, _ = env.reset(seed=4)
    for _ in range(30):
        obs, *_ = env.step(np.array([1.0, 0.2], np.float32))
    assert obs["memory"].shape == (512,) and obs["memory"].sum() > 0
    envs = gym.make_vec(ENV_ID, num_envs=2, **SMALL)
    vobs, _ = envs.reset(seed=4)
    for _ in range(30):
        vobs, *_ = envs.step(np.tile(np.array([1.0, 0.2], np.float32), (2, 1)))
    assert vobs["memory"].shape == (2, 512) and np.array_equal(vobs["memory"][0], obs["memory"])
    envs.close()


def test_bad_actions_and_config():
    env = gym.make(ENV_ID, **SMALL)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    env.step(np.array([5.0, -5.0]))  # clipped, no error
    with pytest.raises(ValueError, match="corridor_widht"):
        gym.make(ENV_ID, corridor_widht=1.5)
    with pytest.raises(ValueError, match="vegetation_echo_prob"):
        gym.make(ENV_ID, vegetation_echo_prob=1.5)
    with pytest.raises(ValueError, match="narrowest corridor"):
        gym.make(ENV_ID, corridor_width=1.0, row_bend=0.3)
    with pytest.raises(ValueError, match="reset options"):
        env.reset(options={"n_rows": 3})


def test_step_before_reset_and_render():
    env = gym.make(ENV_ID, **SMALL, render_mode="rgb_array")
    with pytest.raises(RuntimeError):
        env.unwrapped.step(np.zeros(2))
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
    env.close()
    env.close()


def test_driving_into_the_crop_ends_the_episode_with_a_crop_contact():
    env = gym.make(ENV_ID, **SMALL)
    env.reset(seed=0)
    # Into the first corridor, then curve left into the first row: the first thing touched is the crop.
    for _ in range(50):
        _, _, term, _, info = env.step(np.array([1.0, 0.0]))
    assert info["corridor"] == 0 and not term
    for _ in range(200):
        _, _, term, _, info = env.step(np.array([0.6, 1.0]))
        if term:
            break
    assert term and info["crop_contacts"] == 1 and not info["is_success"]


def test_time_limit_truncates():
    env = gym.make(ENV_ID, **SMALL, time_limit=2.0)
    env.reset(seed=0)
    truncations = []
    for _ in range(20):
        _, _, term, trunc, _ = env.step(np.zeros(2))
        assert not term
        truncations.append(trunc)
    assert truncations == [False] * 19 + [True]


def test_coverage_task_bins_cross_track_and_success():
    lines = (np.array([[0.0, 1.0], [10.0, 1.0]]), np.array([[0.0, 3.0], [5.0, 3.5], [10.0, 3.0]]))
    task = CoverageTask(lines, 0.5, CoverageWeights())
    assert task.n_bins.tolist() == [20, 20]
    k, d = task.locate(5.0, 3.4)
    assert k == 1 and d == pytest.approx(0.1 * math.cos(math.atan2(0.5, 5.0)))
    assert task.locate(-1.0, 1.0) == (-1, 0.0)
    for x in np.linspace(0.0, 10.0, 200):
        out = task.evaluate(np.array([x, 1.05, 0.0]), False, False)
    assert task.corridor_fractions().tolist() == [1.0, 0.0] and not out["is_success"]
    assert out["max_cross_track"] == pytest.approx(0.05)
    for x in np.linspace(10.0, 0.0, 200):
        out = task.evaluate(np.array([x, 3.0 + 0.5 * (1 - abs(x - 5) / 5), 0.0]), False, False)
    assert out["is_success"] and out["coverage"] == 1.0


def test_config_describe_lists_every_argument():
    rows = GreenhouseCoverageConfig().describe()
    assert {r[0] for r in rows} == set(GreenhouseCoverageConfig.field_names())


@pytest.mark.parametrize("kwargs", [{"row_bend": 0.15}, {"row_incline": 0.03}, {"corridor_width_jitter": 0.3}])
def test_a_corridor_with_exactly_the_margin_is_accepted(kwargs):
    """Each leaves 0.9 m (0.899997 m after tan()) of the 1.4 m corridor: the 0.2 m margin, to the millimetre."""
    env = gym.make(ENV_ID, **kwargs)
    env.reset(seed=0)
    env.close()
    with pytest.raises(ValueError, match="narrowest corridor"):
        gym.make(ENV_ID, **{k: v * 1.05 for k, v in kwargs.items()})


def test_memory_marks_the_driven_trail_behind_the_robot_and_echoes_beside_it():
    env = gym.make(ENV_ID, n_rows=2, growth=0.3, terminate_on_contact=False)
    obs, _ = env.reset(seed=2)
    grid = obs["memory"].reshape(2, 16, 16)  # the flat key in C order
    assert grid[0].sum() == 1 and grid[0, 7:9, 7:9].sum() == 1  # the start cell, under the robot
    for _ in range(60):  # straight ahead, 2 m into the first corridor
        obs, *_ = env.step(np.array([1.0, 0.0], np.float32))
    visited, echo = obs["memory"].reshape(2, 16, 16)
    # Rows are ahead (a), columns to the left (b); the robot sits between cells 7 and 8 of each.
    behind = visited[:8, 6:10].sum(axis=1)
    assert np.all(behind[-4:] >= 1) and visited[10:].sum() == 0 and visited[:, :5].sum() == 0
    # The first corridor runs between the wall (right, 0.8 m away: column 6) and a row (left): the right
    # sonars' echoes draw the wall as a line along the trail, and the left ones mark the row's side.
    assert echo[2:8, 6].all() and echo[:, :6].sum() == 0 and echo[6:10, 9:].sum() > 0


def test_memory_is_the_robots_own_estimate():
    # With odometry the memory is drawn in the pose estimate's frame: a compass bias of 0.5 rad turns the
    # trail in the grid, while the robot still sees it straight behind itself. The true path is the same.
    kw = dict(n_rows=2, terminate_on_contact=False, encoder_noise=0.0, compass_noise_std=0.0)
    grids, paths = [], []
    for bias in (0.0, 0.5):
        env = gym.make(ENV_ID, **kw, compass_bias=bias)
        obs, info = env.reset(seed=1)
        for _ in range(50):
            obs, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
        trail = np.argwhere(obs["memory"].reshape(2, 16, 16)[0])
        assert np.all(trail[:, 0] <= 8) and np.all(np.abs(trail[:, 1] - 7.5) <= 1.5)
        grids.append(env.unwrapped.memory.grid[0].copy())
        paths.append((info["x"], info["y"]))
    assert paths[0] == paths[1] and not np.array_equal(grids[0], grids[1])


def test_serpentine_subgoals_and_progress_pay_for_the_turn_into_the_next_corridor():
    lines = tuple(np.array([[0.0, y], [10.0, y]]) for y in (1.0, 3.0, 5.0))
    goals = serpentine_subgoals(lines, 0.8)
    np.testing.assert_allclose(goals, [[10.8, 1], [10.8, 3], [-0.8, 3], [-0.8, 5], [10.8, 5]])
    task = CoverageTask(lines, 0.5, CoverageWeights(progress=1.0), turn_distance=1.0, subgoal_offset=0.8)
    task.reset(np.array([-1.0, 1.0, 0.0]))
    total = 0.0
    for x in np.linspace(-1.0, 10.8, 60):  # along corridor 0 to its far subgoal
        total += task.evaluate(np.array([x, 1.0, 0.0]), False, False)["reward_progress"]
    assert task.route.index == 1 and total == pytest.approx(11.8 - 0.3, abs=0.25)
    # Turning left toward the next corridor's mouth pays pi/2 of turn distance; turning right costs it.
    left = task.evaluate(np.array([10.8, 1.0, math.pi / 2]), False, False)["reward_progress"]
    assert left == pytest.approx(math.pi / 2)
    right = task.evaluate(np.array([10.8, 1.0, -math.pi / 2]), False, False)["reward_progress"]
    assert right == pytest.approx(-math.pi)


def test_env_progress_term_sums_to_the_distance_driven_toward_the_subgoal():
    env = gym.make(ENV_ID, n_rows=1, row_length=4.0, reward_progress=1.0)
    _, info = env.reset(seed=0)
    x0 = info["x"]
    total = 0.0
    for _ in range(25):
        _, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
        total += info["reward_progress"]
    # Straight toward the subgoal (its bearing stays near 0): progress = metres driven toward it.
    assert total == pytest.approx(info["x"] - x0, abs=0.05)
    assert info["subgoal_index"] == 0


def test_the_robot_turns_clear_of_the_row_ends_where_the_subgoal_is_passed():
    # Drive corridor 0 on its centre line until the far subgoal counts as passed, then turn toward the next
    # corridor on a tight arc (0.4 m: in place the rear corner would hit the side wall, 0.8 m away): the
    # 1.5 m robot must not touch the row end. The shaping points where a turn can be driven.
    env = gym.make(ENV_ID, n_rows=2, localization="ground_truth", vegetation_echo_prob=0.0, row_bend=0.0,
                   row_incline=0.0, corridor_width_jitter=0.0)  # fmt: skip
    _, info = env.reset(seed=4)
    line_y = env.unwrapped.corridor_lines()[0][0, 1]
    for _ in range(600):
        steer = np.clip(2.0 * (line_y - info["y"]) - 2.0 * info["yaw"], -1, 1)
        _, _, term, _, info = env.step(np.array([0.6, steer], np.float32))
        assert not term
        if info["subgoal_index"] == 1:
            break
    assert info["subgoal_index"] == 1
    for _ in range(30):  # a quarter turn to the left at 0.6 rad/s (and a little more)
        _, _, term, _, info = env.step(np.array([0.5, 1.0], np.float32))
        assert not term and info["crop_contacts"] == 0 and info["other_contacts"] == 0
    assert info["yaw"] > 1.4


def test_episodes_equal_the_digests_recorded_before_resets_were_made_fast():
    """Seeded rollouts over 8 argument sets (shaped rows, limits, noise, echoes, localization)."""
    from greenhouse_reference import COVERAGE_ID, digests, recorded

    assert digests(COVERAGE_ID) == recorded(COVERAGE_ID)


def _serpentine_oracle(corridors, offset, step=0.005):
    """The serpentine sampled every ``step`` m with its arc lengths, built point by point (not with numpy's interp)."""
    corners = []
    for k, c in enumerate(corridors):
        line = [(c[0, 0] - offset, c[0, 1]), *map(tuple, c), (c[-1, 0] + offset, c[-1, 1])]
        corners.extend(line if k % 2 == 0 else line[::-1])
    samples, arcs, s = [], [], 0.0
    for (ax, ay), (bx, by) in zip(corners[:-1], corners[1:], strict=True):
        length = math.hypot(bx - ax, by - ay)
        n = max(1, int(length / step))
        for i in range(n):
            samples.append((ax + (bx - ax) * i / n, ay + (by - ay) * i / n))
            arcs.append(s + length * i / n)
        s += length
    samples.append(corners[-1])
    arcs.append(s)
    return np.array(samples), np.array(arcs)


def test_route_observation_is_the_serpentine_ahead_in_the_true_robot_frame():
    kw = {"n_rows": 2, "row_length": 5.0, "localization": "ground_truth"}
    env = gym.make(ENV_ID, route_observation=True, **kw)
    plain = gym.make(ENV_ID, **kw)
    obs, _ = env.reset(seed=4)
    plain_obs, _ = plain.reset(seed=4)
    e = env.unwrapped
    samples, arcs = _serpentine_oracle(e.corridor_lines(), 0.5 * e.episode_config.headland)
    assert env.observation_space["route"].shape == (2 * len(ROUTE_AHEAD) + 2,)
    assert "route" not in plain.observation_space.spaces
    policy = make_policy("gonzalez-deliberative", env)
    s_oracle, checked = 0.0, 0
    for t in range(3000):
        # The key only adds itself: the other keys, the reward and the episode are the plain env's.
        assert all(np.array_equal(obs[k], plain_obs[k]) for k in plain_obs)
        x, y, yaw = e.robot.pose
        # The robot's point on the route: the nearest sample within the tracker's window (0.5 m back, 3 m ahead).
        window = (arcs >= s_oracle - 0.5) & (arcs <= s_oracle + 3.0)
        nearest = np.flatnonzero(window)[np.argmin(np.hypot(*(samples[window] - (x, y)).T))]
        s_oracle = arcs[nearest]
        route = (2.0 * obs["route"].astype(np.float64) - 1.0)[:-2].reshape(-1, 2) * 4.0
        for d, (ahead, left) in zip(ROUTE_AHEAD, route, strict=True):
            k = min(np.searchsorted(arcs, s_oracle + d), len(arcs) - 1)
            px, py = samples[k]
            dx, dy = px - x, py - y
            want = (math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy)
            if max(abs(want[0]), abs(want[1])) < 4.0:  # inside the clipped range
                assert abs(ahead - want[0]) < 0.02 and abs(left - want[1]) < 0.02, (t, d, (ahead, left), want)
                checked += 1
        v_true = 2.0 * obs["route"][-2] - 1.0
        assert abs(v_true * e.robot_spec.max_speed - e.robot.v) < 1e-5
        action, _ = policy.predict(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        plain_obs, plain_reward, *_ = plain.step(action)
        assert reward == plain_reward
        if terminated or truncated:
            break
    assert info["is_success"] and checked > 1000
    assert s_oracle > arcs[-1] - 2.0  # the route was followed to its end, through both U-turns


def test_route_observation_is_refused_by_the_batched_form():
    with pytest.raises(ValueError, match="route observation"):
        gym.make_vec(ENV_ID, num_envs=2, route_observation=True)
