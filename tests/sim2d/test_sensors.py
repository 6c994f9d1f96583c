"""LIDAR, sonar and clearance kernels against independent references and known geometry."""

import math

import numpy as np
import pytest

from agri_envs.sim2d.geometry import GeometryBuilder, Kind
from agri_envs.sim2d.raycast import footprint_clearance
from agri_envs.sim2d.reference import geometry_space, reference_scan, reference_sonar
from agri_envs.sim2d.sensors import Lidar, SonarArray, hc_sr04, tim561


def random_scene(seed: int):
    rng = np.random.default_rng(seed)
    b = GeometryBuilder()
    for _ in range(150):
        b.circle(*rng.uniform(-9, 9, 2), rng.uniform(0.02, 0.4), Kind.PLANT)
    for _ in range(30):
        p = rng.uniform(-9, 9, 2)
        q = p + rng.uniform(-3, 3, 2)
        b.capsule(*p, *q, float(rng.choice([0.0, 0.015, 0.05, 0.2])), Kind.WALL)
    b.box(2.0, 2.0, 3.0, 3.5, Kind.OBSTACLE)
    return b.build((-10, -10, 10, 10)), rng


def free_poses(geometry, rng, n, margin=0.05):
    poses = []
    while len(poses) < n:
        pose = np.array([*rng.uniform(-8, 8, 2), rng.uniform(-math.pi, math.pi)])
        if footprint_clearance(pose[0], pose[1], pose[2], 0.01, 0.01, geometry.circles, geometry.capsules) > margin:
            poses.append(pose)
    return poses


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lidar_matches_pymunk_reference(seed):
    geometry, rng = random_scene(seed)
    lidar = Lidar(tim561())
    space = geometry_space(geometry)
    for pose in free_poses(geometry, rng, 8):
        fast = lidar.exact_scan(pose, geometry.circles, geometry.capsules)
        ref = np.maximum(reference_scan(space, *pose, lidar.spec.beam_angles, lidar.spec.max_range), 0.05)
        np.testing.assert_allclose(fast, ref, atol=1e-7)


def test_lidar_exact_against_known_wall_and_circle():
    b = GeometryBuilder()
    b.capsule(2.0, -50.0, 2.0, 50.0, 0.0, Kind.WALL)  # a wall 2 m ahead
    b.circle(0.0, 3.0, 0.5, Kind.POST)  # a post 3 m to the left
    g = b.build((-5, -5, 5, 5))
    lidar = Lidar(tim561())
    ranges = lidar.exact_scan(np.zeros(3), g.circles, g.capsules)
    angles = lidar.spec.beam_angles
    ahead = np.abs(angles) < math.radians(70)
    np.testing.assert_allclose(ranges[ahead], 2.0 / np.cos(angles[ahead]), rtol=1e-12)
    left = int(np.argmin(np.abs(angles - math.pi / 2)))
    assert ranges[left] == pytest.approx(3.0 - 0.5, abs=1e-9) or abs(angles[left] - math.pi / 2) > 1e-9
    assert ranges[left] == pytest.approx(2.5, abs=1e-3)
    behind = np.abs(angles) > math.radians(125)
    assert np.all(ranges[behind] == lidar.spec.max_range)


def test_lidar_full_spec_and_noise_statistics():
    spec = tim561()
    assert spec.n_beams == 811 and spec.angle_step == pytest.approx(math.radians(270) / 810)
    b = GeometryBuilder()
    b.capsule(3.0, -50.0, 3.0, 50.0, 0.05, Kind.WALL)
    g = b.build((-5, -5, 5, 5))
    lidar = Lidar(tim561(noise_std=0.02, dropout_prob=0.05))
    exact = Lidar(tim561()).exact_scan(np.zeros(3), g.circles, g.capsules).copy()
    rng = np.random.default_rng(0)
    scans = np.array([lidar.scan(np.zeros(3), g.circles, g.capsules, rng) for _ in range(200)])
    assert np.all((scans >= spec.min_range) & (scans <= spec.max_range))
    hit = exact < spec.max_range
    dropped = (scans == spec.max_range) & hit
    assert dropped.mean() / hit.mean() == pytest.approx(0.05, abs=0.01)
    err = (scans - exact)[~dropped & hit[None, :].repeat(200, 0)]
    assert abs(err.mean()) < 0.002 and err.std() == pytest.approx(0.02, rel=0.05)


def test_sonar_is_a_cone_not_a_ray():
    b = GeometryBuilder()
    # A thin stem 6 degrees off the sonar axis at 1 m: the axis ray misses it, the 15 deg cone does not.
    b.circle(math.cos(math.radians(6)), math.sin(math.radians(6)), 0.02, Kind.PLANT)
    g = b.build((-5, -5, 5, 5))
    sonar = SonarArray(hc_sr04(), np.array([[0.0, 0.0, 0.0]]))
    assert sonar.exact_ranges(np.zeros(3), g.circles, g.capsules)[0] == pytest.approx(0.98, abs=1e-9)
    assert Lidar(tim561(n_beams=3, aperture=0.2)).exact_scan(np.zeros(3), g.circles, g.capsules)[1] == 10.0
    # Outside the cone (10 deg off axis): no echo.
    b2 = GeometryBuilder()
    b2.circle(math.cos(math.radians(10)), math.sin(math.radians(10)), 0.02, Kind.PLANT)
    g2 = b2.build((-5, -5, 5, 5))
    assert sonar.exact_ranges(np.zeros(3), g2.circles, g2.capsules)[0] == 4.0


@pytest.mark.parametrize("seed", [3, 4])
def test_sonar_matches_dense_ray_fan(seed):
    geometry, rng = random_scene(seed)
    space = geometry_space(geometry)
    mounts = np.array([[0.3, 0.0, 0.0], [0.0, 0.25, math.pi / 2], [-0.3, 0.0, math.pi]])
    sonar = SonarArray(hc_sr04(), mounts)
    for pose in free_poses(geometry, rng, 6, margin=0.5):
        fast = sonar.exact_ranges(pose, geometry.circles, geometry.capsules)
        for j, p in enumerate(sonar.poses_in_world(pose)):
            ref = max(0.02, reference_sonar(space, *p, sonar.spec.aperture / 2, 4.0))
            assert fast[j] <= ref + 1e-9  # the fan can only miss the exact nearest point
            assert fast[j] == pytest.approx(ref, abs=2e-3)


def _point_segment(px, py, seg):
    ax, ay, bx, by, r = seg
    ex, ey = bx - ax, by - ay
    t = np.clip(((px - ax) * ex + (py - ay) * ey) / max(ex * ex + ey * ey, 1e-300), 0, 1)
    return np.hypot(px - (ax + t * ex), py - (ay + t * ey)) - r


def test_clearance_matches_brute_force_on_footprint_boundary():
    geometry, rng = random_scene(5)
    hl, hw = 0.3, 0.25
    s = np.linspace(-1, 1, 801)
    local = np.concatenate(
        [
            np.stack([hl * np.ones_like(s), hw * s], 1),
            np.stack([-hl * np.ones_like(s), hw * s], 1),
            np.stack([hl * s, hw * np.ones_like(s)], 1),
            np.stack([hl * s, -hw * np.ones_like(s)], 1),
        ]
    )
    for pose in free_poses(geometry, rng, 20, margin=0.45):
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        pts = pose[:2] + local @ np.array([[c, sn], [-sn, c]])
        brute = min(
            np.min(
                np.hypot(pts[:, 0, None] - geometry.circles[:, 0], pts[:, 1, None] - geometry.circles[:, 1])
                - geometry.circles[:, 2]
            ),
            min(np.min(_point_segment(pts[:, 0], pts[:, 1], seg)) for seg in geometry.capsules),
        )
        fast = footprint_clearance(*pose, hl, hw, geometry.circles, geometry.capsules)
        assert fast <= brute + 1e-9
        assert fast == pytest.approx(brute, abs=1e-3)


@pytest.mark.parametrize("seed", [5, 6])
def test_sonars_of_a_team_equal_each_body_alone(seed):
    # sonar_ranges_many culls, per body, every primitive beyond the sonars' reach: the ranges must be those of
    # the plain kernel over every primitive, with the body's own circle removed (bit for bit).
    from agri_envs.sim2d.raycast import sonar_ranges, sonar_ranges_many

    geometry, rng = random_scene(seed)
    poses = np.array(free_poses(geometry, rng, 12, margin=0.3))
    bodies = np.column_stack([poses[:, :2], np.full(len(poses), 0.2)])
    circles = np.vstack([geometry.circles, bodies])
    rows = len(geometry.circles) + np.arange(len(poses))
    mounts = np.array([[0.19, 0.0, 0.0], [0.0, 0.19, math.pi / 2], [-0.19, 0.0, math.pi], [0.1, -0.15, -1.0]])
    many = np.empty((len(poses), len(mounts)))
    sonar_ranges_many(poses, mounts, 0.4, 3.0, circles, geometry.capsules, rows, many)
    for b, pose in enumerate(poses):
        alone = np.empty(len(mounts))
        sonar_ranges(*pose, mounts, 0.4, 3.0, np.delete(circles, rows[b], axis=0), geometry.capsules, alone)
        np.testing.assert_array_equal(many[b], alone)
    assert (many < 3.0).any() and (many == 3.0).any()  # echoes and open space both occur
