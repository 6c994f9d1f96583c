"""The compiled twins of Python's scalar semantics and of the 2D world's pieces (agri_envs.sim2d.batched)."""

import math

import numba
import numpy as np

from agri_envs.sim2d.batched import arc, drive_box, py_hypot
from agri_envs.sim2d.diff_drive import DiffDriveSpec, unicycle_arc
from agri_envs.sim2d.geometry import GeometryBuilder, Kind
from agri_envs.sim2d.world import World2D


def _same(a, b):
    return (a == b and math.copysign(1.0, a) == math.copysign(1.0, b)) or (math.isnan(a) and math.isnan(b))


def test_py_hypot_is_cpythons_math_hypot_to_the_bit():
    """The C library's hypot differs from CPython's in the last bit for about 1 pair in 200: not this one."""
    rng = np.random.default_rng(0)
    pairs = np.vstack(
        [
            rng.uniform(-10.0, 10.0, (200_000, 2)),
            rng.standard_normal((100_000, 2)) * 10.0 ** rng.integers(-300, 300, (100_000, 1)),
            [[0.0, -0.0], [-0.0, 3.0], [3.0, 4.0], [1e-310, 2e-310], [5e-324, 0.0], [1e308, 1e308]],
            [[math.inf, math.nan], [math.nan, 1.0], [-math.inf, 2.0], [0.3, -0.4]],
        ]
    )
    assert all(_same(py_hypot(x, y), math.hypot(x, y)) for x, y in pairs.tolist())


@numba.njit
def _min_max(a, b):
    return min(a, b), max(a, b)


def test_compiled_min_and_max_return_what_pythons_do_for_ties_and_signed_zeros():
    """The twins use numba's min and max for Python's: that holds for ties and for min(0.0, -0.0)."""
    values = [0.0, -0.0, 1.5, -2.0, 1.5, math.inf, -math.inf]
    for a in values:
        for b in values:
            lo, hi = _min_max(a, b)
            assert _same(lo, min(a, b)) and _same(hi, max(a, b)), (a, b)


def test_arc_is_unicycle_arc():
    rng = np.random.default_rng(1)
    for x, y, th, v, w, dt in rng.uniform(-3.0, 3.0, (2000, 6)).tolist() + [[0.1, 0.2, 0.3, 0.5, 0.0, 0.1]]:
        assert list(arc(x, y, th, v, w, dt)) == unicycle_arc(np.array([x, y, th]), v, w, dt).tolist()


def test_drive_box_is_world_drive_with_the_exact_footprint():
    """A rectangular robot driven at random among posts and leaves: the twin follows World2D.drive exactly."""
    b = GeometryBuilder()
    rng = np.random.default_rng(2)
    for x, y in rng.uniform(-3.0, 3.0, (25, 2)).tolist():
        b.circle(x, y, 0.05, Kind.POST)
    for x, y, a in rng.uniform(-3.0, 3.0, (15, 3)).tolist():
        b.capsule(x, y, x + 0.3 * math.cos(a), y + 0.3 * math.sin(a), 0.015, Kind.LEAF)
    world = World2D(b.build((-4, -4, 4, 4)))
    spec = DiffDriveSpec(max_speed=1.5, max_accel=5.0)
    robot = world.add_robot(spec, np.array([0.0, 0.0, 0.0]))
    limits = np.array(
        [spec.max_speed, spec.max_reverse_speed, spec.max_turn_rate, spec.max_accel, spec.max_angular_accel]
    )
    pose, vel = robot.pose.copy(), np.zeros(2)
    contacts = 0
    for v_cmd, w_cmd in rng.uniform([-0.5, -1.2], [1.5, 1.2], (1500, 2)).tolist():
        hit = world.drive(robot, v_cmd, w_cmd, 1 / 15)
        twin = drive_box(
            pose,
            vel,
            v_cmd,
            w_cmd,
            limits,
            0.3,
            0.25,
            spec.circumradius,
            world.circles,
            world.capsules,
            1 / 15,
            world.max_substep,
        )
        assert hit == twin and pose.tolist() == robot.pose.tolist() and vel.tolist() == [robot.v, robot.w]
        contacts += hit
        if abs(pose[0]) > 3.5 or abs(pose[1]) > 3.5:
            world.place_robot(robot, np.zeros(3))
            pose, vel = robot.pose.copy(), np.zeros(2)
    assert contacts > 20
