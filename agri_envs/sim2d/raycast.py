"""Batched geometry kernels (numba): LIDAR scans, sonar cones and footprint clearance.

The scan is rasterised primitive by primitive instead of beam by beam: each circle or capsule within
range is turned into the interval of beam indices it can cover (its angular extent seen from the
sensor), and only those beams are intersected with it. The cost is the number of (primitive, beam)
pairs that can actually hit, not ``beams x primitives``. ``tests/sim2d/test_sensors.py`` checks these kernels
against :mod:`agri_envs.sim2d.reference`, which casts every ray one at a time with pymunk.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always")
def _wrap(a: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (a + math.pi) % _TWO_PI - math.pi


@numba.njit(cache=True, inline="always")
def _ray_circle(lx: float, ly: float, r: float, ux: float, uy: float) -> float:
    """Distance along the unit ray ``(ux, uy)`` from the origin to a circle at ``(lx, ly)``; inf if missed."""
    return _ray_disc(lx, ly, lx * lx + ly * ly - r * r, ux, uy)


@numba.njit(cache=True, inline="always")
def _ray_segment(ax: float, ay: float, bx: float, by: float, ux: float, uy: float) -> float:
    """Distance along the unit ray from the origin to segment ``a-b``; inf if missed or parallel."""
    ex = bx - ax
    ey = by - ay
    return _ray_line(ax, ay, ex, ey, ax * ey - ay * ex, ux, uy)


@numba.njit(cache=True, inline="always")
def _ray_line(ax: float, ay: float, ex: float, ey: float, cross: float, ux: float, uy: float) -> float:
    """:func:`_ray_segment` from ``a`` along ``e = b - a`` with ``cross = ax * ey - ay * ex`` computed beforehand."""
    denom = ux * ey - uy * ex
    if abs(denom) < 1e-15:
        return math.inf
    t = cross / denom
    s = (ax * uy - ay * ux) / denom
    if t <= 0.0 or s < 0.0 or s > 1.0:
        return math.inf
    return t


@numba.njit(cache=True, inline="always")
def _ray_disc(lx: float, ly: float, c: float, ux: float, uy: float) -> float:
    """:func:`_ray_circle` of a circle at ``(lx, ly)`` with ``c = lx * lx + ly * ly - r * r`` computed beforehand."""
    b = lx * ux + ly * uy
    disc = b * b - c
    if disc < 0.0:
        return math.inf
    t = b - math.sqrt(disc)
    if t <= 0.0:
        return math.inf
    return t


@numba.njit(cache=True)
def _ray_capsule(ax: float, ay: float, bx: float, by: float, r: float, ux: float, uy: float) -> float:
    """Distance along the unit ray from the origin to a capsule (segment ``a-b`` thickened by ``r``)."""
    if r == 0.0:
        return _ray_segment(ax, ay, bx, by, ux, uy)
    ex = bx - ax
    ey = by - ay
    length = math.sqrt(ex * ex + ey * ey)
    best = math.inf
    if length > 0.0:
        nx = -ey / length * r
        ny = ex / length * r
        t = _ray_segment(ax + nx, ay + ny, bx + nx, by + ny, ux, uy)
        best = min(best, t)
        t = _ray_segment(ax - nx, ay - ny, bx - nx, by - ny, ux, uy)
        best = min(best, t)
    best = min(best, _ray_circle(ax, ay, r, ux, uy))
    best = min(best, _ray_circle(bx, by, r, ux, uy))
    return best


@numba.njit(cache=True, inline="always")
def _capsule_in_frame(
    capsules: np.ndarray, i: int, ox: float, oy: float, ch: float, sh: float
) -> tuple[float, float, float, float]:
    """End points of capsule ``i`` in a frame at ``(ox, oy)`` rotated by the angle with cosine/sine ``ch, sh``."""
    wx = capsules[i, 0] - ox
    wy = capsules[i, 1] - oy
    vx = capsules[i, 2] - ox
    vy = capsules[i, 3] - oy
    return ch * wx + sh * wy, -sh * wx + ch * wy, ch * vx + sh * vy, -sh * vx + ch * vy


@numba.njit(cache=True, inline="always")
def _closest_on_segment(ax: float, ay: float, bx: float, by: float) -> tuple[float, float]:
    """Point of segment ``a-b`` closest to the origin."""
    ex = bx - ax
    ey = by - ay
    l2 = ex * ex + ey * ey
    if l2 == 0.0:
        return ax, ay
    s = -(ax * ex + ay * ey) / l2
    s = min(1.0, max(0.0, s))
    return ax + s * ex, ay + s * ey


@numba.njit(cache=True)
def cast_scan(
    ox: float,
    oy: float,
    heading: float,
    beam_ux: np.ndarray,
    beam_uy: np.ndarray,
    angle0: float,
    dangle: float,
    min_range: float,
    max_range: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    out: np.ndarray,
) -> None:
    """Exact ranges of a planar scan against circles and capsules, written into ``out``.

    Args:
        ox: Sensor x in the world (m).
        oy: Sensor y in the world (m).
        heading: Sensor heading in the world (rad).
        beam_ux: Unit beam directions in the sensor frame, x component, ``(n,)``.
        beam_uy: Unit beam directions in the sensor frame, y component, ``(n,)``.
        angle0: Angle of beam 0 in the sensor frame (rad); beams are evenly spaced by ``dangle``.
        dangle: Angular step between beams (rad).
        min_range: Hits closer than this are reported at ``min_range`` (m).
        max_range: Returned where nothing is hit within range (m).
        circles: ``(n_c, 3)`` circles ``x, y, r``.
        capsules: ``(n_s, 5)`` capsules ``x0, y0, x1, y1, r``.
        out: ``(n,)`` output ranges (m), distance from the sensor origin to the first hit, clipped to
            ``[min_range, max_range]``.
    """
    n = beam_ux.shape[0]
    for k in range(n):
        out[k] = max_range
    ch = math.cos(heading)
    sh = math.sin(heading)
    for i in range(circles.shape[0]):
        wx = circles[i, 0] - ox
        wy = circles[i, 1] - oy
        r = circles[i, 2]
        lx = ch * wx + sh * wy
        ly = -sh * wx + ch * wy
        d = math.sqrt(lx * lx + ly * ly)
        if d - r >= max_range or d <= r:
            continue
        hw = math.asin(r / d)
        th = math.atan2(ly, lx)
        c = lx * lx + ly * ly - r * r  # _ray_circle's beam-independent part
        nearest = d - r - 1e-9  # no hit on this circle is nearer (the margin covers rounding)
        for s in range(3):
            shift = (s - 1) * _TWO_PI
            k0 = max(0, int(math.ceil((th + shift - hw - angle0) / dangle)))
            k1 = min(n - 1, int(math.floor((th + shift + hw - angle0) / dangle)))
            for k in range(k0, k1 + 1):
                if out[k] <= nearest:
                    continue
                t = _ray_disc(lx, ly, c, beam_ux[k], beam_uy[k])
                if t < out[k]:
                    out[k] = t
    for i in range(capsules.shape[0]):
        ax, ay, bx, by = _capsule_in_frame(capsules, i, ox, oy, ch, sh)
        r = capsules[i, 4]
        qx, qy = _closest_on_segment(ax, ay, bx, by)
        dmin = math.sqrt(qx * qx + qy * qy)
        if dmin - r >= max_range or dmin <= r:
            continue
        ta = math.atan2(ay, ax)
        delta = _wrap(math.atan2(by, bx) - ta)
        lo = min(ta, ta + delta)
        hi = max(ta, ta + delta)
        if r > 0.0:
            hw = math.asin(min(1.0, r / dmin))
            lo -= hw
            hi += hw
        # _ray_capsule's beam-independent parts, computed once per capsule (the same numbers, so the same hits):
        # its pieces are two segments (the sides, or the segment itself when r = 0) and the two end discs.
        if r == 0.0:
            sides = 1
            p1x, p1y, q1x, q1y = ax, ay, bx, by
            p2x, p2y, q2x, q2y = ax, ay, bx, by
        else:
            ex = bx - ax
            ey = by - ay
            length = math.sqrt(ex * ex + ey * ey)
            sides = 2 if length > 0.0 else 0
            nx = -ey / length * r if length > 0.0 else 0.0
            ny = ex / length * r if length > 0.0 else 0.0
            p1x, p1y, q1x, q1y = ax + nx, ay + ny, bx + nx, by + ny
            p2x, p2y, q2x, q2y = ax - nx, ay - ny, bx - nx, by - ny
        e1x, e1y, e2x, e2y = q1x - p1x, q1y - p1y, q2x - p2x, q2y - p2y
        c1 = p1x * e1y - p1y * e1x
        c2 = p2x * e2y - p2y * e2x
        ca = ax * ax + ay * ay - r * r
        cb = bx * bx + by * by - r * r
        nearest = dmin - r - 1e-9  # no hit on this capsule is nearer (the margin covers rounding)
        for s in range(3):
            shift = (s - 1) * _TWO_PI
            k0 = max(0, int(math.ceil((lo + shift - angle0) / dangle)))
            k1 = min(n - 1, int(math.floor((hi + shift - angle0) / dangle)))
            for k in range(k0, k1 + 1):
                if out[k] <= nearest:
                    continue
                ux = beam_ux[k]
                uy = beam_uy[k]
                t = _ray_line(p1x, p1y, e1x, e1y, c1, ux, uy) if sides >= 1 else math.inf
                if sides == 2:
                    t = min(t, _ray_line(p2x, p2y, e2x, e2y, c2, ux, uy))
                if r > 0.0:
                    t = min(t, _ray_disc(ax, ay, ca, ux, uy))
                    t = min(t, _ray_disc(bx, by, cb, ux, uy))
                if t < out[k]:
                    out[k] = t
    for k in range(n):
        if out[k] < min_range:
            out[k] = min_range


@numba.njit(cache=True)
def _sonar_body(
    body_x: float,
    body_y: float,
    body_yaw: float,
    mounts: np.ndarray,
    half_aperture: float,
    max_range: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    circle_rows: np.ndarray,
    n_circles: int,
    capsule_rows: np.ndarray,
    n_capsules: int,
    out: np.ndarray,
) -> None:
    """:func:`sonar_ranges` for one body, over the circles ``circle_rows[:n_circles]`` and capsules likewise."""
    ex_x = math.cos(half_aperture)
    ex_y = math.sin(half_aperture)
    cb = math.cos(body_yaw)
    sb = math.sin(body_yaw)
    for j in range(mounts.shape[0]):
        ox = body_x + cb * mounts[j, 0] - sb * mounts[j, 1]
        oy = body_y + sb * mounts[j, 0] + cb * mounts[j, 1]
        ch = math.cos(body_yaw + mounts[j, 2])
        sh = math.sin(body_yaw + mounts[j, 2])
        best = max_range
        for c in range(n_circles):
            i = circle_rows[c]
            wx = circles[i, 0] - ox
            wy = circles[i, 1] - oy
            r = circles[i, 2]
            if abs(wx) - r >= best or abs(wy) - r >= best:
                continue
            lx = ch * wx + sh * wy
            ly = -sh * wx + ch * wy
            d = math.sqrt(lx * lx + ly * ly)
            if d - r >= best or d <= r:
                continue
            if abs(math.atan2(ly, lx)) <= half_aperture:
                best = d - r
                continue
            if abs(math.atan2(ly, lx)) > half_aperture + math.asin(r / d):
                continue
            best = min(best, _ray_circle(lx, ly, r, ex_x, ex_y), _ray_circle(lx, ly, r, ex_x, -ex_y))
        for c in range(n_capsules):
            i = capsule_rows[c]
            ax, ay, bx, by = _capsule_in_frame(capsules, i, ox, oy, ch, sh)
            r = capsules[i, 4]
            qx, qy = _closest_on_segment(ax, ay, bx, by)
            dq = math.sqrt(qx * qx + qy * qy)
            if dq - r >= best or dq <= r:
                continue
            if abs(math.atan2(qy, qx)) <= half_aperture:
                best = dq - r
                continue
            t1 = _ray_capsule(ax, ay, bx, by, r, ex_x, ex_y)
            t2 = _ray_capsule(ax, ay, bx, by, r, ex_x, -ex_y)
            best = min(best, t1, t2)
        out[j] = best


@numba.njit(cache=True)
def _near_rows(
    x: float,
    y: float,
    reach: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    skip: int,
    circle_rows: np.ndarray,
    capsule_rows: np.ndarray,
) -> tuple[int, int]:
    """Rows of the circles and capsules that come within ``reach`` of ``(x, y)`` (circle ``skip`` left out).

    The broad phase of :func:`sonar_ranges_many`: a primitive farther than the sonars' range plus their
    distance from the body centre cannot echo in any of the body's cones, so leaving it out changes
    nothing; every sonar then tests only the primitives near its body.
    """
    n_c = 0
    for i in range(circles.shape[0]):
        if i == skip:
            continue
        if math.hypot(circles[i, 0] - x, circles[i, 1] - y) - circles[i, 2] < reach:
            circle_rows[n_c] = i
            n_c += 1
    n_s = 0
    for i in range(capsules.shape[0]):
        qx, qy = _closest_on_segment(capsules[i, 0] - x, capsules[i, 1] - y, capsules[i, 2] - x, capsules[i, 3] - y)
        if math.sqrt(qx * qx + qy * qy) - capsules[i, 4] < reach:
            capsule_rows[n_s] = i
            n_s += 1
    return n_c, n_s


@numba.njit(cache=True)
def sonar_ranges(
    body_x: float,
    body_y: float,
    body_yaw: float,
    mounts: np.ndarray,
    half_aperture: float,
    max_range: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    out: np.ndarray,
) -> None:
    """Nearest echo inside each sonar's cone (not a single ray), written into ``out``.

    For a convex obstacle, the point nearest to the sonar inside the cone is either the obstacle's
    nearest point overall (when that lies inside the cone) or lies on one of the cone's two edge rays;
    both are computed exactly, so the result is the true nearest echo within the cone. A circle that
    contains the sonar (the robot's own body in :class:`~agri_envs.sim2d.world.World2D`, whose sonars sit
    just inside its outline) gives no echo.

    Args:
        body_x: x of the body carrying the sonars (m).
        body_y: y of the body (m).
        body_yaw: Heading of the body (rad).
        mounts: ``(k, 3)`` sonar ``x, y, yaw`` in the body frame.
        half_aperture: Half the cone's opening angle (rad).
        max_range: Returned when nothing lies in the cone within range (m).
        circles: ``(n_c, 3)`` circles.
        capsules: ``(n_s, 5)`` capsules.
        out: ``(k,)`` output distances (m).
    """
    poses = np.empty((1, 3))
    poses[0, 0], poses[0, 1], poses[0, 2] = body_x, body_y, body_yaw
    sonar_ranges_many(poses, mounts, half_aperture, max_range, circles, capsules, np.full(1, -1), out.reshape(1, -1))


@numba.njit(cache=True)
def sonar_ranges_many(
    poses: np.ndarray,
    mounts: np.ndarray,
    half_aperture: float,
    max_range: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    skip: np.ndarray,
    out: np.ndarray,
) -> None:
    """:func:`sonar_ranges` for many identical bodies in one call (a robot team).

    Args:
        poses: ``(n, 3)`` body poses ``x, y, yaw``.
        mounts: ``(k, 3)`` sonar mounts in the body frame (the same on every body).
        half_aperture: Half the cone's opening angle (rad).
        max_range: Returned when nothing lies in a cone within range (m).
        circles: ``(n_c, 3)`` circles (the bodies themselves among them).
        capsules: ``(n_s, 5)`` capsules.
        skip: ``(n,)`` row of ``circles`` that is body ``b`` itself (never sensed by its own sonars), -1: none.
        out: ``(n, k)`` output distances (m).
    """
    circle_rows = np.empty(circles.shape[0], dtype=np.int64)
    capsule_rows = np.empty(capsules.shape[0], dtype=np.int64)
    mount_reach = 0.0
    for j in range(mounts.shape[0]):
        mount_reach = max(mount_reach, math.hypot(mounts[j, 0], mounts[j, 1]))
    reach = max_range + mount_reach + 1e-9
    for b in range(poses.shape[0]):
        x, y = poses[b, 0], poses[b, 1]
        n_c, n_s = _near_rows(x, y, reach, circles, capsules, skip[b], circle_rows, capsule_rows)
        _sonar_body(
            x,
            y,
            poses[b, 2],
            mounts,
            half_aperture,
            max_range,
            circles,
            capsules,
            circle_rows,
            n_c,
            capsule_rows,
            n_s,
            out[b],
        )


@numba.njit(cache=True, inline="always")
def _point_box_distance(x: float, y: float, hx: float, hy: float) -> float:
    """Distance from a point to an origin-centred box (negative inside, by the depth to the nearest side)."""
    dx = abs(x) - hx
    dy = abs(y) - hy
    if dx <= 0.0 and dy <= 0.0:
        return max(dx, dy)
    dx = max(dx, 0.0)
    dy = max(dy, 0.0)
    return math.sqrt(dx * dx + dy * dy)


@numba.njit(cache=True)
def _segment_hits_box(ax: float, ay: float, bx: float, by: float, hx: float, hy: float) -> bool:
    """Whether segment ``a-b`` touches the origin-centred box (Liang-Barsky clipping)."""
    t0 = 0.0
    t1 = 1.0
    dx = bx - ax
    dy = by - ay
    for p, q in ((-dx, ax + hx), (dx, hx - ax), (-dy, ay + hy), (dy, hy - ay)):
        if p == 0.0:
            if q < 0.0:
                return False
        else:
            t = q / p
            if p < 0.0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
            if t0 > t1:
                return False
    return True


@numba.njit(cache=True)
def footprint_clearance(
    px: float,
    py: float,
    heading: float,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    skip: int = -1,
) -> float:
    """Smallest distance (m) between a rectangular footprint and any obstacle; <= 0 means contact.

    Args:
        px: Footprint centre x (m).
        py: Footprint centre y (m).
        heading: Footprint orientation (rad); its length runs along the heading.
        half_length: Half the footprint's length (m).
        half_width: Half the footprint's width (m).
        circles: ``(n_c, 3)`` circles.
        capsules: ``(n_s, 5)`` capsules.
        skip: Row of ``circles`` to ignore (the footprint's own body in a multi-robot world); -1: none.

    Returns:
        The clearance, ``inf`` when there are no obstacles.
    """
    ch = math.cos(heading)
    sh = math.sin(heading)
    circ = math.sqrt(half_length * half_length + half_width * half_width)
    best = math.inf
    for i in range(circles.shape[0]):
        if i == skip:
            continue
        wx = circles[i, 0] - px
        wy = circles[i, 1] - py
        r = circles[i, 2]
        if math.sqrt(wx * wx + wy * wy) - r - circ >= best:
            continue
        lx = ch * wx + sh * wy
        ly = -sh * wx + ch * wy
        best = min(best, _point_box_distance(lx, ly, half_length, half_width) - r)
    for i in range(capsules.shape[0]):
        ax, ay, bx, by = _capsule_in_frame(capsules, i, px, py, ch, sh)
        r = capsules[i, 4]
        qx, qy = _closest_on_segment(ax, ay, bx, by)
        if math.sqrt(qx * qx + qy * qy) - r - circ >= best:
            continue
        if _segment_hits_box(ax, ay, bx, by, half_length, half_width):
            best = min(best, -r)
            continue
        d = min(
            _point_box_distance(ax, ay, half_length, half_width),
            _point_box_distance(bx, by, half_length, half_width),
        )
        for cx, cy in (
            (half_length, half_width),
            (-half_length, half_width),
            (half_length, -half_width),
            (-half_length, -half_width),
        ):
            qx, qy = _closest_on_segment(ax - cx, ay - cy, bx - cx, by - cy)
            d = min(d, math.sqrt(qx * qx + qy * qy))
        best = min(best, d - r)
    return best


@numba.njit(cache=True)
def disc_clearance(
    px: float, py: float, radius: float, circles: np.ndarray, capsules: np.ndarray, skip: int = -1
) -> float:
    """Smallest distance (m) between a disc (a round robot) and any obstacle; <= 0 means contact.

    Args:
        px: Disc centre x (m).
        py: Disc centre y (m).
        radius: Disc radius (m).
        circles: ``(n_c, 3)`` circles.
        capsules: ``(n_s, 5)`` capsules.
        skip: Row of ``circles`` to ignore (the disc's own body); -1: none.

    Returns:
        The clearance, ``inf`` when there are no obstacles.
    """
    best = math.inf
    for i in range(circles.shape[0]):
        if i == skip:
            continue
        wx = circles[i, 0] - px
        wy = circles[i, 1] - py
        r = circles[i, 2] + radius
        if abs(wx) - r >= best or abs(wy) - r >= best:
            continue
        best = min(best, math.sqrt(wx * wx + wy * wy) - r)
    for i in range(capsules.shape[0]):
        ax = capsules[i, 0] - px
        ay = capsules[i, 1] - py
        bx = capsules[i, 2] - px
        by = capsules[i, 3] - py
        r = capsules[i, 4] + radius
        if min(ax, bx) - r >= best or -max(ax, bx) - r >= best or min(ay, by) - r >= best or -max(ay, by) - r >= best:
            continue
        qx, qy = _closest_on_segment(ax, ay, bx, by)
        best = min(best, math.sqrt(qx * qx + qy * qy) - r)
    return best
