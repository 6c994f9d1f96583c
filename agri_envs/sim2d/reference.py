"""Slow, obvious reference sensors: one pymunk segment query per ray.

Used by the tests as an independent oracle for the numba kernels in :mod:`agri_envs.sim2d.raycast`
(pymunk's collision code is a separate implementation of the same geometry).
"""

from __future__ import annotations

import math

import numpy as np
import pymunk

from agri_envs.sim2d.geometry import Geometry


def geometry_space(geometry: Geometry, extra_circles: np.ndarray | None = None) -> pymunk.Space:
    """A pymunk space holding every circle and capsule of ``geometry`` (plus ``extra_circles``)."""
    space = pymunk.Space()
    body = space.static_body
    circles = geometry.circles if extra_circles is None else np.vstack([geometry.circles, extra_circles])
    for x, y, r in circles:
        space.add(pymunk.Circle(body, float(r), offset=(float(x), float(y))))
    for x0, y0, x1, y1, r in geometry.capsules:
        space.add(pymunk.Segment(body, (float(x0), float(y0)), (float(x1), float(y1)), float(r)))
    return space


def reference_ray(space: pymunk.Space, x: float, y: float, angle: float, max_range: float) -> float:
    """Distance to the first shape along one ray, ``max_range`` when nothing is hit."""
    end = (x + max_range * math.cos(angle), y + max_range * math.sin(angle))
    hit = space.segment_query_first((x, y), end, 0.0, pymunk.ShapeFilter())
    if hit is None:
        return max_range
    return float(hit.alpha * max_range)


def reference_scan(
    space: pymunk.Space, x: float, y: float, heading: float, beam_angles: np.ndarray, max_range: float
) -> np.ndarray:
    """A whole scan, one ray at a time."""
    return np.array([reference_ray(space, x, y, heading + a, max_range) for a in beam_angles])


def reference_sonar(
    space: pymunk.Space,
    x: float,
    y: float,
    heading: float,
    half_aperture: float,
    max_range: float,
    n_rays: int = 2001,
) -> float:
    """Nearest echo in a cone, approximated by a dense fan of rays (converges to the exact value)."""
    angles = heading + np.linspace(-half_aperture, half_aperture, n_rays)
    return float(min(reference_ray(space, x, y, float(a), max_range) for a in angles))


def reference_disc_clearance(space: pymunk.Space, x: float, y: float, radius: float) -> float:
    """Distance (m) from a disc of ``radius`` at ``(x, y)`` to the nearest shape of ``space`` (pymunk's query)."""
    hit = space.point_query_nearest((x, y), 1e9, pymunk.ShapeFilter())
    if hit is None:
        return math.inf
    return float(hit.distance) - radius
