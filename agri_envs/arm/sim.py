"""The pybullet side of GrapeHarvest: one physics client per instance, the arm, the vine row, the camera.

Like panda-gym's ``PyBullet`` wrapper, :class:`ArmSim` owns its client (DIRECT by default, so several
sims live in one process) and closes it in :meth:`close`. The arm is driven kinematically (joint values
set directly, no dynamics), and collisions are pybullet's closest-point queries between the arm and the
anti-collision boxes only.
"""

from __future__ import annotations

import ctypes
import os
import sys
from typing import Any

import numpy as np

from agri_envs.arm.robot_model import URDF_PATH
from agri_envs.arm.scene import BASE_HEIGHT, PEDUNCLE_GAP, ROW_X, Cluster, Scene


def _flush_c_stdout() -> None:
    """Flush the C library's stdio buffers (best effort)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


def _import_pybullet_quietly() -> Any:
    """Import pybullet with the C-level stdout and stderr silenced: it prints "pybullet build time: ..."."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no usable descriptors: nothing to silence
        import pybullet

        return pybullet
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            import pybullet

            _flush_c_stdout()  # the line may sit in C's buffer when the stream is not a terminal
        finally:
            os.close(devnull)
    finally:
        for fd, copy in zip((1, 2), saved, strict=True):
            os.dup2(copy, fd)
            os.close(copy)
    return pybullet


pb = _import_pybullet_quietly()

_GREEN = (0.28, 0.55, 0.22, 1.0)
_BROWN = (0.45, 0.32, 0.2, 1.0)
_GRAPE = (0.35, 0.12, 0.45, 1.0)
_BOX = (0.9, 0.15, 0.15, 1.0)


class ArmSim:
    """The arm on its platform in front of the vine row, in one pybullet client.

    The anti-collision boxes of a scene are the links of one fixed multibody (one pybullet call per
    scene, and one closest-points query per step for all of them); pybullet's answers for a link are
    the same, bit for bit, as for a separate body with the same box. Visual shapes (berries, stems,
    drawn boxes, platform) are only made when ``visuals`` is set, i.e. when the env renders, and a
    scene's own at its first frame (so resets between recorded episodes stay cheap).

    pybullet never frees a collision or visual shape that a body has used (``removeBody`` keeps it and
    ``removeCollisionShape`` refuses), so every scene leaves its shapes behind; once
    :data:`SHAPES_PER_CLIENT` have piled up, the next :meth:`load_scene` empties the world
    (``resetSimulation``, which frees them all) and reloads the arm. Memory stays flat over any number
    of resets.

    Args:
        gui: Open pybullet's own window (needs a display) instead of a DIRECT client.
        show_boxes: Draw the anti-collision boxes (translucent) in rendered images.
        visuals: Make the visual shapes that rendered images need (False: collision geometry only).
    """

    N_JOINTS = 6
    TIP_LINK = 7  # the clamp_centre link of the URDF
    #: Shapes a client may accumulate before :meth:`load_scene` empties its world (about 50 default scenes
    #: without visuals: about 2 MiB, and one reload of the arm, ~6 ms, per 50 resets).
    SHAPES_PER_CLIENT = 600

    def __init__(self, gui: bool = False, show_boxes: bool = True, visuals: bool = True) -> None:
        self.gui = gui
        self.show_boxes = show_boxes
        self.visuals = visuals or gui
        self._per_cluster = 3 if show_boxes else 2  # visual bodies per cluster: wire box, berries, peduncle
        self.client: int | None = None
        self._connect()

    def _connect(self) -> None:
        self.client = pb.connect(pb.GUI if self.gui else pb.DIRECT)
        if self.gui:
            pb.configureDebugVisualizer(pb.COV_ENABLE_GUI, 0, physicsClientId=self.client)
        self._build()

    def _build(self) -> None:
        """Load the arm (and the static visuals) into the client's empty world."""
        self.robot = pb.loadURDF(str(URDF_PATH), useFixedBase=True, physicsClientId=self.client)
        self._shapes = 0  # collision and visual shapes made since the world was last emptied
        self._boxes_body = -1  # the multibody whose links are the scene's boxes (-1: none)
        self._removed: set[int] = set()  # boxes of harvested clusters, out of the scene
        self._visual_bodies: list[int] = []  # per cluster: wire box, berries, peduncle; then obstacle boxes
        self._scene: Scene | None = None  # loaded, its visual bodies not made yet
        if self.visuals:
            self._static_visuals()

    def _static_visuals(self) -> None:
        """Ground, mobile platform and the row's posts: visual only (they take no part in collisions)."""
        self._visual_box((0.0, 0.0, -BASE_HEIGHT - 0.01), (2.0, 2.0, 0.01), (0.55, 0.5, 0.4, 1))
        self._visual_box((-0.15, 0.0, -BASE_HEIGHT + 0.3), (0.45, 0.35, 0.3), (0.3, 0.35, 0.45, 1))
        self._visual_box((0.0, 0.0, -BASE_HEIGHT / 2 - 0.2), (0.07, 0.07, BASE_HEIGHT / 2 - 0.05), (0.4, 0.4, 0.42, 1))
        for y in (-1.2, 1.2):
            self._visual_box((ROW_X, y, -BASE_HEIGHT / 2 + 0.15), (0.03, 0.03, BASE_HEIGHT / 2 + 0.15), _BROWN)

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has disconnected the client."""
        return self.client is None

    @property
    def _c(self) -> int:
        if self.client is None:
            raise RuntimeError("ArmSim is closed")
        return self.client

    def _visual_box(self, centre: tuple[float, ...], half: tuple[float, ...], rgba: tuple[float, ...]) -> int:
        c = self._c
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=list(half), rgbaColor=list(rgba), physicsClientId=c)
        self._shapes += 1
        return pb.createMultiBody(baseMass=0, baseVisualShapeIndex=vis, basePosition=list(centre), physicsClientId=c)

    def _wire_box(self, lo: np.ndarray, hi: np.ndarray, rgba: tuple[float, ...]) -> int:
        """A box drawn as its 12 edges (the tiny renderer has no transparency; Luo Fig. 2), visual only."""
        c = self._c
        half = 0.5 * (hi - lo)
        t = 0.002
        extents, centres = [], []
        for axis in range(3):
            for s1 in (-1, 1):
                for s2 in (-1, 1):
                    e = np.full(3, t)
                    e[axis] = half[axis]
                    ctr = np.zeros(3)
                    others = [k for k in range(3) if k != axis]
                    ctr[others[0]], ctr[others[1]] = s1 * half[others[0]], s2 * half[others[1]]
                    extents.append(e.tolist())
                    centres.append(ctr.tolist())
        vis = pb.createVisualShapeArray(
            shapeTypes=[pb.GEOM_BOX] * 12,
            halfExtents=extents,
            rgbaColors=[list(rgba)] * 12,
            visualFramePositions=centres,
            physicsClientId=c,
        )
        self._shapes += 12
        return pb.createMultiBody(
            baseMass=0, baseVisualShapeIndex=vis, basePosition=(0.5 * (lo + hi)).tolist(), physicsClientId=c
        )

    def _cluster_bodies_of(self, cl: Cluster) -> tuple[int, int]:
        """Berries (one multi-sphere visual body) and peduncle of a cluster."""
        c = self._c
        n = len(cl.berries)
        # pybullet crashes on arrays of more than 16 shapes: clusters have at most 15 berries.
        vis = pb.createVisualShapeArray(
            shapeTypes=[pb.GEOM_SPHERE] * n,
            radii=cl.berries[:, 3].tolist(),
            rgbaColors=[list(_GRAPE)] * n,
            visualFramePositions=cl.berries[:, :3].tolist(),
            physicsClientId=c,
        )
        berries = pb.createMultiBody(baseMass=0, baseVisualShapeIndex=vis, physicsClientId=c)
        top = cl.cut_point + PEDUNCLE_GAP * cl.down
        length = PEDUNCLE_GAP + 0.05  # from the berries to a little above the cutting point
        stem = pb.createVisualShape(pb.GEOM_CAPSULE, radius=0.004, length=length, rgbaColor=_GREEN, physicsClientId=c)
        self._shapes += n + 1
        centre = top - 0.5 * length * cl.down
        peduncle = pb.createMultiBody(
            baseMass=0,
            baseVisualShapeIndex=stem,
            basePosition=centre.tolist(),
            baseOrientation=_quat_z_to(-cl.down),
            physicsClientId=c,
        )
        return berries, peduncle

    def load_scene(self, scene: Scene) -> None:
        """Replace the clusters, stems and leaves by those of ``scene`` (bodies of the last one removed)."""
        if self._shapes >= self.SHAPES_PER_CLIENT:  # free the shapes the earlier scenes left behind
            pb.resetSimulation(physicsClientId=self._c)
            self._build()
        c = self._c
        for body in self._visual_bodies + ([self._boxes_body] if self._boxes_body >= 0 else []):
            pb.removeBody(body, physicsClientId=c)
        self._visual_bodies, self._boxes_body, self._removed = [], -1, set()
        los = [cl.box_lo for cl in scene.clusters] + [ob.lo for ob in scene.obstacles]
        his = [cl.box_hi for cl in scene.clusters] + [ob.hi for ob in scene.obstacles]
        if los:
            n = len(los)
            shapes = [
                pb.createCollisionShape(pb.GEOM_BOX, halfExtents=(0.5 * (hi - lo)).tolist(), physicsClientId=c)
                for lo, hi in zip(los, his, strict=True)
            ]
            self._shapes += n
            self._boxes_body = pb.createMultiBody(
                baseMass=0,
                linkMasses=[0.0] * n,
                linkCollisionShapeIndices=shapes,
                linkVisualShapeIndices=[-1] * n,
                linkPositions=[(0.5 * (lo + hi)).tolist() for lo, hi in zip(los, his, strict=True)],
                linkOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
                linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n,
                linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
                linkParentIndices=[0] * n,
                linkJointTypes=[pb.JOINT_FIXED] * n,
                linkJointAxis=[[0.0, 0.0, 1.0]] * n,
                physicsClientId=c,
            )
            if self.visuals:  # the renderer would draw the bare collision boxes: make them invisible
                for link in range(n):
                    pb.changeVisualShape(self._boxes_body, link, rgbaColor=[0.0, 0.0, 0.0, 0.0], physicsClientId=c)
        self._scene = scene  # its visual bodies are made at the next render()

    def _scene_visuals(self) -> None:
        """Berries, stems, leaves and drawn boxes of the loaded scene (made when a frame first needs them)."""
        scene, self._scene = self._scene, None
        if scene is None or not self.visuals:
            return
        for cl in scene.clusters:
            wire = [self._wire_box(cl.box_lo, cl.box_hi, _BOX)] if self.show_boxes else []
            self._visual_bodies += wire + list(self._cluster_bodies_of(cl))
        for ob in scene.obstacles:
            half = tuple((0.5 * (ob.hi - ob.lo)).tolist())
            centre = tuple((0.5 * (ob.lo + ob.hi)).tolist())
            self._visual_bodies.append(self._visual_box(centre, half, _GREEN if ob.kind == "leaf" else _BROWN))
        for index in self._removed:
            self._hide_cluster(index)

    def remove_cluster(self, index: int) -> None:
        """Take a harvested cluster (berries, peduncle and box) out of the scene: it is in the clamp now."""
        self._removed.add(index)
        self._hide_cluster(index)

    def _hide_cluster(self, index: int) -> None:
        k = self._per_cluster
        for body in self._visual_bodies[k * index : k * (index + 1)]:
            pb.resetBasePositionAndOrientation(body, [0.0, 0.0, -50.0 - index], [0, 0, 0, 1], physicsClientId=self._c)

    def set_joints(self, q: np.ndarray) -> None:
        """Put the arm at joint values ``q`` (rad), kinematically."""
        c = self._c
        for j in range(self.N_JOINTS):
            pb.resetJointState(self.robot, j, float(q[j]), physicsClientId=c)

    def tip_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Clamp-centre position (m) and rotation matrix in the base frame."""
        state = pb.getLinkState(self.robot, self.TIP_LINK, computeForwardKinematics=True, physicsClientId=self._c)
        return np.array(state[4]), np.array(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)

    def link_poses(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Position and rotation matrix of the URDF frames of links 1..6, tool and clamp centre."""
        states = pb.getLinkStates(self.robot, list(range(8)), computeForwardKinematics=True, physicsClientId=self._c)
        return [(np.array(s[4]), np.array(pb.getMatrixFromQuaternion(s[5])).reshape(3, 3)) for s in states]

    def _closest(self, distance: float) -> list[Any]:
        """Closest points (pybullet's) between the arm and the scene's boxes within ``distance`` (m)."""
        if self._boxes_body < 0:
            return []
        return list(pb.getClosestPoints(self.robot, self._boxes_body, distance=distance, physicsClientId=self._c))

    def collisions(self, margin: float = 0.0) -> list[int]:
        """Indices (clusters first, then obstacles) of the boxes the arm touches or comes within ``margin`` of."""
        hit = {int(pt[4]) for pt in self._closest(margin)}  # the box's link index
        return sorted(hit - self._removed)

    def min_distance(self, limit: float = 0.5) -> float:
        """Smallest signed distance (m) between the arm and any box still in the scene, capped at ``limit``."""
        best = limit
        for pt in self._closest(limit):
            if int(pt[4]) not in self._removed:
                best = min(best, pt[8])
        return best

    def render(self, width: int, height: int) -> np.ndarray:
        """An RGB frame (height, width, 3) from a fixed camera behind and beside the platform."""
        c = self._c
        self._scene_visuals()
        view = pb.computeViewMatrix(
            cameraEyePosition=[-0.2, -1.35, 0.45],
            cameraTargetPosition=[0.6, 0.0, -0.25],
            cameraUpVector=[0, 0, 1],
            physicsClientId=c,
        )
        proj = pb.computeProjectionMatrixFOV(
            fov=50.0, aspect=width / height, nearVal=0.05, farVal=6.0, physicsClientId=c
        )
        img = pb.getCameraImage(width, height, view, proj, renderer=pb.ER_TINY_RENDERER, shadow=0, physicsClientId=c)
        return np.asarray(img[2], dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def close(self) -> None:
        """Disconnect the client (idempotent)."""
        if self.client is not None:
            try:
                pb.disconnect(physicsClientId=self.client)
            finally:
                self.client = None


def _quat_z_to(direction: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) rotating the z axis onto ``direction``."""
    d = direction / np.linalg.norm(direction)
    axis = np.cross([0.0, 0.0, 1.0], d)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return [0.0, 0.0, 0.0, 1.0] if d[2] > 0 else [1.0, 0.0, 0.0, 0.0]
    angle = np.arctan2(s, d[2])
    axis = axis / s * np.sin(angle / 2)
    return [float(axis[0]), float(axis[1]), float(axis[2]), float(np.cos(angle / 2))]
