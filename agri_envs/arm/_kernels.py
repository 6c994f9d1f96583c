"""Fast, certified decisions for the scene sampler (numba): IK reachability, arm-box collisions, corridors.

The scene sampler (:mod:`agri_envs.arm.scene`) rejects most of the clusters and leaves it draws, and each
rejection used to cost numpy calls on 3-vectors and 4x4 matrices (analytic IK, eq. 7's point test). The
kernels here compute the same quantities in compiled scalar code and return, with every yes/no answer,
whether it is *certain*: every comparison that decided it cleared its threshold by more than :data:`TOL`,
and no ill-conditioned step (a wrist or shoulder near its singularity, an IK branch on the edge of
reach) entered it. Their values differ from numpy's by rounding only (about 1e-15 m or rad: other
summation orders, fused multiply-adds, another libm), far below :data:`TOL`, so a certain answer is the
answer numpy's code gives. When an answer is not certain, the sampler asks numpy's code itself; the
scenes, and so the episodes, stay bit for bit the same on any CPU.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from agri_envs.arm.kinematics import A1, A2, A3, D4, DH_TABLE, JOINT_LIMITS
from agri_envs.arm.robot_model import TOOL_LENGTH, point_set

#: A comparison is certain when its two sides differ by more than this (m or rad).
TOL = 1e-9
#: Below this, a singular value (wrist pitch, shoulder radius, IK discriminant) amplifies rounding too much:
#: the kernels answer UNCERTAIN (angle errors stay below 1e-16 / _WELL = 1e-12 rad elsewhere).
_WELL = 1e-4

CERTAIN_NO, CERTAIN_YES, UNCERTAIN = 0, 1, -1

_LOW = np.ascontiguousarray(JOINT_LIMITS[:, 0])
_HIGH = np.ascontiguousarray(JOINT_LIMITS[:, 1])
_ALPHA_COS = np.round(np.cos(DH_TABLE[:, 0]), 15)
_ALPHA_SIN = np.sin(DH_TABLE[:, 0])
_DH_A = np.ascontiguousarray(DH_TABLE[:, 1])
_DH_D = np.ascontiguousarray(DH_TABLE[:, 2])
_POINTS = point_set(0.02)  # the scene checker's point set (ArmCollisionModel's default spacing)
_PT_FRAME = _POINTS.frame.astype(np.int64)
_PT_XYZ = np.ascontiguousarray(_POINTS.points[:, :3])
_PT_RADIUS = np.ascontiguousarray(_POINTS.radius)


@numba.njit(cache=True)
def _tool_pose(cut: np.ndarray, approach: np.ndarray, down: np.ndarray, offset: float) -> np.ndarray:
    """Flange pose (4x4) that puts the clamp centre ``offset`` back from the cut (scene.cut_pose, then the tool)."""
    n = math.sqrt(approach[0] ** 2 + approach[1] ** 2 + approach[2] ** 2)
    z = approach / n
    dz = down[0] * z[0] + down[1] * z[1] + down[2] * z[2]
    x = down - dz * z
    x = x / math.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2)
    y = np.array([z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]])
    t = np.eye(4)
    for r in range(3):
        t[r, 0], t[r, 1], t[r, 2] = x[r], y[r], z[r]
        t[r, 3] = cut[r] - offset * approach[r] - TOOL_LENGTH * z[r]
    return t


@numba.njit(cache=True)
def _wrap_certain(x: float) -> tuple[float, bool]:
    """kinematics._wrap, and whether ``x`` is clear of its jump."""
    m = (x + math.pi) % (2 * math.pi)
    return m - math.pi, min(m, 2 * math.pi - m) > TOL


@numba.njit(cache=True)
def nearest_ik(pose: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, int]:
    """kinematics.nearest_ik (all 8 branches of eq. 4, the valid one nearest ``ref``) with its certainty.

    Returns:
        ``(q, status)``: ``CERTAIN_YES`` with the joint values, ``CERTAIN_NO`` (no valid branch), or
        ``UNCERTAIN``.
    """
    px, py, pz = pose[0, 3], pose[1, 3], pose[2, 3]
    r_xy = math.hypot(px, py)
    if r_xy < _WELL:
        return np.zeros(6), UNCERTAIN
    base = math.atan2(py, px)
    eps = 1e-9  # kinematics._LIMIT_EPS
    best = np.zeros(6)
    best_cost, second_cost = np.inf, np.inf
    found = False
    for i1 in range(2):
        t1 = base + i1 * math.pi
        c1, s1 = math.cos(t1), math.sin(t1)
        u = c1 * px + s1 * py - A1
        w = pz
        k = (u * u + w * w - A2 * A2 - A3 * A3 - D4 * D4) / (2 * A2)
        disc = A3 * A3 + D4 * D4 - k * k
        if abs(disc + 1e-12) <= _WELL:
            return np.zeros(6), UNCERTAIN
        if disc < -1e-12:
            continue  # both elbows of this shoulder out of reach, certainly
        root = math.sqrt(max(disc, 0.0))
        for i3 in range(2):
            t3 = math.atan2(A3, D4) - math.atan2(k, root if i3 == 0 else -root)
            c3, s3 = math.cos(t3), math.sin(t3)
            big_a = A2 + A3 * c3 - D4 * s3
            big_b = A3 * s3 + D4 * c3
            ya, xa = -big_b * u - big_a * w, big_a * u - big_b * w
            if math.hypot(ya, xa) < _WELL:
                return np.zeros(6), UNCERTAIN
            t2 = math.atan2(ya, xa)
            t23 = t2 + t3
            c23, s23 = math.cos(t23), math.sin(t23)
            r03 = np.array([[c1 * c23, -c1 * s23, -s1], [s1 * c23, -s1 * s23, c1], [-s23, -c23, 0.0]])
            m = np.zeros((3, 3))  # R_03^T R_06
            for r in range(3):
                for cc in range(3):
                    m[r, cc] = r03[0, r] * pose[0, cc] + r03[1, r] * pose[1, cc] + r03[2, r] * pose[2, cc]
            n13, n23 = m[0, 2], -m[2, 2]
            n31, n32, n33 = m[1, 0], m[1, 1], m[1, 2]
            s5 = math.sqrt(max(n13 * n13 + n23 * n23, 0.0))
            if s5 < _WELL:
                return np.zeros(6), UNCERTAIN  # at or near the wrist singularity: numpy decides
            t5 = math.atan2(s5, n33)
            t4 = math.atan2(-n23, -n13)
            t6 = math.atan2(-n32, n31)
            for iw in range(2):
                q = np.array([t1, t2, t3, t4, t5, t6])
                if iw == 1:
                    q[3], q[4], q[5] = t4 + math.pi, -t5, t6 + math.pi
                valid = True
                for j in range(6):
                    wrapped, ok = _wrap_certain(q[j] - ref[j])
                    if not ok:
                        return np.zeros(6), UNCERTAIN
                    near = ref[j] + wrapped
                    hi, lo = _HIGH[j] + eps, _LOW[j] - eps
                    if abs(near - hi) <= TOL:
                        return np.zeros(6), UNCERTAIN
                    if near > hi:
                        near -= 2 * math.pi
                    if abs(near - lo) <= TOL:
                        return np.zeros(6), UNCERTAIN
                    if near < lo:
                        near += 2 * math.pi
                    if abs(near - lo) <= TOL or abs(near - hi) <= TOL:
                        return np.zeros(6), UNCERTAIN
                    if near < lo or near > hi:
                        valid = False
                    q[j] = near
                if not valid:
                    continue
                cost = 0.0
                for j in range(6):
                    cost = max(cost, abs(q[j] - ref[j]))
                if cost < best_cost:
                    second_cost, best_cost, best, found = best_cost, cost, q, True
                elif cost < second_cost:
                    second_cost = cost
    if not found:
        return np.zeros(6), CERTAIN_NO
    if second_cost - best_cost <= TOL:
        return best, UNCERTAIN  # two branches (nearly) tie: numpy's argmin decides
    return best, CERTAIN_YES


@numba.njit(cache=True)
def harvest_configurations(
    cut: np.ndarray,
    approach: np.ndarray,
    down: np.ndarray,
    home: np.ndarray,
    pre_cut: float,
    branch: float,
    margin: float,
) -> tuple[np.ndarray, np.ndarray, int]:
    """scene.harvest_configurations of one cluster, with its certainty: ``(pre, cut, status)``."""
    none = np.zeros(6)
    pre, st = nearest_ik(_tool_pose(cut, approach, down, pre_cut), home)
    if st != CERTAIN_YES:
        return none, none, st
    reach = 0.0
    for j in range(3):
        reach = max(reach, abs(pre[j] - home[j]))
    if abs(reach - branch) <= TOL:
        return none, none, UNCERTAIN
    if reach > branch:
        return none, none, CERTAIN_NO
    q, st = nearest_ik(_tool_pose(cut, approach, down, 0.0), pre)
    if st != CERTAIN_YES:
        return none, none, st
    jump = 0.0
    for j in range(6):
        jump = max(jump, abs(q[j] - pre[j]))
    if abs(jump - 0.8) <= TOL:
        return none, none, UNCERTAIN
    if jump > 0.8:
        return none, none, CERTAIN_NO
    inside = True
    for cfg in (pre, q):
        for j in range(6):
            d = min(cfg[j] - (_LOW[j] + margin), (_HIGH[j] - margin) - cfg[j])
            if abs(d) <= TOL:
                return none, none, UNCERTAIN
            if d < 0.0:
                inside = False
    if not inside:
        return none, none, CERTAIN_NO
    return pre, q, CERTAIN_YES


@numba.njit(cache=True)
def _link_frames(q: np.ndarray) -> np.ndarray:
    """kinematics.link_frames for one configuration: (6, 4, 4)."""
    frames = np.zeros((6, 4, 4))
    for i in range(6):
        c, s = math.cos(q[i]), math.sin(q[i])
        ca, sa, a, d = _ALPHA_COS[i], _ALPHA_SIN[i], _DH_A[i], _DH_D[i]
        t = np.zeros((4, 4))
        t[0, 0], t[0, 1], t[0, 3] = c, -s, a
        t[1, 0], t[1, 1], t[1, 2], t[1, 3] = s * ca, c * ca, -sa, -d * sa
        t[2, 0], t[2, 1], t[2, 2], t[2, 3] = s * sa, c * sa, ca, d * ca
        t[3, 3] = 1.0
        if i == 0:
            frames[i] = t
        else:
            for r in range(4):
                for cc in range(4):
                    frames[i, r, cc] = (
                        frames[i - 1, r, 0] * t[0, cc]
                        + frames[i - 1, r, 1] * t[1, cc]
                        + frames[i - 1, r, 2] * t[2, cc]
                        + frames[i - 1, r, 3] * t[3, cc]
                    )
    return frames


@numba.njit(cache=True)
def arm_points(q: np.ndarray) -> np.ndarray:
    """World coordinates (m, 3) of the checker's arm points (robot_model.PointSet.world) for one configuration."""
    frames = _link_frames(q)
    out = np.empty((len(_PT_FRAME), 3))
    for p in range(len(_PT_FRAME)):
        f = frames[_PT_FRAME[p]]
        for r in range(3):
            out[p, r] = f[r, 0] * _PT_XYZ[p, 0] + f[r, 1] * _PT_XYZ[p, 1] + f[r, 2] * _PT_XYZ[p, 2] + f[r, 3]
    return out


@numba.njit(cache=True)
def collides(points: np.ndarray, lo: np.ndarray, hi: np.ndarray, margin: float) -> int:
    """Whether arm points (k, m, 3) of k configurations touch any box (collision.ArmCollisionModel.collides().any()).

    A point is inside a box grown by its radius plus ``margin`` (eq. 6); certain when the decisive
    comparisons clear :data:`TOL`.
    """
    uncertain = False
    for c in range(points.shape[0]):
        for p in range(points.shape[1]):
            grow = _PT_RADIUS[p] + margin
            for b in range(lo.shape[0]):
                dmin = np.inf
                for k in range(3):
                    x = points[c, p, k]
                    dmin = min(dmin, x - (lo[b, k] - grow), (hi[b, k] + grow) - x)
                if dmin > TOL:
                    return CERTAIN_YES
                if dmin >= -TOL:
                    uncertain = True
    return UNCERTAIN if uncertain else CERTAIN_NO


@numba.njit(cache=True)
def corridor(cut: np.ndarray, approach: np.ndarray, down: np.ndarray, corners: np.ndarray, pre_cut: float, grow: float):
    """scene.corridor: the AABB swept by the tool box from the pre-cut pose to the cut (``corners`` (8, 3))."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for offset in (0.0, pre_cut):
        t = _tool_pose(cut, approach, down, offset)
        for r in range(3):  # back from the flange to the clamp centre
            t[r, 3] += TOOL_LENGTH * t[r, 2]
        for k in range(corners.shape[0]):
            for r in range(3):
                v = t[r, 0] * corners[k, 0] + t[r, 1] * corners[k, 1] + t[r, 2] * corners[k, 2] + t[r, 3]
                lo[r] = min(lo[r], v)
                hi[r] = max(hi[r], v)
    return lo - grow, hi + grow


@numba.njit(cache=True)
def overlap(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> int:
    """scene._overlap of two AABBs (``lo1 <= hi2`` and ``lo2 <= hi1`` on every axis), with its certainty."""
    dmin = np.inf
    for k in range(3):
        dmin = min(dmin, hi2[k] - lo1[k], hi1[k] - lo2[k])
    if abs(dmin) <= TOL:
        return UNCERTAIN
    return CERTAIN_YES if dmin >= 0.0 else CERTAIN_NO


@numba.njit(cache=True)
def cluster_box(cut: np.ndarray, draws: np.ndarray, gap: float, margin: float):
    """scene._build_cluster's approach, hanging axis and anti-collision box (lo, hi), up to rounding."""
    yaw = math.atan2(cut[1], cut[0]) + draws[0]
    approach = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    c, s = math.cos(draws[1]), math.sin(draws[1])
    down = np.array([-approach[1] * s, approach[0] * s, -c])  # (0, 0, -1) turned about the approach
    side = np.array(
        [
            down[1] * approach[2] - down[2] * approach[1],
            down[2] * approach[0] - down[0] * approach[2],
            down[0] * approach[1] - down[1] * approach[0],
        ]
    )
    length, radius, berry = draws[2], draws[3], 0.013
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for ring in range(5):
        level = 0.25 * ring
        ring_r = (radius - berry) * (1.0 - 0.7 * level)
        along = gap + berry + level * (length - 2 * berry)
        n = 5 - ring
        for k in range(n):
            ang = draws[4 + ring] + 2 * math.pi * k / n
            ca, sa = math.cos(ang), math.sin(ang)
            for r in range(3):
                v = cut[r] + along * down[r] + ring_r * (ca * approach[r] + sa * side[r])
                lo[r] = min(lo[r], v - berry)
                hi[r] = max(hi[r], v + berry)
    return approach, down, lo - margin, hi + margin


@numba.njit(cache=True)
def too_close(cut: np.ndarray, others: np.ndarray, limit: float) -> int:
    """Whether ``cut`` lies within ``limit`` of any row of ``others`` (k, 3), with its certainty."""
    uncertain = False
    for i in range(others.shape[0]):
        d = math.sqrt((cut[0] - others[i, 0]) ** 2 + (cut[1] - others[i, 1]) ** 2 + (cut[2] - others[i, 2]) ** 2)
        if d < limit - TOL:
            return CERTAIN_YES
        if d <= limit + TOL:
            uncertain = True
    return UNCERTAIN if uncertain else CERTAIN_NO
