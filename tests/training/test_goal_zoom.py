"""The goal zoom: what the network is shown, how its action is scaled back, and the 1 mm cut it makes possible."""

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import agri_envs  # noqa: F401  (registers the envs)
from agri_baselines import make_policy, policy_spec
from agri_envs.arm.task import goal_errors
from agri_training.evaluation.episode import run_episode
from agri_training.learned import zoo  # noqa: F401  (registers the shipped policies)
from agri_training.learned.goal_zoom import GoalZoom


def _goal(position, rotation):
    axes = rotation.as_matrix()
    return np.concatenate([position, axes[:, 0], axes[:, 1]])


def _pair(distance, angle, rng):
    """A clamp pose and a goal ``distance`` m away along a random direction, turned ``angle`` rad about the clamp's
    third axis (both goal axes then lie ``angle`` from the clamp's)."""
    start = Rotation.from_rotvec(rng.normal(size=3))
    direction = rng.normal(size=3)
    position = rng.normal(size=3) * 0.3
    turned = start * Rotation.from_rotvec([0.0, 0.0, angle])
    achieved = _goal(position, start)
    desired = _goal(position + distance * direction / np.linalg.norm(direction), turned)
    return achieved, desired


@pytest.mark.parametrize(
    ("distance", "angle", "k", "kr"),
    [(0.05, 0.3, 1.0, 1.0), (0.002, 0.01, 10.0, 20.0), (0.0005, 0.1, 20.0, 2.0), (0.01, 0.5, 2.0, 1.0)],
)
def test_errors_below_the_zoom_are_shown_magnified_in_the_same_direction(distance, angle, k, kr):
    rng = np.random.default_rng(3)
    zoom = GoalZoom(position=0.02, angle=0.2, max_factor=20.0)
    achieved, desired = _pair(distance, angle, rng)
    fk, fkr, shown = zoom.factors(achieved, desired)
    assert (fk, fkr) == pytest.approx((k, kr))
    pos, ang = goal_errors(achieved, shown)  # oracle: the env's own error measure
    assert float(pos) == pytest.approx(k * distance, rel=1e-6)
    assert float(ang) == pytest.approx(kr * angle, rel=1e-5)
    np.testing.assert_allclose(shown[:3] - achieved[:3], k * (desired[:3] - achieved[:3]), atol=1e-12)
    if k == 1.0 and kr == 1.0:
        np.testing.assert_allclose(shown, desired, atol=1e-9)  # far from the goal nothing changes


def test_the_action_is_scaled_back_and_zoomed_steps_are_counted():
    zoom = GoalZoom()
    np.testing.assert_allclose(zoom.act(np.ones(6), (10.0, 4.0)), [0.1, 0.1, 0.1, 0.25, 0.25, 0.25])
    near = _pair(0.001, 0.01, np.random.default_rng(0))
    far = _pair(0.1, 0.5, np.random.default_rng(1))
    for start, (achieved, desired) in zip([True, False, False], [near, far, near], strict=True):
        seen, _ = zoom.observe({"achieved_goal": achieved, "desired_goal": desired, "observation": np.zeros(3)}, start)
        assert set(seen) == {"achieved_goal", "desired_goal", "observation"}
    assert zoom.episode_metrics() == {"zoomed_steps": 2.0}
    zoom.observe({"achieved_goal": far[0], "desired_goal": far[1]}, True)
    assert zoom.episode_metrics() == {"zoomed_steps": 0.0}
    for bad in ({"position": 0.0}, {"angle": -1.0}, {"max_factor": 0.5}):
        with pytest.raises(ValueError, match="GoalZoom needs"):
            GoalZoom(**bad)


def test_the_zoom_lets_the_vine_policy_cut_to_a_millimetre_where_it_stopped_short():
    kw = {"min_clusters": 2, "max_clusters": 5, "feasible_scenes": False, "position_tolerance": 0.001}
    kw |= {"orientation_tolerance": 0.01, **policy_spec("sac-her-grape-vine-shielded").env_kwargs}
    env = gym.make("agri_envs/GrapeHarvest-v1", **kw)
    plain = run_episode(env, make_policy("sac-her-grape-vine-shielded", env), 20000, None)["record"]
    zoomed = run_episode(env, make_policy("sac-her-grape-vine-shielded-zoom", env), 20000, None)["record"]
    assert not plain["is_success"] and plain["truncated"] and plain["harvested"] == 0  # stops 3 mm short of the first
    assert zoomed["is_success"] and not zoomed["collision"] and zoomed["zoomed_steps"] > 0


def test_a_zoom_on_an_env_without_goals_is_refused():
    from agri_training.learned.policy import LearnedPolicy
    from agri_training.learned.zoo import zoo_path

    env = gym.make("agri_envs/GreenhouseCoverage-v2", localization="ground_truth", route_observation=True)
    with pytest.raises(ValueError, match="observes achieved_goal and desired_goal"):
        LearnedPolicy(zoo_path("dagger-greenhouse-coverage-half-circle"), env, goal_zoom=GoalZoom())
