"""González et al. (2009): Pure Pursuit, the sonar peak filter, the sensory map and the pseudo-reactive controller.

Pure algorithms (no Gymnasium) first:

* :class:`PurePursuit` (Coulter 1992) follows a planned path with a 1 m look-ahead (sec. 4.2);
* :func:`peak_filter` / :class:`PeakFilter` implement eq. 1;
* :class:`SensoryMap` builds eq. 2's map of sonar echoes along the way;
* :class:`PseudoReactiveController`: the behaviours go straight, turn left, turn right and stop; the turn
  rule (two turns to one side, then two to the other, each measured by the compass and stopped at 90 deg);
  the front sonar slowing the robot; the centering (Fig. 7) and inclined-corridor (Fig. 8) processes.

Then the SB3-style policies for ``agri_envs/GreenhouseCoverage-v2`` (``gonzalez-deliberative``,
``gonzalez-pseudo-reactive``, ``gonzalez-hybrid``) as thin adapters over them.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque

import numpy as np

# --------------------------------------------------------------------------------------------------
# Pure Pursuit
# --------------------------------------------------------------------------------------------------


class PurePursuit:
    """Pure Pursuit path tracking (Coulter 1992) with an interpolated look-ahead point.

    The path is followed by arc length: the robot's closest point is searched forward only, within
    ``search_window`` metres of the last one (so a path that passes the same place twice is followed in
    order); the look-ahead point lies ``lookahead`` metres further along the path, interpolated between
    path points. Near the goal the look-ahead point is the goal itself, the speed follows the braking
    distance, and the robot stops within ``goal_tolerance``.

    With ``min_lookahead`` set, the look-ahead is regulated by the curvature of the path ahead (as adaptive
    and regulated Pure Pursuit do): ``lookahead`` where the next ``lookahead`` metres run straight, shortened
    to ``curve_ratio`` times the radius of the tightest bend among them, never below ``min_lookahead``.
    A fixed look-ahead starts turning a full look-ahead before a bend and cuts inside it: with 1 m, the
    Fitorobot cut every headland turn of its plan by 0.27-0.30 m. Without ``min_lookahead`` the look-ahead
    is fixed (Coulter's original).

    Args:
        path: ``(N, 2)`` path points (m), N >= 2.
        lookahead: Look-ahead distance (m); the paper's 1 m. With ``min_lookahead``: on straight paths.
        goal_tolerance: The goal counts as reached within this distance (m).
        search_window: How far ahead of the last closest point the next one is searched (m).
        min_lookahead: Shortest regulated look-ahead (m), or None for a fixed look-ahead.
        curve_ratio: Regulated look-ahead per metre of bend radius.
        curve_scale: Half-length of the chord over which the path's curvature is measured (m): bends
            shorter than this (the staircase of a path on a grid) do not shorten the look-ahead.
    """

    def __init__(
        self,
        path: np.ndarray,
        lookahead: float = 1.0,
        goal_tolerance: float = 0.15,
        search_window: float = 2.0,
        min_lookahead: float | None = None,
        curve_ratio: float = 0.5,
        curve_scale: float = 0.3,
    ) -> None:
        pts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9])
        pts = pts[keep]
        if len(pts) < 2:
            raise ValueError("PurePursuit: the path needs at least two distinct points")
        if not lookahead > 0 or not goal_tolerance > 0 or not search_window > 0:
            raise ValueError("PurePursuit: lookahead, goal_tolerance and search_window must be > 0 m")
        if min_lookahead is not None and not 0 < min_lookahead <= lookahead:
            raise ValueError(f"PurePursuit: min_lookahead must be in (0, lookahead={lookahead}] m, got {min_lookahead}")
        if not curve_ratio > 0 or not curve_scale > 0:
            raise ValueError("PurePursuit: curve_ratio and curve_scale must be > 0")
        self.path = pts
        self.s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        self.lookahead = lookahead
        self.goal_tolerance = goal_tolerance
        self.search_window = search_window
        self.min_lookahead = min_lookahead
        self.curve_ratio = curve_ratio
        #: Curvature (1/m) at every path point, measured over a chord of +-curve_scale metres.
        self.curvature = path_curvature(pts, self.s, curve_scale)
        self.progress = 0.0  # arc length of the closest point (m), never decreases
        self.distance = 0.0  # distance of the robot from that point at the last call of closest() (m)
        self.done = False

    @property
    def length(self) -> float:
        """Total path length (m)."""
        return float(self.s[-1])

    def point_at(self, s: float) -> np.ndarray:
        """The path point at arc length ``s`` (m), interpolated, clamped to the path's ends."""
        s = min(max(s, 0.0), self.length)
        return np.array([np.interp(s, self.s, self.path[:, 0]), np.interp(s, self.s, self.path[:, 1])])

    def closest(self, x: float, y: float) -> tuple[float, float]:
        """Forward-only closest point: ``(arc length, distance)`` within the search window; updates progress."""
        i0 = max(0, int(np.searchsorted(self.s, self.progress, side="right")) - 1)
        i1 = min(len(self.path) - 1, int(np.searchsorted(self.s, self.progress + self.search_window)) + 1)
        a = self.path[i0:i1]
        b = self.path[i0 + 1 : i1 + 1]
        if len(a) == 0:
            return self.progress, float(math.hypot(x - self.path[-1, 0], y - self.path[-1, 1]))
        d = b - a
        l2 = np.maximum(np.sum(d * d, axis=1), 1e-18)
        t = np.clip(((x - a[:, 0]) * d[:, 0] + (y - a[:, 1]) * d[:, 1]) / l2, 0.0, 1.0)
        q = a + t[:, None] * d
        dist = np.hypot(q[:, 0] - x, q[:, 1] - y)
        k = int(np.argmin(dist))
        s = float(self.s[i0 + k] + t[k] * math.sqrt(l2[k]))
        self.progress = max(self.progress, s)
        self.distance = float(dist[k])
        return self.progress, self.distance

    def bend_ahead(self, s: float) -> float:
        """The largest path curvature (1/m) within ``lookahead`` metres ahead of arc length ``s``."""
        i0 = max(0, int(np.searchsorted(self.s, s, side="right")) - 1)
        i1 = int(np.searchsorted(self.s, s + self.lookahead, side="right"))
        return float(self.curvature[i0 : max(i1, i0 + 1)].max())

    def lookahead_at(self, s: float) -> float:
        """The look-ahead (m) at arc length ``s``: fixed, or regulated by the bends of the next ``lookahead`` m."""
        if self.min_lookahead is None:
            return self.lookahead
        kappa = self.bend_ahead(s)
        if kappa <= 0:
            return self.lookahead
        return min(self.lookahead, max(self.min_lookahead, self.curve_ratio / kappa))

    def lookahead_point(self, x: float, y: float) -> np.ndarray:
        """The look-ahead point for a robot at ``(x, y)``: the look-ahead past the closest point, along the path."""
        s, _ = self.closest(x, y)
        return self.point_at(s + self.lookahead_at(s))

    def command(
        self, pose: np.ndarray, max_speed: float, max_turn_rate: float, max_accel: float, turn_in_place: float = 0.3
    ) -> tuple[float, float]:
        """Velocities ``(v, w)`` (m/s, rad/s) that steer toward the look-ahead point.

        The curvature is Coulter's ``2 y_L / L^2`` with the look-ahead point ``(x_L, y_L)`` in the robot
        frame at distance L; the speed is the largest that keeps ``|w| <= max_turn_rate`` and can still
        brake before the goal. A point more than ``turn_in_place`` rad off the heading makes the (tracked)
        robot turn on the spot first. At the goal the robot stops and :attr:`done` becomes True.

        Args:
            pose: ``(x, y, yaw)`` of the robot.
            max_speed: Speed limit (m/s).
            max_turn_rate: Turn-rate limit (rad/s).
            max_accel: Braking deceleration used for the approach to the goal (m/s^2).
            turn_in_place: Heading error above which the robot rotates on the spot (rad).
        """
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        goal = self.path[-1]
        d_goal = math.hypot(goal[0] - x, goal[1] - y)
        target = self.lookahead_point(x, y)
        remaining = self.length - self.progress
        if self.done or (remaining < self.lookahead and d_goal < self.goal_tolerance):
            self.done = True
            return 0.0, 0.0
        dx, dy = target[0] - x, target[1] - y
        c, s = math.cos(yaw), math.sin(yaw)
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        dist = math.hypot(lx, ly)
        alpha = math.atan2(ly, lx)
        if remaining < self.lookahead and lx <= 0.0:
            # The goal is beside or behind the robot within the last look-ahead: it has been passed.
            self.done = d_goal < self.lookahead
            if self.done:
                return 0.0, 0.0
        if abs(alpha) > turn_in_place:
            return 0.0, math.copysign(max_turn_rate, alpha)
        curvature = 2.0 * ly / max(dist * dist, 1e-9)
        v = min(max_speed, math.sqrt(2.0 * max_accel * max(0.0, remaining)))
        if abs(curvature) * v > max_turn_rate:
            v = max_turn_rate / abs(curvature)
        return v, v * curvature


def path_curvature(path: np.ndarray, s: np.ndarray, scale: float) -> np.ndarray:
    """Unsigned curvature (1/m) at every point of a polyline, from the turn of a chord of +-``scale`` metres.

    At point i the headings of the chords from ``s_i - scale`` to ``s_i`` and from ``s_i`` to
    ``s_i + scale`` (points interpolated along the path, clamped to its ends) differ by an angle; that
    angle over the arc length between the chords' midpoints is the curvature. A circle of radius R gives
    ``1 / R`` for ``scale`` well under R; a corner of angle a gives ``a / scale`` within ``scale`` of it.

    Args:
        path: ``(N, 2)`` points (m).
        s: Arc length at each point (m), increasing.
        scale: Chord half-length (m), > 0.
    """
    def at(t: np.ndarray) -> np.ndarray:
        t = np.clip(t, 0.0, s[-1])
        return np.column_stack([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])])

    back, here, ahead = at(s - scale), path, at(s + scale)
    h0 = np.arctan2(*(here - back).T[::-1])
    h1 = np.arctan2(*(ahead - here).T[::-1])
    turn = np.abs(np.arctan2(np.sin(h1 - h0), np.cos(h1 - h0)))
    span = np.minimum(s, scale) + np.minimum(s[-1] - s, scale)  # chords are shorter at the ends
    short = np.minimum(np.hypot(*(here - back).T), np.hypot(*(ahead - here).T)) < 1e-9  # at an end: no turn
    out = np.where(short, 0.0, turn / np.maximum(0.5 * span, 1e-9))
    return np.asarray(out, dtype=np.float64)


# --------------------------------------------------------------------------------------------------
# Peak filter (eq. 1) and sensory map (eq. 2)
# --------------------------------------------------------------------------------------------------


class PeakFilter:
    """The sonar peak filter of eq. 1 for one sensor, fed one reading at a time.

    A reading ``s_k`` is a peak when it differs by more than ``eps`` from more than half of the ``n``
    previous raw readings; a peak is replaced by the last accepted (filtered) value. A real change of
    distance (a corridor's end) persists, fills the window and is accepted after about ``n / 2`` readings.

    Reading of eq. 1: it is printed with ``(s_k - s_i) < eps`` inside the indicator, which would flag the
    readings that agree with the window. The text says a peak is a reading that "differs a greater quantity
    than a threshold" from the window, so we count ``|s_k - s_i| > eps`` (papers/README.md: text wins).

    Args:
        n: Window size (previous readings compared with the current one).
        eps: Threshold (m).
    """

    def __init__(self, n: int = 5, eps: float = 0.3) -> None:
        if n < 1:
            raise ValueError(f"PeakFilter: n must be >= 1, got {n}")
        if not eps > 0:
            raise ValueError(f"PeakFilter: eps must be > 0 m, got {eps}")
        self.n = n
        self.eps = eps
        self.window: deque[float] = deque(maxlen=n)
        self.value: float | None = None
        self.last_was_peak = False

    def reset(self) -> None:
        """Forget the window."""
        self.window.clear()
        self.value = None
        self.last_was_peak = False

    def __call__(self, s: float) -> float:
        """Filter one reading and return the filtered value."""
        s = float(s)
        peak = False
        if len(self.window) == self.n:
            differing = sum(abs(s - si) > self.eps for si in self.window)
            peak = differing > self.n / 2
        self.window.append(s)
        self.last_was_peak = peak
        if not peak or self.value is None:
            self.value = s
        return self.value


def peak_filter(series: np.ndarray, n: int = 5, eps: float = 0.3) -> np.ndarray:
    """Apply eq. 1 to a whole series (see :class:`PeakFilter`); returns a new array."""
    f = PeakFilter(n, eps)
    return np.array([f(v) for v in np.asarray(series, dtype=np.float64).reshape(-1)])


def sonar_echo(
    x: float, y: float, heading: float, mount: np.ndarray | tuple[float, float, float], d: float
) -> tuple[float, float]:
    """Eq. 2: where an echo at range ``d`` lies, seen from the robot's pose ``(x, y, heading)``.

    ``mount`` is the sonar's ``(x, y, yaw)`` in the body frame; range 0 gives the sonar's own position.
    """
    mx, my, myaw = (float(v) for v in mount)
    c, s = math.cos(heading), math.sin(heading)
    return x + c * mx - s * my + d * math.cos(heading + myaw), y + s * mx + c * my + d * math.sin(heading + myaw)


class SensoryMap:
    """The sensory map of eq. 2: sonar echoes placed in the odometry frame along the way.

    Eq. 2 places an echo at distance ``d`` seen by a sonar at angle ``theta`` from the robot's position
    ``(x, y)``: ``x - d sin(theta)``, ``y - d cos(theta)``, with angles measured like a compass. In our frame
    (angles counter-clockwise from x) the same point is ``(x, y) + d (cos(h + theta), sin(h + theta))``;
    we also add the sonar's mounting position, which matters on a 1.5 m long robot.

    Args:
        mounts: ``(k, 3)`` sonar ``x, y, yaw`` in the body frame.
        max_range: Readings at or beyond this are no echo and are not mapped (m).
        cell: Echoes closer than this to one already in the map are merged (m).
    """

    def __init__(self, mounts: np.ndarray, max_range: float, cell: float = 0.05) -> None:
        self.mounts = np.asarray(mounts, dtype=np.float64).reshape(-1, 3)
        self.max_range = max_range
        self.cell = cell
        self._cells: set[tuple[int, int]] = set()
        self.points: list[tuple[float, float]] = []
        self.trajectory: list[tuple[float, float]] = []

    def add(self, x: float, y: float, heading: float, ranges: np.ndarray, valid: np.ndarray | None = None) -> None:
        """Add the echoes of one set of readings taken at pose ``(x, y, heading)`` (eq. 2)."""
        self.trajectory.append((x, y))
        for k, mount in enumerate(self.mounts):
            d = float(ranges[k])
            if d >= self.max_range - 1e-6 or (valid is not None and not valid[k]):
                continue
            px, py = sonar_echo(x, y, heading, mount, d)
            key = (int(math.floor(px / self.cell)), int(math.floor(py / self.cell)))
            if key not in self._cells:
                self._cells.add(key)
                self.points.append((px, py))

    def as_array(self) -> np.ndarray:
        """``(n, 2)`` echo positions (m)."""
        return np.array(self.points, dtype=np.float64).reshape(-1, 2)

    def occupancy(
        self, resolution: float = 0.05, obstacle_radius: float = 0.1, free_radius: float = 1.0, margin: float = 1.5
    ) -> tuple[np.ndarray, tuple[float, float]]:
        """The map as an occupancy grid for the deliberative planner (hybrid architecture, Fig. 2).

        Only what the robot perceived is free: cells within ``free_radius`` of its trajectory that are not
        within ``obstacle_radius`` of an echo. Everything else (unexplored) is blocked.

        Returns:
            ``(occupancy, origin)``: boolean grid (True = blocked) and the world position of its corner.
        """
        from scipy import ndimage as ndi

        traj = np.array(self.trajectory, dtype=np.float64).reshape(-1, 2)
        pts = self.as_array()
        if len(traj) == 0:
            raise ValueError("SensoryMap: nothing was recorded")
        allp = np.vstack([traj, pts]) if len(pts) else traj
        lo = allp.min(axis=0) - margin
        hi = allp.max(axis=0) + margin
        shape = (int(math.ceil((hi[1] - lo[1]) / resolution)), int(math.ceil((hi[0] - lo[0]) / resolution)))

        def mark(points: np.ndarray) -> np.ndarray:
            grid = np.zeros(shape, dtype=bool)
            if len(points):
                ij = np.floor((points - lo) / resolution).astype(np.int64)
                grid[ij[:, 1], ij[:, 0]] = True
            return grid

        near_traj = ndi.distance_transform_edt(~mark(traj)) * resolution <= free_radius
        near_echo = ndi.distance_transform_edt(~mark(pts)) * resolution <= obstacle_radius
        return ~(near_traj & ~near_echo), (float(lo[0]), float(lo[1]))


# --------------------------------------------------------------------------------------------------
# Pseudo-reactive controller (sec. 3.2)
# --------------------------------------------------------------------------------------------------


class MouthDetector:
    """Finds a corridor's mouth in one lateral sonar's readings while crossing the headland.

    This project's own entry logic (the paper gives none). The sonar looks at the row ends: a reading
    below ``closed_range`` is a row end (or the plants beside it), above ``open_range`` it looks down a
    corridor. The decision is taken on the readings through eq. 1's peak filter (its own instance), so a
    burst of echoes slipping into the foliage does not open a mouth: a mouth opens when the filtered reading
    rises above ``open_range`` after at least ``min_closed`` row-end readings, and closes once it has stayed
    below ``closed_range`` for ``confirm`` readings (leaves reaching into the corridor close it only
    briefly); an open stretch shorter than ``min_width`` is dropped (a gap between plants).
    Looking down a corridor of plants the beam reads anything from ``open_range`` to its maximum range, and
    eq. 1 takes such a string of readings for peaks (each differs by more than ``eps`` from most of the
    window) and holds the row end's value: the readings are therefore saturated at ``open_range + eps / 2``
    before the filter, which keeps every distinction the decision needs. Eq. 1 accepts a real change only
    once it fills most of its window, later on a ramp (the cone sliding past a row end) than on a step, so
    the mouth's ends are dated by the raw readings: where the run of raw readings above (below)
    ``closed_range`` that the filter has just accepted began (a single reading of the other side inside
    the run does not end it). The same threshold at both ends makes the
    middle of the mouth the corridor's centre line.

    Args:
        open_range: Filtered readings above this look down a corridor (m).
        closed_range: Readings below this see a row end (m).
        min_width: Shortest open stretch that counts as a mouth (m).
        min_closed: Row-end readings needed before a mouth counts (the corridor just left is no mouth).
        memory: Raw readings kept to date the ends.
        filter_n: Eq. 1's window n.
        filter_eps: Eq. 1's threshold eps (m).
        confirm: Filtered row-end readings that close a mouth.
        merge_gap: A mouth that opens within this distance (m) of the last one's end continues it (leaves
            that closed it for longer than ``confirm`` readings).
    """

    def __init__(
        self,
        open_range: float,
        closed_range: float,
        min_width: float,
        min_closed: int = 2,
        memory: int = 40,
        filter_n: int = 5,
        filter_eps: float = 0.3,
        confirm: int = 5,
        merge_gap: float = 0.3,
    ) -> None:
        if not open_range >= closed_range:
            raise ValueError(f"MouthDetector: open_range ({open_range}) must be >= closed_range ({closed_range})")
        self.open_range = open_range
        self.closed_range = closed_range
        self.min_width = min_width
        self.min_closed = min_closed
        self.memory = memory
        self.filter = PeakFilter(filter_n, filter_eps)
        self.confirm = confirm
        self.merge_gap = merge_gap
        self.reset()

    def reset(self) -> None:
        """Forget the readings (a new headland crossing)."""
        self._raw: deque[tuple[float, float]] = deque(maxlen=self.memory)
        self.filter.reset()
        self.closed = 0
        self.opened_at: float | None = None
        self._closing: tuple[float, int] | None = None  # (dated end, filtered row-end readings since)
        self.last: tuple[float, float] | None = None  # the last mouth found

    @property
    def is_open(self) -> bool:
        """True while the sonar looks down a mouth (after a row end)."""
        return self.opened_at is not None

    def _run_start(self, is_open: bool) -> float:
        """Travelled distance of the first raw reading of the latest run on the open (closed) side.

        A single reading of the other side does not end the run: past a row end, echoes slipping into the
        foliage read long now and then, and would otherwise date the end of a mouth late.
        """
        start = self._raw[-1][0]
        other = 0
        for s, r in reversed(self._raw):
            if (r >= self.closed_range) != is_open:
                other += 1
                if other == 2:
                    break
                continue
            other = 0
            start = s
        return start

    def update(self, s: float, raw: float) -> tuple[float, float] | None:
        """Feed one reading taken at travelled distance ``s``; a mouth ``(start, end)`` when one closes.

        Args:
            s: Distance travelled along the headland (m).
            raw: The sonar's raw reading (m).

        Returns:
            None, or the travelled distances (m) at which the sonar entered and left the mouth.
        """
        self._raw.append((s, float(raw)))
        filtered = self.filter(min(float(raw), self.open_range + 0.5 * self.filter.eps))
        if filtered < self.closed_range:
            self.closed += 1
            if self.opened_at is not None:
                end, count = self._closing or (self._run_start(False), 0)
                self._closing = (end, count + 1)
                if count + 1 >= self.confirm:
                    start, self.opened_at, self._closing = self.opened_at, None, None
                    if self.last is not None and start - self.last[1] <= self.merge_gap:
                        start = self.last[0]
                    if end - start >= self.min_width:
                        self.last = (start, end)
                        return start, end
        elif filtered > self.open_range:
            self._closing = None  # it opened again: leaves, not the next row end
            if self.opened_at is None and self.closed >= self.min_closed:
                self.opened_at = self._run_start(True)
        return None


@dataclasses.dataclass(frozen=True)
class PseudoReactiveParams:
    """Gains and thresholds of the pseudo-reactive controller (the paper's are "obtained heuristically").

    Attributes:
        cruise_speed: Speed along corridors (m/s).
        turn_rate: Rotation speed of the turn behaviours (rad/s).
        turn_speed: Forward speed during the first turn at a corridor end (m/s): an arc of radius
            ``turn_speed / turn_rate`` that leaves a wall beside the robot; the second turn, in the open
            headland, is on the spot.
        slow_distance: The front sonar starts slowing the robot below this distance (m).
        stop_distance: ... and stops it here (m).
        side_valid: Lateral readings below this see a row or a wall beside the robot; above, the row ended (m).
        side_open: Crossing the headland, a turn-side reading above this looks down a corridor's mouth (m).
        row_end_range: Crossing the headland, the turn-side sonar sees a row end closer than this (m).
        exit_distance: Distance driven after the turn-side middle sonar sees the rows end, before the first
            90 deg turn (m).
        mouth_width: Shortest open stretch of the turn-side front sonar that counts as a corridor's mouth
            (m, :class:`MouthDetector`).
        across_speed: Speed along the headland once the front lateral sonar looks down a mouth (m/s): the
            robot must stop on the mouth's centre line within its acceleration limit.
        brake_decel: Deceleration the approach to the mouth's centre line plans with (m/s^2), below the
            robot's limit.
        entry_tolerance: The second turn starts within this distance of the mouth's centre line (m).
        confirm_overrun: Past the centre line by more than this without the middle sonar looking down the
            mouth too, the mouth is dropped as a false one (m).
        min_corridor: Distance driven between rows before a corridor end may be detected (m).
        end_confirm: The turn side must stay open over this distance before the corridor end counts (m).
        k_heading: Heading gain (1/s).
        k_center: Centering gain: heading offset per metre of lateral offset (rad/m), Fig. 7.
        max_center_angle: Largest heading offset of the centering process (rad).
        k_incline: Per-step gain of the inclined-corridor correction of the reference heading, Fig. 8.
        map_range: Echoes farther than this are not put in the sensory map (m).
        filter_n: Peak filter window n (eq. 1).
        filter_eps: Peak filter threshold eps (m, eq. 1).
    """

    cruise_speed: float = 0.4
    turn_rate: float = 0.4
    turn_speed: float = 0.2
    slow_distance: float = 1.2
    stop_distance: float = 0.35
    side_valid: float = 1.2
    side_open: float = 2.5
    row_end_range: float = 2.0
    exit_distance: float = 0.55
    mouth_width: float = 0.15
    across_speed: float = 0.2
    brake_decel: float = 0.2
    entry_tolerance: float = 0.03
    confirm_overrun: float = 0.3
    min_corridor: float = 2.0
    end_confirm: float = 0.45
    k_heading: float = 1.2
    k_center: float = 0.6
    max_center_angle: float = 0.15
    k_incline: float = 0.05
    map_range: float = 1.5
    filter_n: int = 5
    filter_eps: float = 0.3


def adapted_params(
    params: PseudoReactiveParams, max_speed: float, max_turn_rate: float, budget: float
) -> PseudoReactiveParams:
    """``params`` for a robot with other limits and a tighter time budget than the one it was tuned for.

    The gains were tuned on the default Fitorobot (0.5 m/s, 0.6 rad/s), whose episodes take under half of
    the env's time limit. The limit is sized to the robot's speed limits (``mission_time``), so a faster
    robot gets less time: with ``budget`` (the default robot's limit over this one's) above 2 the speeds and
    the turn rate grow by ``budget / 2``, so that an episode keeps within the limit. The turn rate never
    exceeds the robot's, and the first turn's forward speed follows the turn rate so that its arc keeps its
    radius (``turn_speed / turn_rate``, 0.5 m): on a robot that turns slower than ``turn_rate`` the arc
    would otherwise widen into the rows. With the default limits the parameters come back unchanged.

    Args:
        params: The tuned parameters.
        max_speed: The robot's forward speed limit (m/s).
        max_turn_rate: The robot's turn rate limit (rad/s).
        budget: The default robot's time limit over this robot's (1 with the default limits).
    """
    scale = max(1.0, 0.5 * budget)
    turn_rate = min(params.turn_rate * scale, max_turn_rate)
    return dataclasses.replace(
        params,
        cruise_speed=min(params.cruise_speed * scale, max_speed),
        across_speed=min(params.across_speed * scale, max_speed),
        turn_rate=turn_rate,
        turn_speed=params.turn_speed * (turn_rate / params.turn_rate),
    )


FRONT, LF, LM, LR, RF, RM, RR = range(7)
SONAR_BASELINE = 1.2  # m between the front and rear lateral sonars of the Fitorobot


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


class PseudoReactiveController:
    """The pseudo-reactive corridor follower of sec. 3.2 for one robot (no map).

    Phases: ``corridor`` (go straight with centering and inclined-corridor correction), ``exit`` (drive out
    past the rows), ``turn1`` (turn 90 deg by the compass), ``across`` (go straight along the headland, at
    right angles to the corridor's heading, until the robot stands on the next corridor's centre line),
    ``turn2`` (second 90 deg turn, on the spot) and ``stop`` (a wall ahead at a corridor end: no further
    corridor). The turn rule: the first turn goes to the open side; each corridor end takes two turns to one
    side, the next end two turns to the other.

    Corridor entry (this project's own; the paper gives none): crossing the headland, the turn-side front
    lateral sonar, 0.6 m ahead of the robot's centre, finds the next mouth in its eq. 1-filtered readings
    (:class:`MouthDetector`: an open stretch after a row end, at least ``mouth_width`` long); the middle of
    that stretch is the corridor's centre line, which the robot's centre reaches 0.6 m later. The robot
    slows once the front sonar looks down a mouth, brakes onto the centre line (backing up if it overran),
    and turns on the spot there once the middle lateral sonar also looks down the mouth; a mouth the middle
    sonar never confirms is dropped. Entering, the robot centres on the front lateral pair before the middle
    pair is between the rows.

    Args:
        params: Gains and thresholds.
        mounts: Sonar mounts (``(7, 3)``, the Fitorobot's order: front, left f/m/r, right f/m/r).
        max_range: Sonar maximum range (m).
    """

    def __init__(self, params: PseudoReactiveParams, mounts: np.ndarray, max_range: float) -> None:
        self.p = params
        self.max_range = max_range
        self.mounts = np.asarray(mounts, dtype=np.float64)
        self.map = SensoryMap(self.mounts, max_range)
        self.filters = [PeakFilter(params.filter_n, params.filter_eps) for _ in range(len(self.mounts))]
        self.reset()

    def reset(self) -> None:
        """New run: empty map, fresh filters, first turn side undecided."""
        self.map = SensoryMap(self.mounts, self.max_range)
        for f in self.filters:
            f.reset()
        self.phase = "corridor"
        self.behaviour = "go straight"
        self.reference: float | None = None  # corridor heading (rad)
        self.turn_side = 0  # +1 left, -1 right, 0 undecided
        self.turns = 0
        self.turn_start = 0.0
        self.in_rows = 0.0
        self.mark: tuple[float, float] | None = None
        self.seen_row = False
        self.row_count = 0
        self.arc = False
        self.end_mark: tuple[float, float] | None = None
        p = self.p
        self.mouth_front = MouthDetector(
            p.side_open, p.row_end_range, p.mouth_width, filter_n=p.filter_n, filter_eps=p.filter_eps
        )
        self.mouth_middle = MouthDetector(
            p.side_open, p.row_end_range, p.mouth_width, filter_n=p.filter_n, filter_eps=p.filter_eps
        )
        self.across_heading = 0.0
        self.entry: float | None = None  # travelled distance along the headland of the next centre line

    def _travelled(self, x: float, y: float) -> float:
        if self.mark is None:
            return 0.0
        return math.hypot(x - self.mark[0], y - self.mark[1])

    def command(self, sonar: np.ndarray, heading: float, x: float, y: float, dt: float) -> tuple[float, float]:
        """One control step: ``(v, w)`` from the raw sonar ranges (m), the compass and the odometry position."""
        p = self.p
        filt = np.array([f(v) for f, v in zip(self.filters, sonar, strict=True)])
        # Map only what the filter vouches for: a full window, no peak, and an echo near enough for its
        # position to be known (a 20 deg cone at 4 m is 1.4 m wide).
        valid_echo = np.array(
            [
                len(f.window) == f.n and not f.last_was_peak and v < p.map_range
                for f, v in zip(self.filters, filt, strict=True)
            ]
        )
        self.map.add(x, y, heading, filt, valid_echo)
        if self.reference is None:
            self.reference = heading
        front = filt[FRONT]
        left, right = filt[[LF, LM, LR]], filt[[RF, RM, RR]]
        slow = min(1.0, max(0.0, (front - p.stop_distance) / (p.slow_distance - p.stop_distance)))
        if self.phase == "corridor":
            return self._corridor(left, right, heading, x, y, slow, dt)
        if self.phase == "exit":
            if self._travelled(x, y) >= p.exit_distance or front < p.stop_distance + 0.3:
                self.phase, self.turn_start, self.arc = "turn1", heading, True
                return self._turn(heading)
            return self._straight(heading, self.reference, p.cruise_speed * slow)
        if self.phase == "turn1":
            if abs(_wrap(heading - self.turn_start)) >= math.pi / 2:
                # Along the headland at right angles to the corridor's heading (not to the heading the turn
                # began at, which the centering had swung by up to max_center_angle).
                self.across_heading = _wrap(self.reference + self.turn_side * math.pi / 2)
                self.phase, self.mark, self.seen_row, self.entry = "across", (x, y), False, None
                self._fresh_filters()  # readings taken while rotating say nothing about the row ends
                self.mouth_front.reset()
                self.mouth_middle.reset()
                return self._straight(heading, self.across_heading, 0.0)
            return self._turn(heading)
        if self.phase == "across":
            return self._across(sonar, filt, heading, x, y, slow)
        if self.phase == "turn2":
            if abs(_wrap(heading - self.turn_start)) >= math.pi / 2:
                self.reference = _wrap(self.across_heading + self.turn_side * math.pi / 2)
                self.turns += 2
                self.phase, self.in_rows, self.mark = "corridor", 0.0, (x, y)
                self._fresh_filters()
                return self._straight(heading, self.reference, 0.0)
            return self._turn(heading)
        self.behaviour = "stop"
        return 0.0, 0.0

    def _across(
        self, sonar: np.ndarray, filt: np.ndarray, heading: float, x: float, y: float, slow: float
    ) -> tuple[float, float]:
        """Cross the headland to the next corridor's centre line (see the class docstring), then turn."""
        p = self.p
        assert self.mark is not None
        across = self.across_heading
        s = (x - self.mark[0]) * math.cos(across) + (y - self.mark[1]) * math.sin(across)
        i_front, i_mid = (LF, LM) if self.turn_side > 0 else (RF, RM)
        found = self.mouth_front.update(s, float(sonar[i_front]))
        middle = self.mouth_middle.update(s, float(sonar[i_mid]))
        if filt[i_mid] < p.row_end_range:
            self.row_count += 1
            self.seen_row = self.seen_row or self.row_count >= 2
        if found is not None:  # a later mouth (or one merged with the last) replaces the estimate
            self.entry = 0.5 * (found[0] + found[1]) + float(self.mounts[i_front, 0])
        elif self.entry is None and middle is not None and not self.mouth_front.is_open:
            # The front sonar missed it: the middle one's mouth, behind the robot.
            self.entry = 0.5 * (middle[0] + middle[1]) + float(self.mounts[i_mid, 0])
        v = p.cruise_speed * slow
        if self.mouth_front.is_open:
            v = min(v, p.across_speed)
        if self.entry is not None:
            remaining = self.entry - s
            # The middle sonar confirms the mouth when it entered it before the centre line.
            m_start = self.mouth_middle.opened_at
            confirmed = m_start is not None and m_start <= self.entry + p.entry_tolerance
            if confirmed and abs(remaining) <= p.entry_tolerance:
                self.phase, self.turn_start, self.arc = "turn2", heading, False
                return self._turn(heading)
            if not confirmed and (remaining < -p.confirm_overrun or m_start is not None):
                # The middle sonar never looked down it, or only past its supposed centre line: the front
                # sonar's mouth was a wrong one (leaves closed it early); look on.
                self.entry = None
            elif not confirmed and remaining <= p.entry_tolerance:
                v = min(v, 0.05)  # creep on until the middle sonar looks down the mouth too
            else:
                # Brake onto the centre line within brake_decel (v = sqrt(2 a d), linear near it); back up
                # if the robot overran it.
                speed = min(p.across_speed, math.sqrt(2 * p.brake_decel * abs(remaining)), abs(remaining))
                v = min(v, speed) if remaining > 0 else -speed
        if filt[FRONT] < p.stop_distance + 0.15:
            if self.seen_row:
                # A wall ahead past a row end: the last corridor runs along the wall. The robot cannot
                # drive on to its centre line, so it turns in along an arc (as the first turn does).
                self.phase, self.turn_start, self.arc = "turn2", heading, True
                return self._turn(heading)
            self.phase, self.behaviour = "stop", "stop"
            return 0.0, 0.0
        return self._straight(heading, across, v)

    def _fresh_filters(self) -> None:
        for f in self.filters:
            f.reset()
        self.row_count = 0

    def _turn(self, heading: float) -> tuple[float, float]:
        self.behaviour = "turn left" if self.turn_side > 0 else "turn right"
        return (self.p.turn_speed if self.arc else 0.0), self.turn_side * self.p.turn_rate

    def _straight(self, heading: float, target: float, v: float) -> tuple[float, float]:
        err = _wrap(target - heading)
        w = max(-self.p.turn_rate, min(self.p.turn_rate, self.p.k_heading * err))
        self.behaviour = "turn left" if w > 0.05 else "turn right" if w < -0.05 else "go straight"
        return v * max(0.2, 1.0 - abs(err) / 0.5), w

    def _corridor(
        self, left: np.ndarray, right: np.ndarray, heading: float, x: float, y: float, slow: float, dt: float
    ) -> tuple[float, float]:
        p = self.p
        assert self.reference is not None
        lv, rv = left < p.side_valid, right < p.side_valid
        between_rows = bool(lv[1] and rv[1])
        if between_rows:
            self.in_rows += p.cruise_speed * dt
            # Inclined corridor (Fig. 8): front and rear lateral readings differ -> the rows run at an angle
            # to the robot; the reference turns toward the side whose front reading is larger.
            angles = []
            if lv[0] and lv[2]:
                angles.append(math.atan2(left[2] - left[0], SONAR_BASELINE))
            if rv[0] and rv[2]:
                angles.append(math.atan2(right[0] - right[2], SONAR_BASELINE))
            if angles:
                rel = float(np.mean(angles))  # robot heading relative to the rows (left positive)
                self.reference = _wrap(self.reference + p.k_incline * _wrap(heading - rel - self.reference))
        # Centering (Fig. 7): turn toward the side with the larger lateral readings (step 1), go straight
        # (step 2), turn back as the offset vanishes (step 3).
        offset = 0.0
        if between_rows:
            offset = 0.5 * (float(np.mean(left[lv])) - float(np.mean(right[rv])))
        elif lv[0] and rv[0]:
            # Entering: only the front lateral pair is between the rows yet; centre on it.
            offset = 0.5 * (float(left[0]) - float(right[0]))
        target = self.reference + max(-p.max_center_angle, min(p.max_center_angle, p.k_center * offset))
        # Corridor end: the front and middle sonars of the turn side (undecided: either side) no longer see a row.
        if self.in_rows >= p.min_corridor:
            open_l, open_r = bool(np.all(left[:2] > p.side_valid)), bool(np.all(right[:2] > p.side_valid))
            side = self.turn_side_for(open_l, open_r)
            if side == 0:
                self.end_mark = None
            elif self.end_mark is None:
                self.end_mark = (x, y)
            elif math.hypot(x - self.end_mark[0], y - self.end_mark[1]) >= p.end_confirm:
                # Open for end_confirm metres: not a gap between plants or a burst of vegetation echoes.
                self.turn_side = side
                self.phase, self.mark, self.end_mark = "exit", self.end_mark, None
        return self._straight(heading, target, p.cruise_speed * slow)

    def turn_side_for(self, open_left: bool, open_right: bool) -> int:
        """The turn rule: +1 (left) / -1 (right) when the rows end on the side the rule picks, else 0.

        The first corridor end turns to the open side (left when both are open); after two turns to one
        side (one corridor end) the next two go to the other side.
        """
        if self.turns == 0 and self.turn_side == 0:
            if open_left:
                return 1
            return -1 if open_right else 0
        side = -self.turn_side  # the previous end took two turns to turn_side: this one takes two the other way
        return side if (open_left if side > 0 else open_right) else 0
