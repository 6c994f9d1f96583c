"""Hector SLAM: interpolation and gradient oracles, once-per-scan updates, scan matching, recorded drives."""

import math

import gymnasium as gym
import numpy as np
import pytest
from hector_reference import ReferenceHectorSlam

import agri_envs  # noqa: F401
from agri_baselines import make_policy, policy_spec
from agri_baselines.hector_slam import HectorSlam, HectorSlamConfig, interpolate_map
from agri_envs.sim2d.gridmap import rasterize
from agri_training.evaluation.episode import localization_errors, run_episode, start_frame_to_world

ENV_ID = "agri_envs/GreenhouseNav-v2"


def compose(a, b):
    """Pose ``a`` followed by the relative pose ``b`` (SE(2))."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


@pytest.fixture(scope="module")
def scene():
    """A greenhouse without people; returns the env (reset) to scan its geometry without noise."""
    env = gym.make(ENV_ID, n_people=0)
    env.reset(seed=3)
    yield env.unwrapped
    env.close()


def exact_scan(e, pose):
    return e.lidar.exact_scan(np.asarray(pose, float), e.world.circles, e.world.capsules).copy()


def make_slam(e, **kw):
    return HectorSlam(HectorSlamConfig(**kw), e.lidar.spec.beam_angles, e.lidar.spec.mount)


def test_interpolation_hits_cell_values_and_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    grid = rng.uniform(0, 1, (12, 15)).astype(np.float32)
    ij = np.array([[3, 4], [7, 11], [0, 0]])
    at_cells = interpolate_map(grid, ij[:, ::-1].astype(float))  # map coordinates are (x=j, y=i)
    assert np.allclose(at_cells[:, 0], grid[ij[:, 0], ij[:, 1]])
    # Analytic gradient of the bilinear patch (the paper's eqs. 5-6) against central differences.
    pts = rng.uniform(1.05, 10.95, (200, 2))
    pts = pts[(np.abs(pts - np.rint(pts)) > 0.02).all(axis=1)]  # stay off cell borders (kinks)
    h = 1e-6
    fx = (interpolate_map(grid, pts + [h, 0])[:, 0] - interpolate_map(grid, pts - [h, 0])[:, 0]) / (2 * h)
    fy = (interpolate_map(grid, pts + [0, h])[:, 0] - interpolate_map(grid, pts - [0, h])[:, 0]) / (2 * h)
    got = interpolate_map(grid, pts)
    assert np.allclose(got[:, 1], fx, atol=1e-5) and np.allclose(got[:, 2], fy, atol=1e-5)
    # The swapped weights of the ROS code would differ from the true derivative somewhere.
    i0 = np.floor(pts).astype(int)
    f = pts - i0
    v00, v10 = grid[i0[:, 1], i0[:, 0]], grid[i0[:, 1], i0[:, 0] + 1]
    v01, v11 = grid[i0[:, 1] + 1, i0[:, 0]], grid[i0[:, 1] + 1, i0[:, 0] + 1]
    swapped = (1 - f[:, 0]) * (v10 - v00) + f[:, 0] * (v11 - v01)
    assert not np.allclose(swapped, fx, atol=1e-3)
    assert np.isnan(interpolate_map(grid, np.array([[-0.5, 3.0], [14.5, 3.0]]))).all()


def test_each_cell_updated_once_per_scan():
    angles = np.array([0.0, 0.0, 0.3])
    slam = HectorSlam(HectorSlamConfig(levels=1, map_size=64), angles)
    twice = HectorSlam(HectorSlamConfig(levels=1, map_size=64), np.array([0.0, 0.3]))
    slam.update(np.array([1.0, 1.0, 1.0]))  # the first beam twice: its cells must count once
    twice.update(np.array([1.0, 1.0]))
    assert np.array_equal(slam.log_odds[0], twice.log_odds[0])
    l_occ = math.log(0.9 / 0.1)
    l_free = math.log(0.4 / 0.6)
    lo = slam.log_odds[0]
    assert lo.max() == pytest.approx(l_occ) and lo.min() == pytest.approx(l_free)
    # A cell crossed by one beam and hit by another counts as hit, once.
    cross = HectorSlam(HectorSlamConfig(levels=1, map_size=64), np.array([0.0, 0.0]))
    cross.update(np.array([2.0, 1.0]))
    end = cross.world_to_map(np.array([1.0, 0.0]))
    assert cross.log_odds[0][int(round(end[1])), int(round(end[0]))] == pytest.approx(l_occ)


def test_config_and_input_validation():
    with pytest.raises(ValueError, match="map_size"):
        HectorSlamConfig(map_size=1000, levels=5)
    with pytest.raises(ValueError, match="update_free"):
        HectorSlamConfig(update_free=0.6)
    slam = HectorSlam(HectorSlamConfig(map_size=64), np.zeros(5))
    with pytest.raises(ValueError, match="expected 5 ranges"):
        slam.update(np.ones(4))


def test_matcher_recovers_rigid_offsets_against_its_own_map(scene):
    start = scene.robot.pose.copy()
    scan = exact_scan(scene, start)
    slam = make_slam(scene)
    slam.update(scan)
    points = slam.scan_points(scan)
    rng = np.random.default_rng(1)
    for _ in range(10):
        offset = rng.uniform([-0.15, -0.15, -0.12], [0.15, 0.15, 0.12])
        found = slam.match(points, offset)
        assert np.hypot(*found[:2]) < 0.01 and abs(found[2]) < math.radians(0.5), (offset, found)


def test_matcher_recovers_a_known_motion(scene):
    start = scene.robot.pose.copy()
    slam = make_slam(scene)
    slam.update(exact_scan(scene, start))
    rng = np.random.default_rng(2)
    for _ in range(5):
        motion = rng.uniform([-0.12, -0.08, -0.1], [0.12, 0.08, 0.1])
        second = exact_scan(scene, compose(start, motion))
        found = slam.match(slam.scan_points(second), np.zeros(3))
        assert np.hypot(*(found[:2] - motion[:2])) < 0.02 and abs(found[2] - motion[2]) < math.radians(0.5)


def test_recorded_drive_stays_near_the_ground_truth_and_maps_the_scene():
    kw = {"n_rows": 1, "row_length": 4.0, "n_people": 1, "full_scan": True, "localization": "ground_truth"}
    env = gym.make(ENV_ID, **kw)
    policy = make_policy("harik-apf-gt", env)
    e = env.unwrapped
    slam = make_slam(e)
    obs, info = env.reset(seed=5)
    truth, estimate, start = [], [], True
    while True:
        estimate.append(slam.update(obs["scan"].astype(np.float64) * e.lidar.spec.max_range))
        truth.append((info["x"], info["y"], info["yaw"]))
        action, _ = policy.predict(obs, episode_start=np.array([start]))
        start = False
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert info["is_success"]
    truth = np.array(truth)
    errors = localization_errors(truth, start_frame_to_world(truth[0], np.array(estimate)))
    assert errors["ate_rmse"] < 0.05 and errors["final_position_error"] < 0.05, errors
    assert slam.map_updates < slam.scans  # updates only past the motion thresholds
    # The exported map agrees with the scene: its occupied cells lie on or next to true geometry.
    grid = slam.occupancy_grid(0, start_pose=tuple(truth[0]))
    occupied = grid.cell_to_world(np.argwhere(grid.occupied_mask(65)))
    truth_grid = rasterize(e.layout.geometry, 0.05)
    cells = truth_grid.world_to_cell(occupied)
    inside = truth_grid.in_grid(cells)
    near = np.zeros(len(cells), bool)
    occ = truth_grid.occupied_mask()
    for di in (-2, -1, 0, 1, 2):
        for dj in (-2, -1, 0, 1, 2):
            i = np.clip(cells[:, 0] + di, 0, truth_grid.height - 1)
            j = np.clip(cells[:, 1] + dj, 0, truth_grid.width - 1)
            near |= inside & occ[i, j]
    assert len(occupied) > 200 and near.mean() > 0.9
    env.close()


def test_harik_apf_is_not_privileged_and_solves_the_easy_preset():
    spec = policy_spec("harik-apf")
    assert not spec.privileged and spec.env_kwargs == {"localization": "none", "full_scan": True}
    with pytest.raises(ValueError, match="localization='none'"):
        make_policy("harik-apf", gym.make(ENV_ID, full_scan=True))
    env = gym.make(ENV_ID, n_rows=1, row_length=4.0, n_people=0, full_scan=True, localization="none")
    policy = make_policy("harik-apf", env)
    for seed in range(3):
        record = run_episode(env, policy, seed, None)["record"]
        assert record["is_success"] and not record["collision"], record
        assert record["ate_rmse"] < 0.05, record
    env.close()


@pytest.mark.parametrize("guard, mapped", [(-0.5, False), (None, True)])
def test_free_space_guard_keeps_a_person_out_of_the_map(scene, guard, mapped):
    start = scene.robot.pose.copy()
    slam = make_slam(scene, free_space_guard=guard)
    slam.update(exact_scan(scene, start))
    for k in range(1, 8):  # look around a little so the space ahead is known free
        slam.update_map(slam.scan_points(exact_scan(scene, compose(start, (0.0, 0.0, 0.07 * k)))), slam.pose)
    person = compose(start, (1.2, 0.0, 0.0))
    circles = np.vstack([scene.world.circles, [[person[0], person[1], 0.2]]])
    with_person = scene.lidar.exact_scan(start, circles, scene.world.capsules).copy()
    for _ in range(3):
        slam.update_map(slam.scan_points(with_person), slam.pose)
    near_side = slam.world_to_map(np.array([1.0, 0.0]))  # the person's surface, in the map frame
    cell = slam.log_odds[0][int(round(near_side[1])), int(round(near_side[0]))]
    assert (cell > 0) == mapped


def test_the_slam_module_imports_no_gymnasium():
    import subprocess
    import sys

    code = "import sys, agri_baselines.hector_slam; print('gymnasium' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_checked_gauss_newton_never_raises_the_matching_cost(scene):
    from agri_baselines.hector_slam import _gauss_newton, _matching_cost

    start = scene.robot.pose.copy()
    slam = make_slam(scene)
    slam.update(exact_scan(scene, start))
    rng = np.random.default_rng(4)
    for _ in range(20):
        motion = rng.uniform([-0.6, -0.6, -0.5], [0.6, 0.6, 0.5])
        points = slam.scan_points(exact_scan(scene, compose(start, motion)))
        for level in range(slam.config.levels):
            cell = slam.cell_size(level)
            args = (slam.prob[level], cell, slam._origin)
            in_cells = (points[:, 0] / cell, points[:, 1] / cell)
            pose = rng.uniform([-0.5, -0.5, -0.4], [0.5, 0.5, 0.4])
            before = _matching_cost(*args, *in_cells, *pose)
            after = _gauss_newton(*args, points, pose, 5, 0.2, 3)
            assert after <= before and after == pytest.approx(_matching_cost(*args, *in_cells, *pose))


def _worst_error_in_a_fast_turn(scene, slam, odometry):
    """A turn on the spot speeding up to 0.4 rad per scan; the worst pose error (rad + m) of ``slam`` along it.

    ``odometry``: give the SLAM each scan's true turn as its odometry.
    """
    start = scene.robot.pose.copy()
    heading, worst = 0.0, 0.0
    for k in range(40):
        turn = min(0.04 * k, 0.4)
        heading += turn
        scan = exact_scan(scene, compose(start, (0.0, 0.0, heading)))
        pose = slam.update(scan, (0.0, 0.0, turn) if odometry else None)
        error = abs(math.atan2(math.sin(pose[2] - heading), math.cos(pose[2] - heading))) + math.hypot(*pose[:2])
        worst = max(worst, error)
    return worst


@pytest.mark.parametrize("constant_velocity", [True, False])
def test_constant_velocity_prediction_follows_a_fast_turn_on_the_spot(scene, constant_velocity):
    """Matched from the last pose, the estimate is lost in the fast turn; the prediction follows it."""
    worst = _worst_error_in_a_fast_turn(scene, make_slam(scene, constant_velocity=constant_velocity), False)
    assert (worst < 0.05) == constant_velocity, worst


@pytest.mark.parametrize("odometry", [True, False])
def test_an_odometry_guess_follows_the_turn_that_matching_from_the_last_pose_loses(scene, odometry):
    """The same turn, matched from the last pose moved on by the measured motion (no prediction of its own)."""
    worst = _worst_error_in_a_fast_turn(scene, make_slam(scene, constant_velocity=False), odometry)
    assert (worst < 0.05) == odometry, worst


def test_the_odometry_guess_is_taken_in_the_robot_frame(scene):
    """Driving sideways in the map frame while facing +y: the guess (forward, left) turns with the heading."""
    start = scene.robot.pose.copy()
    slam = make_slam(scene, constant_velocity=False, iterations_fine=1, iterations_coarse=0)
    slam.reset((0.0, 0.0, math.pi / 2))
    slam.update(exact_scan(scene, compose(start, (0.0, 0.0, math.pi / 2))))
    truth = compose(start, (0.0, 0.3, math.pi / 2))  # 0.3 m along the start frame's y: the robot's forward
    pose = slam.update(exact_scan(scene, truth), (0.3, 0.0, 0.0))
    assert abs(pose[1] - 0.3) < 0.03 and abs(pose[0]) < 0.03, pose


def _recorded_scans(kwargs: dict, seed: int, steps: int) -> tuple[list[np.ndarray], dict]:
    """The full scans harik-apf-gt's drive gives (m), and the env's LIDAR geometry."""
    env = gym.make(ENV_ID, full_scan=True, localization="ground_truth", **kwargs)
    policy = make_policy("harik-apf-gt", env)
    obs, _ = env.reset(seed=seed)
    scans = []
    for k in range(steps):
        scans.append(obs["scan"].astype(np.float64) * env.unwrapped.lidar.spec.max_range)
        action, _ = policy.predict(obs, episode_start=np.array([k == 0]))
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    spec = env.unwrapped.lidar.spec
    return scans, {"beam_angles": spec.beam_angles, "lidar_mount": spec.mount}


@pytest.mark.parametrize(
    ("kwargs", "config"),
    [
        ({"n_people": 3, "people_tease_prob": 0.8}, {}),  # people in the way: the free-space guard at work
        ({"scene": "corridor", "office_width": 1.4, "n_people": 0}, {}),  # 180 deg turns near walls
        ({"n_people": 2}, {"free_space_guard": None, "max_step_halvings": 0, "constant_velocity": False}),  # plain
        ({"scene": "corridor", "n_people": 1}, {"levels": 2, "iterations_coarse": 0, "map_size": 512}),
    ],
)
def test_compiled_scan_path_is_the_earlier_implementation_bit_for_bit(kwargs, config):
    """Pose after every scan, and every level's log-odds, probabilities and marks, on scans recorded in the env."""
    scans, geometry = _recorded_scans(kwargs, seed=7, steps=400)
    cfg = HectorSlamConfig(**config)
    ours, theirs = HectorSlam(cfg, **geometry), ReferenceHectorSlam(cfg, **geometry)
    for scan in scans:
        assert ours.update(scan).tobytes() == theirs.update(scan).tobytes()
    assert ours.map_updates == theirs.map_updates > 5
    for name in ("log_odds", "prob", "_mark"):
        for a, b in zip(getattr(ours, name), getattr(theirs, name), strict=True):
            assert a.tobytes() == b.tobytes(), name
    ours.reset()
    theirs.reset()
    for scan in scans[:50]:  # a new map after reset, in the same instance
        assert ours.update(scan).tobytes() == theirs.update(scan).tobytes()
