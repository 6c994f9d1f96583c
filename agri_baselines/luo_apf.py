"""Luo et al. (2018): energy-optimal harvesting order (eq. 11) and APF sampling path points (Alg. 1).

:func:`harvest_order` picks the order of the clusters that minimises the weighted sum of joint rotations
of eq. 11 over the tour home -> clusters -> home, exactly (all n! orders, n <= 5 here). The joint values at
each cluster are the analytic IK solution at its cutting pose nearest the home configuration.

:func:`plan_harvest` then generates the path points of Alg. 1 cluster after cluster. From the clamp's
current position it samples ``n_samples`` points on a sphere of radius ``step`` around it, scores them
with the artificial potential field ``U = U_att + U_rep`` (eqs. 12-13, 15; the forces of eqs. 14 and 16
are its negative gradient, which the sampling follows), turns the scores into probabilities
``p ~ exp(-U / temperature)``, and takes the most probable sample whose configuration (analytic IK, the
solution nearest the current joints, eq. 4) keeps the whole arm clear of every box (the point-set test of
eqs. 6-9); when none is, it samples again. The orientation is interpolated (slerp) from the start
orientation to the cluster's along the way. Each harvest ends with a straight approach over the last
:data:`~agri_envs.arm.scene.PRE_CUT` metres along the cluster's approach axis (the clamp must come in from
the front, its pallet under the berries) and the same way back; the cut cluster's box leaves with it.
When Alg. 1 runs out of samples at a path point (a dead end), the planner backs out of that point and
samples again from the one before, at most ``max_backtracks`` times per segment; :attr:`Plan.fallbacks`
counts how often. The repulsion's rho and eta follow from the paper's two conditions on the field
(see :data:`RHO` and :data:`ETA`);
``luo-apf-attract-only`` is the ablation without it.

:class:`LuoApfPolicy` is the thin SB3-style adapter: it reads the cutting points and boxes from the
GrapeHarvest-v1 observation (what the paper's vision system supplies), plans once per episode and
follows the joint waypoints through joint-delta actions. The planner itself imports no Gymnasium.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from typing import Any

import numpy as np

from agri_envs.arm.collision import ArmCollisionModel, box_distance
from agri_envs.arm.kinematics import JOINT_LIMITS, ik_branches
from agri_envs.arm.robot_model import TOOL_HALF_Y, TOOL_LENGTH, flange_pose_for_tip, tip_pose
from agri_envs.arm.scene import PRE_CUT, cut_pose

#: Weights omega_i of eq. 11. The paper weighs each joint by its motor's power without giving numbers; we
#: take the rated powers of a 6-axis arm of this size (400, 400, 200, 100, 100, 50 W) as shares of the total.
JOINT_WEIGHTS = np.array([400.0, 400.0, 200.0, 100.0, 100.0, 50.0]) / 1250.0


#: Distance (m) at which the tool's side reaches a box when the clamp centre is that far from it: the
#: jaw half-opening TOOL_HALF_Y (3.5 cm), the widest part of the tool around the clamp centre.
TOOL_REACH = TOOL_HALF_Y
#: Farthest distance (m) from the clamp to its goal in the workspace (home to the farthest pre-cut pose).
GOAL_REACH = 0.6
#: rho of eq. 15 (m): the tool's length. Eqs. 12-16 act on one point, the clamp centre X, but what must
#: keep clear of a box is the whole tool, which reaches TOOL_LENGTH (15 cm) behind X toward the wrist:
#: a box within that range of X can meet the tool, so that is the range over which it must repel
#: ("the maximum range of the impact of the obstacle", and the paper's own remedy for its one failure,
#: a larger safety margin between the end-effector and the cluster). The paper's first condition
#: (U_sum = 0 and minimal at the goal) then holds for every box but the goal's own cluster, whose box is
#: 5-7 cm from the pre-cut goal: it moves the field's minimum outward along the approach. Alg. 1 still
#: ends at the goal, because it stops sampling within one step of X_g and places X_g itself.
#: (rho = 5 cm, the largest range that keeps condition 1 for every box, leaves every chosen path point
#: outside every range: the repulsion then changes nothing, as the audit of issue 12 found.)
RHO = TOOL_LENGTH
#: eta of eq. 15. The paper's second condition: the system must be stable, the clamp never pulled into a
#: box. With eq. 14 and eq. 16, the repulsion at TOOL_REACH from a box (the tool's side touching it)
#: equals the strongest attraction the clamp ever feels, k * GOAL_REACH (k = 1):
#: eta (1/d - 1/rho) / d^2 = k D  =>  eta = k D d^2 / (1/d - 1/rho), about 3.4e-5.
ETA = 1.0 * GOAL_REACH * TOOL_REACH**2 / (1.0 / TOOL_REACH - 1.0 / RHO)


@dataclasses.dataclass(frozen=True)
class LuoApfParams:
    """Parameters of Alg. 1 (the paper tunes them "repeatedly" without giving values; these are ours).

    Attributes:
        step: Radius of the sampling neighbourhood, i.e. the distance between path points (m).
        n_samples: Samples drawn per neighbourhood.
        k_att: Attractive gain k of eq. 13 (1/m^2 scale of U).
        eta: Repulsive gain eta of eq. 15 (0: the attract-only ablation); see :data:`ETA`.
        rho: Influence range rho of an obstacle in eq. 15 (m); see :data:`RHO`.
        temperature: Temperature of the sample probabilities ``exp(-U / T)``.
        max_resample: Neighbourhoods drawn at one path point before it counts as a dead end.
        max_backtracks: Dead ends per segment the planner backs out of (the fallback: drop the last path
            point and sample again from the one before) before it gives up.
        max_points: Path points per segment before the planner gives up.
        max_joint_jump: Largest joint change between consecutive path points (rad): a larger one would
            switch IK branch and sweep the arm through unchecked space.
        max_rotation: Largest change of the clamp's orientation between consecutive path points (rad).
        margin: Clearance added around every box in the collision test (m).
        spacing: d_min of eq. 7, the spacing of the arm's point set (m).
    """

    step: float = 0.03
    n_samples: int = 12
    k_att: float = 1.0
    eta: float = ETA
    rho: float = RHO
    temperature: float = 1e-4
    max_resample: int = 8
    max_backtracks: int = 10
    max_points: int = 200
    max_joint_jump: float = 0.35
    max_rotation: float = 0.2
    margin: float = 0.004
    spacing: float = 0.02


@dataclasses.dataclass(frozen=True)
class ClusterTarget:
    """What the planner knows of a cluster: its cutting pose and its box."""

    cut_point: np.ndarray
    approach: np.ndarray
    down: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray

    def tip_pose(self, offset: float = 0.0) -> np.ndarray:
        """Clamp pose at the cut, or ``offset`` metres back along the approach."""
        return cut_pose(self.cut_point, self.approach, self.down, offset)


@dataclasses.dataclass
class Plan:
    """A full harvesting plan.

    Attributes:
        order: Cluster indices in harvesting order.
        points: Clamp-centre path points (K, 3) in the base frame (m), start included.
        waypoints: Joint values (K, 6) at the path points (rad).
        cuts: Index into ``points`` of each cut, in harvesting order.
        success: Whether every segment was planned.
        planning_time: Wall time of the whole plan (s).
        energy: Value of eq. 11's objective for ``order``.
        min_box_clearance: Smallest distance (m) from the clamp centre at any path point Alg. 1 chose to
            any box still in the scene (inf when there is none). The poses the task fixes are left out:
            the segments' goals (pre-cut poses, 5-7 cm from their own box, and home) and the straight
            approaches to the cuts (the cut is 5 cm above its box). They are the same for every planner
            and would hide what eq. 15 does.
        fallbacks: How often the dead-end fallback (backtracking) fired.
    """

    order: tuple[int, ...]
    points: np.ndarray
    waypoints: np.ndarray
    cuts: list[int]
    success: bool
    planning_time: float
    energy: float
    min_box_clearance: float = math.inf
    fallbacks: int = 0

    @property
    def path_length(self) -> float:
        """Eq. 17: length of the polyline through the path points (m)."""
        return float(np.sum(np.linalg.norm(np.diff(self.points, axis=0), axis=1)))


def order_cost(q_home: np.ndarray, q_clusters: np.ndarray, order: tuple[int, ...]) -> float:
    """Eq. 11 for one order: sum over joints of omega_i times the joint's total rotation on the tour."""
    tour = np.vstack([q_home, q_clusters[list(order)], q_home])
    return float(np.sum(JOINT_WEIGHTS * np.abs(np.diff(tour, axis=0))))


def harvest_order(q_home: np.ndarray, q_clusters: np.ndarray) -> tuple[tuple[int, ...], float]:
    """The order minimising eq. 11, searched over every permutation (ties: the first in lexicographic order).

    Args:
        q_home: Home configuration (6,).
        q_clusters: Configuration at each cluster's cut, shape (n, 6).

    Returns:
        ``(order, cost)``.
    """
    n = len(q_clusters)
    if n == 0:
        return (), 0.0
    nodes = np.vstack([q_home, q_clusters])
    pair = np.sum(JOINT_WEIGHTS * np.abs(nodes[:, None, :] - nodes[None, :, :]), axis=-1)  # (n+1, n+1)
    perms = np.array(list(itertools.permutations(range(1, n + 1))))
    cost = pair[0, perms[:, 0]] + pair[perms[:, -1], 0]
    if n > 1:
        cost += np.sum(pair[perms[:, :-1], perms[:, 1:]], axis=1)
    best = int(np.argmin(cost))
    return tuple(int(i) - 1 for i in perms[best]), float(cost[best])


def _log_rotation(r: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix."""
    cos = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    angle = math.acos(cos)
    if angle < 1e-9:
        return np.zeros(3)
    if math.pi - angle < 1e-6:  # half turn: the axis from the symmetric part
        axis = np.sqrt(np.maximum((np.diag(r) + 1.0) / 2.0, 0.0))
        k = int(np.argmax(axis))
        axis[[i for i in range(3) if i != k]] *= np.sign(r[k, [i for i in range(3) if i != k]] + 1e-300)
        return angle * axis / np.linalg.norm(axis)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return angle * w / (2.0 * math.sin(angle))


def _exp_rotations(vecs: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (N, 3): shape (N, 3, 3)."""
    angle = np.linalg.norm(vecs, axis=1)
    k = vecs / np.maximum(angle, 1e-12)[:, None]
    kx = np.zeros((len(vecs), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx[:, 1, 0], kx[:, 2, 0], kx[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * kx + (1.0 - c) * kx @ kx


class ApfPlanner:
    """Alg. 1 against a set of AABBs, with the arm's point-set collision test.

    Args:
        lo: Box minima (B, 3) (m).
        hi: Box maxima (B, 3) (m).
        rng: Random generator of the samples.
        params: Planner parameters.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, rng: np.random.Generator, params: LuoApfParams) -> None:
        self.p = params
        self.rng = rng
        self.model = ArmCollisionModel(lo, hi, margin=params.margin, spacing=params.spacing)
        self.fallbacks = 0

    def clearance(self, x: np.ndarray) -> float:
        """Smallest distance (m) from points (N, 3) to the current boxes (inf without boxes)."""
        if len(self.model.lo) == 0 or len(x) == 0:
            return math.inf
        return float(np.min(box_distance(np.asarray(x).reshape(-1, 3), self.model.lo, self.model.hi)))

    def set_boxes(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Replace the obstacle boxes (a harvested cluster's box leaves the scene)."""
        self.model.set_boxes(lo, hi)

    def potential(self, x: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """U_sum of eq. 12 at points (N, 3): eq. 13 plus eq. 15 summed over the boxes.

        ``X - X_0`` of eq. 15 is read as the distance from X to the nearest point of the obstacle's box.
        """
        p = self.p
        u = 0.5 * p.k_att * np.sum((x - goal) ** 2, axis=1)
        if len(self.model.lo):
            d = np.maximum(box_distance(x, self.model.lo, self.model.hi), 1e-4)
            near = d < p.rho
            u = u + np.sum(np.where(near, 0.5 * p.eta * (1.0 / d - 1.0 / p.rho) ** 2, 0.0), axis=1)
        return u

    def reachable(self, poses: np.ndarray, q_current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest IK solutions to ``q_current`` of clamp poses (N, 4, 4), and which are reachable.

        Reachable: an analytic solution inside the joint ranges, with no joint changing by more than
        ``max_joint_jump`` (a larger change is a switch of IK branch).
        """
        q, valid = ik_branches(flange_pose_for_tip(poses), q_current)
        jump = np.max(np.abs(q - q_current) * (1.0 + JOINT_WEIGHTS), axis=2)
        jump[~valid] = np.inf
        rows = np.arange(len(q))
        best = np.argmin(jump, axis=1)
        q_best = q[rows, best]
        ok = np.isfinite(jump[rows, best]) & (np.max(np.abs(q_best - q_current), axis=1) <= self.p.max_joint_jump)
        return q_best, ok

    def solve(self, poses: np.ndarray, q_current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`reachable`, and collision-free (eqs. 6-9) too."""
        q_best, ok = self.reachable(poses, q_current)
        if ok.any():
            idx = np.flatnonzero(ok)
            ok[idx] = ~self.model.collides(q_best[idx])
        return q_best, ok

    def segment(self, q: np.ndarray, goal: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
        """Path points and joint values from configuration ``q`` to the clamp pose ``goal`` (Alg. 1).

        Returns:
            ``(points, configurations)`` excluding the start and ending exactly at the goal, or None when
            no collision-free path point was found.
        """
        p = self.p
        q_start = q
        start = tip_pose(q)
        x, r0, rg, xg = start[:3, 3], start[:3, :3], goal[:3, :3], goal[:3, 3]
        total = max(float(np.linalg.norm(xg - x)), 1e-9)
        turn = _log_rotation(r0.T @ rg)
        angle = float(np.linalg.norm(turn))
        rot_step = 1.0 if angle < 1e-9 else p.max_rotation / angle  # orientation progress per path point
        frac = 0.0
        points: list[np.ndarray] = []
        configs: list[np.ndarray] = []
        fracs_done: list[float] = []
        backtracks = 0
        for _ in range(p.max_points):
            if np.linalg.norm(xg - x) <= p.step and frac + rot_step >= 1.0:
                q_goal, ok = self.solve(goal[None], q)
                if not ok[0]:
                    return None
                points.append(xg.copy())
                configs.append(q_goal[0])
                return points, configs
            for _attempt in range(p.max_resample):
                dirs = self.rng.normal(size=(p.n_samples, 3))
                samples = x + p.step * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
                u = self.potential(samples, xg)
                prob = np.exp(-(u - u.min()) / p.temperature)
                prob /= prob.sum()
                # Orientation: slerp by the distance covered, but by at most max_rotation per path point.
                progress = 1.0 - np.clip(np.linalg.norm(xg - samples, axis=1) / total, 0.0, 1.0)
                fracs = np.clip(progress, frac, min(1.0, frac + rot_step))
                poses = np.zeros((p.n_samples, 4, 4))
                poses[:, :3, :3] = r0 @ _exp_rotations(fracs[:, None] * turn)
                poses[:, :3, 3], poses[:, 3, 3] = samples, 1.0
                q_new, ok = self.reachable(poses, q)
                # The most probable reachable sample that keeps the arm clear; a colliding one is resampled.
                pick = next((int(k) for k in np.argsort(-prob) if ok[k] and not self.model.collides(q_new[k])[0]), -1)
                if pick >= 0:
                    x, q, frac = samples[pick], q_new[pick], float(fracs[pick])
                    points.append(x.copy())
                    configs.append(q.copy())
                    fracs_done.append(frac)
                    break
            else:
                # Dead end: Alg. 1 ran out of samples. Fallback: back out of the last path point and sample
                # again from the one before (fresh samples take another way), at most max_backtracks times.
                if backtracks >= p.max_backtracks or not points:
                    return None
                backtracks += 1
                self.fallbacks += 1
                points.pop()
                configs.pop()
                fracs_done.pop()
                if points:
                    x, q, frac = points[-1], configs[-1], fracs_done[-1]
                else:
                    x, q, frac = start[:3, 3], q_start, 0.0
        return None

    def straight(self, q: np.ndarray, target: ClusterTarget) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
        """Path points of the straight approach from the pre-cut pose to the cut (orientation fixed)."""
        n = max(1, math.ceil(PRE_CUT / self.p.step))
        poses = np.array([target.tip_pose(PRE_CUT * (1.0 - k / n)) for k in range(1, n + 1)])
        q_new, ok = self.solve(poses, q)  # one batch: the approach is short, the IK branch stays that of q
        steps = np.diff(np.vstack([q, q_new]), axis=0)
        if not ok.all() or np.max(np.abs(steps)) > self.p.max_joint_jump:
            return None
        return list(poses[:, :3, 3]), list(q_new)


def cut_configurations(q_home: np.ndarray, targets: list[ClusterTarget]) -> np.ndarray | None:
    """Joint values at each cluster's cut (IK nearest home, through its pre-cut pose), for eq. 11."""
    out = []
    for t in targets:
        pre, ok = ik_branches(flange_pose_for_tip(t.tip_pose(PRE_CUT))[None], q_home)
        if not ok[0].any():
            return None
        q_pre = pre[0][ok[0]][np.argmin(np.max(np.abs(pre[0][ok[0]] - q_home), axis=1))]
        cut, ok = ik_branches(flange_pose_for_tip(t.tip_pose())[None], q_pre)
        if not ok[0].any():
            return None
        out.append(cut[0][ok[0]][np.argmin(np.max(np.abs(cut[0][ok[0]] - q_pre), axis=1))])
    return np.array(out).reshape(-1, 6)


def plan_harvest(
    q_start: np.ndarray,
    targets: list[ClusterTarget],
    obstacles_lo: np.ndarray,
    obstacles_hi: np.ndarray,
    rng: np.random.Generator,
    params: LuoApfParams | None = None,
) -> Plan:
    """The full plan: eq. 11's order, then Alg. 1 to each cluster, the cut, and back home.

    Args:
        q_start: Start (and home) configuration (6,).
        targets: The clusters.
        obstacles_lo: Minima (B, 3) of the boxes other than the clusters' (stems, leaves).
        obstacles_hi: Maxima (B, 3) of those boxes.
        rng: Random generator of Alg. 1's samples.
        params: Planner parameters (defaults when None).
    """
    t0 = time.perf_counter()
    p = params or LuoApfParams()
    q_home = np.asarray(q_start, dtype=np.float64)
    q_cut = cut_configurations(q_home, targets)
    order, energy = harvest_order(q_home, q_cut) if q_cut is not None else (tuple(range(len(targets))), math.nan)
    left = list(range(len(targets)))

    def boxes() -> tuple[np.ndarray, np.ndarray]:
        lo = np.vstack([obstacles_lo.reshape(-1, 3)] + [targets[i].box_lo[None] for i in left])
        hi = np.vstack([obstacles_hi.reshape(-1, 3)] + [targets[i].box_hi[None] for i in left])
        return lo, hi

    planner = ApfPlanner(*boxes(), rng=rng, params=p)
    q = q_home.copy()
    points, configs, cuts = [tip_pose(q)[:3, 3]], [q.copy()], []
    success = True
    clearance = math.inf
    home_pose = tip_pose(q_home)
    for i in (*order, None):
        goal = home_pose if i is None else targets[i].tip_pose(PRE_CUT)
        seg = planner.segment(q, goal)
        if seg is not None:
            # The segment's last point is its goal (a pre-cut pose, or home): fixed by the task, not chosen.
            clearance = min(clearance, planner.clearance(np.array(seg[0][:-1])))
        if seg is not None and i is not None:
            approach = planner.straight(seg[1][-1], targets[i])
            seg = None if approach is None else (seg[0] + approach[0], seg[1] + approach[1])
        if seg is None:
            success = False
            break
        points += seg[0]
        configs += seg[1]
        if i is not None:  # cut, then back out the way the clamp came in, without the cut cluster's box
            n_in = math.ceil(PRE_CUT / p.step)
            cuts.append(len(points) - 1)
            points += points[-n_in - 1 : -1][::-1]
            configs += configs[-n_in - 1 : -1][::-1]
            left.remove(i)
            planner.set_boxes(*boxes())
        q = configs[-1]
    elapsed = time.perf_counter() - t0
    return Plan(
        order, np.array(points), np.array(configs), cuts, success, elapsed, energy, clearance, planner.fallbacks
    )


# ---------------------------------------------------------------------------------------- policy adapter


def targets_from_observation(
    observation: dict[str, np.ndarray], layout: dict[str, slice]
) -> tuple[list[ClusterTarget], np.ndarray, np.ndarray]:
    """Unharvested clusters and the other boxes from a GrapeHarvest-v1 observation.

    The designated cluster's cut is ``desired_goal`` and its box the ``target_box`` slot; the other
    clusters carry box and cut in their slots (see the env's Observation Space).

    Args:
        observation: The env's dict observation (one env, not batched).
        layout: ``env.unwrapped.layout``: where each part of ``observation["observation"]`` sits.

    Returns:
        ``(targets, lo, hi)``: the clusters (designated first) and the minima and maxima of the stems' and
        leaves' boxes.
    """
    o = np.asarray(observation["observation"], dtype=np.float64)
    goal = np.asarray(observation["desired_goal"], dtype=np.float64)
    targets = []
    box = o[layout["target_box"]]
    if box[0] > 0.5:
        targets.append(ClusterTarget(goal[:3], goal[3:6], goal[6:9], box[1:4], box[4:7]))
    for c in o[layout["others"]].reshape(-1, 16):
        if c[0] > 0.5:
            targets.append(ClusterTarget(c[7:10], c[10:13], c[13:16], c[1:4], c[4:7]))
    rest = o[layout["obstacles"]].reshape(-1, 7)
    rest = rest[rest[:, 0] > 0.5]
    return targets, rest[:, 1:4], rest[:, 4:7]


def joints_from_observation(obs: np.ndarray) -> np.ndarray:
    """Joint values (rad) from the observation's normalised joints."""
    lo, hi = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
    return lo + (np.asarray(obs[:6], dtype=np.float64) + 1.0) * 0.5 * (hi - lo)


class LuoApfPolicy:
    """SB3-style ``predict`` adapter: plan at the start of each episode, then follow the joint waypoints.

    Args:
        max_joint_step: The env's ``max_joint_step`` (rad per step at action 1).
        seed: Seed of Alg. 1's sampling (each episode continues the same stream).
        params: Planner parameters.
    """

    def __init__(
        self,
        max_joint_step: float,
        layout: dict[str, slice],
        seed: int = 0,
        params: LuoApfParams | None = None,
    ) -> None:
        self.max_joint_step = max_joint_step
        self.layout = layout
        self.params = params or LuoApfParams()
        self.rng = np.random.default_rng(seed)
        self.plans: list[Plan | None] = []
        self.cursor: list[int] = []

    def _start(self, env_index: int, obs: dict[str, np.ndarray]) -> None:
        targets, lo, hi = targets_from_observation(obs, self.layout)
        q0 = joints_from_observation(obs["observation"])
        plan = plan_harvest(q0, targets, lo, hi, self.rng, self.params)
        while len(self.plans) <= env_index:
            self.plans.append(None)
            self.cursor.append(0)
        self.plans[env_index], self.cursor[env_index] = plan, 1

    def predict(
        self,
        observation: dict[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, Any]:
        """Joint-delta actions toward the next waypoint of each env's plan (batched or single observation)."""
        obs = np.asarray(observation["observation"])
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        goals = np.asarray(observation["desired_goal"]).reshape(len(batch), -1)
        starts = np.ones(len(batch), bool) if episode_start is None else np.asarray(episode_start, bool).reshape(-1)
        actions = np.zeros((len(batch), 6), dtype=np.float32)
        for k, o in enumerate(batch):
            if starts[k] or k >= len(self.plans) or self.plans[k] is None:
                self._start(k, {"observation": o, "desired_goal": goals[k]})
            plan = self.plans[k]
            assert plan is not None
            q = joints_from_observation(o)
            while self.cursor[k] < len(plan.waypoints) and np.max(np.abs(plan.waypoints[self.cursor[k]] - q)) < 1e-4:
                self.cursor[k] += 1
            if self.cursor[k] < len(plan.waypoints):
                delta = plan.waypoints[self.cursor[k]] - q
                actions[k] = np.clip(delta / self.max_joint_step, -1.0, 1.0)
        return (actions[0] if single else actions), state

    def episode_metrics(self, index: int) -> dict[str, Any]:
        """Table 2's columns for the last plan of env ``index``: order, path length, path points, time."""
        plan = self.plans[index] if index < len(self.plans) else None
        if plan is None:
            return {}
        # Clusters are numbered as the observation lists them: 1 is the env's designated one.
        return {
            "order": "->".join(str(i + 1) for i in plan.order),
            "path_length_mm": plan.path_length * 1000.0,
            "path_points": len(plan.points),
            "planning_time_ms": plan.planning_time * 1000.0,
            "plan_success": plan.success,
            "energy": plan.energy,
            "min_box_clearance": plan.min_box_clearance if math.isfinite(plan.min_box_clearance) else None,
            "fallbacks": plan.fallbacks,
        }


def make_luo_apf(env: Any) -> LuoApfPolicy:
    """Registry factory: the policy for a GrapeHarvest-v1 env with joint-delta actions.

    Env arguments it adapts to: the scene (clusters, their boxes and tilt, leaves, canes: read from the
    observation when it plans), ``max_joint_step`` (its actions step along the plan at that rate) and the
    tolerances (its plan ends exactly on each cutting pose, so any tolerance holds). It needs
    ``control="joint"`` and ignores the reward arguments and ``time_slack`` (it plans once, and its tour is
    within Table 2's time in every pinned suite).
    """
    cfg = env.unwrapped.config
    if cfg.control != "joint":
        raise ValueError(f"luo-apf drives joint-delta actions: make the env with control='joint' (got {cfg.control!r})")
    return LuoApfPolicy(cfg.max_joint_step, env.unwrapped.layout)


def make_luo_apf_attract_only(env: Any) -> LuoApfPolicy:
    """Registry factory of the ablation: luo-apf with eta = 0 (no repulsion, eq. 15 switched off)."""
    policy = make_luo_apf(env)
    policy.params = dataclasses.replace(policy.params, eta=0.0)
    return policy
