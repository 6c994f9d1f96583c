"""Polyline and PathProgress: arc-length projection windows on a path that folds back on itself."""

import math

import numpy as np

from agri_envs.sim2d.polyline import PathProgress, Polyline

HAIRPIN = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 1.0], [0.0, 1.0]])


def test_progress_stays_on_its_leg_of_a_hairpin_where_the_other_leg_is_nearer():
    progress = PathProgress(Polyline(HAIRPIN))
    assert progress.reset(np.array([0.2, 0.1, 0.0])) == 0.2
    # 0.6 m beside the first leg and 0.4 m beside the return leg: the window keeps it on the first.
    for x in np.arange(0.5, 9.0, 0.5):
        assert math.isclose(progress.update(np.array([x, 0.6, 0.0])), x)
    # Around the bend and back along the return leg, its arc length keeps growing.
    for y in (0.2, 0.5, 0.8):
        progress.update(np.array([9.9, y, 0.0]))
    assert math.isclose(progress.update(np.array([9.0, 0.9, math.pi])), 12.0)
    for x in np.arange(8.5, 1.9, -0.5):  # 0.4 m from the return leg, 0.6 m from the first: on the return leg
        assert math.isclose(progress.update(np.array([x, 0.6, math.pi])), 21.0 - x)
    # Back at the first leg's end (arc length 10), the window (0.5 m back) keeps it on the return leg.
    assert math.isclose(progress.update(np.array([10.0, 0.0, 0.0])), 18.5)


def test_points_ahead_are_in_the_robot_frame_and_clamped_to_the_end():
    progress = PathProgress(Polyline(HAIRPIN))
    pose = np.array([8.0, 0.0, math.pi / 2])  # on the first leg, facing +y
    progress.reset(pose)
    progress.s = 8.0
    ahead = progress.ahead(pose, np.array([0.0, 1.0, 2.5, 100.0]))
    # (x, y) -> (ahead, left) with the robot facing +y: ahead = dy, left = -dx.
    want = np.array([[0.0, 0.0], [0.0, -1.0], [0.5, -2.0], [1.0, 8.0]])
    np.testing.assert_allclose(ahead, want, atol=1e-12)
