"""The shared 2D world: a pymunk space seen from above (no gravity).

Static obstacles come from a :class:`~agri_envs.sim2d.geometry.Geometry`; people (and other moving
obstacles) are kinematic pymunk bodies that the space integrates; robots are kinematic bodies driven as
unicycles. Robot motion never tunnels: a step that could reach an obstacle (the clearance kernel says
so) is split into substeps shorter than half the thinnest obstacle, and pymunk's shape query stops the
robot at the last pose before contact.

A world outlives its episodes: :meth:`World2D.set_scene` swaps the static scene and
:meth:`World2D.place_robot` moves a robot to its new start, so an env's reset keeps its pymunk space,
bodies and movers; the scene's static pymunk shapes are built only around the places where a contact query
needs them (a query only ever tests the shapes whose bounding boxes meet the robot's).

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

from agri_envs.sim2d.batched import limited_velocity, sweep
from agri_envs.sim2d.diff_drive import DiffDriveSpec, limit_velocity, unicycle_arc
from agri_envs.sim2d.geometry import Geometry
from agri_envs.sim2d.raycast import disc_clearance, footprint_clearance

# Pymunk collision categories: robots do not sense or hit themselves through these filters.
_ROBOT_GROUP_BASE = 1000


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
        v, w = limited_velocity(vel[k, 0], vel[k, 1], cmd[k, 0], cmd[k, 1], limits[k], dt)
        x, y, th, hit = sweep(
            poses[k, 0],
            poses[k, 1],
            poses[k, 2],
            v,
            w,
            dt,
            abs(v) * dt,
            max_substep,
            radius[k],
            0.0,
            0.0,
            circles,
            capsules,
            rows[k],
        )
        poses[k, 0], poses[k, 1], poses[k, 2] = x, y, th
        vel[k, 0], vel[k, 1] = (0.0, 0.0) if hit else (v, w)
        contact[k] = hit
        if rows[k] >= 0:
            circles[rows[k], 0] = x
            circles[rows[k], 1] = y


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
        self.space = pymunk.Space()
        self.space.gravity = (0.0, 0.0)
        self.movers: list[pymunk.Body] = []
        for _ in range(n_movers):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            shape = pymunk.Circle(body, 0.2)
            self.space.add(body, shape)
            self.movers.append(body)
        self.robots: list[RobotBody] = []
        _LIVE_WORLDS.add(self)
        self._disc_cache: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        # The scene's static pymunk shapes are built only where a contact query needs them (see _touches).
        self.geometry: Geometry | None = None
        self._static_shapes: list[pymunk.Shape] = []
        #: Every circle the sensors see: static ones, then one slot per mover (then one per robot, see add_robot).
        self.circles = np.zeros((n_movers, 3))
        self.circles[:, 2] = 0.2
        self._mover_slice = slice(0, n_movers)
        self.set_scene(geometry)

    def set_scene(self, geometry: Geometry) -> None:
        """Replace the static scene, keeping the movers, the robots and the pymunk space (a new episode).

        Building pymunk shapes costs far more than a reset may, and most of a scene never comes near a
        robot: the static shapes are built only where a contact query needs them (:meth:`_touches`), so
        a new scene only drops the shapes the last one built. The movers' and robots' rows of
        :attr:`circles` keep their values; robots keep their poses until moved (:meth:`place_robot`).

        Args:
            geometry: The new static scene (the current one again: nothing changes).
        """
        if geometry is self.geometry:
            return
        self.geometry = geometry
        n_static = len(geometry.circles)
        moving = self.circles[self._mover_slice.start :]  # movers, then robots
        shift = n_static - self._mover_slice.start
        self.circles = np.vstack([geometry.circles, moving])
        self._mover_slice = slice(n_static, n_static + len(self.movers))
        for robot in self.robots:
            if robot.circle_index >= 0:
                robot.circle_index += shift
        self._disc_cache.clear()
        self.capsules = np.ascontiguousarray(geometry.capsules)
        radii = np.concatenate([geometry.circles[:, 2], geometry.capsules[:, 4][geometry.capsules[:, 4] > 0]])
        # Substep length: half the thinnest obstacle's half-thickness, so a substep can never jump over it.
        self.max_substep = max(0.002, 0.5 * (float(radii.min()) if len(radii) else 0.1))
        if self._static_shapes:
            self.space.remove(*self._static_shapes)
            self._static_shapes = []
        self._static_bbs = static_bounding_boxes(geometry)
        self._static_built = np.zeros(len(self._static_bbs), dtype=np.bool_)

    def _build_static_near(self, x: float, y: float, reach: float) -> None:
        """Add to the space every static shape of the scene whose bounding box meets the square ``(x, y) +- reach``.

        A shape query only tests the shapes whose bounding boxes overlap the query shape's, so a space
        holding every shape near the query answers exactly as one holding the whole scene.
        """
        assert self.geometry is not None
        todo = _unbuilt_overlapping(self._static_bbs, self._static_built, x - reach, y - reach, x + reach, y + reach)
        if len(todo) == 0:
            return
        geometry = self.geometry
        static = self.space.static_body
        n_circles = len(geometry.circles)
        segments = np.flatnonzero(geometry.capsules[:, 4] > 0)  # r = 0: the edges of polygons, added as polygons
        shapes: list[pymunk.Shape] = []
        for k in todo.tolist():
            if k < n_circles:
                x0, y0, r = geometry.circles[k].tolist()
                shapes.append(pymunk.Circle(static, r, offset=(x0, y0)))
            elif k < n_circles + len(segments):
                x0, y0, x1, y1, r = geometry.capsules[segments[k - n_circles]].tolist()
                shapes.append(pymunk.Segment(static, (x0, y0), (x1, y1), r))
            else:
                poly = geometry.polygons[k - n_circles - len(segments)]
                shapes.append(pymunk.Poly(static, [(float(p[0]), float(p[1])) for p in poly]))
        self.space.add(*shapes)
        self._static_shapes.extend(shapes)
        self._static_built[todo] = True

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

    def place_robot(self, robot: RobotBody, pose: np.ndarray) -> None:
        """Put a robot of this world at ``pose``, standing still (a new episode)."""
        robot.pose = np.array(pose, dtype=np.float64)
        robot.v = 0.0
        robot.w = 0.0
        self._sync(robot, robot.pose)

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


    def place_robots(self, robots: Sequence[RobotBody], poses: np.ndarray) -> None:
        """:meth:`place_robot` for several robots: ``poses`` is ``(n, 3)``, one ``(x, y, yaw)`` per robot."""
        for robot, pose in zip(robots, np.asarray(poses, dtype=np.float64).reshape(-1, 3), strict=True):
            self.place_robot(robot, pose)

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
        # The robot's bounding box lies within its circumradius of the pose (the margin covers rounding).
        self._build_static_near(float(pose[0]), float(pose[1]), robot.spec.circumradius + 1e-6)
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


def static_bounding_boxes(geometry: Geometry) -> np.ndarray:
    """``(n, 4)`` ``xmin, ymin, xmax, ymax`` of every static pymunk shape of a scene, in the order they are numbered.

    Circles first, then the capsules of positive radius (pymunk segments), then the polygons; the
    zero-radius capsules are polygon edges and have no shape of their own. Each box is computed the way
    pymunk (Chipmunk) computes the shape's own.
    """
    c = geometry.circles
    boxes = [np.column_stack([c[:, 0] - c[:, 2], c[:, 1] - c[:, 2], c[:, 0] + c[:, 2], c[:, 1] + c[:, 2]])]
    s = geometry.capsules[geometry.capsules[:, 4] > 0]
    lo_x, hi_x = np.minimum(s[:, 0], s[:, 2]), np.maximum(s[:, 0], s[:, 2])
    lo_y, hi_y = np.minimum(s[:, 1], s[:, 3]), np.maximum(s[:, 1], s[:, 3])
    boxes.append(np.column_stack([lo_x - s[:, 4], lo_y - s[:, 4], hi_x + s[:, 4], hi_y + s[:, 4]]))
    if geometry.polygons:
        boxes.append(np.array([[*p.min(axis=0), *p.max(axis=0)] for p in geometry.polygons]))
    return np.ascontiguousarray(np.vstack(boxes).reshape(-1, 4))


@numba.njit(cache=True)
def _unbuilt_overlapping(
    boxes: np.ndarray, built: np.ndarray, xmin: float, ymin: float, xmax: float, ymax: float
) -> np.ndarray:
    """Indices of the boxes not yet ``built`` that meet the box ``xmin .. xmax, ymin .. ymax`` (touching counts)."""
    out = np.empty(boxes.shape[0], dtype=np.int64)
    n = 0
    for i in range(boxes.shape[0]):
        if not built[i] and boxes[i, 0] <= xmax and xmin <= boxes[i, 2] and boxes[i, 1] <= ymax and ymin <= boxes[i, 3]:
            out[n] = i
            n += 1
    return out[:n]


#: Worlds not closed yet, closed by the exit hook below before the interpreter wipes module globals.
_LIVE_WORLDS: weakref.WeakSet[World2D] = weakref.WeakSet()


@atexit.register
def _close_live_worlds() -> None:
    for world in list(_LIVE_WORLDS):
        world.close()
    gc.collect()  # pymunk bodies and shapes hold handles to themselves: only the collector frees them
