"""Scene parts added for GreenhouseCoverage: bent/inclined rows and corridor widths, vegetation echoes."""

import math

import numpy as np
import pytest

from agri_envs.scenes.greenhouse import PLANT_RADIUS, LayoutParams, generate_layout, row_shapes, serpentine_waypoints
from agri_envs.sim2d.geometry import Kind
from agri_envs.sim2d.sensors import SonarArray, SonarSpec


def _plants(layout):
    g = layout.geometry
    return g.circles[g.circle_kinds == Kind.PLANT]


def test_defaults_keep_the_rovers_straight_rows():
    p = LayoutParams()
    layout = generate_layout(p, np.random.default_rng(0))
    plants = _plants(layout)
    rows = p.row_centres()
    off = np.min(np.abs(plants[:, 1:2] - rows[None, :]), axis=1)
    assert np.all(off <= p.plant_jitter + 1e-12)
    assert np.array_equal(layout.waypoints, serpentine_waypoints(p))
    assert layout.geometry.bounds[3] == pytest.approx(p.height + 0.1)
    # Nothing extra is drawn from the generator when the new features are off.
    a = np.random.default_rng(5)
    row_shapes(p, a)
    assert a.random() == np.random.default_rng(5).random()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bent_and_inclined_rows(seed):
    p = LayoutParams(n_rows=3, row_length=10.0, corridor_width=1.4, row_width=0.6, row_incline=0.03, row_bend=0.2)
    shapes = row_shapes(p, np.random.default_rng(seed))
    layout = generate_layout(p, np.random.default_rng(seed))
    plants = _plants(layout)
    assert np.all(np.abs(shapes.bend) <= 0.2) and np.any(np.abs(shapes.bend) > 0.02)
    assert np.all(np.abs(np.arctan(shapes.slope)) <= 0.03)
    xm = p.headland + 0.5 * p.row_length
    for r in range(p.n_rows):
        mine = np.abs(plants[:, 1] - p.row_centres()[r]) < 0.6  # the rows are 2 m apart
        xs, ys = plants[mine, 0], plants[mine, 1]
        assert mine.sum() >= 20
        ends = (np.abs(xs - xs.min()) < 1.0) | (np.abs(xs - xs.max()) < 1.0)
        mid = np.abs(xs - xm) < 0.5
        # A straight line through the plants near both ends; the middle ones sit `bend` off it.
        fit = np.polyfit(xs[ends], ys[ends], 1)
        assert abs(fit[0] - shapes.slope[r]) < 0.25 * abs(shapes.bend[r]) / p.row_length * 8 + 0.01
        off = np.mean(ys[mid] - np.polyval(fit, xs[mid]))
        assert abs(off - shapes.bend[r] * (1 - 0.7 / (0.5 * p.row_length))) < 0.05


def test_corridor_width_variation_and_centre_lines():
    p = LayoutParams(n_rows=4, corridor_width=1.4, row_width=0.6, corridor_width_jitter=0.3, growth=0.5)
    shapes = row_shapes(p, np.random.default_rng(3))
    layout = generate_layout(p, np.random.default_rng(3))
    lines = layout.corridors
    assert len(lines) == p.n_rows + 1
    half = PLANT_RADIUS[0] + 0.5 * (PLANT_RADIUS[1] - PLANT_RADIUS[0])
    edges = np.r_[0.0, np.repeat(shapes.centre, 2) + np.tile([-half, half], p.n_rows), shapes.height]
    widths = edges[1::2] - edges[0::2] - 2 * (0.5 * p.row_width - half) * np.r_[0.5, np.ones(p.n_rows - 1), 0.5]
    assert np.all(np.abs(widths - p.corridor_width) <= p.corridor_width_jitter + 1e-9)
    assert np.std(widths) > 0.02
    for k, line in enumerate(lines):  # each centre line runs midway between the plants beside it
        assert line[0, 1] == pytest.approx(0.5 * (edges[2 * k] + edges[2 * k + 1]))
    assert layout.geometry.bounds[3] == pytest.approx(shapes.height + 0.1)


def test_max_narrowing_bounds_the_generated_corridors():
    p = LayoutParams(
        n_rows=5, row_length=12.0, corridor_width=1.6, row_incline=0.02, row_bend=0.15, corridor_width_jitter=0.2
    )
    for seed in range(10):
        shapes = row_shapes(p, np.random.default_rng(seed))
        xs = np.linspace(shapes.x0, shapes.x1, 50)
        for r in range(p.n_rows - 1):
            gap = shapes.row_y(r + 1, xs) - shapes.row_y(r, xs) - p.row_width
            assert gap.min() >= p.corridor_width - p.max_narrowing() - 1e-9


def test_sonar_slip_statistics_and_off_by_default():
    from agri_envs.sim2d.geometry import GeometryBuilder

    b = GeometryBuilder()
    b.circle(1.0, 0.0, 0.2, Kind.PLANT)
    b.capsule(3.0, -2.0, 3.0, 2.0, 0.05, Kind.WALL)
    geo = b.build((-1, -3, 4, 3))
    solid = (geo.circles[geo.circle_kinds != Kind.PLANT], geo.capsules)
    mounts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2]])
    rng = np.random.default_rng(0)
    pose = np.zeros(3)
    sonar = SonarArray(SonarSpec(foliage_slip_prob=0.3, max_range=4.0), mounts)
    r = np.array([sonar.ranges(pose, geo.circles, geo.capsules, rng, solid=solid) for _ in range(4000)])
    slipped = r[:, 0] > 0.8 + 1e-6
    assert abs(slipped.mean() - 0.3) < 0.03  # the per-reading probability
    assert np.all(r[slipped, 0] <= 2.95 + 1e-9)  # never beyond the solid wall behind the plant
    assert np.all(r[:, 1] == 4.0)  # no foliage in view: never a slip
    plain = SonarArray(SonarSpec(max_range=4.0), mounts)
    assert np.all(plain.ranges(pose, geo.circles, geo.capsules, rng, solid=solid)[0] == pytest.approx(0.8))
