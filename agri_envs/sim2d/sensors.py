"""Range sensors attached to a body: a planar LIDAR and ultrasonic sonars.

Sensors know where they sit on their body, measure the scene with the batched kernels of
:mod:`agri_envs.sim2d.raycast`, add their noise from the generator they are given, and describe their
own rays/cones for drawing. Presets: :func:`tim561` (SICK TiM561) and :func:`hc_sr04` (HC-SR04).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from agri_envs.sim2d.raycast import cast_scan, sonar_ranges, sonar_ranges_many


@dataclasses.dataclass(frozen=True)
class LidarSpec:
    """A planar scanning LIDAR.

    Attributes:
        n_beams: Number of beams, evenly spread over the aperture.
        aperture: Angle between the first and the last beam (rad).
        min_range: Readings closer than this are reported as ``min_range`` (m).
        max_range: Reported when nothing is hit (m).
        rate_hz: Scan frequency (Hz).
        noise_std: Standard deviation of Gaussian range noise (m).
        dropout_prob: Probability that a beam returns no echo (reported as ``max_range``).
        mount: ``(x, y, yaw)`` of the sensor in its body's frame (m, m, rad).
    """

    n_beams: int = 811
    aperture: float = math.radians(270.0)
    min_range: float = 0.05
    max_range: float = 10.0
    rate_hz: float = 15.0
    noise_std: float = 0.0
    dropout_prob: float = 0.0
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.n_beams < 2:
            raise ValueError(f"LidarSpec: n_beams must be >= 2, got {self.n_beams}")
        if not 0 < self.aperture <= 2 * math.pi:
            raise ValueError(f"LidarSpec: aperture must be in (0, 2*pi], got {self.aperture}")
        if not 0 <= self.min_range < self.max_range:
            raise ValueError("LidarSpec: need 0 <= min_range < max_range")
        if self.noise_std < 0 or not 0 <= self.dropout_prob <= 1:
            raise ValueError("LidarSpec: noise_std must be >= 0 and dropout_prob in [0, 1]")

    @property
    def angle_step(self) -> float:
        """Angle between neighbouring beams (rad)."""
        return self.aperture / (self.n_beams - 1)

    @property
    def beam_angles(self) -> np.ndarray:
        """Beam angles in the sensor frame (rad), from ``-aperture/2`` to ``+aperture/2``."""
        return -0.5 * self.aperture + self.angle_step * np.arange(self.n_beams)


def tim561(**overrides: float | int | tuple[float, float, float]) -> LidarSpec:
    """SICK TiM561: 270 deg aperture, 0.33 deg steps (811 beams), 0.05-10 m, 15 Hz (Harik 2018, sec. 2.1)."""
    base: dict[str, Any] = {
        "n_beams": 811,
        "aperture": math.radians(270.0),
        "min_range": 0.05,
        "max_range": 10.0,
        "rate_hz": 15.0,
    }
    base.update(overrides)
    return LidarSpec(**base)  # type: ignore[arg-type]


class Lidar:
    """A LIDAR mounted on a body; :meth:`scan` returns the ranges of one revolution."""

    def __init__(self, spec: LidarSpec) -> None:
        self.spec = spec
        angles = spec.beam_angles
        self._ux = np.cos(angles)
        self._uy = np.sin(angles)
        self._angle0 = float(angles[0])
        self._exact = np.empty(spec.n_beams)

    def pose_in_world(self, body_pose: np.ndarray) -> tuple[float, float, float]:
        """Sensor ``(x, y, heading)`` in the world for a body at ``(x, y, yaw)``."""
        x, y, yaw = float(body_pose[0]), float(body_pose[1]), float(body_pose[2])
        mx, my, myaw = self.spec.mount
        c, s = math.cos(yaw), math.sin(yaw)
        return x + c * mx - s * my, y + s * mx + c * my, yaw + myaw

    def exact_scan(self, body_pose: np.ndarray, circles: np.ndarray, capsules: np.ndarray) -> np.ndarray:
        """Noise-free ranges (m) against the given primitives, clipped to ``[min_range, max_range]``.

        The returned array is reused by the next call; copy it to keep it.
        """
        sx, sy, sh = self.pose_in_world(body_pose)
        out = self._exact
        cast_scan(
            sx,
            sy,
            sh,
            self._ux,
            self._uy,
            self._angle0,
            self.spec.angle_step,
            self.spec.min_range,
            self.spec.max_range,
            circles,
            capsules,
            out,
        )
        return out

    def scan(
        self, body_pose: np.ndarray, circles: np.ndarray, capsules: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        """Ranges (m) with Gaussian noise and dropouts drawn from ``rng`` (a fresh array)."""
        spec = self.spec
        exact = self.exact_scan(body_pose, circles, capsules)
        if spec.noise_std <= 0 and spec.dropout_prob <= 0:
            return exact.copy()
        ranges = rng.standard_normal(spec.n_beams) if spec.noise_std > 0 else np.zeros(spec.n_beams)
        ranges *= spec.noise_std
        ranges += exact
        if spec.dropout_prob > 0:
            ranges[rng.random(spec.n_beams) < spec.dropout_prob] = spec.max_range
        np.minimum(ranges, spec.max_range, out=ranges)
        np.maximum(ranges, spec.min_range, out=ranges)
        return ranges


@dataclasses.dataclass(frozen=True)
class SonarSpec:
    """An ultrasonic range finder that reports the nearest echo inside its cone.

    Attributes:
        aperture: Full opening angle of the cone (rad).
        min_range: Closest measurable distance (m).
        max_range: Reported when no echo returns (m).
        noise_std: Standard deviation of Gaussian range noise (m).
        foliage_slip_prob: Vegetation echoes (González 2009, Fig. 9): probability that a reading whose
            nearest echo comes off foliage slips between the leaves and reads long, uniformly between the
            foliage and the nearest solid echo behind it (or ``max_range``). 0 (off) by default; it needs
            the solid obstacles passed to :meth:`SonarArray.ranges`.
    """

    aperture: float = math.radians(15.0)
    min_range: float = 0.02
    max_range: float = 4.0
    noise_std: float = 0.0
    foliage_slip_prob: float = 0.0

    def __post_init__(self) -> None:
        if not 0 < self.aperture < math.pi:
            raise ValueError(f"SonarSpec: aperture must be in (0, pi), got {self.aperture}")
        if not 0 <= self.min_range < self.max_range:
            raise ValueError("SonarSpec: need 0 <= min_range < max_range")
        if not 0 <= self.foliage_slip_prob <= 1:
            raise ValueError(f"SonarSpec: foliage_slip_prob must be in [0, 1], got {self.foliage_slip_prob}")


def hc_sr04(**overrides: float) -> SonarSpec:
    """HC-SR04 ultrasonic sensor: 0.02-4 m, about a 15 deg cone."""
    base = {"aperture": math.radians(15.0), "min_range": 0.02, "max_range": 4.0}
    base.update(overrides)
    return SonarSpec(**base)


class SonarArray:
    """Several identical sonars placed on one body (mounts ``(k, 3)``: ``x, y, yaw`` in the body frame)."""

    def __init__(self, spec: SonarSpec, mounts: np.ndarray) -> None:
        self.spec = spec
        self.mounts = np.asarray(mounts, dtype=np.float64).reshape(-1, 3)
        self._poses = np.empty_like(self.mounts)
        self._out = np.empty(len(self.mounts))

    def __len__(self) -> int:
        return len(self.mounts)

    def poses_in_world(self, body_pose: np.ndarray) -> np.ndarray:
        """``(k, 3)`` sonar poses in the world for a body at ``(x, y, yaw)`` (reused array)."""
        x, y, yaw = float(body_pose[0]), float(body_pose[1]), float(body_pose[2])
        c, s = math.cos(yaw), math.sin(yaw)
        m = self.mounts
        p = self._poses
        p[:, 0] = x + c * m[:, 0] - s * m[:, 1]
        p[:, 1] = y + s * m[:, 0] + c * m[:, 1]
        p[:, 2] = yaw + m[:, 2]
        return p

    def exact_ranges(self, body_pose: np.ndarray, circles: np.ndarray, capsules: np.ndarray) -> np.ndarray:
        """Noise-free nearest-echo distances (m), clipped to ``[min_range, max_range]`` (reused array)."""
        spec = self.spec
        sonar_ranges(
            float(body_pose[0]),
            float(body_pose[1]),
            float(body_pose[2]),
            self.mounts,
            0.5 * spec.aperture,
            spec.max_range,
            circles,
            capsules,
            self._out,
        )
        np.maximum(self._out, spec.min_range, out=self._out)
        return self._out

    def ranges(
        self,
        body_pose: np.ndarray,
        circles: np.ndarray,
        capsules: np.ndarray,
        rng: np.random.Generator,
        solid: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """Distances (m) with Gaussian noise from ``rng`` (a fresh array).

        Args:
            body_pose: ``(x, y, yaw)`` of the body.
            circles: Every circle the sonars see.
            capsules: Every capsule the sonars see.
            rng: Source of the noise and the vegetation echoes.
            solid: ``(circles, capsules)`` of the obstacles that are not foliage. With
                ``spec.foliage_slip_prob > 0`` a reading is a foliage echo when the solid obstacles alone
                read farther; such readings slip long with that probability (see :class:`SonarSpec`).
        """
        out = self.exact_ranges(body_pose, circles, capsules).copy()
        if self.spec.foliage_slip_prob > 0 and solid is not None:
            hard = self.exact_ranges(body_pose, solid[0], solid[1])
            slip = (out < hard - 1e-9) & (rng.random(len(out)) < self.spec.foliage_slip_prob)
            if np.any(slip):
                out[slip] = rng.uniform(out[slip], hard[slip])
        if self.spec.noise_std > 0:
            out += self.spec.noise_std * rng.standard_normal(len(out))
            np.clip(out, self.spec.min_range, self.spec.max_range, out=out)
        return out

    def ranges_many(
        self,
        poses: np.ndarray,
        circles: np.ndarray,
        capsules: np.ndarray,
        skip: np.ndarray,
        rng: np.random.Generator,
        out: np.ndarray,
    ) -> np.ndarray:
        """Distances (m) of the sonars of many bodies that carry this same array (a robot team), in one call.

        Args:
            poses: ``(n, 3)`` body poses.
            circles: Every circle the sonars see (the bodies themselves among them).
            capsules: Every capsule the sonars see.
            skip: ``(n,)`` row of ``circles`` that is body ``b`` itself (its own sonars never see it), -1: none.
            rng: Source of the Gaussian noise (one ``(n, k)`` draw).
            out: ``(n, k)`` buffer for the noise-free ranges.

        Returns:
            ``(n, k)`` ranges clipped to ``[min_range, max_range]``: ``out`` itself without noise, else a
            fresh array.
        """
        spec = self.spec
        sonar_ranges_many(poses, self.mounts, 0.5 * spec.aperture, spec.max_range, circles, capsules, skip, out)
        if spec.noise_std > 0:
            ranges = out + spec.noise_std * rng.standard_normal(out.shape)
            np.clip(ranges, spec.min_range, spec.max_range, out=ranges)
            return ranges
        np.maximum(out, spec.min_range, out=out)
        return out
