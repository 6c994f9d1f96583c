"""Kinematics of Luo et al.'s 6-DOF harvesting arm (Luo 2018, sec. 2.1): modified D-H model, analytic IK.

Pure numpy (no pybullet, no Gymnasium), in metres and radians. Frames follow Craig's modified
Denavit-Hartenberg convention (eq. 1): ``T_{i-1,i} = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(theta_i)
TransZ(d_i)``. Frames 4, 5 and 6 share one origin (a_4 = a_5 = d_5 = d_6 = 0), so the flange origin is
the wrist centre and the IK decouples into position (joints 1-3) and orientation (joints 4-6).

Reading of Table 1 (see ``shared/papers/README.md``): the table prints a_1 = 155 mm and a_3 = 155 mm, but
the paper's worked example (eq. 5, from its Matlab model) gives p_x = c_1 (a_1 + a_3 + a_2 c_2) = 217.5 mm
at q = (pi/3, -pi/3, pi/3, pi/6, pi/2, pi/4), which needs a_1 + a_3 = 255 mm. We keep a_1 = 155 mm (the
shoulder offset, printed with its own row) and change a_3 to 100 mm; with that, the table's twists,
a_2 = 360 mm and d_4 = 365 mm reproduce every entry of eq. 5 (the rotation part does not depend on the
lengths). The structure is Craig's PUMA 560 with d_3 = 0 plus a shoulder offset a_1.
"""

from __future__ import annotations

import math

import numpy as np

#: Link lengths and offset (m), Table 1 with a_3 = 100 mm (see the module docstring).
A1, A2, A3, D4 = 0.155, 0.360, 0.100, 0.365

#: Modified D-H table, one row per joint: (alpha_{i-1} [rad], a_{i-1} [m], d_i [m]); theta_i is the joint.
DH_TABLE = np.array(
    [
        [0.0, 0.0, 0.0],
        [-math.pi / 2, A1, 0.0],
        [0.0, A2, 0.0],
        [-math.pi / 2, A3, D4],
        [math.pi / 2, 0.0, 0.0],
        [-math.pi / 2, 0.0, 0.0],
    ]
)

#: Joint ranges (rad), Table 1: rows are joints 1..6, columns (low, high).
JOINT_LIMITS = np.radians(
    np.array([[-170.0, 170.0], [-60.0, 150.0], [-170.0, 75.0], [-190.0, 190.0], [-125.0, 125.0], [-360.0, 360.0]])
)

#: The worked example of eq. 5 (rad).
EQ5_Q = np.array([math.pi / 3, -math.pi / 3, math.pi / 3, math.pi / 6, math.pi / 2, math.pi / 4])

_LIMIT_EPS = 1e-9  # joint values this close outside a range count as inside (IK round-off at the limits)


_ALPHA_COS = np.round(np.cos(DH_TABLE[:, 0]), 15)  # exact zeros for the +-90 deg twists
_ALPHA_SIN = np.sin(DH_TABLE[:, 0])


def dh_transforms(q: np.ndarray) -> np.ndarray:
    """Eq. 1 for every joint of a batch: ``out[n, i]`` is ``T_{i, i+1}`` at ``q[n, i]``, shape (N, 6, 4, 4)."""
    c, s = np.cos(q), np.sin(q)
    ca, sa = _ALPHA_COS, _ALPHA_SIN
    a, d = DH_TABLE[:, 1], DH_TABLE[:, 2]
    out = np.zeros(q.shape[:-1] + (6, 4, 4))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 3] = c, -s, a
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2], out[..., 1, 3] = s * ca, c * ca, -sa, -d * sa
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2], out[..., 2, 3] = s * sa, c * sa, ca, d * ca
    out[..., 3, 3] = 1.0
    return out


def link_frames(q: np.ndarray) -> np.ndarray:
    """Base-to-link transforms of frames 1..6 (eq. 2's partial products).

    Args:
        q: Joint values, shape (6,) or (N, 6) (rad).

    Returns:
        Shape (6, 4, 4) or (N, 6, 4, 4): ``out[..., i, :, :]`` is the pose of frame ``i + 1`` in frame 0.
    """
    qa = np.asarray(q, dtype=np.float64)
    frames = dh_transforms(qa.reshape(-1, 6))
    for i in range(1, 6):
        frames[:, i] = frames[:, i - 1] @ frames[:, i]
    return frames[0] if qa.ndim == 1 else frames


def forward_kinematics(q: np.ndarray) -> np.ndarray:
    """Base-to-flange transform (eq. 2) in metres.

    Args:
        q: Joint values, shape (6,) or (N, 6) (rad).

    Returns:
        The 4x4 homogeneous transform of frame 6 in frame 0, shape (4, 4) or (N, 4, 4).
    """
    return link_frames(q)[..., 5, :, :]


def within_limits(q: np.ndarray, eps: float = _LIMIT_EPS) -> np.ndarray:
    """Whether joint values (shape (..., 6)) lie inside the joint ranges of Table 1."""
    qa = np.asarray(q)
    return np.all((qa >= JOINT_LIMITS[:, 0] - eps) & (qa <= JOINT_LIMITS[:, 1] + eps), axis=-1)


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + np.pi) % (2 * np.pi) - np.pi


def _representative(theta: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The 2 pi-equivalent of ``theta`` nearest ``ref``, moved into the joint range when one exists there.

    Joints 4 and 6 have ranges wider than a turn (Table 1), so one configuration has several in-range
    values; the one nearest the reference is returned. Out-of-range results stay out (and are dropped).
    """
    near = ref + _wrap(theta - ref)
    low, high = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
    near = np.where(near > high + _LIMIT_EPS, near - 2 * np.pi, near)
    near = np.where(near < low - _LIMIT_EPS, near + 2 * np.pi, near)
    return near


def ik_branches(poses: np.ndarray, q_ref: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All 8 analytic branches of the IK (eq. 4, completed) for a batch of flange poses.

    Branches are (shoulder: theta_1 or theta_1 + pi) x (elbow: the +- root of eq. 4's theta_3) x (wrist:
    theta_5 or -theta_5 with theta_4, theta_6 turned by pi). Eq. 4 prints one branch of each; the others
    follow from the same equations with the other root.

    Args:
        poses: Flange poses in frame 0, shape (N, 4, 4).
        q_ref: Reference joint values, shape (N, 6) or (6,): picks the 2 pi-representative of each angle and
            the free angles at singularities (shoulder over the base axis, theta_5 = 0). Defaults to zeros.

    Returns:
        ``(q, valid)`` of shapes (N, 8, 6) and (N, 8): joint values and whether the branch exists (the
        wrist centre is reachable) and lies inside the joint ranges.
    """
    poses = np.asarray(poses, dtype=np.float64)
    n = poses.shape[0]
    ref = np.zeros((n, 6)) if q_ref is None else np.broadcast_to(np.asarray(q_ref, dtype=np.float64), (n, 6))
    px, py, pz = poses[:, 0, 3], poses[:, 1, 3], poses[:, 2, 3]
    rot = poses[:, :3, :3]
    # theta_1 (eq. 4): the wrist centre lies in the arm plane; facing it, or facing away (+pi).
    r_xy = np.hypot(px, py)
    base = np.where(r_xy > 1e-12, np.arctan2(py, px), ref[:, 0])
    t1 = np.stack([base, base + np.pi], axis=1)  # (N, 2)
    c1, s1 = np.cos(t1), np.sin(t1)
    u = c1 * px[:, None] + s1 * py[:, None] - A1  # horizontal reach beyond the shoulder offset, (N, 2)
    w = np.broadcast_to(pz[:, None], u.shape)
    # theta_3 (eq. 4): a_3 c_3 - d_4 s_3 = k with k as printed (a_1 terms folded into u).
    k = (u * u + w * w - A2 * A2 - A3 * A3 - D4 * D4) / (2 * A2)
    rr = A3 * A3 + D4 * D4
    disc = rr - k * k
    reach_ok = disc >= -1e-12
    root = np.sqrt(np.maximum(disc, 0.0))
    t3 = math.atan2(A3, D4) - np.arctan2(k[:, :, None], np.stack([root, -root], axis=2))  # (N, 2, 2)
    c3, s3 = np.cos(t3), np.sin(t3)
    # theta_2: [u, w] = [[A, -B], [-B, -A]] [c_2, s_2] with A = a_2 + a_3 c_3 - d_4 s_3, B = a_3 s_3 + d_4 c_3.
    big_a = A2 + A3 * c3 - D4 * s3
    big_b = A3 * s3 + D4 * c3
    uu, ww = u[:, :, None], w[:, :, None]
    t2 = np.arctan2(-big_b * uu - big_a * ww, big_a * uu - big_b * ww)
    # Wrist: N = RotX(90) R_03^T R_06 = Rz(theta_4) Ry(-theta_5) Rz(theta_6) (ZYZ Euler angles).
    t23 = t2 + t3
    c1b, s1b = np.cos(t1)[:, :, None], np.sin(t1)[:, :, None]
    c23, s23 = np.cos(t23), np.sin(t23)
    # R_03 = Rz(theta_1) RotX(-90) Rz(theta_2 + theta_3); its columns, written out:
    r03 = np.empty((n, 2, 2, 3, 3))
    r03[..., 0, 0], r03[..., 0, 1], r03[..., 0, 2] = c1b * c23, -c1b * s23, -s1b
    r03[..., 1, 0], r03[..., 1, 1], r03[..., 1, 2] = s1b * c23, -s1b * s23, c1b
    r03[..., 2, 0], r03[..., 2, 1], r03[..., 2, 2] = -s23, -c23, 0.0
    m = np.swapaxes(r03, -1, -2) @ rot[:, None, None]  # R_03^T R_06
    # Left-multiplying by RotX(90) maps the rows (r1, r2, r3) of M to (r1, -r3, r2).
    n11, n13, n21, n23 = m[..., 0, 0], m[..., 0, 2], -m[..., 2, 0], -m[..., 2, 2]
    n31, n32, n33 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    s5 = np.sqrt(np.maximum(n13 * n13 + n23 * n23, 0.0))
    t5 = np.arctan2(s5, n33)
    singular = s5 < 1e-10
    ref4 = ref[:, 3][:, None, None]
    t4 = np.where(singular, ref4, np.arctan2(-n23, -n13))
    t6 = np.where(singular, np.arctan2(n21, n11) - ref4, np.arctan2(-n32, n31))
    # Flipped wrist: (theta_4 + pi, -theta_5, theta_6 + pi).
    q = np.empty((n, 2, 2, 2, 6))
    q[..., 0] = t1[:, :, None, None]
    q[..., 1] = t2[..., None]
    q[..., 2] = t3[..., None]
    q[..., 0, 3], q[..., 0, 4], q[..., 0, 5] = t4, t5, t6
    q[..., 1, 3], q[..., 1, 4], q[..., 1, 5] = t4 + np.pi, -t5, t6 + np.pi
    sols = _representative(q.reshape(n, 8, 6), ref[:, None, :])
    valid = np.repeat(reach_ok, 4, axis=1) & within_limits(sols)
    return sols, valid


def inverse_kinematics(pose: np.ndarray, q_ref: np.ndarray | None = None, tol: float = 1e-9) -> np.ndarray:
    """Every analytic IK solution of a flange pose that lies inside the joint ranges.

    Args:
        pose: Base-to-flange transform (4, 4), metres.
        q_ref: Reference configuration (6,): chooses the 2 pi-representative of joints 4 and 6 (whose ranges
            exceed a turn) and the free angles at singular poses. Defaults to zeros (principal values).
        tol: Solutions closer than this (rad, max norm) to an earlier one are dropped as duplicates.

    Returns:
        Array of shape (k, 6), 0 <= k <= 8; empty when the pose is out of reach or every branch violates a
        joint range.
    """
    q, valid = ik_branches(np.asarray(pose, dtype=np.float64)[None], q_ref)
    sols: list[np.ndarray] = []
    for cand in q[0][valid[0]]:
        if all(np.max(np.abs(cand - s)) > tol for s in sols):
            sols.append(cand)
    return np.array(sols).reshape(-1, 6)


def nearest_ik(pose: np.ndarray, q_current: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray | None:
    """The IK solution nearest ``q_current`` (weighted max-abs joint change), or None when unreachable."""
    q, valid = ik_branches(np.asarray(pose, dtype=np.float64)[None], q_current)
    if not valid[0].any():
        return None
    w = np.ones(6) if weights is None else weights
    cost = np.max(np.abs(q[0] - q_current) * w, axis=1)
    cost[~valid[0]] = np.inf
    return q[0, int(np.argmin(cost))]
