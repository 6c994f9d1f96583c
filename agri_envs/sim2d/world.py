"""The shared 2D world: a pymunk space seen from above (no gravity).

Static obstacles come from a :class:`~agri_envs.sim2d.geometry.Geometry`; people (and other moving
obstacles) are kinematic pymunk bodies that the space integrates; robots are kinematic bodies driven as
unicycles. Robot motion never tunnels: a step that could reach an obstacle (the clearance kernel says
so) is split into substeps shorter than half the thinnest obstacle, and pymunk's shape query stops the
robot at the last pose before contact.

The world also keeps flat arrays of every circle and capsule (static ones followed by the moving ones)
for the numba sensor kernels. Every robot is an obstacle to every other robot: each one owns a row of
:attr:`World2D.circles` (a round robot its disc, a rectangular one its circumscribed circle, a
conservative stand-in for the other robots' sensors and clearance; contact between rectangles is still
exact through pymunk). A robot never senses itself: its sensors sit inside its own circle, which the
sensor kernels skip, and its clearance skips its own row. A world with a single robot has no robot row at
all, so single-robot envs pay nothing for this.
"""

from __future__ import annotations

import atexit
import dataclasses
import gc
import math
import weakref
from collections.abc import Sequence

import numba
import numpy as np
import pymunk

from agri_envs.sim2d.diff_drive import DiffDriveSpec, limit_velocity, unicycle_arc
from agri_envs.sim2d.geometry import Geometry
from agri_envs.sim2d.raycast import disc_clearance, footprint_clearance

# Pymunk collision categories: robots do not sense or hit themselves through these filters.
_ROBOT_GROUP_BASE = 1000


@numba.njit(cache=True)
def _arc(x: float, y: float, th: float, v: float, w: float, dt: float) -> tuple[float, float, float]:
    """:func:`~agri_envs.sim2d.diff_drive.unicycle_arc` on scalars."""
    if abs(w) < 1e-9:
        return x + v * dt * math.cos(th), y + v * dt * math.sin(th), th
    th1 = th + w * dt
    k = v / w
    return (
        x + k * (math.sin(th1) - math.sin(th)),
        y - k * (math.cos(th1) - math.cos(th)),
        math.atan2(math.sin(th1), math.cos(th1)),
    )


@numba.njit(cache=True)
def _drive_discs(
    poses: np.ndarray,
    vel: np.ndarray,
    cmd: np.ndarray,
    limits: np.ndarray,
    radius: np.ndarray,
    rows: np.ndarray,
    circles: np.ndarray,
    capsules: np.ndarray,
    dt: float,
    max_substep: float,
    contact: np.ndarray,
) -> None:
    """:meth:`World2D.drive` for many disc robots in turn (each sees the others where they already are)."""
    for k in range(poses.shape[0]):
        vmax, vrev, wmax, acc, wacc = limits[k, 0], limits[k, 1], limits[k, 2], limits[k, 3], limits[k, 4]
        v_cmd = min(vmax, max(-vrev, cmd[k, 0]))
        w_cmd = min(wmax, max(-wmax, cmd[k, 1]))
        dv = acc * dt
        dw = wacc * dt
        v = vel[k, 0] + min(dv, max(-dv, v_cmd - vel[k, 0]))
        w = vel[k, 1] + min(dw, max(-dw, w_cmd - vel[k, 1]))
        x, y, th = poses[k, 0], poses[k, 1], poses[k, 2]
        r = radius[k]
        skip = rows[k]
        reach = abs(v) * dt
        clear = disc_clearance(x, y, r, circles, capsules, skip)
        hit = False
        if clear > reach + 1e-6:
            x, y, th = _arc(x, y, th, v, w, dt)
        else:
            n_sub = max(1, math.ceil(reach / max_substep))
            h = dt / n_sub
            inside = clear <= 0.0
            for _ in range(n_sub):
                cx, cy, cth = _arc(x, y, th, v, w, h)
                new_clear = disc_clearance(cx, cy, r, circles, capsules, skip)
                if new_clear <= 0.0:
                    if not inside or new_clear <= clear:
                        hit = True
                        break
                    clear = new_clear
                else:
                    inside = False
                x, y, th = cx, cy, cth
        poses[k, 0], poses[k, 1], poses[k, 2] = x, y, th
        if hit:
            vel[k, 0], vel[k, 1] = 0.0, 0.0
        else:
            vel[k, 0], vel[k, 1] = v, w
        contact[k] = hit
        if skip >= 0:
            circles[skip, 0] = x
            circles[skip, 1] = y


@dataclasses.dataclass
class RobotBody:
    """A differential-drive robot living in a :class:`World2D`.

    Attributes:
        spec: Size and limits.
        pose: ``(x, y, yaw)`` in the world (m, m, rad).
        v: Achieved linear velocity (m/s).
        w: Achieved angular velocity (rad/s).
        body: The kinematic pymunk body.
        shape: Its box (or disc) shape.
        radius: Disc radius of a round robot (m); 0 for a rectangular one.
        circle_index: Its row in :attr:`World2D.circles` (what the other robots sense); -1 while it is the
            world's only robot.
    """

    spec: DiffDriveSpec
    pose: np.ndarray
    v: float
    w: float
    body: pymunk.Body
    shape: pymunk.Shape
    radius: float = 0.0
    circle_index: int = -1


class World2D:
    """A pymunk space with static geometry, moving circular obstacles (people) and robots.

    Args:
        geometry: The static scene.
        n_movers: Number of moving circular obstacles (people) to reserve slots for.
    """

    def __init__(self, geometry: Geometry, n_movers: int = 0) -> None:
        self.geometry = geometry
        self.space = pymunk.Space()
        self.space.gravity = (0.0, 0.0)
        self._static_shapes: list[pymunk.Shape] = []
        self.movers: list[pymunk.Body] = []
        for _ in range(n_movers):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            shape = pymunk.Circle(body, 0.2)
            self.space.add(body, shape)
            self.movers.append(body)
        self.robots: list[RobotBody] = []
        self.circles = np.zeros((0, 3))
        self._set_scene(geometry, np.column_stack([np.zeros((n_movers, 2)), np.full(n_movers, 0.2)]))
        _LIVE_WORLDS.add(self)

    def _set_scene(self, geometry: Geometry, mover_rows: np.ndarray) -> None:
        """Static shapes and the sensor arrays for ``geometry``: static circles, then movers, then robots."""
        self.geometry = geometry
        static = self.space.static_body
        shapes: list[pymunk.Shape] = []
        for x, y, r in geometry.circles.tolist():
            shapes.append(pymunk.Circle(static, r, offset=(x, y)))
        for x0, y0, x1, y1, r in geometry.capsules.tolist():
            if r > 0:  # zero-radius capsules are polygon edges; the polygon itself is added below
                shapes.append(pymunk.Segment(static, (x0, y0), (x1, y1), r))
        for poly in geometry.polygons:
            shapes.append(pymunk.Poly(static, [(float(p[0]), float(p[1])) for p in poly]))
        if self._static_shapes:
            self.space.remove(*self._static_shapes)
        self.space.add(*shapes)
        self._static_shapes = shapes
        n_static = len(geometry.circles)
        robot_rows = self.robot_circles.copy() if len(self.robots) >= 2 else np.zeros((0, 3))
        #: Every circle the sensors see: static ones, then one slot per mover, then one per robot.
        self.circles = np.vstack([geometry.circles, mover_rows, robot_rows])
        self.capsules = np.ascontiguousarray(geometry.capsules)
        self._mover_slice = slice(n_static, n_static + len(mover_rows))
        if len(robot_rows):
            for k, robot in enumerate(self.robots):
                robot.circle_index = n_static + len(mover_rows) + k
        self._disc_cache: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        thin = [float(r) for r in geometry.circles[:, 2]] + [float(r) for r in geometry.capsules[:, 4] if r > 0]
        # Substep length: half the thinnest obstacle's half-thickness, so a substep can never jump over it.
        self.max_substep = max(0.002, 0.5 * min(thin, default=0.1))

    def replace_scene(self, geometry: Geometry) -> None:
        """Swap the static scene for another, keeping the movers and the robots (their bodies are reused).

        The robots' rows in :attr:`circles` move behind the new static circles; their ``circle_index``
        follows. Nothing happens when ``geometry`` is the current scene.
        """
        if geometry is not self.geometry:
            self._set_scene(geometry, self.mover_circles.copy())

    def place_robots(self, robots: Sequence[RobotBody], poses: np.ndarray) -> None:
        """Put robots at new poses, at rest (a new episode), without making new bodies.

        Args:
            robots: Robots of this world.
            poses: ``(n, 3)`` poses ``(x, y, yaw)``.
        """
        p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        for robot, pose in zip(robots, p, strict=True):
            robot.pose = pose.copy()
            robot.v = robot.w = 0.0
            self._sync(robot, robot.pose)

    def close(self) -> None:
        """Free the pymunk objects now (idempotent); the world cannot be used afterwards.

        pymunk frees its C objects from cffi callbacks that read pymunk's module globals. A space still
        alive when the interpreter wipes those globals at exit (an env that was never closed, kept
        alive into that phase) makes the callbacks fail with ``Exception ignored ... spacefree ...
        'NoneType' object has no attribute 'new_handle'``. Closing drops every reference to pymunk
        objects, so they are freed while pymunk is intact; an exit hook closes the worlds left open.
        """
        if "space" not in self.__dict__:
            return
        self.space.remove(*self.space.shapes, *self.space.bodies)
        del self.space
        self.movers.clear()
        for robot in self.robots:
            del robot.body, robot.shape
        self.robots.clear()

    # -- moving obstacles -------------------------------------------------------------------------------
    @property
    def mover_circles(self) -> np.ndarray:
        """View of the movers' rows in :attr:`circles` (``x, y, r``)."""
        return self.circles[self._mover_slice]

    def place_mover(self, i: int, x: float, y: float, radius: float, vx: float = 0.0, vy: float = 0.0) -> None:
        """Put mover ``i`` at ``(x, y)`` with a radius and a velocity the next :meth:`step` integrates."""
        body = self.movers[i]
        shape = next(iter(body.shapes))
        if isinstance(shape, pymunk.Circle) and shape.radius != radius:
            shape.unsafe_set_radius(radius)
        body.position = (x, y)
        body.velocity = (vx, vy)
        self.space.reindex_shapes_for_body(body)
        self.mover_circles[i] = (x, y, radius)

    def set_mover_velocity(self, i: int, vx: float, vy: float) -> None:
        """Set the velocity mover ``i`` keeps during the next :meth:`step`."""
        self.movers[i].velocity = (vx, vy)

    def step(self, dt: float) -> None:
        """Advance the space (moves the kinematic movers) and refresh the sensor arrays."""
        self.space.step(dt)
        rows = self.mover_circles
        for i, body in enumerate(self.movers):
            p = body.position
            rows[i, 0] = p.x
            rows[i, 1] = p.y

    # -- robots -----------------------------------------------------------------------------------------
    def add_robot(self, spec: DiffDriveSpec, pose: np.ndarray, radius: float | None = None) -> RobotBody:
        """Add a kinematic robot at ``pose``: rectangular (``spec.length x spec.width``), or a disc.

        Args:
            spec: Size and limits.
            pose: ``(x, y, yaw)``.
            radius: Make the robot a disc of this radius (m) instead of a rectangle.

        Raises:
            ValueError: For a non-positive radius.
        """
        if radius is not None and not radius > 0:
            raise ValueError(f"add_robot: radius must be > 0 (m), got {radius}")
        body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        shape: pymunk.Shape
        if radius is None:
            shape = pymunk.Poly.create_box(body, (spec.length, spec.width))
        else:
            shape = pymunk.Circle(body, float(radius))
        shape.filter = pymunk.ShapeFilter(group=_ROBOT_GROUP_BASE + len(self.robots))
        self.space.add(body, shape)
        robot = RobotBody(
            spec=spec,
            pose=np.array(pose, dtype=np.float64),
            v=0.0,
            w=0.0,
            body=body,
            shape=shape,
            radius=0.0 if radius is None else float(radius),
        )
        self.robots.append(robot)
        # A lone robot needs no row (nobody else could sense it): a one-robot world keeps exactly the
        # arrays it had before robots could see each other. The second robot brings rows for everyone.
        if len(self.robots) >= 2:
            for r in self.robots:
                if r.circle_index < 0:
                    r.circle_index = len(self.circles)
                    outline = r.radius if r.radius > 0 else r.spec.circumradius
                    self.circles = np.vstack([self.circles, [[float(r.pose[0]), float(r.pose[1]), outline]]])
        self._sync(robot, robot.pose)
        return robot

    def add_disc_robots(self, spec: DiffDriveSpec, poses: np.ndarray, radius: float) -> list[RobotBody]:
        """Add ``len(poses)`` round robots of one size at once (what :meth:`add_robot` does, in one pass).

        Args:
            spec: Size and limits, shared by all.
            poses: ``(n, 3)`` start poses ``(x, y, yaw)``.
            radius: Disc radius (m), > 0.

        Returns:
            The new robots, in order.

        Raises:
            ValueError: For a non-positive radius or poses not of shape ``(n, 3)``.
        """
        p = np.asarray(poses, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"add_disc_robots: poses must have shape (n, 3), got {p.shape}")
        if not radius > 0:
            raise ValueError(f"add_disc_robots: radius must be > 0 (m), got {radius}")
        if len(p) == 0:
            return []
        if len(self.robots) + len(p) < 2:
            return [self.add_robot(spec, p[0], radius)]
        first = len(self.robots)
        new: list[RobotBody] = []
        bodies: list[pymunk.Body | pymunk.Shape] = []
        for k in range(len(p)):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            shape = pymunk.Circle(body, float(radius))
            shape.filter = pymunk.ShapeFilter(group=_ROBOT_GROUP_BASE + first + k)
            body.position = (float(p[k, 0]), float(p[k, 1]))
            body.angle = float(p[k, 2])
            bodies += (body, shape)
            new.append(
                RobotBody(spec=spec, pose=p[k].copy(), v=0.0, w=0.0, body=body, shape=shape, radius=float(radius))
            )
        self.space.add(*bodies)
        self.robots.extend(new)
        rows: list[list[float]] = []
        for r in self.robots:  # the first robot of a world gets its row once a second one arrives
            if r.circle_index < 0:
                r.circle_index = len(self.circles) + len(rows)
                outline = r.radius if r.radius > 0 else r.spec.circumradius
                rows.append([float(r.pose[0]), float(r.pose[1]), outline])
        self.circles = np.vstack([self.circles, np.array(rows).reshape(-1, 3)])
        return new

    def _sync(self, robot: RobotBody, pose: np.ndarray) -> None:
        robot.body.position = (float(pose[0]), float(pose[1]))
        robot.body.angle = float(pose[2])
        self.space.reindex_shapes_for_body(robot.body)
        if robot.circle_index >= 0:
            row = self.circles[robot.circle_index]
            row[0] = pose[0]
            row[1] = pose[1]

    def clearance(self, robot: RobotBody, pose: np.ndarray | None = None) -> float:
        """Distance (m) between the robot's footprint and the nearest obstacle or other robot (<= 0: contact)."""
        p = robot.pose if pose is None else pose
        if robot.radius > 0:
            return float(
                disc_clearance(float(p[0]), float(p[1]), robot.radius, self.circles, self.capsules, robot.circle_index)
            )
        s = robot.spec
        return float(
            footprint_clearance(
                float(p[0]),
                float(p[1]),
                float(p[2]),
                0.5 * s.length,
                0.5 * s.width,
                self.circles,
                self.capsules,
                robot.circle_index,
            )
        )

    def _touches(self, robot: RobotBody, pose: np.ndarray) -> bool:
        if robot.radius > 0:  # a disc's clearance is exact: no need to ask pymunk
            return self.clearance(robot, pose) <= 0.0
        self._sync(robot, pose)
        return bool(self.space.shape_query(robot.shape))

    @property
    def robot_circles(self) -> np.ndarray:
        """``(n_robots, 3)`` view of the robots' rows in :attr:`circles` (added last, in order; empty for one robot)."""
        if len(self.robots) < 2:
            return self.circles[:0]
        return self.circles[self.robots[0].circle_index :]

    def drive_discs(
        self,
        robots: Sequence[RobotBody],
        cmd: np.ndarray,
        dt: float,
        poses: np.ndarray | None = None,
        vel: np.ndarray | None = None,
    ) -> np.ndarray:
        """:meth:`drive` for many disc robots at once (one compiled call; robots move in list order).

        Each robot sees the ones before it at their new poses and the ones after it at their old poses,
        exactly as a loop of :meth:`drive` would. The robots' pymunk bodies are synced only when the world
        also holds rectangular robots (the only users of pymunk queries).

        Args:
            robots: Disc robots of this world.
            cmd: ``(n, 2)`` commanded ``v, omega`` (m/s, rad/s).
            dt: Duration (s).
            poses: The robots' current poses ``(n, 3)`` float64, kept by the caller; updated in place (the
                robots' ``pose`` become views of its rows). Gathered from the robots when None.
            vel: Their ``(n, 2)`` float64 achieved ``v, omega``, likewise.

        Returns:
            ``(n,)`` bool, True for each robot that touched something (it stopped before the contact).

        Raises:
            ValueError: If a robot is not a disc or ``cmd`` has the wrong shape.
        """
        key = tuple(r.circle_index for r in robots)
        cache = self._disc_cache.get(key)
        if cache is None:
            if any(r.radius <= 0 for r in robots):
                raise ValueError("drive_discs: every robot must be a disc (add_robot(..., radius=r))")
            limits = np.array(
                [
                    [
                        r.spec.max_speed,
                        r.spec.max_reverse_speed,
                        r.spec.max_turn_rate,
                        r.spec.max_accel,
                        r.spec.max_angular_accel,
                    ]
                    for r in robots
                ],
                dtype=np.float64,
            ).reshape(-1, 5)
            cache = (limits, np.array([r.radius for r in robots]), np.array(key, dtype=np.int64))
            self._disc_cache[key] = cache
        limits, radius, rows = cache
        c = np.asarray(cmd, dtype=np.float64)
        if c.shape != (len(robots), 2):
            raise ValueError(f"drive_discs: cmd must have shape ({len(robots)}, 2), got {c.shape}")
        if poses is None:
            poses = np.array([r.pose for r in robots], dtype=np.float64).reshape(-1, 3)
        if vel is None:
            vel = np.array([(r.v, r.w) for r in robots], dtype=np.float64).reshape(-1, 2)
        contact = np.zeros(len(robots), dtype=np.bool_)
        _drive_discs(poses, vel, c, limits, radius, rows, self.circles, self.capsules, dt, self.max_substep, contact)
        sync = any(r.radius <= 0 for r in self.robots)
        speeds = vel.tolist()
        for k, r in enumerate(robots):
            r.pose = poses[k]
            r.v, r.w = speeds[k]
            if sync:
                self._sync(r, r.pose)
        return contact

    def drive(self, robot: RobotBody, v_cmd: float, w_cmd: float, dt: float) -> bool:
        """Drive a robot for ``dt`` seconds toward the commanded velocities; return True on contact.

        On contact the robot stays at the last pose that did not touch anything (or that moved it out of
        an existing overlap) and its velocities drop to zero.
        """
        v, w = limit_velocity(robot.spec, robot.v, robot.w, v_cmd, w_cmd, dt)
        # A disc that turns in place sweeps no new area; a rectangle's corners do.
        reach = abs(v) * dt + (0.0 if robot.radius > 0 else abs(w) * dt * robot.spec.circumradius)
        pose = robot.pose
        clear = self.clearance(robot)
        if clear > reach + 1e-6:
            robot.pose = unicycle_arc(pose, v, w, dt)
            robot.v, robot.w = v, w
            self._sync(robot, robot.pose)
            return False
        n_sub = max(1, math.ceil(reach / self.max_substep))
        h = dt / n_sub
        inside = clear <= 0.0
        contact = False
        for _ in range(n_sub):
            candidate = unicycle_arc(pose, v, w, h)
            if self._touches(robot, candidate):
                new_clear = self.clearance(robot, candidate)
                if not inside or new_clear <= clear:
                    contact = True
                    break
                clear = new_clear
            else:
                inside = False
            pose = candidate
        robot.pose = pose
        robot.v, robot.w = (0.0, 0.0) if contact else (v, w)
        self._sync(robot, pose)
        return contact


#: Worlds not closed yet, closed by the exit hook below before the interpreter wipes module globals.
_LIVE_WORLDS: weakref.WeakSet[World2D] = weakref.WeakSet()


@atexit.register
def _close_live_worlds() -> None:
    for world in list(_LIVE_WORLDS):
        world.close()
    gc.collect()  # pymunk bodies and shapes hold handles to themselves: only the collector frees them
