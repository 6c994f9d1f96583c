"""Arm kinematics: eq. 5, IK round trips over random joints, pybullet's link poses, the URDF generator."""

import math

import numpy as np
import pytest

from agri_envs.arm.kinematics import (
    EQ5_Q,
    JOINT_LIMITS,
    forward_kinematics,
    inverse_kinematics,
    link_frames,
)
from agri_envs.arm.robot_model import URDF_PATH, tip_pose, urdf_text


def random_joints(rng, n):
    return rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], size=(n, 6))


def test_forward_kinematics_reproduces_eq5():
    t = forward_kinematics(EQ5_Q)
    r2, r6, r3 = math.sqrt(2) / 4, math.sqrt(6) / 4, math.sqrt(3) / 2
    exact = np.array(
        [
            [r2, r2, -r3, 0.2175],
            [-r6, -r6, -0.5, 0.435 * r3],
            [-math.sqrt(2) / 2, math.sqrt(2) / 2, 0.0, -0.365 + 0.36 * r3],
            [0, 0, 0, 1],
        ]
    )
    np.testing.assert_allclose(t, exact, atol=1e-6)
    printed = np.array(  # eq. 5 as printed (mm, 4 decimals)
        [[0.3536, 0.3536, -0.8660, 217.5], [-0.6124, -0.6124, -0.5, 376.7211], [-0.7071, 0.7071, 0.0, -53.2309]]
    )
    mm = t[:3].copy()
    mm[:, 3] *= 1000.0
    np.testing.assert_allclose(mm, printed, atol=6e-5)


def test_ik_of_eq5_contains_the_example():
    sols = inverse_kinematics(forward_kinematics(EQ5_Q))
    assert np.min(np.max(np.abs(sols - EQ5_Q), axis=1)) < 1e-9


def test_ik_round_trip_on_random_joints():
    rng = np.random.default_rng(0)
    counts = []
    for q in random_joints(rng, 1000):
        pose = forward_kinematics(q)
        sols = inverse_kinematics(pose, q_ref=q)
        counts.append(len(sols))
        assert len(sols) >= 1 and len(sols) <= 8
        assert np.min(np.max(np.abs(sols - q), axis=1)) < 1e-9, q
        back = forward_kinematics(sols)
        assert np.max(np.abs(back[:, :3, 3] - pose[:3, 3])) < 1e-9
        assert np.max(np.abs(back[:, :3, :3] - pose[:3, :3])) < 1e-9
        assert np.all(sols >= JOINT_LIMITS[:, 0] - 1e-9) and np.all(sols <= JOINT_LIMITS[:, 1] + 1e-9)
        # Without a reference, the input is found up to whole turns of the joints.
        plain = inverse_kinematics(pose)
        diff = np.angle(np.exp(1j * (plain - q)))
        assert np.min(np.max(np.abs(diff), axis=1)) < 1e-9
    assert 8 in counts  # all branches are found where the ranges allow them


def test_unreachable_pose_has_no_solution():
    pose = np.eye(4)
    pose[:3, 3] = [2.0, 0.0, 0.0]
    assert inverse_kinematics(pose).shape == (0, 6)


def test_batched_fk_matches_single():
    qs = random_joints(np.random.default_rng(1), 5)
    np.testing.assert_array_equal(link_frames(qs)[3], link_frames(qs[3]))


def test_shipped_urdf_is_generated_from_the_dh_table():
    assert URDF_PATH.read_text() == urdf_text()


def test_pybullet_link_poses_equal_forward_kinematics():
    pb = pytest.importorskip("pybullet")
    client = pb.connect(pb.DIRECT)
    try:
        robot = pb.loadURDF(str(URDF_PATH), useFixedBase=True, physicsClientId=client)
        for q in random_joints(np.random.default_rng(2), 50):
            for j in range(6):
                pb.resetJointState(robot, j, q[j], physicsClientId=client)
            states = pb.getLinkStates(robot, list(range(8)), computeForwardKinematics=1, physicsClientId=client)
            frames = link_frames(q)
            for j in range(6):
                rot = np.array(pb.getMatrixFromQuaternion(states[j][5])).reshape(3, 3)
                np.testing.assert_allclose(states[j][4], frames[j, :3, 3], atol=1e-6)
                np.testing.assert_allclose(rot, frames[j, :3, :3], atol=1e-6)
            np.testing.assert_allclose(states[7][4], tip_pose(q)[:3, 3], atol=1e-6)
    finally:
        pb.disconnect(physicsClientId=client)


def test_joint_ranges_are_table1_not_mirrored():
    """Table 1's ranges are asymmetric for joints 2 and 3: a mirrored table (low <-> -high) must fail."""
    from agri_envs.arm.kinematics import within_limits

    table1 = np.radians([[-170, 170], [-60, 150], [-170, 75], [-190, 190], [-125, 125], [-360, 360]])
    np.testing.assert_allclose(JOINT_LIMITS, table1)
    q = np.radians([0.0, 140.0, -160.0, 0.0, 0.0, 0.0])  # inside Table 1, outside its mirror image
    assert within_limits(q)
    assert not within_limits(np.radians([0.0, -140.0, 0.0, 0.0, 0.0, 0.0]))
    assert not within_limits(np.radians([0.0, 0.0, 160.0, 0.0, 0.0, 0.0]))
    # The joint-limit clip of the env acts on the same table: a step past 150 deg stops there.
    import gymnasium as gym

    import agri_envs  # noqa: F401

    env = gym.make("agri_envs/GrapeHarvest-v1", max_joint_step=0.5)
    env.reset(seed=0)
    for _ in range(12):
        env.step(np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0], dtype=np.float32))
    assert env.unwrapped.q[1] == pytest.approx(np.radians(150.0))
    env.close()
