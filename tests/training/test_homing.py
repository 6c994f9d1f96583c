"""Joint homing: the last stretch home along the joint line, where the clamp's straight line stalls at a limit."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs  # noqa: F401  (registers the envs)
from agri_baselines import make_policy, policy_spec
from agri_envs.arm.grape_harvest import end_effector_step
from agri_envs.arm.kinematics import JOINT_LIMITS
from agri_envs.arm.robot_model import goal_vector, tip_pose
from agri_envs.arm.scene import HOME_Q
from agri_training.evaluation.episode import run_episode
from agri_training.learned import zoo  # noqa: F401  (registers the shipped policies)
from agri_training.learned.homing import HOME_GOAL, JointHoming

_STEPS = (0.04, 0.2)  # the shipped arm policies' max_ee_step and max_ee_rotation


def _observation(q, desired=HOME_GOAL):
    """The parts of a GrapeHarvest observation the rule reads, for joints ``q``."""
    lo, hi = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
    pose = tip_pose(q)
    joints = np.zeros(20, np.float32)
    joints[:6] = 2.0 * (q - lo) / (hi - lo) - 1.0
    return {
        "observation": joints,
        "achieved_goal": goal_vector(pose[:3, 3], pose[:3, :3]).astype(np.float32),
        "desired_goal": np.asarray(desired, np.float32),
    }


def _near_home(rng, size=0.012):
    """Joints near home's, joint 2 (at its lower limit at home) pushed inside its range."""
    offset = rng.uniform(-size, size, 6)
    offset[1] = abs(offset[1])
    return HOME_Q + offset


@pytest.mark.parametrize("seed", range(8))
def test_the_arm_follows_the_joint_line_home_in_a_few_steps(seed):
    homing = JointHoming(*_STEPS)
    q = _near_home(np.random.default_rng(seed))
    assert homing.applies(_observation(q))
    for step in range(5):
        action = homing.action(_observation(q))
        assert np.all(np.abs(action) <= 1.0)
        moved = end_effector_step(q, action, *_STEPS)[0]  # oracle: the env's own IK
        line, went = HOME_Q - q, moved - q
        assert np.linalg.norm(HOME_Q - moved) < np.linalg.norm(line) or np.linalg.norm(line) < 1e-5
        if step > 0 and np.linalg.norm(line) > 1e-5:  # the first step may lock joint 2 at its limit
            assert np.linalg.norm(HOME_Q - moved) < 0.5 * np.linalg.norm(line)
            assert float(line @ went) / (np.linalg.norm(line) * np.linalg.norm(went)) > 0.99
        q = moved
    home = tip_pose(HOME_Q)
    assert np.linalg.norm(tip_pose(q)[:3, 3] - home[:3, 3]) < 1e-5  # 0.01 mm
    np.testing.assert_allclose(q, HOME_Q, atol=1e-5)


def test_a_long_line_is_cut_to_one_step():
    homing = JointHoming(*_STEPS)
    q = HOME_Q + np.array([0.3, 0.4, -0.3, 0.2, 0.3, -0.2])
    action = homing.action(_observation(q))
    assert float(np.max(np.abs(action))) == pytest.approx(1.0, abs=1e-6)
    line, went = HOME_Q - q, end_effector_step(q, action, *_STEPS)[0] - q
    assert float(line @ went) / (np.linalg.norm(line) * np.linalg.norm(went)) > 0.99  # a part of the line, not clipped


def test_it_acts_only_near_home_on_home_s_branch_with_home_as_goal():
    homing = JointHoming(*_STEPS)
    q = _near_home(np.random.default_rng(0), size=0.002)
    assert homing.applies(_observation(q))
    cut = HOME_GOAL.copy()
    cut[0] += 0.001  # a cut 1 mm beside home is not home
    assert not homing.applies(_observation(q, desired=cut))
    assert not homing.applies(_observation(HOME_Q + np.array([0.0, 0.2, 0.0, 0.0, 0.0, 0.0])))  # beyond 2 cm
    other_branch = q.copy()
    other_branch[5] -= 2 * np.pi  # the same clamp pose, a turn of the last joint away
    assert np.linalg.norm(tip_pose(other_branch)[:3, 3] - tip_pose(q)[:3, 3]) < 1e-9
    assert not homing.applies(_observation(other_branch))


def test_it_counts_its_steps_and_leaves_other_actions_alone():
    homing = JointHoming(*_STEPS)
    near, far = _observation(_near_home(np.random.default_rng(1))), _observation(HOME_Q + 0.3)
    network = np.full(6, 0.5, np.float32)
    assert np.array_equal(homing.decide(far, network, True), network)
    assert not np.array_equal(homing.decide(near, network, False), network)
    homing.decide(near, network, False)
    assert homing.episode_metrics() == {"homing_steps": 2.0}
    homing.decide(far, network, True)
    assert homing.episode_metrics() == {"homing_steps": 0.0}


def test_bad_arguments_and_joint_control_are_refused():
    for bad in ({"position": 0.0}, {"max_joint_offset": -1.0}, {"max_ee_step": 0.0}):
        with pytest.raises(ValueError, match="JointHoming needs"):
            JointHoming(**{"max_ee_step": 0.04, "max_ee_rotation": 0.2, **bad})
    with pytest.raises(ValueError, match="control='ee'"):
        JointHoming.for_env(gym.make("agri_envs/GrapeHarvest-v1", control="joint"))


def test_homing_brings_the_zoomed_vine_policy_home_where_it_stalled_at_joint_2_s_limit():
    kw = {"min_clusters": 2, "max_clusters": 5, "feasible_scenes": False, "position_tolerance": 0.005}
    kw |= {"orientation_tolerance": 0.1, **policy_spec("sac-her-grape-vine-shielded").env_kwargs}
    env = gym.make("agri_envs/GrapeHarvest-v1", **kw)
    zoomed = run_episode(env, make_policy("sac-her-grape-vine-shielded-zoom", env), 20048, None)["record"]
    homed = run_episode(env, make_policy("sac-her-grape-vine-shielded-zoom-homing", env), 20048, None)["record"]
    assert zoomed["truncated"] and zoomed["harvested"] == zoomed["n_clusters"]  # every cut, then 7.8 mm from home
    assert homed["is_success"] and not homed["collision"] and 0 < homed["homing_steps"] < 10
    assert homed["harvested"] == zoomed["harvested"]


def test_homing_on_an_env_without_goals_is_refused():
    from agri_training.learned.policy import LearnedPolicy
    from agri_training.learned.zoo import zoo_path

    env = gym.make("agri_envs/GreenhouseCoverage-v2", localization="ground_truth", route_observation=True)
    with pytest.raises(ValueError, match="observes achieved_goal and desired_goal"):
        LearnedPolicy(zoo_path("dagger-greenhouse-coverage-half-circle"), env, homing=True)
