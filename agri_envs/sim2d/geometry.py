"""Static 2D scene geometry in the form the sensors, the physics and the renderer all read.

Every obstacle is one of three primitives, stored in flat float64 arrays so numba kernels can scan them:

* circles ``(n, 3)``: ``x, y, r`` (plants, posts, trees, people, round robots);
* capsules ``(m, 5)``: ``x0, y0, x1, y1, r``, a segment thickened by ``r`` (walls, leaves; ``r = 0``
  gives the plain edges of polygons);
* polygons: convex vertex lists, used for physics and drawing; their edges also appear as ``r = 0``
  capsules so the sensors see them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from enum import IntEnum

import numpy as np


class Kind(IntEnum):
    """What a primitive stands for (drawing colours, reports, reward terms)."""

    WALL = 0
    POST = 1
    PLANT = 2
    LEAF = 3
    TREE = 4
    PERSON = 5
    OBSTACLE = 6
    ROBOT = 7


@dataclasses.dataclass
class Geometry:
    """Static obstacles of a scene.

    Attributes:
        circles: ``(n, 3)`` float64 ``x, y, r`` in metres.
        circle_kinds: ``(n,)`` int8 :class:`Kind` per circle.
        capsules: ``(m, 5)`` float64 ``x0, y0, x1, y1, r`` in metres.
        capsule_kinds: ``(m,)`` int8 :class:`Kind` per capsule.
        polygons: Convex polygons ``(k_i, 2)`` (counter-clockwise), for physics and drawing.
        polygon_kinds: :class:`Kind` per polygon.
        bounds: ``(xmin, ymin, xmax, ymax)`` of the scene in metres.
    """

    circles: np.ndarray
    circle_kinds: np.ndarray
    capsules: np.ndarray
    capsule_kinds: np.ndarray
    polygons: list[np.ndarray]
    polygon_kinds: list[int]
    bounds: tuple[float, float, float, float]

    @classmethod
    def empty(cls, bounds: tuple[float, float, float, float]) -> Geometry:
        """A scene with no obstacles."""
        return cls(
            circles=np.zeros((0, 3)),
            circle_kinds=np.zeros(0, np.int8),
            capsules=np.zeros((0, 5)),
            capsule_kinds=np.zeros(0, np.int8),
            polygons=[],
            polygon_kinds=[],
            bounds=bounds,
        )


def _kinds(kinds: np.ndarray | Kind, n: int) -> list[int]:
    """``n`` kinds as ints: one per row, or the same one repeated."""
    if isinstance(kinds, np.ndarray):
        return kinds.astype(np.int64).tolist()
    return [int(kinds)] * n


class GeometryBuilder:
    """Collects primitives one by one and packs them into a :class:`Geometry`."""

    def __init__(self) -> None:
        self._circles: list[tuple[float, ...]] = []
        self._circle_kinds: list[int] = []
        self._capsules: list[tuple[float, ...]] = []
        self._capsule_kinds: list[int] = []
        self._polygons: list[np.ndarray] = []
        self._polygon_kinds: list[int] = []

    def circle(self, x: float, y: float, r: float, kind: Kind) -> None:
        """Add a circle of radius ``r`` (m) centred at ``(x, y)``."""
        if r <= 0:
            raise ValueError(f"circle radius must be positive, got {r}")
        self._circles.append((float(x), float(y), float(r)))
        self._circle_kinds.append(int(kind))

    def capsule(self, x0: float, y0: float, x1: float, y1: float, r: float, kind: Kind) -> None:
        """Add a segment from ``(x0, y0)`` to ``(x1, y1)`` thickened by ``r`` (m) on each side."""
        if r < 0:
            raise ValueError(f"capsule radius must be >= 0, got {r}")
        self._capsules.append((float(x0), float(y0), float(x1), float(y1), float(r)))
        self._capsule_kinds.append(int(kind))

    def circles(self, rows: np.ndarray, kinds: np.ndarray | Kind) -> None:
        """Add many circles at once: ``rows`` ``(n, 3)`` ``x, y, r`` (m), with one kind or one kind per row."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
        if np.any(rows[:, 2] <= 0):
            raise ValueError(f"circle radius must be positive, got {rows[:, 2].min()}")
        self._circles.extend(map(tuple, rows.tolist()))
        self._circle_kinds.extend(_kinds(kinds, len(rows)))

    def capsules(self, rows: np.ndarray, kinds: np.ndarray | Kind) -> None:
        """Add many capsules at once: ``rows`` ``(n, 5)`` ``x0, y0, x1, y1, r`` (m), with one kind or one per row."""
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, 5)
        if np.any(rows[:, 4] < 0):
            raise ValueError(f"capsule radius must be >= 0, got {rows[:, 4].min()}")
        self._capsules.extend(map(tuple, rows.tolist()))
        self._capsule_kinds.extend(_kinds(kinds, len(rows)))

    def polygon(self, vertices: np.ndarray, kind: Kind) -> None:
        """Add a convex polygon (vertices ``(k, 2)``); its edges become zero-radius capsules for sensing."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 2)
        if len(v) < 3:
            raise ValueError("a polygon needs at least 3 vertices")
        area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        if area2 < 0:
            v = v[::-1].copy()
        self._polygons.append(v)
        self._polygon_kinds.append(int(kind))
        for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
            self.capsule(a[0], a[1], b[0], b[1], 0.0, kind)

    def box(self, xmin: float, ymin: float, xmax: float, ymax: float, kind: Kind) -> None:
        """Add an axis-aligned rectangle."""
        self.polygon(np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]]), kind)

    def build(self, bounds: tuple[float, float, float, float]) -> Geometry:
        """Pack everything added so far."""
        return Geometry(
            circles=np.array(self._circles, dtype=np.float64).reshape(-1, 3),
            circle_kinds=np.array(self._circle_kinds, dtype=np.int8),
            capsules=np.array(self._capsules, dtype=np.float64).reshape(-1, 5),
            capsule_kinds=np.array(self._capsule_kinds, dtype=np.int8),
            polygons=list(self._polygons),
            polygon_kinds=list(self._polygon_kinds),
            bounds=tuple(float(b) for b in bounds),  # type: ignore[arg-type]
        )


def enclosing_bounds(boxes: Iterable[tuple[float, float, float, float]]) -> tuple[float, float, float, float]:
    """The smallest ``(xmin, ymin, xmax, ymax)`` that holds every box (e.g. one canvas for several scenes)."""
    b = np.array(list(boxes), dtype=np.float64).reshape(-1, 4)
    return (float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max()))
