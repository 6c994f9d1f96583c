"""Differential-drive motion in the pymunk world: exact unicycle, limits, no tunnelling."""

import math

import numpy as np
import pytest

from agri_envs.sim2d.diff_drive import DiffDriveSpec, limit_velocity, unicycle_arc
from agri_envs.sim2d.geometry import GeometryBuilder, Kind
from agri_envs.sim2d.world import World2D


def test_unicycle_arc_matches_fine_euler_integration():
    pose = np.array([1.0, -2.0, 0.3])
    v, w, dt = 0.7, -1.1, 0.5
    x, y, th = pose
    n = 200000
    h = dt / n
    for _ in range(n):
        x += v * math.cos(th) * h
        y += v * math.sin(th) * h
        th += w * h
    np.testing.assert_allclose(unicycle_arc(pose, v, w, dt), [x, y, th], atol=1e-5)
    np.testing.assert_allclose(
        unicycle_arc(pose, v, 0.0, dt), [1 + 0.35 * math.cos(0.3), -2 + 0.35 * math.sin(0.3), 0.3]
    )


def test_velocity_and_acceleration_limits():
    spec = DiffDriveSpec(max_speed=0.6, max_reverse_speed=0.3, max_turn_rate=1.2, max_accel=1.0, max_angular_accel=3.0)
    dt = 1 / 15
    v = w = 0.0
    for _ in range(100):
        v2, w2 = limit_velocity(spec, v, w, 5.0, -5.0, dt)
        assert v2 - v <= 1.0 * dt + 1e-12 and w - w2 <= 3.0 * dt + 1e-12
        v, w = v2, w2
    assert v == pytest.approx(0.6) and w == pytest.approx(-1.2)
    for _ in range(100):
        v, w = limit_velocity(spec, v, w, -5.0, 0.0, dt)
    assert v == pytest.approx(-0.3)


@pytest.mark.parametrize(
    "obstacle",
    [("leaf", (2.0, -0.3, 2.0, 0.3, 0.015)), ("post", (2.0, 0.0, 0.05)), ("wall", (2.0, -3.0, 2.0, 3.0, 0.05))],
)
@pytest.mark.parametrize("speed", [0.6, 2.0])
def test_no_tunnelling_at_any_allowed_speed(obstacle, speed):
    name, params = obstacle
    b = GeometryBuilder()
    if len(params) == 3:
        b.circle(*params, Kind.POST)
    else:
        b.capsule(*params, Kind.LEAF)
    world = World2D(b.build((-5, -5, 5, 5)))
    spec = DiffDriveSpec(max_speed=speed, max_accel=50.0)
    robot = world.add_robot(spec, np.array([0.0, 0.0, 0.0]))
    contacts = 0
    for _ in range(200):
        contacts += world.drive(robot, speed, 0.0, 1 / 15)
        assert robot.pose[0] < 2.0, f"robot crossed the {name}"
        assert world.clearance(robot) > -0.01
    assert contacts > 0
    assert world.clearance(robot) < world.max_substep + 1e-9


def test_robot_can_back_out_of_contact():
    b = GeometryBuilder()
    b.capsule(1.0, -2.0, 1.0, 2.0, 0.05, Kind.WALL)
    world = World2D(b.build((-3, -3, 3, 3)))
    robot = world.add_robot(DiffDriveSpec(), np.array([0.0, 0.0, 0.0]))
    for _ in range(60):
        world.drive(robot, 0.6, 0.0, 1 / 15)
    stuck_x = robot.pose[0]
    for _ in range(30):
        assert not world.drive(robot, -0.3, 0.0, 1 / 15)
    assert robot.pose[0] < stuck_x - 0.2


def test_movers_are_integrated_by_the_space():
    world = World2D(GeometryBuilder().build((-3, -3, 3, 3)), n_movers=2)
    world.place_mover(0, 0.0, 0.0, 0.2, vx=1.0, vy=0.5)
    world.place_mover(1, 1.0, 1.0, 0.3)
    world.step(0.5)
    np.testing.assert_allclose(world.mover_circles, [[0.5, 0.25, 0.2], [1.0, 1.0, 0.3]])
