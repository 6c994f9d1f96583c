"""Compiled pieces of a 2D world step, shared by the batched envs (numba, one world at a time).

The batched envs (:mod:`agri_envs.rover.vector`, ...) step many worlds in one compiled loop. Their single
envs stay the reference: every function here is the twin of a piece of Python in :mod:`agri_envs.sim2d`
(named in its docstring) and computes the same numbers bit for bit, drawing the same random numbers from
the same NumPy generator (numba draws NumPy's own streams, sharing the generator's state). To get there:

* Python's float semantics are kept where they differ from C's: :func:`py_hypot` is CPython's ``math.hypot``
  (its own algorithm, not the C library's); numba's ``min`` and ``max`` already return what Python's do,
  ties and signed zeros included (``tests/sim2d/test_batched.py`` checks both).
* Operations keep the reference's order (floating-point addition is not associative), and no fused
  multiply-adds are formed (numba does not contract without ``fastmath``).
* Contact: the single env asks pymunk whether the robot's box overlaps anything; the twin uses the exact
  footprint distance of :func:`~agri_envs.sim2d.raycast.footprint_clearance` (``<= 0``: contact). The two
  can disagree only where a pose touches an obstacle exactly, to within rounding; the batched envs' tests
  check that this never happened in their runs.
"""

from __future__ import annotations

import math
import sys

import numba
import numpy as np

from agri_envs.sim2d.raycast import cast_scan, disc_clearance, footprint_clearance, sonar_ranges

# -- Python's scalar semantics ----------------------------------------------------------------------------


_T27 = 134217729.0  # 2**27 + 1: Veltkamp's constant, splits a double into two 26-bit halves
_DBL_MIN = 2.2250738585072014e-308


@numba.njit(cache=True, inline="always")
def _split(x: float) -> tuple[float, float]:
    """Veltkamp split: ``hi + lo == x`` exactly, each with at most 26 significant bits."""
    t = x * _T27
    hi = t - (t - x)
    return hi, x - hi


@numba.njit(cache=True)
def _norm_t27(ax: float, ay: float, big: float) -> float:
    """CPython 3.10 and 3.11 ``vector_norm`` of ``(ax, ay)`` (``Modules/mathmodule.c``), ``big`` the larger."""
    _, max_e = math.frexp(big)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    frac3 = 0.0
    if max_e >= -1023:
        scale = math.ldexp(1.0, -max_e)
        for v in (ax, ay):
            hi, lo = _split(v * scale)
            sq = hi * hi
            old = csum
            csum += sq
            frac1 += (old - csum) + sq
            sq = 2.0 * hi * lo
            old = csum
            csum += sq
            frac2 += (old - csum) + sq
            frac3 += lo * lo
        h = math.sqrt(csum - 1.0 + (frac1 + frac2 + frac3))
        hi, lo = _split(h)
        sq = -hi * hi
        old = csum
        csum += sq
        frac1 += (old - csum) + sq
        sq = -2.0 * hi * lo
        old = csum
        csum += sq
        frac2 += (old - csum) + sq
        sq = -lo * lo
        old = csum
        csum += sq
        frac3 += (old - csum) + sq
        sq = csum - 1.0 + (frac1 + frac2 + frac3)
        return (h + sq / (2.0 * h)) / scale
    for v in (ax, ay):  # subnormal scale: divide by the largest instead
        q = v / big
        q = q * q
        old = csum
        csum += q
        frac1 += (old - csum) + q
    return big * math.sqrt(csum - 1.0 + frac1)


@numba.njit(cache=True, inline="always")
def _product(x: float, y: float) -> tuple[float, float]:
    """``x * y`` rounded and its exact rounding error (Dekker), which is what ``fma(x, y, -x * y)`` gives."""
    z = x * y
    xh, xl = _split(x)
    yh, yl = _split(y)
    return z, ((xh * yh - z) + xh * yl + xl * yh) + xl * yl


@numba.njit(cache=True)
def _norm_fma(ax: float, ay: float, big: float) -> float:
    """CPython 3.12+ ``vector_norm``: the same sum of squares, squared with ``fma`` error terms."""
    _, max_e = math.frexp(big)
    if max_e < -1023:  # subnormals: scale up by DBL_MIN first
        return _DBL_MIN * _norm_fma(ax / _DBL_MIN, ay / _DBL_MIN, big / _DBL_MIN)
    scale = math.ldexp(1.0, -max_e)
    csum = 1.0
    frac1 = 0.0
    frac2 = 0.0
    for v in (ax, ay):
        hi, lo = _product(v * scale, v * scale)
        s = csum + hi
        frac2 += (csum - s) + hi
        csum = s
        frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi, lo = _product(-h, h)
    s = csum + hi
    frac2 += (csum - s) + hi
    csum = s
    frac1 += lo
    q = csum - 1.0 + (frac1 + frac2)
    h += q / (2.0 * h)
    return h / scale


_norm = _norm_fma if sys.version_info >= (3, 12) else _norm_t27  # CPython changed the algorithm in 3.12


@numba.njit(cache=True)
def py_hypot(x: float, y: float) -> float:
    """CPython's ``math.hypot(x, y)`` for the running interpreter (not the C library's ``hypot``)."""
    ax = abs(x)
    ay = abs(y)
    if math.isinf(ax) or math.isinf(ay):
        return math.inf
    if math.isnan(ax) or math.isnan(ay):
        return math.nan
    big = max(ax, ay)
    if big == 0.0:
        return 0.0
    return _norm(ax, ay, big)


# -- motion -----------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def arc(x: float, y: float, th: float, v: float, w: float, dt: float) -> tuple[float, float, float]:
    """:func:`~agri_envs.sim2d.diff_drive.unicycle_arc` on scalars: the pose after ``dt`` at ``(v, w)``."""
    if abs(w) < 1e-9:
        return x + v * dt * math.cos(th), y + v * dt * math.sin(th), th
    th1 = th + w * dt
    k = v / w
    return (
        x + k * (math.sin(th1) - math.sin(th)),
        y - k * (math.cos(th1) - math.cos(th)),
        math.atan2(math.sin(th1), math.cos(th1)),
    )


@numba.njit(cache=True, inline="always")
def limited_velocity(
    v: float, w: float, v_cmd: float, w_cmd: float, limits: np.ndarray, dt: float
) -> tuple[float, float]:
    """:func:`~agri_envs.sim2d.diff_drive.limit_velocity` on scalars.

    ``limits``: ``max_speed, max_reverse_speed, max_turn_rate, max_accel, max_angular_accel``.
    """
    v_cmd = min(limits[0], max(-limits[1], v_cmd))
    w_cmd = min(limits[2], max(-limits[2], w_cmd))
    dv = limits[3] * dt
    dw = limits[4] * dt
    return v + min(dv, max(-dv, v_cmd - v)), w + min(dw, max(-dw, w_cmd - w))


@numba.njit(cache=True, inline="always")
def _clearance(
    x: float,
    y: float,
    th: float,
    radius: float,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    skip: int,
) -> float:
    """Clearance of a disc (``radius > 0``) or of a rectangular footprint at ``(x, y, th)``."""
    if radius > 0.0:
        return disc_clearance(x, y, radius, circles, capsules, skip)
    return footprint_clearance(x, y, th, half_length, half_width, circles, capsules, skip)


@numba.njit(cache=True)
def sweep(
    x: float,
    y: float,
    th: float,
    v: float,
    w: float,
    dt: float,
    reach: float,
    max_substep: float,
    radius: float,
    half_length: float,
    half_width: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    skip: int,
) -> tuple[float, float, float, bool]:
    """:meth:`~agri_envs.sim2d.world.World2D.drive`'s motion at the new velocities ``(v, w)``, with exact contact.

    One arc when nothing lies within ``reach``; otherwise substeps no longer than ``max_substep`` that stop
    at the last pose that touches nothing (or that moved out of an overlap it started in). A disc robot
    (``radius > 0``) or a rectangle (``half_length``, ``half_width``); ``skip`` is its own row of ``circles``.

    Returns:
        The new pose ``x, y, th`` and whether the robot touched something (it stopped before).
    """
    clear = _clearance(x, y, th, radius, half_length, half_width, circles, capsules, skip)
    if clear > reach + 1e-6:
        x, y, th = arc(x, y, th, v, w, dt)
        return x, y, th, False
    n_sub = max(1, math.ceil(reach / max_substep))
    h = dt / n_sub
    inside = clear <= 0.0
    for _ in range(n_sub):
        cx, cy, cth = arc(x, y, th, v, w, h)
        new_clear = _clearance(cx, cy, cth, radius, half_length, half_width, circles, capsules, skip)
        if new_clear <= 0.0:
            if not inside or new_clear <= clear:
                return x, y, th, True
            clear = new_clear
        else:
            inside = False
        x, y, th = cx, cy, cth
    return x, y, th, False


@numba.njit(cache=True)
def drive_box(
    pose: np.ndarray,
    vel: np.ndarray,
    v_cmd: float,
    w_cmd: float,
    limits: np.ndarray,
    half_length: float,
    half_width: float,
    circumradius: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    dt: float,
    max_substep: float,
) -> bool:
    """:meth:`~agri_envs.sim2d.world.World2D.drive` for a world's only, rectangular robot; updates in place.

    Contact is the exact footprint distance reaching zero (see the module docstring).

    Args:
        pose: ``(3,)`` ``x, y, yaw``, updated.
        vel: ``(2,)`` achieved ``v, w``, updated (zero after a contact).
        v_cmd: Commanded linear velocity (m/s).
        w_cmd: Commanded angular velocity (rad/s).
        limits: ``max_speed, max_reverse_speed, max_turn_rate, max_accel, max_angular_accel``.
        half_length: Half the footprint's length (m).
        half_width: Half the footprint's width (m).
        circumradius: The footprint's circumradius (m), as :attr:`DiffDriveSpec.circumradius` gives it.
        circles: ``(n, 3)`` circles of the world (people included).
        capsules: ``(m, 5)`` capsules of the world.
        dt: Duration (s).
        max_substep: The world's substep length near obstacles (m).

    Returns:
        True on contact (the robot stays at the last pose that did not touch anything).
    """
    v, w = limited_velocity(vel[0], vel[1], v_cmd, w_cmd, limits, dt)
    # A rectangle that turns in place sweeps its corners: they reach as far as the circumradius turns.
    reach = abs(v) * dt + abs(w) * dt * circumradius
    x, y, th, contact = sweep(
        pose[0], pose[1], pose[2], v, w, dt, reach, max_substep, 0.0, half_length, half_width, circles, capsules, -1
    )
    pose[0], pose[1], pose[2] = x, y, th
    vel[0], vel[1] = (0.0, 0.0) if contact else (v, w)
    return contact


# -- people -------------------------------------------------------------------------------------------------

WALK, STAND = 0, 1


@numba.njit(cache=True)
def step_people(
    rng: np.random.Generator,
    rows: np.ndarray,
    prev_node: np.ndarray,
    next_node: np.ndarray,
    speed: np.ndarray,
    mode: np.ndarray,
    timer: np.ndarray,
    reacted: np.ndarray,
    nodes: np.ndarray,
    adjacency: np.ndarray,
    degree: np.ndarray,
    robot_x: float,
    robot_y: float,
    robot_reach: float,
    dt: float,
    notice_distance: float,
    tease_prob: float,
    stand_low: float,
    stand_high: float,
) -> None:
    """:meth:`~agri_envs.sim2d.crowd.Crowd.plan` then the world's step for the people of one world.

    Args:
        rng: The env's generator.
        rows: ``(p, 3)`` the people's rows of the world's circles (``x, y, r``); ``x, y`` move.
        prev_node: ``(p,)`` node each person comes from, updated.
        next_node: ``(p,)`` node each person walks to, updated.
        speed: ``(p,)`` walking speeds (m/s).
        mode: ``(p,)`` :data:`WALK` or :data:`STAND`, updated.
        timer: ``(p,)`` standing time left (s), updated.
        reacted: ``(p,)`` whether each person already reacted to the robot, updated.
        nodes: ``(k, 2)`` route nodes (m).
        adjacency: ``(k, d)`` each node's sorted neighbours (padded).
        degree: ``(k,)`` number of neighbours of each node.
        robot_x: Robot centre x (m).
        robot_y: Robot centre y (m).
        robot_reach: Robot circumradius (m).
        dt: Step (s).
        notice_distance: A robot closer than this ahead makes a person react (m).
        tease_prob: Chance of standing in the robot's way instead of turning back.
        stand_low: Shortest standing time (s).
        stand_high: Longest standing time (s).
    """
    n = rows.shape[0]
    vel = np.zeros((n, 2))
    for i in range(n):
        if mode[i] == STAND:
            timer[i] -= dt
            if timer[i] <= 0.0:
                mode[i] = WALK
                prev_node[i], next_node[i] = next_node[i], prev_node[i]
            continue
        px, py = rows[i, 0], rows[i, 1]
        nx, ny = nodes[next_node[i], 0], nodes[next_node[i], 1]
        dist = py_hypot(nx - px, ny - py)
        if dist < 1e-6:  # arrived: walk on to a random neighbour, not straight back if possible
            node = next_node[i]
            n_options = 0
            for j in range(degree[node]):
                n_options += adjacency[node, j] != prev_node[i]
            choice = prev_node[i]  # a dead end: back where they came from (NumPy draws nothing from one option)
            if n_options > 0:
                pick = rng.integers(0, n_options)
                for j in range(degree[node]):
                    if adjacency[node, j] != prev_node[i]:
                        if pick == 0:
                            choice = adjacency[node, j]
                            break
                        pick -= 1
            prev_node[i] = node
            next_node[i] = choice
            nx, ny = nodes[choice, 0], nodes[choice, 1]
            dist = py_hypot(nx - px, ny - py)
        hx, hy = (nx - px) / dist, (ny - py) / dist
        dx, dy = robot_x - px, robot_y - py
        centre = py_hypot(dx, dy)
        if centre - robot_reach < notice_distance and dx * hx + dy * hy > 0.3 * centre:  # the robot is ahead
            if not reacted[i] and rng.random() >= tease_prob:
                prev_node[i], next_node[i] = next_node[i], prev_node[i]
            else:  # stand in the robot's way (or keep waiting for it to leave)
                mode[i] = STAND
                timer[i] = rng.uniform(stand_low, stand_high) if not reacted[i] else 1.0
            reacted[i] = True
        else:
            reacted[i] = False
            s = min(speed[i], dist / dt)  # stop exactly on the node
            vel[i, 0], vel[i, 1] = hx * s, hy * s
    for i in range(n):  # the space integrates the kinematic bodies
        rows[i, 0] = rows[i, 0] + vel[i, 0] * dt
        rows[i, 1] = rows[i, 1] + vel[i, 1] * dt


# -- sensors ------------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def lidar_scan(
    rng: np.random.Generator,
    pose: np.ndarray,
    mount: np.ndarray,
    beam_ux: np.ndarray,
    beam_uy: np.ndarray,
    angle0: float,
    dangle: float,
    min_range: float,
    max_range: float,
    noise_std: float,
    dropout_prob: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    out: np.ndarray,
) -> None:
    """:meth:`~agri_envs.sim2d.sensors.Lidar.scan` of a body at ``pose``, written into ``out`` (m)."""
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    sx = pose[0] + c * mount[0] - s * mount[1]
    sy = pose[1] + s * mount[0] + c * mount[1]
    heading = pose[2] + mount[2]
    cast_scan(sx, sy, heading, beam_ux, beam_uy, angle0, dangle, min_range, max_range, circles, capsules, out)
    if noise_std <= 0.0 and dropout_prob <= 0.0:
        return
    if noise_std > 0.0:  # all the noise first, then all the dropouts, as NumPy draws them
        for k in range(out.shape[0]):
            out[k] = rng.standard_normal() * noise_std + out[k]
    if dropout_prob > 0.0:
        for k in range(out.shape[0]):
            if rng.random() < dropout_prob:
                out[k] = max_range
    for k in range(out.shape[0]):
        out[k] = max(min(out[k], max_range), min_range)


@numba.njit(cache=True)
def sonar_scan(
    rng: np.random.Generator,
    pose: np.ndarray,
    mounts: np.ndarray,
    half_aperture: float,
    min_range: float,
    max_range: float,
    noise_std: float,
    slip_prob: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    solid_circles: np.ndarray,
    solid_capsules: np.ndarray,
    out: np.ndarray,
    hard: np.ndarray,
) -> None:
    """:meth:`~agri_envs.sim2d.sensors.SonarArray.ranges` of a body at ``pose``, written into ``out`` (m).

    With ``slip_prob > 0`` a reading whose echo comes off foliage (the solid obstacles alone read farther)
    slips long with that probability, as the single env's sonars do; ``hard`` is scratch for those readings.
    """
    sonar_ranges(pose[0], pose[1], pose[2], mounts, half_aperture, max_range, circles, capsules, out)
    n = out.shape[0]
    for k in range(n):
        out[k] = max(out[k], min_range)
    if slip_prob > 0.0:
        sonar_ranges(pose[0], pose[1], pose[2], mounts, half_aperture, max_range, solid_circles, solid_capsules, hard)
        slip = np.zeros(n, dtype=np.bool_)
        for k in range(n):  # every sonar's chance is drawn, then the slipped readings' lengths, as NumPy does
            hard[k] = max(hard[k], min_range)
            slip[k] = rng.random() < slip_prob
        for k in range(n):
            if slip[k] and out[k] < hard[k] - 1e-9:
                out[k] = out[k] + (hard[k] - out[k]) * rng.random()
    if noise_std > 0.0:
        for k in range(n):
            out[k] = out[k] + noise_std * rng.standard_normal()
        for k in range(n):
            out[k] = min(max(out[k], min_range), max_range)


@numba.njit(cache=True)
def wheel_odometry(
    rng: np.random.Generator, estimate: np.ndarray, v: float, w: float, dt: float, noise: float, gyro_bias: float
) -> None:
    """:meth:`~agri_envs.sim2d.odometry.WheelOdometry.integrate`: ``estimate`` (x, y, yaw) after ``dt``, in place."""
    v = v * (1.0 + noise * rng.standard_normal())
    w = w * (1.0 + noise * rng.standard_normal()) + gyro_bias
    th = estimate[2]
    th_mid = th + 0.5 * w * dt
    estimate[0] = estimate[0] + v * dt * math.cos(th_mid)
    estimate[1] = estimate[1] + v * dt * math.sin(th_mid)
    estimate[2] = math.atan2(math.sin(th + w * dt), math.cos(th + w * dt))


@numba.njit(cache=True)
def compass_read(rng: np.random.Generator, yaw: float, bias: float, noise_std: float) -> float:
    """:meth:`~agri_envs.sim2d.odometry.Compass.read`: the measured heading (rad) of a body heading ``yaw``."""
    h = yaw + bias
    if noise_std > 0:
        h += noise_std * rng.standard_normal()
    return math.atan2(math.sin(h), math.cos(h))


@numba.njit(cache=True)
def track_odometry(
    rng: np.random.Generator,
    v: float,
    w: float,
    heading: float,
    dt: float,
    gauge: float,
    scale: np.ndarray,
    noise: float,
    estimate: np.ndarray,
) -> tuple[float, float]:
    """:meth:`~agri_envs.sim2d.odometry.TrackOdometry.update`: measured ``(v, w)``; ``estimate`` ``(x, y)`` advances."""
    half = 0.5 * gauge
    left = (v - w * half) * scale[0]
    right = (v + w * half) * scale[1]
    if noise > 0:
        n_left = rng.standard_normal()
        n_right = rng.standard_normal()
        left = left * (1.0 + noise * n_left)
        right = right * (1.0 + noise * n_right)
    v_meas = 0.5 * (left + right)
    w_meas = (right - left) / gauge
    estimate[0] = estimate[0] + v_meas * dt * math.cos(heading)
    estimate[1] = estimate[1] + v_meas * dt * math.sin(heading)
    return v_meas, w_meas


@numba.njit(cache=True)
def pooled(scan: np.ndarray, starts: np.ndarray, scale: float, out: np.ndarray) -> None:
    """``np.minimum.reduceat(scan, starts) / scale`` as float32 into ``out`` (sectors from each start to the next)."""
    n = starts.shape[0]
    for j in range(n):
        lo = starts[j]
        hi = starts[j + 1] if j + 1 < n else scan.shape[0]
        best = scan[lo]
        for k in range(lo + 1, hi):
            best = min(best, scan[k])
        out[j] = np.float32(best / scale)
