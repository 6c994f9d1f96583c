"""Geometry of the harvesting arm, built on the D-H table: the URDF for pybullet and the point set of eqs. 6-9.

One description serves both: every link carries capsules (around the segments joining its frame origins)
and the tool carries one box (clamp, pallet and scissor as one body, Luo sec. 4.1). :func:`urdf_text`
turns it into the URDF that pybullet loads (shipped as ``harvest_arm.urdf``; regenerate it with
``python -m agri_envs.arm.robot_model``), and :func:`point_set` into the discrete points ``P_link`` whose
containment in the obstacle boxes is the collision test of eqs. 6-9. Sizes follow a small industrial arm
of the paper's dimensions (0.36 m upper arm, 0.37 m forearm).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from agri_envs.arm.kinematics import A1, A2, A3, D4, DH_TABLE, JOINT_LIMITS, link_frames

URDF_PATH = Path(__file__).with_name("harvest_arm.urdf")

#: Distance from the flange (frame 6 origin) to the clamp centre along z_6 (m): the tool's tip.
TOOL_LENGTH = 0.15
#: Half extents of the tool's collision box (m) in the flange frame: x_6 (pallet side), y_6 (jaw opening).
TOOL_HALF_X, TOOL_HALF_Y = 0.02, 0.035
#: The tool box spans z_6 in [TOOL_BASE, TOOL_LENGTH + TOOL_OVERHANG] (m).
TOOL_BASE, TOOL_OVERHANG = 0.03, 0.01

#: Flange-to-clamp-centre transform.
TOOL_TRANSFORM = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, TOOL_LENGTH], [0, 0, 0, 1.0]])


@dataclasses.dataclass(frozen=True)
class Capsule:
    """A capsule in a link frame: segment ``p0``-``p1`` (m) swept by a sphere of ``radius`` (m)."""

    link: int  # 0: base frame, 1..6: D-H frames
    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float


#: Collision capsules of links 1..6 (the base pedestal never reaches the vine and is not checked).
CAPSULES = (
    Capsule(1, (0.0, 0.0, -0.10), (0.0, 0.0, 0.02), 0.07),  # shoulder housing on the column
    Capsule(1, (0.0, 0.0, 0.0), (A1, 0.0, 0.0), 0.06),  # shoulder offset a_1
    Capsule(2, (0.0, 0.0, 0.0), (A2, 0.0, 0.0), 0.05),  # upper arm a_2
    Capsule(3, (0.0, 0.0, 0.0), (A3, 0.0, 0.0), 0.05),  # elbow, offset a_3
    Capsule(3, (A3, 0.0, 0.0), (A3, D4 - 0.09, 0.0), 0.04),  # forearm along z_4 (d_4)
    Capsule(4, (0.0, 0.0, -0.09), (0.0, 0.0, -0.03), 0.04),  # wrist end of the forearm
    Capsule(5, (0.0, 0.0, -0.035), (0.0, 0.0, 0.035), 0.035),  # wrist pitch housing
    Capsule(6, (0.0, 0.0, 0.0), (0.0, 0.0, TOOL_BASE), 0.035),  # flange
)


def tool_box_in_flange() -> tuple[np.ndarray, np.ndarray]:
    """Centre and half extents (m) of the tool's collision box in the flange frame."""
    z0, z1 = TOOL_BASE, TOOL_LENGTH + TOOL_OVERHANG
    return np.array([0.0, 0.0, 0.5 * (z0 + z1)]), np.array([TOOL_HALF_X, TOOL_HALF_Y, 0.5 * (z1 - z0)])


# ----------------------------------------------------------------------------------------------- URDF


def _rpy_z_to(direction: np.ndarray) -> tuple[float, float, float]:
    """Roll-pitch-yaw (URDF's fixed-axis convention) of a frame whose z axis points along ``direction``."""
    d = direction / np.linalg.norm(direction)
    pitch = math.atan2(math.hypot(d[0], d[1]), d[2])
    yaw = math.atan2(d[1], d[0])
    return 0.0, pitch, yaw


def _fmt(v: tuple[float, ...] | np.ndarray) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


def _inertial(mass: float) -> str:
    return (
        f'<inertial><origin xyz="0 0 0"/><mass value="{mass}"/>'
        '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>'
    )


def _geometry(kind: str, origin: str, geometry: str, material: str = "") -> str:
    mat = f'<material name="{material}"/>' if material else ""
    return f"<{kind}>{origin}<geometry>{geometry}</geometry>{mat}</{kind}>"


def _capsule_elements(c: Capsule) -> list[str]:
    p0, p1 = np.array(c.p0), np.array(c.p1)
    centre, axis = 0.5 * (p0 + p1), p1 - p0
    length = float(np.linalg.norm(axis))
    origin = f'<origin xyz="{_fmt(centre)}" rpy="{_fmt(_rpy_z_to(axis))}"/>'
    geometry = f'<capsule radius="{c.radius}" length="{length:.9g}"/>'
    return [_geometry("visual", origin, geometry, "arm"), _geometry("collision", origin, geometry)]


def _tool_elements() -> list[str]:
    centre, half = tool_box_in_flange()
    out = [_geometry("collision", f'<origin xyz="{_fmt(centre)}"/>', f'<box size="{_fmt(2 * half)}"/>')]
    # Visual parts: palm, two clamp fingers around the tip, the pallet under them (+x_6), the scissor blade.
    parts = [
        ((0.0, 0.0, 0.07), (0.04, 0.07, 0.08), "tool"),
        ((0.0, 0.026, 0.135), (0.03, 0.012, 0.05), "finger"),
        ((0.0, -0.026, 0.135), (0.03, 0.012, 0.05), "finger"),
        ((0.017, 0.0, 0.13), (0.006, 0.06, 0.06), "pallet"),
        ((-0.014, 0.0, 0.155), (0.008, 0.05, 0.01), "scissor"),
    ]
    for xyz, size, mat in parts:
        out.append(_geometry("visual", f'<origin xyz="{_fmt(xyz)}"/>', f'<box size="{_fmt(size)}"/>', mat))
    return out


def urdf_text() -> str:
    """The arm's URDF, generated from :data:`~agri_envs.arm.kinematics.DH_TABLE` and the link geometry.

    Joint ``i`` sits in frame ``i - 1`` at ``RotX(alpha_{i-1}) TransX(a_{i-1}) TransZ(d_i)``, i.e. URDF
    origin ``xyz = (a, -d sin(alpha), d cos(alpha))``, ``rpy = (alpha, 0, 0)``, axis z: so the URDF frame of
    link ``i`` is the D-H frame ``i``, and pybullet's link frames equal :func:`link_frames`.
    """
    materials = {
        "arm": "0.93 0.55 0.12 1",
        "base": "0.35 0.35 0.38 1",
        "tool": "0.25 0.25 0.28 1",
        "finger": "0.75 0.75 0.78 1",
        "pallet": "0.2 0.45 0.8 1",
        "scissor": "0.85 0.1 0.1 1",
    }
    lines = ['<?xml version="1.0"?>', '<robot name="luo2018_harvest_arm">']
    lines += [f'<material name="{k}"><color rgba="{v}"/></material>' for k, v in materials.items()]
    pedestal = _geometry("visual", '<origin xyz="0 0 -0.3"/>', '<cylinder radius="0.09" length="0.36"/>', "base")
    lines.append(f'<link name="base">{_inertial(0.0)}{pedestal}</link>')
    names = ["base"] + [f"link{i}" for i in range(1, 7)]
    for i in range(1, 7):
        alpha, a, d = DH_TABLE[i - 1]
        body = "".join(e for c in CAPSULES if c.link == i for e in _capsule_elements(c))
        lines.append(f'<link name="{names[i]}">{_inertial(1.0)}{body}</link>')
        xyz = (a, -d * math.sin(alpha), d * math.cos(alpha))
        lo, hi = JOINT_LIMITS[i - 1]
        lines.append(
            f'<joint name="joint{i}" type="revolute"><parent link="{names[i - 1]}"/><child link="{names[i]}"/>'
            f'<origin xyz="{_fmt(xyz)}" rpy="{_fmt((alpha, 0.0, 0.0))}"/><axis xyz="0 0 1"/>'
            f'<limit lower="{lo:.9g}" upper="{hi:.9g}" effort="100" velocity="3"/></joint>'
        )
    lines.append(f'<link name="tool">{_inertial(0.5)}{"".join(_tool_elements())}</link>')
    lines.append(
        '<joint name="tool_joint" type="fixed"><parent link="link6"/><child link="tool"/><origin xyz="0 0 0"/></joint>'
    )
    lines.append(f'<link name="clamp_centre">{_inertial(0.01)}</link>')
    lines.append(
        '<joint name="clamp_joint" type="fixed"><parent link="tool"/><child link="clamp_centre"/>'
        f'<origin xyz="0 0 {TOOL_LENGTH}"/></joint>'
    )
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------ point set (eq. 7)


@dataclasses.dataclass(frozen=True)
class PointSet:
    """The arm discretised into points ``P_link`` (eq. 7), each with the radius it stands for.

    Attributes:
        frame: Index into :func:`link_frames` (0..5 for D-H frames 1..6) of the frame each point rides on.
        points: Homogeneous coordinates in that frame, shape (m, 4).
        radius: Per point: how far the arm's surface can be from it (m). A point is "inside" a box (eq. 6)
            when it lies in the box grown by this radius, which makes the test conservative: capsule
            points sit on the axis (radius + half the spacing), tool points on the box surface (the
            spacing times sqrt(1/2)).
    """

    frame: np.ndarray
    points: np.ndarray
    radius: np.ndarray

    def world(self, frames: np.ndarray) -> np.ndarray:
        """Point coordinates in the base frame for link frames of shape (N, 6, 4, 4): shape (N, m, 3)."""
        f = frames[:, self.frame]  # (N, m, 4, 4)
        return np.einsum("nmij,mj->nmi", f[:, :, :3, :], self.points)


def point_set(spacing: float = 0.02) -> PointSet:
    """Discretise the arm's capsules and tool box with points at most ``spacing`` (m, d_min of eq. 7) apart."""
    frames, pts, radii = [], [], []
    for c in CAPSULES:
        p0, p1 = np.array(c.p0), np.array(c.p1)
        n = max(2, math.ceil(np.linalg.norm(p1 - p0) / spacing) + 1)
        seg = p0 + np.linspace(0.0, 1.0, n)[:, None] * (p1 - p0)
        step = np.linalg.norm(p1 - p0) / (n - 1)
        frames += [c.link - 1] * n
        pts.append(seg)
        radii += [c.radius + 0.5 * step] * n
    centre, half = tool_box_in_flange()
    axes = [np.linspace(-h, h, max(2, math.ceil(2 * h / spacing) + 1)) for h in half]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    surface = grid[np.any(np.isclose(np.abs(grid), half), axis=1)] + centre
    steps = [2 * h / (len(a) - 1) for h, a in zip(half, axes, strict=True)]
    frames += [5] * len(surface)
    pts.append(surface)
    radii += [math.sqrt(0.5) * max(steps)] * len(surface)
    xyz = np.concatenate(pts)
    return PointSet(np.array(frames), np.hstack([xyz, np.ones((len(xyz), 1))]), np.array(radii))


def tip_pose(q: np.ndarray) -> np.ndarray:
    """Base-to-clamp-centre transform(s) for joint values of shape (6,) or (N, 6)."""
    return link_frames(q)[..., 5, :, :] @ TOOL_TRANSFORM


def goal_vector(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """The 9-vector of a clamp pose used as goal: position (3), approach axis (tool z), pallet axis (tool x)."""
    return np.concatenate([position, rotation[:, 2], rotation[:, 0]])


def flange_pose_for_tip(tip: np.ndarray) -> np.ndarray:
    """The flange pose that puts the clamp centre at ``tip`` (4x4 or (N, 4, 4))."""
    return tip @ np.linalg.inv(TOOL_TRANSFORM)


if __name__ == "__main__":  # regenerate the shipped URDF
    URDF_PATH.write_text(urdf_text())
    print(f"wrote {URDF_PATH}")
