"""Robots are obstacles to each other in the shared 2D world: sensed, solid, never overlapping."""

import math

import numpy as np
import pytest

from agri_envs.rover import robot as rover
from agri_envs.sim2d.diff_drive import DiffDriveSpec
from agri_envs.sim2d.geometry import GeometryBuilder, Kind
from agri_envs.sim2d.raycast import disc_clearance, sonar_ranges_many
from agri_envs.sim2d.reference import geometry_space, reference_disc_clearance, reference_scan, reference_sonar
from agri_envs.sim2d.sensors import Lidar, SonarArray, hc_sr04, tim561
from agri_envs.sim2d.world import World2D

DISC = DiffDriveSpec(length=0.33, width=0.33, max_speed=0.4, max_reverse_speed=0.4, max_turn_rate=2.0)


def _room():
    b = GeometryBuilder()
    for x0, y0, x1, y1 in ((0, 0, 6, 0), (6, 0, 6, 4), (6, 4, 0, 4), (0, 4, 0, 0)):
        b.capsule(x0, y0, x1, y1, 0.05, Kind.WALL)
    b.circle(4.5, 1.0, 0.2, Kind.POST)
    b.box(1.0, 3.0, 1.6, 3.5, Kind.OBSTACLE)
    return b.build((0, 0, 6, 4))


def test_disc_clearance_matches_pymunk_and_skips_itself():
    g = _room()
    rng = np.random.default_rng(1)
    space = geometry_space(g)
    for _ in range(200):
        x, y, r = rng.uniform(0.3, 5.7), rng.uniform(0.3, 3.7), rng.uniform(0.05, 0.3)
        ours = disc_clearance(x, y, r, g.circles, g.capsules)
        assert ours == pytest.approx(reference_disc_clearance(space, x, y, r), abs=1e-9)
    # The row to skip is ignored, every other row counts.
    circles = np.vstack([g.circles, [[3.0, 2.0, 0.2]]])
    assert disc_clearance(3.0, 2.0, 0.2, circles, g.capsules, len(circles) - 1) > 1.0
    assert disc_clearance(3.0, 2.0, 0.2, circles, g.capsules) < 0


def test_robot_sonars_see_other_robots_like_the_pymunk_reference():
    world = World2D(_room())
    poses = [(2.0, 2.0, 0.0), (2.6, 2.1, 1.0), (2.0, 1.2, -0.5), (1.4, 2.3, 2.0)]
    robots = [world.add_robot(DISC, np.array(p), radius=0.165) for p in poses]
    angles = np.radians([90, 41, 15, -15, -41, -90, -145, 145])
    mounts = np.stack([0.16 * np.cos(angles), 0.16 * np.sin(angles), angles], axis=1)
    out = np.empty((4, 8))
    rows = np.array([r.circle_index for r in robots])
    sonar_ranges_many(np.array(poses), mounts, 0.3, 3.0, world.circles, world.capsules, rows, out)
    for k, robot in enumerate(robots):
        others = np.array([[*p[:2], 0.165] for j, p in enumerate(poses) if j != k])
        space = geometry_space(world.geometry, others)
        for j, (mx, my, ma) in enumerate(mounts):
            x, y, th = robot.pose
            sx = x + math.cos(th) * mx - math.sin(th) * my
            sy = y + math.sin(th) * mx + math.cos(th) * my
            ref = reference_sonar(space, sx, sy, th + ma, 0.3, 3.0, n_rays=801)
            assert out[k, j] == pytest.approx(ref, abs=2e-3)
    # Someone right in front of robot 0 (robot 1 is at 2.6, 2.1): the front sonars see it.
    assert out[0, 2:4].min() < 0.5


def test_rover_lidar_sees_another_robot_but_not_itself():
    geometry = _room()
    spec = rover.rover_spec(0.6, 1.2, 1.0, 3.0)
    lidar = Lidar(tim561(mount=rover.LIDAR_MOUNT))
    alone = World2D(geometry)
    r0 = alone.add_robot(spec, np.array([2.0, 2.0, 0.0]))
    scan_alone = lidar.exact_scan(r0.pose, alone.circles, alone.capsules).copy()
    ref = reference_scan(geometry_space(geometry), *lidar.pose_in_world(r0.pose), lidar.spec.beam_angles, 10.0)
    np.testing.assert_allclose(scan_alone, np.maximum(ref, 0.05), atol=1e-6)  # no echo from its own body
    world = World2D(geometry)
    a = world.add_robot(spec, np.array([2.0, 2.0, 0.0]))
    world.add_robot(DISC, np.array([3.2, 2.0, 0.0]), radius=0.165)
    scan = lidar.exact_scan(a.pose, world.circles, world.capsules)
    ahead = np.argmin(np.abs(lidar.spec.beam_angles))
    sx = lidar.pose_in_world(a.pose)[0]
    assert scan[ahead] == pytest.approx(3.2 - 0.165 - sx, abs=1e-6)
    sonars = SonarArray(hc_sr04(), rover.SONAR_MOUNTS)
    assert sonars.exact_ranges(a.pose, world.circles, world.capsules)[0] == pytest.approx(3.2 - 0.165 - 2.3, abs=1e-6)
    assert world.clearance(a) == pytest.approx(3.2 - 0.165 - 2.3, abs=1e-6)


def test_robots_cannot_drive_through_each_other():
    world = World2D(_room())
    a = world.add_robot(DISC, np.array([2.0, 2.0, 0.0]), radius=0.165)
    b = world.add_robot(DISC, np.array([3.0, 2.0, math.pi]), radius=0.165)
    hits = []
    for _ in range(60):
        hits.append(world.drive(a, 0.4, 0.0, 0.1))
        hits.append(world.drive(b, 0.4, 0.0, 0.1))
        d = math.hypot(*(a.pose[:2] - b.pose[:2]))
        assert d >= 0.33 - 1e-9
    assert any(hits) and d < 0.36
    # A rectangular rover is stopped by a disc robot as well (pymunk contact, clearance fast path).
    rover_spec = rover.rover_spec(0.6, 1.2, 1.0, 3.0)
    w2 = World2D(_room())
    r = w2.add_robot(rover_spec, np.array([2.0, 1.5, 0.0]))
    w2.add_robot(DISC, np.array([3.5, 1.5, 0.0]), radius=0.165)
    for _ in range(60):
        w2.drive(r, 0.6, 0.0, 0.1)
    assert 3.5 - 0.165 - 0.3 - 0.05 < r.pose[0] <= 3.5 - 0.165 - 0.3 + 1e-9  # stopped just before the disc


def test_drive_discs_equals_one_drive_call_per_robot():
    rng = np.random.default_rng(3)
    worlds = [World2D(_room()), World2D(_room())]
    starts = [(1.0 + 0.5 * k, 1.5 + 0.1 * k, 0.3 * k) for k in range(6)]
    teams = [[w.add_robot(DISC, np.array(p), radius=0.165) for p in starts] for w in worlds]
    for _ in range(80):
        cmd = rng.uniform([-0.4, -2.0], [0.4, 2.0], (6, 2))
        hit_a = [worlds[0].drive(r, float(c[0]), float(c[1]), 0.1) for r, c in zip(teams[0], cmd, strict=True)]
        hit_b = worlds[1].drive_discs(teams[1], cmd, 0.1)
        np.testing.assert_allclose([r.pose for r in teams[0]], [r.pose for r in teams[1]], atol=1e-12)
        assert hit_a == hit_b.tolist()
    with pytest.raises(ValueError, match="shape"):
        worlds[1].drive_discs(teams[1], np.zeros((5, 2)), 0.1)
    with pytest.raises(ValueError, match="radius"):
        worlds[1].add_robot(DISC, np.zeros(3), radius=0.0)


def _other_room():
    b = GeometryBuilder()
    for x0, y0, x1, y1 in ((0, 0, 8, 0), (8, 0, 8, 5), (8, 5, 0, 5), (0, 5, 0, 0)):
        b.capsule(x0, y0, x1, y1, 0.05, Kind.WALL)
    b.circle(2.0, 2.0, 0.3, Kind.POST)
    b.circle(6.0, 3.0, 0.1, Kind.POST)
    b.box(3.0, 0.5, 3.5, 1.5, Kind.OBSTACLE)
    return b.build((0, 0, 8, 5))


def test_a_reused_world_equals_a_fresh_one():
    # replace_scene + place_robots (a new episode in the same bodies) must leave the world exactly as a world
    # built from scratch for the new scene with the robots added at the new poses: same sensor arrays, same
    # motion and contacts.
    poses_a = np.array([[1.0, 1.0, 0.0], [2.0, 1.0, 0.5], [3.0, 2.5, 1.0]])
    poses_b = np.array([[1.0, 4.0, -0.3], [5.0, 1.0, 2.0], [4.2, 3.0, 0.0]])
    reused = World2D(_room(), n_movers=2)
    robots = reused.add_disc_robots(DISC, poses_a, 0.165)
    reused.place_mover(1, 9.0, 9.0, 0.2)
    reused.drive_discs(robots, np.full((3, 2), 0.3), 0.1)
    geometry = _other_room()
    reused.set_scene(geometry)
    reused.place_robots(robots, poses_b)
    fresh = World2D(geometry, n_movers=2)
    fresh_robots = fresh.add_disc_robots(DISC, poses_b, 0.165)
    fresh.place_mover(1, 9.0, 9.0, 0.2)
    np.testing.assert_array_equal(reused.circles, fresh.circles)
    np.testing.assert_array_equal(reused.capsules, fresh.capsules)
    assert [r.circle_index for r in robots] == [r.circle_index for r in fresh_robots]
    assert reused.max_substep == fresh.max_substep and len(reused.space.shapes) == len(fresh.space.shapes)
    cmd = np.array([[0.4, 0.0], [0.4, 1.0], [-0.4, 0.3]])
    for _ in range(30):
        a = reused.drive_discs(robots, cmd, 0.1)
        b = fresh.drive_discs(fresh_robots, cmd, 0.1)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal([r.pose for r in robots], [r.pose for r in fresh_robots])
    assert np.all(reused.circles[:2] == geometry.circles)
