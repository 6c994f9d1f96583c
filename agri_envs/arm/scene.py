"""The vine row in front of the arm: grape clusters with cutting points and anti-collision boxes, stems, leaves.

Pure numpy; coordinates are the arm's base frame (frame 0, at the shoulder, z up, x toward the row), in
metres. A cluster (Luo Fig. 2) is a cone of berries hanging from its peduncle; the cutting point sits on
the peduncle :data:`PEDUNCLE_GAP` above the berries, and the axis-aligned box around the berries (grown
by :data:`BOX_MARGIN`) is what the arm must not touch. The clamp reaches the cutting point from the open
side of the row (the cluster's *approach* axis, horizontal) with the pallet under the berries (the tool's
x axis along the cluster's hanging axis), which is the orientation that "fits the cluster".

Two ways to draw a scene (``SceneParams.feasible``):

* as Luo did (sec. 4.2, the default): cutting points uniformly at random in the region of the workspace
  in front of the row, "randomly given in the configuration space of the manipulator": the arm can
  stand at each cut and pre-cut pose without touching a box, and nothing else is checked: a cluster's
  box may lie across another's approach, a stem may stand close behind a cut; a planner can fail there,
  and reports say so. Leaves are ours, not the paper's: they never block an approach or a cut pose.
* feasible only (a documented option for training presets): every cutting pose and its pre-cut pose
  (:data:`PRE_CUT` back along the approach) has an IK solution in the home branch whose whole arm clears
  every box, and no leaf or stem blocks the clamp's straight approach corridor.

Stems (trunk, cordon, canes) stand in the row plane behind the clusters; leaves fill the canopy around
them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from agri_envs.arm import _kernels
from agri_envs.arm.collision import ArmCollisionModel
from agri_envs.arm.kinematics import nearest_ik, within_limits
from agri_envs.arm.robot_model import (
    TOOL_HALF_X,
    TOOL_HALF_Y,
    TOOL_LENGTH,
    TOOL_OVERHANG,
    flange_pose_for_tip,
    goal_vector,
)

#: Height of the shoulder (frame 0) above the ground (m): the column on the mobile platform.
BASE_HEIGHT = 1.55
#: Distance of the row plane (trunk, cordon, canes) from the arm's base axis (m).
ROW_X = 0.86
#: Region of the cutting points in frame 0 (m): the part of the workspace (Fig. 3) in front of the row.
CUT_LOW = np.array([0.60, -0.30, -0.34])
CUT_HIGH = np.array([0.77, 0.30, -0.06])
#: Distance from the cutting point to the top of the berries along the cluster axis (m).
PEDUNCLE_GAP = 0.06
#: Growth of the berries' bounding box into the anti-collision box (m).
BOX_MARGIN = 0.01
#: Pre-cut distance: the clamp comes in along the approach axis over the last PRE_CUT metres (m).
PRE_CUT = 0.10
#: Home configuration (rad): the arm tucked in, the clamp 0.45 m in front of the base, pointing down.
HOME_Q = np.radians(np.array([0.0, -60.0, 70.0, 0.0, -40.0, 180.0]))
_YAW_JITTER = math.radians(12.0)
_BRANCH_REACH = math.radians(90.0)
_LIMIT_MARGIN = math.radians(10.0)
_MAX_ATTEMPTS = 200
#: Clearance the scene checker keeps between the arm's points and every box (m).
_CHECK_MARGIN = 0.005
#: Corners of the tool box in the clamp-centre frame, as :func:`corridor` sweeps them (m).
_TOOL_CORNERS = np.array(
    [[sx * TOOL_HALF_X, sy * TOOL_HALF_Y, z] for sx in (-1, 1) for sy in (-1, 1) for z in (TOOL_OVERHANG, -TOOL_LENGTH)]
)


def cut_pose(cut_point: np.ndarray, approach: np.ndarray, down: np.ndarray, offset: float = 0.0) -> np.ndarray:
    """Clamp-centre pose at a cutting point (``offset`` = 0) or ``offset`` metres back along the approach."""
    t = np.eye(4)
    t[:3, :3] = tool_rotation(approach, down)
    t[:3, 3] = cut_point - offset * approach
    return t


def tool_rotation(approach: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Rotation whose z axis is the approach direction and x axis the (orthogonalised) pallet-side axis."""
    z = approach / np.linalg.norm(approach)
    x = down - np.dot(down, z) * z
    x /= np.linalg.norm(x)
    (z0, z1, z2), (x0, x1, x2) = z.tolist(), x.tolist()
    rot = np.empty((3, 3))
    rot[:, 0], rot[:, 2] = x, z
    rot[:, 1] = (z1 * x2 - z2 * x1, z2 * x0 - z0 * x2, z0 * x1 - z1 * x0)  # np.cross(z, x), operation for operation
    return rot


@dataclasses.dataclass(frozen=True)
class Cluster:
    """One grape cluster.

    Attributes:
        cut_point: Cutting point on the peduncle (m).
        approach: Unit approach direction of the clamp (its z axis at the cut).
        down: Unit hanging axis of the cluster (the tool's x axis, pallet side, at the cut).
        berries: Berry spheres, shape (k, 4): centre (m) and radius (m).
        box_lo: Anti-collision box minimum ``P_min`` (m).
        box_hi: Anti-collision box maximum ``P_max`` (m).
    """

    cut_point: np.ndarray
    approach: np.ndarray
    down: np.ndarray
    berries: np.ndarray
    box_lo: np.ndarray
    box_hi: np.ndarray

    def tip_pose(self, offset: float = 0.0) -> np.ndarray:
        """Clamp-centre pose at the cut (``offset`` = 0) or ``offset`` metres back along the approach."""
        return cut_pose(self.cut_point, self.approach, self.down, offset)

    def goal(self) -> np.ndarray:
        """The goal vector of the cut: position (3), approach axis (3), pallet axis (3)."""
        return goal_vector(self.cut_point, self.tip_pose()[:3, :3])


@dataclasses.dataclass(frozen=True)
class Obstacle:
    """A stem or a leaf, modelled by its AABB (sec. 2.2)."""

    kind: str  # "trunk", "cordon", "cane" or "leaf"
    lo: np.ndarray
    hi: np.ndarray


@dataclasses.dataclass(frozen=True)
class Scene:
    """Clusters and further obstacles of one episode."""

    clusters: tuple[Cluster, ...]
    obstacles: tuple[Obstacle, ...]

    def boxes(self, harvested: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` of every box still in the scene (harvested clusters' boxes leave with them)."""
        keep = [c for i, c in enumerate(self.clusters) if harvested is None or not harvested[i]]
        lo = [c.box_lo for c in keep] + [o.lo for o in self.obstacles]
        hi = [c.box_hi for c in keep] + [o.hi for o in self.obstacles]
        return np.array(lo).reshape(-1, 3), np.array(hi).reshape(-1, 3)


@dataclasses.dataclass(frozen=True)
class SceneParams:
    """What varies between episodes (see the env's Arguments)."""

    min_clusters: int = 2
    max_clusters: int = 5
    n_leaves: int = 4
    n_canes: int = 2
    cluster_tilt: float = 0.17
    feasible: bool = False


def make_cluster(rng: np.random.Generator, cut: np.ndarray, tilt_max: float) -> Cluster:
    """A cluster with its cutting point at ``cut``, approached from the base side with a random lean."""
    return _build_cluster(cut, _cluster_draws(rng, tilt_max))


def _cluster_draws(rng: np.random.Generator, tilt_max: float) -> tuple[float, ...]:
    """The random numbers of one cluster, in the order :func:`make_cluster` has always drawn them.

    Yaw jitter, lean, length, radius and the phases of the 5 berry rings: drawn before the cluster is
    built, so that a candidate rejected for its cutting point alone costs nothing more than its draws.
    """
    jitter = rng.uniform(-_YAW_JITTER, _YAW_JITTER)
    tilt = rng.uniform(-tilt_max, tilt_max)
    length, radius = rng.uniform(0.10, 0.16), rng.uniform(0.035, 0.05)
    phases = [rng.uniform(0, 2 * math.pi) for _ in range(5)]
    return (jitter, tilt, length, radius, *phases)


def _build_cluster(cut: np.ndarray, draws: tuple[float, ...]) -> Cluster:
    """The cluster of :func:`make_cluster` from its draws.

    Written out in Python floats, operation for operation what the numpy version computed (Rodrigues'
    rotation of the down axis about the approach, ``np.cross``, the berry rings), so the result is bit for bit
    the same, only without the overhead of numpy calls on 3-vectors (``tests/envs/test_grape_harvest_env.py``
    checks it against that version). The rotation's one dot product (the approach with the z axis) is a sum
    of exact zeros.
    """
    jitter, tilt, length, radius = draws[:4]
    cx, cy, cz = float(cut[0]), float(cut[1]), float(cut[2])
    yaw = math.atan2(cy, cx) + jitter
    a0, a1, a2 = math.cos(yaw), math.sin(yaw), 0.0
    # Rodrigues: rotate v = (0, 0, -1) about the approach a by tilt: v c + (a x v) s + a (a . v) (1 - c)
    c, s = math.cos(tilt), math.sin(tilt)
    v0, v1, v2 = 0.0, 0.0, -1.0
    x0, x1, x2 = a1 * v2 - a2 * v1, a2 * v0 - a0 * v2, a0 * v1 - a1 * v0
    dot = a0 * v0 + a1 * v1 + a2 * v2
    d0 = v0 * c + x0 * s + a0 * dot * (1 - c)
    d1 = v1 * c + x1 * s + a1 * dot * (1 - c)
    d2 = v2 * c + x2 * s + a2 * dot * (1 - c)
    s0, s1, s2 = d1 * a2 - d2 * a1, d2 * a0 - d0 * a2, d0 * a1 - d1 * a0  # side = down x approach
    berry = 0.013
    rows = []
    for ring, level in enumerate((0.0, 0.25, 0.5, 0.75, 1.0)):  # np.linspace(0, 1, 5): rings of 5, 4, 3, 2, 1
        ring_r = (radius - berry) * (1.0 - 0.7 * level)
        along = PEDUNCLE_GAP + berry + level * (length - 2 * berry)
        e0, e1, e2 = cx + along * d0, cy + along * d1, cz + along * d2
        n = 5 - int(round(4 * level))
        phase = draws[4 + ring]
        for k in range(n):
            ang = phase + 2 * math.pi * k / n
            ca, sa = math.cos(ang), math.sin(ang)
            rows.append(
                (
                    e0 + ring_r * (ca * a0 + sa * s0),
                    e1 + ring_r * (ca * a1 + sa * s1),
                    e2 + ring_r * (ca * a2 + sa * s2),
                    berry,
                )
            )
    b = np.array(rows)
    lo = np.min(b[:, :3] - b[:, 3:], axis=0) - BOX_MARGIN
    hi = np.max(b[:, :3] + b[:, 3:], axis=0) + BOX_MARGIN
    return Cluster(np.array(cut, dtype=np.float64), np.array([a0, a1, a2]), np.array([d0, d1, d2]), b, lo, hi)


def corridor(cluster: Cluster, grow: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """AABB swept by the tool coming in from the pre-cut pose to the cut (grown by ``grow``)."""
    corners = []
    for offset in (0.0, PRE_CUT):
        t = cluster.tip_pose(offset)
        for sx in (-1, 1):
            for sy in (-1, 1):
                for z in (TOOL_OVERHANG, -TOOL_LENGTH):
                    corners.append(t[:3, :3] @ np.array([sx * TOOL_HALF_X, sy * TOOL_HALF_Y, z]) + t[:3, 3])
    c = np.array(corners)
    return c.min(axis=0) - grow, c.max(axis=0) + grow


def _overlap(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> bool:
    return bool(np.all(lo1 <= hi2) and np.all(lo2 <= hi1))


def harvest_configurations(cluster: Cluster, q_ref: np.ndarray = HOME_Q) -> tuple[np.ndarray, np.ndarray] | None:
    """Joint values at the pre-cut and the cut pose (IK nearest ``q_ref``), or None when out of reach.

    Out of reach also means: only reachable by a shoulder or elbow more than 90 deg from home, or within
    10 deg of a joint limit.
    """
    pre = nearest_ik(flange_pose_for_tip(cluster.tip_pose(PRE_CUT)), q_ref)
    # The arm works in its home branch (shoulder facing the row, elbow up): a cluster that only a turned-
    # around arm could reach is not in the workspace of Fig. 3.
    if pre is None or np.max(np.abs(pre[:3] - HOME_Q[:3])) > _BRANCH_REACH:
        return None
    cut = nearest_ik(flange_pose_for_tip(cluster.tip_pose()), pre)
    if cut is None or np.max(np.abs(cut - pre)) > 0.8:  # the approach must not switch IK branch
        return None
    # Keep clear of the joint limits, so that the arm can still move away from the cut.
    if not (within_limits(pre, -_LIMIT_MARGIN) and within_limits(cut, -_LIMIT_MARGIN)):
        return None
    return pre, cut


class _Checker:
    """Validity of a scene under construction: harvest configurations and corridors stay free."""

    def __init__(self) -> None:
        self.model = ArmCollisionModel(np.zeros((0, 3)), np.zeros((0, 3)), margin=_CHECK_MARGIN)
        self.lo: list[np.ndarray] = []
        self.hi: list[np.ndarray] = []
        self.configs: list[np.ndarray] = [HOME_Q]
        self.corridors: list[tuple[np.ndarray, np.ndarray]] = []

    def free_with(self, lo: np.ndarray, hi: np.ndarray, configs: list[np.ndarray]) -> bool:
        """Would every configuration stay free with the extra box, and the extra configs with every box?"""
        if any(_overlap(lo, hi, clo, chi) for clo, chi in self.corridors):
            return False
        self.model.set_boxes(lo[None], hi[None])
        if self.model.collides(np.array(self.configs + configs)).any():
            return False
        if configs and self.lo:
            self.model.set_boxes(np.array(self.lo), np.array(self.hi))
            if self.model.collides(np.array(configs)).any():
                return False
        return True

    def add(self, lo: np.ndarray, hi: np.ndarray, configs: list[np.ndarray], corridor_box: tuple | None) -> None:
        self.lo.append(lo)
        self.hi.append(hi)
        self.configs += configs
        if corridor_box is not None:
            self.corridors.append(corridor_box)


def sample_scene(rng: np.random.Generator, params: SceneParams) -> Scene:
    """Draw the clusters, stems and leaves of one episode (see the module docstring for the guarantees)."""
    return sample_scene_and_configurations(rng, params)[0]


def vine_obstacles(rng: np.random.Generator, top: float, n_canes: int) -> list[Obstacle]:
    """The vine's wood around the clusters: the cordon at ``top``, the trunk and ``n_canes`` canes (random y).

    Draws one uniform for the trunk, then one per cane, in that order (the scene's random stream).
    """
    obstacles = [
        Obstacle("cordon", np.array([ROW_X - 0.02, -0.7, top - 0.02]), np.array([ROW_X + 0.02, 0.7, top + 0.02])),
    ]
    trunk_y = rng.uniform(-0.4, 0.4)
    obstacles.append(
        Obstacle(
            "trunk",
            np.array([ROW_X - 0.03, trunk_y - 0.03, -BASE_HEIGHT]),
            np.array([ROW_X + 0.03, trunk_y + 0.03, top - 0.02]),
        )
    )
    for _ in range(n_canes):
        y = rng.uniform(-0.6, 0.6)
        obstacles.append(
            Obstacle("cane", np.array([ROW_X - 0.01, y - 0.01, top - 0.55]), np.array([ROW_X + 0.01, y + 0.01, top]))
        )
    return obstacles


def sample_scene_reference(rng: np.random.Generator, params: SceneParams) -> Scene:
    """:func:`sample_scene` as first written, all in numpy: the oracle the fast sampler is tested against."""
    n = int(rng.integers(params.min_clusters, params.max_clusters + 1))
    while True:
        scene = _try_scene_reference(rng, params, n)
        if scene is not None:
            return scene


def sample_scene_and_configurations(
    rng: np.random.Generator, params: SceneParams
) -> tuple[Scene, tuple[tuple[np.ndarray, np.ndarray], ...]]:
    """:func:`sample_scene`, and :func:`harvest_configurations` of each cluster (computed while drawing)."""
    n = int(rng.integers(params.min_clusters, params.max_clusters + 1))
    while True:
        drawn = _try_scene(rng, params, n)
        if drawn is not None:
            return drawn


def _overlaps_any(lo: np.ndarray, hi: np.ndarray, los: list[np.ndarray], his: list[np.ndarray]) -> bool:
    return any(_overlap(lo, hi, blo, bhi) for blo, bhi in zip(los, his, strict=True))


def _try_scene_reference(rng: np.random.Generator, params: SceneParams, n: int) -> Scene | None:
    """The sampler as first written (numpy throughout): the oracle of :func:`_try_scene`."""
    check = _Checker()
    clusters: list[Cluster] = []
    cors: list[tuple[np.ndarray, np.ndarray]] = []
    for _ in range(_MAX_ATTEMPTS):
        if len(clusters) == n:
            break
        c = make_cluster(rng, rng.uniform(CUT_LOW, CUT_HIGH), params.cluster_tilt)
        if any(np.linalg.norm(c.cut_point - o.cut_point) < 0.12 for o in clusters):
            continue
        cor = corridor(c)
        # Feasible scenes keep every approach corridor free; Luo's random scenes do not check it.
        if params.feasible and _overlaps_any(cor[0], cor[1], check.lo, check.hi):
            continue
        if not params.feasible and _overlaps_any(c.box_lo, c.box_hi, check.lo, check.hi):
            continue  # two clusters cannot fill the same space
        # Both: "randomly given in the configuration space of the manipulator" (sec. 4.2): the arm can
        # stand at the cut and pre-cut poses without touching a box (C_free of eqs. 8-9).
        configs = harvest_configurations(c)
        if configs is None or not check.free_with(c.box_lo, c.box_hi, list(configs)):
            continue
        check.add(c.box_lo, c.box_hi, list(configs), cor if params.feasible else None)
        cors.append(cor)
        clusters.append(c)
    if len(clusters) < n:
        return None
    top = max(c.cut_point[2] for c in clusters) + 0.14
    obstacles = vine_obstacles(rng, top, params.n_canes)
    for o in obstacles:
        if not check.free_with(o.lo, o.hi, []):
            return None
        check.add(o.lo, o.hi, [], None)
    for _ in range(params.n_leaves):
        for _attempt in range(30):
            centre = rng.uniform([0.60, -0.45, -0.42], [ROW_X, 0.45, top])
            half = rng.uniform([0.03, 0.04, 0.015], [0.06, 0.07, 0.04])
            # Leaves are ours, not the paper's (its scenes hold clusters and their boxes): they never block an
            # approach corridor or a cut pose, so that the random part stays the paper's, the clusters.
            if check.free_with(centre - half, centre + half, []) and not _overlaps_any(
                centre - half, centre + half, [cr[0] for cr in cors], [cr[1] for cr in cors]
            ):
                leaf = Obstacle("leaf", centre - half, centre + half)
                obstacles.append(leaf)
                check.add(leaf.lo, leaf.hi, [], None)
                break
    return Scene(tuple(clusters), tuple(obstacles))


class _Candidate:
    """A drawn cluster: the kernel's frame and box for the tests, :func:`_build_cluster`'s on demand (exact)."""

    def __init__(self, cut: np.ndarray, draws: tuple[float, ...]) -> None:
        self.cut_point, self.draws = cut, draws
        self.approach, self.down, self.box_lo, self.box_hi = _kernels.cluster_box(
            cut, np.array(draws), PEDUNCLE_GAP, BOX_MARGIN
        )
        self._exact: Cluster | None = None

    def exact(self) -> Cluster:
        if self._exact is None:
            self._exact = _build_cluster(self.cut_point, self.draws)
        return self._exact


class _Box:
    """An AABB for the tests: ``lo``/``hi`` (a candidate's may be the kernel's) and the exact one on demand."""

    def __init__(
        self, lo: np.ndarray, hi: np.ndarray, exact: Callable[[], tuple[np.ndarray, np.ndarray]] | None = None
    ) -> None:
        self.lo, self.hi = lo, hi
        self._exact = exact

    def exact(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.lo, self.hi) if self._exact is None else self._exact()

    def overlaps(self, other: _Box) -> bool:
        """``_overlap`` of the two exact boxes."""
        st = _kernels.overlap(self.lo, self.hi, other.lo, other.hi)
        if st == _kernels.UNCERTAIN:
            return _overlap(*self.exact(), *other.exact())
        return st == _kernels.CERTAIN_YES


def _candidate_box(cand: _Candidate) -> _Box:
    def exact() -> tuple[np.ndarray, np.ndarray]:
        c = cand.exact()
        return c.box_lo, c.box_hi

    return _Box(cand.box_lo, cand.box_hi, exact)


def _corridor_box(cand: _Candidate) -> _Box:
    """The candidate's approach corridor (:func:`corridor`), the kernel's, exact on demand."""
    lo, hi = _kernels.corridor(cand.cut_point, cand.approach, cand.down, _TOOL_CORNERS, PRE_CUT, 0.02)
    return _Box(lo, hi, lambda: corridor(cand.exact()))


class _Harvest:
    """Harvest configurations of a candidate: the kernel's (certified reachable), numpy's on demand."""

    def __init__(self, cand: _Candidate | None, fast: tuple[np.ndarray, np.ndarray]) -> None:
        self.cand = cand
        self.fast = fast
        self._exact: tuple[np.ndarray, np.ndarray] | None = None if cand is not None else fast

    def exact(self) -> tuple[np.ndarray, np.ndarray]:
        if self._exact is None:
            assert self.cand is not None
            configs = harvest_configurations(self.cand.exact())
            assert configs is not None  # the kernel certified it reachable
            self._exact = configs
        return self._exact


def _fast_harvest(cand: _Candidate) -> _Harvest | None:
    """:func:`harvest_configurations` through the kernel; numpy's own when the kernel cannot be certain."""
    pre, cut, st = _kernels.harvest_configurations(
        cand.cut_point, cand.approach, cand.down, HOME_Q, PRE_CUT, _BRANCH_REACH, _LIMIT_MARGIN
    )
    if st == _kernels.CERTAIN_NO:
        return None
    if st == _kernels.CERTAIN_YES:
        return _Harvest(cand, (pre, cut))
    exact = harvest_configurations(cand.exact())
    return None if exact is None else _Harvest(None, exact)


class _FastChecker:
    """:class:`_Checker` answering through the certified kernels, and through numpy where they are unsure.

    Its answers are :class:`_Checker`'s: a kernel's certain answer equals numpy's (see
    :mod:`agri_envs.arm._kernels`), and an uncertain one is replaced by the very call :class:`_Checker`
    makes, on the exact boxes and numpy's own harvest configurations.
    """

    def __init__(self) -> None:
        self.boxes: list[_Box] = []
        self.harvests: list[_Harvest] = []
        self.points = _kernels.arm_points(HOME_Q)[None]  # arm points of every accepted configuration
        self.corridors: list[_Box] = []

    def _exact_configs(self) -> list[np.ndarray]:
        return [HOME_Q] + [q for h in self.harvests for q in h.exact()]

    def free_with(self, box: _Box, extra: _Harvest | None) -> bool:
        """:meth:`_Checker.free_with` with the extra configurations of ``extra`` (a cluster's, or none)."""
        if any(cor.overlaps(box) for cor in self.corridors):
            return False
        new = np.zeros((0,) + self.points.shape[1:])
        if extra is not None:
            new = np.stack([_kernels.arm_points(q) for q in extra.fast])
        st = _kernels.collides(np.concatenate([self.points, new]), box.lo[None], box.hi[None], _CHECK_MARGIN)
        if st == _kernels.UNCERTAIN:
            lo, hi = box.exact()
            configs = self._exact_configs() + (list(extra.exact()) if extra is not None else [])
            st = int(ArmCollisionModel(lo[None], hi[None], margin=_CHECK_MARGIN).collides(np.array(configs)).any())
        if st == _kernels.CERTAIN_YES:
            return False
        if extra is not None and self.boxes:
            los, his = np.array([b.lo for b in self.boxes]), np.array([b.hi for b in self.boxes])
            st = _kernels.collides(new, los, his, _CHECK_MARGIN)
            if st == _kernels.UNCERTAIN:
                model = ArmCollisionModel(los, his, margin=_CHECK_MARGIN)  # accepted boxes are exact
                st = int(model.collides(np.array(extra.exact())).any())
            if st == _kernels.CERTAIN_YES:
                return False
        return True

    def add(self, box: _Box, extra: _Harvest | None, cor: _Box | None) -> None:
        lo, hi = box.exact()
        self.boxes.append(_Box(lo, hi))
        if extra is not None:
            self.harvests.append(extra)
            self.points = np.concatenate([self.points, np.stack([_kernels.arm_points(q) for q in extra.fast])])
        if cor is not None:
            self.corridors.append(cor)


def _try_scene(
    rng: np.random.Generator, params: SceneParams, n: int
) -> tuple[Scene, tuple[tuple[np.ndarray, np.ndarray], ...]] | None:
    """One try of :func:`_try_scene_reference`, the same draws and the same decisions, made fast.

    Each candidate is tested on the kernels' frame, box, corridor and harvest configurations (certified,
    :mod:`agri_envs.arm._kernels`) and built exactly only when it is kept or a test is too close to
    call. Returns the scene and the harvest configurations of its clusters (the kernel's: equal to
    numpy's up to rounding).
    """
    tilt = params.cluster_tilt
    draw_low = np.array([*CUT_LOW, -_YAW_JITTER, -tilt, 0.10, 0.035] + [0.0] * 5)
    draw_high = np.array([*CUT_HIGH, _YAW_JITTER, tilt, 0.16, 0.05] + [2 * math.pi] * 5)
    check = _FastChecker()
    clusters: list[Cluster] = []
    harvest: list[_Harvest] = []
    cors: list[_Box] = []
    cuts = np.zeros((0, 3))
    for _ in range(_MAX_ATTEMPTS):
        if len(clusters) == n:
            break
        # The cut and make_cluster's draws (whether or not the cluster is kept) in one call: Generator.uniform
        # computes every element, array or scalar bounds alike, as low + (high - low) * next_double, in order.
        u = rng.uniform(draw_low, draw_high)
        cut, draws = u[:3], tuple(u[3:].tolist())
        st = _kernels.too_close(cut, cuts, 0.12)
        if st == _kernels.UNCERTAIN:
            st = int(any(np.linalg.norm(cut - o.cut_point) < 0.12 for o in clusters))
        if st == _kernels.CERTAIN_YES:
            continue
        cand = _Candidate(cut, draws)
        box = _candidate_box(cand)
        cor = _corridor_box(cand)
        # Feasible scenes keep every approach corridor free; Luo's random scenes do not check it.
        if params.feasible and any(cor.overlaps(b) for b in check.boxes):
            continue
        if not params.feasible and any(box.overlaps(b) for b in check.boxes):
            continue  # two clusters cannot fill the same space
        # Both: "randomly given in the configuration space of the manipulator" (sec. 4.2): the arm can
        # stand at the cut and pre-cut poses without touching a box (C_free of eqs. 8-9).
        configs = _fast_harvest(cand)
        if configs is None or not check.free_with(box, configs):
            continue
        check.add(box, configs, cor if params.feasible else None)
        cors.append(cor)
        clusters.append(cand.exact())
        harvest.append(configs)
        cuts = np.concatenate([cuts, cut[None]])
    if len(clusters) < n:
        return None
    top = max(c.cut_point[2] for c in clusters) + 0.14
    obstacles = vine_obstacles(rng, top, params.n_canes)
    for o in obstacles:
        if not check.free_with(_Box(o.lo, o.hi), None):
            return None
        check.add(_Box(o.lo, o.hi), None, None)
    leaf_low = np.array([0.60, -0.45, -0.42, 0.03, 0.04, 0.015])
    leaf_high = np.array([ROW_X, 0.45, top, 0.06, 0.07, 0.04])
    for _ in range(params.n_leaves):
        for _attempt in range(30):
            u = rng.uniform(leaf_low, leaf_high)  # centre, then half extents: the reference's two calls in one
            centre, half = u[:3], u[3:]
            # Leaves are ours, not the paper's (its scenes hold clusters and their boxes): they never block an
            # approach corridor or a cut pose, so that the random part stays the paper's, the clusters.
            leaf = _Box(centre - half, centre + half)
            if check.free_with(leaf, None) and not any(cor.overlaps(leaf) for cor in cors):
                obstacles.append(Obstacle("leaf", leaf.lo, leaf.hi))
                check.add(leaf, None, None)
                break
    return Scene(tuple(clusters), tuple(obstacles)), tuple(h.fast for h in harvest)
