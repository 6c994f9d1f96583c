"""A* (agri_baselines.astar) against scipy's csgraph Dijkstra on the same 8-connected graph."""

import math

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from agri_baselines import astar
from agri_envs.sim2d.astar import distance_field, path_cost


def _graph(occ: np.ndarray) -> csr_matrix:
    """The 8-connected grid graph with costs 1 / sqrt 2 and the no-corner-cutting rule, built independently."""
    h, w = occ.shape
    rows, cols, cost = [], [], []
    for i in range(h):
        for j in range(w):
            if occ[i, j]:
                continue
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    ni, nj = i + di, j + dj
                    if (di, dj) == (0, 0) or not (0 <= ni < h and 0 <= nj < w) or occ[ni, nj]:
                        continue
                    if di and dj and (occ[i, nj] or occ[ni, j]):
                        continue
                    rows.append(i * w + j)
                    cols.append(ni * w + nj)
                    cost.append(math.hypot(di, dj))
    return csr_matrix((cost, (rows, cols)), shape=(h * w, h * w))


def test_astar_costs_equal_dijkstra_on_random_grids():
    rng = np.random.default_rng(0)
    found = 0
    for _ in range(150):
        h, w = rng.integers(2, 30, 2)
        occ = rng.random((h, w)) < rng.uniform(0.0, 0.45)
        s = (int(rng.integers(h)), int(rng.integers(w)))
        g = (int(rng.integers(h)), int(rng.integers(w)))
        occ[s] = occ[g] = False
        dist = dijkstra(_graph(occ), indices=s[0] * w + s[1])
        path = astar(occ, s, g)
        truth = dist[g[0] * w + g[1]]
        if path is None:
            assert not np.isfinite(truth)
            continue
        found += 1
        assert path[0] == s and path[-1] == g
        steps = np.diff(np.array(path), axis=0)
        assert np.all(np.abs(steps).max(axis=1) == 1)  # 8-connected moves only
        assert not any(occ[c] for c in path)
        for (i, j), (di, dj) in zip(path[:-1], steps, strict=True):
            if di and dj:  # the corner-cutting rule
                assert not occ[i + di, j] and not occ[i, j + dj]
        assert path_cost(path) == pytest.approx(truth, abs=1e-9)
        np.testing.assert_allclose(distance_field(occ, s).ravel(), dist, atol=1e-9)
    assert found > 80


def test_no_path_blocked_ends_and_bad_input():
    occ = np.zeros((5, 5), bool)
    occ[:, 2] = True
    assert astar(occ, (0, 0), (4, 4)) is None
    assert astar(occ, (0, 2), (4, 4)) is None
    # Two blocked cells touching at a corner: no squeezing through diagonally.
    occ = np.zeros((2, 2), bool)
    occ[0, 1] = occ[1, 0] = True
    assert astar(occ, (0, 0), (1, 1)) is None
    assert astar(np.zeros((3, 3), bool), (1, 1), (1, 1)) == [(1, 1)]
    with pytest.raises(ValueError, match="outside"):
        astar(np.zeros((3, 3), bool), (0, 0), (3, 0))
    with pytest.raises(ValueError, match="2D"):
        astar(np.zeros(9, bool), (0, 0), (1, 1))
    with pytest.raises(ValueError, match="pair"):
        astar(np.zeros((3, 3), bool), (0,), (1, 1))


def test_straight_and_diagonal_costs():
    occ = np.zeros((20, 30), bool)
    assert path_cost(astar(occ, (0, 0), (0, 29))) == pytest.approx(29)
    assert path_cost(astar(occ, (0, 0), (19, 19))) == pytest.approx(19 * math.sqrt(2))
    assert path_cost(astar(occ, (0, 0), (5, 29))) == pytest.approx(24 + 5 * math.sqrt(2))
