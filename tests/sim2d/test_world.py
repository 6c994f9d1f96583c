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


def _full_space_touches(geometry, spec):
    """Contact test against a pymunk space holding every static shape of ``geometry`` (what worlds built before)."""
    import pymunk

    space = pymunk.Space()
    static = space.static_body
    for x, y, r in geometry.circles.tolist():
        space.add(pymunk.Circle(static, r, offset=(x, y)))
    for x0, y0, x1, y1, r in geometry.capsules.tolist():
        if r > 0:
            space.add(pymunk.Segment(static, (x0, y0), (x1, y1), r))
    for poly in geometry.polygons:
        space.add(pymunk.Poly(static, poly.tolist()))
    body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    box = pymunk.Poly.create_box(body, (spec.length, spec.width))
    space.add(body, box)

    def touches(pose):
        body.position = (float(pose[0]), float(pose[1]))
        body.angle = float(pose[2])
        space.reindex_shapes_for_body(body)
        return bool(space.shape_query(box))

    return touches


def test_a_world_reused_across_scenes_touches_exactly_like_one_holding_the_whole_scene():
    """Static shapes built only near the queries, scene after scene, give the whole scene's contacts."""
    from agri_envs.scenes.greenhouse import LayoutParams, generate_layout
    from agri_envs.scenes.office import CorridorParams, generate_office_corridor

    rng = np.random.default_rng(3)
    leafy = LayoutParams(n_rows=3, row_length=5.0, growth=0.9, n_trees=3, row_bend=0.1, corridor_width=1.5)
    scenes = [
        (generate_layout(leafy, rng) if k % 2 else generate_office_corridor(CorridorParams(), rng)).geometry
        for k in range(8)
    ]
    spec = DiffDriveSpec(length=1.5, width=0.7)
    world = World2D(scenes[0], n_movers=1)
    robot = world.add_robot(spec, np.zeros(3))
    hits = 0
    for geometry in scenes:
        world.set_scene(geometry)
        assert len(world.space.shapes) == 2  # the mover and the robot: the scene's shapes come with queries
        world.place_mover(0, 1e6, 1e6, 0.2)
        reference = _full_space_touches(geometry, spec)
        xmin, ymin, xmax, ymax = geometry.bounds
        for _ in range(1500):
            pose = rng.uniform([xmin, ymin, -np.pi], [xmax, ymax, np.pi])
            expected = reference(pose)
            assert world._touches(robot, pose) == expected, (geometry.bounds, pose)
            hits += expected
    assert 0.1 < hits / (1500 * len(scenes)) < 0.95  # both answers are common


def test_set_scene_keeps_movers_robots_and_their_rows():
    b = GeometryBuilder()
    b.circle(2.0, 0.0, 0.1, Kind.POST)
    one = b.build((-3, -3, 3, 3))
    b.circle(-2.0, 0.0, 0.1, Kind.POST)
    b.capsule(0.0, 2.0, 1.0, 2.0, 0.05, Kind.WALL)
    two = b.build((-3, -3, 3, 3))
    world = World2D(one, n_movers=1)
    robots = [world.add_robot(DiffDriveSpec(), np.array([x, 0.0, 0.0]), radius=0.2) for x in (0.0, 1.0)]
    world.place_mover(0, 0.5, 1.0, 0.3)
    world.set_scene(two)
    np.testing.assert_array_equal(world.circles[:2], two.circles)
    np.testing.assert_array_equal(world.mover_circles, [[0.5, 1.0, 0.3]])
    assert [r.circle_index for r in robots] == [3, 4]
    np.testing.assert_array_equal(world.robot_circles[:, :2], [[0.0, 0.0], [1.0, 0.0]])
    world.place_robot(robots[1], np.array([-1.0, -1.0, 0.5]))
    assert robots[1].v == robots[1].w == 0.0 and world.robot_circles[1, 0] == -1.0
    assert world.clearance(robots[0]) == pytest.approx(math.hypot(0.5, 1.0) - 0.3 - 0.2)  # the mover is nearest
