"""The training teacher ``coverage-half-circle``: its path, its registration, and that it beats the planner."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401
from agri_baselines import list_policies, make_policy, policy_spec
from agri_baselines.coverage_teacher import serpentine_with_half_circles
from agri_training.evaluation.episode import run_episode
from agri_training.leaderboard.entries import policy_reference

ENV_ID = "agri_envs/GreenhouseCoverage-v2"


@pytest.mark.parametrize("extend", [0.0, 0.4])
def test_half_circles_join_the_corridors_at_the_given_distance_past_their_ends(extend):
    corridors = [np.array([[0.0, y], [5.0, y]]) for y in (0.0, 2.0, 4.2)]
    path = serpentine_with_half_circles(corridors, np.array([-1.0, 0.0]), extend)
    assert np.allclose(path[0], [-1.0, 0.0]) and np.allclose(path[-1], [5.0 + extend, 4.2])
    steps = np.hypot(*np.diff(path, axis=0).T)
    assert steps.max() <= 0.1 + 1e-9  # resampled every 10 cm
    # every point past the ends lies on its half circle: centre between the two corridors' ends, radius half
    # their distance; the first turn is at the far end (x = 5 + extend), the second at the near one (-extend)
    for lo, hi, x0 in ((0.0, 2.0, 5.0 + extend), (2.0, 4.2, -extend)):
        centre, radius = np.array([x0, (lo + hi) / 2]), (hi - lo) / 2
        outside = (path[:, 0] > 5.0 + extend + 1e-6) if x0 > 0 else (path[:, 0] < -extend - 1e-6)
        turn = path[outside & (path[:, 1] >= lo) & (path[:, 1] <= hi)]
        assert len(turn) > 10
        np.testing.assert_allclose(np.hypot(*(turn - centre).T), radius, atol=0.01)  # chords of 24-gon: < 1 cm
        assert np.abs(turn[:, 0] - x0).max() == pytest.approx(radius, abs=0.01)
    # the corridors are driven along their centre lines, alternately forward and back
    inside = path[(path[:, 0] > 0.5) & (path[:, 0] < 4.5)]
    assert set(np.round(inside[:, 1], 6)) == {0.0, 2.0, 4.2}
    for y, direction in ((0.0, 1.0), (2.0, -1.0), (4.2, 1.0)):
        assert np.all(direction * np.diff(inside[np.isclose(inside[:, 1], y), 0]) > 0)


def test_the_teacher_is_built_by_name_but_listed_only_when_asked():
    spec = policy_spec("coverage-half-circle")
    assert spec.teacher and spec.privileged and not spec.learned
    assert "coverage-half-circle" not in [s.name for s in list_policies(ENV_ID)]
    assert "coverage-half-circle" in [s.name for s in list_policies(ENV_ID, teachers=True)]
    with pytest.raises(ValueError, match="ground_truth"):
        make_policy("coverage-half-circle", gym.make(ENV_ID, localization="odometry"))
    with pytest.raises(ValueError, match="is a training teacher, not a baseline"):
        policy_reference("coverage-half-circle")  # what an entry records: a teacher has none
    assert policy_reference("gonzalez-deliberative")["kind"] == "baseline"


@pytest.mark.parametrize(
    "kw", [{"n_rows": 3, "row_length": 8.0}, {"n_rows": 4, "row_length": 6.0, "corridor_width": 1.8}]
)
def test_teacher_covers_the_greenhouse_without_contact_faster_than_the_planner(kw):
    env = gym.make(ENV_ID, localization="ground_truth", **kw)
    for seed in (20000, 20001):
        fast = run_episode(env, make_policy("coverage-half-circle", env), seed, None)["record"]
        planner = run_episode(env, make_policy("gonzalez-deliberative", env), seed, None)["record"]
        assert fast["is_success"] and fast["crop_contacts"] == 0 and not fast["collision"]
        assert planner["is_success"]
        assert fast["episode_time"] < 0.95 * planner["episode_time"], (fast["episode_time"], planner["episode_time"])
