"""The compiled Euclidean distance transform against scipy's (the oracle): the same values, bit for bit."""

import numpy as np
import pytest
from scipy import ndimage

from agri_envs.scenes.office import OfficeFloorParams, generate_office_floor
from agri_envs.sim2d.distance import euclidean_distance_transform
from agri_envs.sim2d.gridmap import rasterize


@pytest.mark.parametrize("seed", range(5))
def test_equals_scipy_on_random_grids(seed):
    rng = np.random.default_rng(seed)
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(1, 50, 2))
        free = rng.random((h, w)) > rng.uniform(0.005, 0.995)
        free.flat[rng.integers(free.size)] = False  # at least one feature
        np.testing.assert_array_equal(euclidean_distance_transform(free), ndimage.distance_transform_edt(free))


def test_equals_scipy_on_an_office_map():
    grid = rasterize(generate_office_floor(OfficeFloorParams(), np.random.default_rng(3)), 0.05)
    free = grid.data < 50
    np.testing.assert_array_equal(euclidean_distance_transform(free), ndimage.distance_transform_edt(free))


def test_single_feature_and_no_feature():
    free = np.ones((5, 7), dtype=bool)
    free[2, 3] = False
    i, j = np.indices(free.shape)
    np.testing.assert_array_equal(euclidean_distance_transform(free), np.hypot(i - 2, j - 3))
    assert np.isinf(euclidean_distance_transform(np.ones((3, 3), dtype=bool))).all()
    with pytest.raises(ValueError, match="2D"):
        euclidean_distance_transform(np.ones(4, dtype=bool))
