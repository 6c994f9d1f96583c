"""Occupancy grid maps: rasterise a scene, save and load ROS ``map_server`` maps, turn a map back into a scene.

Conventions (those of ROS ``map_server`` / ``nav_msgs/OccupancyGrid``):

* ``data[i, j]`` is the cell in row ``i`` and column ``j``; **row 0 is the lowest y** and column 0 the
  lowest x. Values: ``-1`` unknown, ``0`` free, ``100`` occupied (values in between are occupancy
  probabilities in percent).
* ``origin = (x, y, yaw)`` is the world pose of the **lower-left corner of cell (0, 0)** (not its centre).
  A cell ``(i, j)`` covers ``[j, j + 1] x [i, i + 1] * resolution`` in the grid frame; its centre is at
  ``((j + 0.5) * resolution, (i + 0.5) * resolution)`` in that frame, rotated by ``yaw`` and shifted by
  ``origin``. :func:`rasterize` always produces ``yaw = 0``.
* On disk the image is stored top row first, as any image viewer shows it, so image row 0 is grid row
  ``H - 1``: :func:`save_ros_map` and :func:`load_ros_map` flip the rows, exactly as ``map_saver`` and
  ``map_server`` do.

The sample map ``agri_envs/scenes/maps/example_greenhouse.yaml`` was made from the default greenhouse::

    from agri_envs.scenes.greenhouse import LayoutParams, generate_layout
    layout = generate_layout(LayoutParams(), np.random.default_rng(0))
    save_ros_map(rasterize(layout.geometry, 0.05), "agri_envs/scenes/maps/example_greenhouse.yaml")
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any

import numba
import numpy as np
import yaml

from agri_envs.sim2d.geometry import Geometry, GeometryBuilder, Kind

UNKNOWN = -1
FREE = 0
OCCUPIED = 100

# What map_saver writes (trinary): occupied black, free (almost) white, unknown grey.
PGM_OCCUPIED = 0
PGM_FREE = 254
PGM_UNKNOWN = 205
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196

# Refuse to allocate grids larger than this (a typo in the resolution should fail loudly, not swap).
_MAX_CELLS = 200_000_000

PathLike = str | os.PathLike[str]


@dataclasses.dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A 2D occupancy grid with ROS semantics (see the module docstring for the frame conventions).

    Attributes:
        data: ``(H, W)`` int8 occupancy, row 0 = lowest y: ``-1`` unknown, ``0`` free, ``100`` occupied.
            Stored as a read-only copy.
        resolution: Edge length of a cell (m/cell).
        origin: ``(x, y, yaw)`` of the lower-left corner of cell ``(0, 0)`` in the world (m, m, rad).
    """

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        raw = np.asarray(self.data)
        if raw.ndim != 2 or raw.shape[0] == 0 or raw.shape[1] == 0:
            raise ValueError(f"OccupancyGrid: data must be a non-empty 2D array, got shape {raw.shape}")
        if raw.dtype.kind not in "iu":
            raise ValueError(f"OccupancyGrid: data must hold integers (-1, 0..100), got dtype {raw.dtype}")
        if raw.size and (raw.min() < -1 or raw.max() > 100):
            raise ValueError("OccupancyGrid: data values must be -1 (unknown) or 0..100 (occupancy percent)")
        data = raw.astype(np.int8, copy=True)
        data.setflags(write=False)
        resolution = float(self.resolution)
        if not (math.isfinite(resolution) and resolution > 0):
            raise ValueError(f"OccupancyGrid: resolution must be a positive number of m/cell, got {self.resolution}")
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise ValueError(f"OccupancyGrid: origin must be three finite numbers (x, y, yaw), got {self.origin}")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "resolution", resolution)
        object.__setattr__(self, "origin", origin)

    @property
    def height(self) -> int:
        """Number of rows (cells along y)."""
        return int(self.data.shape[0])

    @property
    def width(self) -> int:
        """Number of columns (cells along x)."""
        return int(self.data.shape[1])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the grid's extent in the world (m), axis-aligned even if rotated."""
        w, h = self.width * self.resolution, self.height * self.resolution
        corners = self._grid_to_world(np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]))
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def _grid_to_world(self, p: np.ndarray) -> np.ndarray:
        """Map points ``(..., 2)`` from the grid frame (m, origin at the lower-left corner) to the world."""
        ox, oy, yaw = self.origin
        if yaw == 0.0:
            return p + np.array([ox, oy])
        c, s = math.cos(yaw), math.sin(yaw)
        x, y = p[..., 0], p[..., 1]
        return np.stack([ox + c * x - s * y, oy + s * x + c * y], axis=-1)

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """Indices of the cells containing world points.

        Args:
            xy: ``(..., 2)`` world points ``(x, y)`` (m).

        Returns:
            ``(..., 2)`` int64 ``(i, j)`` = (row, column), so ``data[i, j]`` is the cell. Points outside the
            grid give indices outside ``[0, H) x [0, W)``; check with :meth:`in_grid`.
        """
        p = np.asarray(xy, dtype=np.float64)
        if p.shape[-1:] != (2,):
            raise ValueError(f"world_to_cell: expected points of shape (..., 2), got {p.shape}")
        ox, oy, yaw = self.origin
        dx, dy = p[..., 0] - ox, p[..., 1] - oy
        if yaw != 0.0:
            c, s = math.cos(yaw), math.sin(yaw)
            dx, dy = c * dx + s * dy, -s * dx + c * dy
        j = np.floor(dx / self.resolution).astype(np.int64)
        i = np.floor(dy / self.resolution).astype(np.int64)
        return np.stack([i, j], axis=-1)

    def cell_to_world(self, ij: np.ndarray) -> np.ndarray:
        """World coordinates of cell centres.

        Args:
            ij: ``(..., 2)`` integer ``(i, j)`` = (row, column) indices.

        Returns:
            ``(..., 2)`` float64 ``(x, y)`` of the cells' centres (m).
        """
        c = np.asarray(ij)
        if c.shape[-1:] != (2,):
            raise ValueError(f"cell_to_world: expected indices of shape (..., 2), got {c.shape}")
        local = np.stack([(c[..., 1] + 0.5) * self.resolution, (c[..., 0] + 0.5) * self.resolution], axis=-1)
        return self._grid_to_world(local.astype(np.float64))

    def in_grid(self, ij: np.ndarray) -> np.ndarray:
        """Whether cell indices ``(..., 2)`` ``(i, j)`` lie inside the grid (bool ``(...)``)."""
        c = np.asarray(ij)
        return (c[..., 0] >= 0) & (c[..., 0] < self.height) & (c[..., 1] >= 0) & (c[..., 1] < self.width)

    def occupied_mask(self, threshold: int = 50) -> np.ndarray:
        """Boolean ``(H, W)`` mask of occupied cells: occupancy ``>= threshold`` percent (unknown is not occupied)."""
        return self.data >= threshold

    def free_mask(self, threshold: int = 50) -> np.ndarray:
        """Boolean ``(H, W)`` mask of known free cells: ``0 <= occupancy < threshold`` percent."""
        return (self.data >= 0) & (self.data < threshold)


# --------------------------------------------------------------------------------------------------
# Rasterisation
# --------------------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _window(lo: float, hi: float, start: float, res: float, n: int) -> tuple[int, int]:
    """Half-open index range of the cells whose centres ``start + (k + 0.5) * res`` lie in ``[lo, hi]``."""
    k0 = max(0, math.ceil((lo - start) / res - 0.5))
    k1 = min(n, math.floor((hi - start) / res - 0.5) + 1)
    return k0, k1


@numba.njit(cache=True)
def _rasterize_kernel(
    occ: np.ndarray,
    xs: np.ndarray,
    ys: np.ndarray,
    xmin: float,
    ymin: float,
    res: float,
    circles: np.ndarray,
    capsules: np.ndarray,
    vertices: np.ndarray,
    starts: np.ndarray,
) -> None:
    """Mark the cells whose centre lies in a circle, within a capsule's radius, or in a convex polygon.

    Every primitive is tested over the cells of its bounding box only; the arithmetic is that of the
    vectorised numpy form this replaced, term for term, so the grids are the same bit for bit.
    """
    height, width = occ.shape
    for c in range(circles.shape[0]):
        cx, cy, r = circles[c, 0], circles[c, 1], circles[c, 2]
        j0, j1 = _window(cx - r, cx + r, xmin, res, width)
        i0, i1 = _window(cy - r, cy + r, ymin, res, height)
        for i in range(i0, i1):
            for j in range(j0, j1):
                if (xs[j] - cx) ** 2 + (ys[i] - cy) ** 2 <= r * r:
                    occ[i, j] = True
    for c in range(capsules.shape[0]):
        ax, ay, bx, by, r = capsules[c, 0], capsules[c, 1], capsules[c, 2], capsules[c, 3], capsules[c, 4]
        j0, j1 = _window(min(ax, bx) - r, max(ax, bx) + r, xmin, res, width)
        i0, i1 = _window(min(ay, by) - r, max(ay, by) + r, ymin, res, height)
        ex, ey = bx - ax, by - ay
        l2 = ex * ex + ey * ey
        for i in range(i0, i1):
            dy = ys[i] - ay
            for j in range(j0, j1):
                dx = xs[j] - ax
                if l2 == 0.0:
                    d = dx * dx + dy * dy
                else:
                    t = min(max((dx * ex + dy * ey) / l2, 0.0), 1.0)
                    qx, qy = dx - t * ex, dy - t * ey
                    d = qx * qx + qy * qy
                if d <= r * r:
                    occ[i, j] = True
    for p in range(starts.shape[0] - 1):
        a0, a1 = starts[p], starts[p + 1]
        vx0, vy0 = vertices[a0, 0], vertices[a0, 1]
        vx1, vy1 = vx0, vy0
        for k in range(a0, a1):
            vx0, vy0 = min(vx0, vertices[k, 0]), min(vy0, vertices[k, 1])
            vx1, vy1 = max(vx1, vertices[k, 0]), max(vy1, vertices[k, 1])
        j0, j1 = _window(vx0, vx1, xmin, res, width)
        i0, i1 = _window(vy0, vy1, ymin, res, height)
        for i in range(i0, i1):
            py = ys[i]
            for j in range(j0, j1):
                px = xs[j]
                inside = True
                for k in range(a0, a1):
                    nk = k + 1 if k + 1 < a1 else a0
                    ax, ay = vertices[k, 0], vertices[k, 1]
                    bx, by = vertices[nk, 0], vertices[nk, 1]
                    if not (bx - ax) * (py - ay) - (by - ay) * (px - ax) >= 0.0:
                        inside = False
                        break
                if inside:
                    occ[i, j] = True


def _edge_keys(segments: np.ndarray) -> np.ndarray:
    """Order-independent keys ``(k, 4)`` of segments ``(k, 4)`` ``ax, ay, bx, by`` (rounded end points, lower first)."""
    a = np.round(np.asarray(segments, dtype=np.float64).reshape(-1, 4), 9)
    swap = (a[:, 0] > a[:, 2]) | ((a[:, 0] == a[:, 2]) & (a[:, 1] > a[:, 3]))
    a[swap] = a[swap][:, [2, 3, 0, 1]]
    return a


def rasterize(
    geometry: Geometry,
    resolution: float = 0.05,
    bounds: tuple[float, float, float, float] | None = None,
    unknown_outside: bool = False,
) -> OccupancyGrid:
    """Rasterise a scene into an occupancy grid (cell-centre sampling).

    A cell is occupied (100) when its centre lies inside a circle, within ``r`` of a capsule's segment, or
    inside a polygon; every other cell is free (0). Zero-radius capsules that are polygon edges are
    covered by their polygon's interior; other zero-radius capsules (free-standing thin walls) are drawn
    one cell thick (centres within half a cell of the segment) so they do not vanish from the map.

    Each primitive is tested with one vectorised numpy expression over the cells of its bounding box.

    Args:
        geometry: The scene.
        resolution: Cell size (m/cell).
        bounds: ``(xmin, ymin, xmax, ymax)`` of the map (m); defaults to ``geometry.bounds``. The grid
            starts at ``(xmin, ymin)`` and is rounded up to whole cells.
        unknown_outside: Mark cells whose centre lies outside ``geometry.bounds`` as unknown (-1) instead
            of free, e.g. when ``bounds`` pads the scene.

    Returns:
        The grid, with ``origin = (xmin, ymin, 0)``.

    Raises:
        ValueError: If the resolution is not positive, the bounds are empty, or the grid would be huge.
    """
    res = float(resolution)
    if not (math.isfinite(res) and res > 0):
        raise ValueError(f"rasterize: resolution must be a positive number of m/cell, got {resolution}")
    xmin, ymin, xmax, ymax = (float(v) for v in (geometry.bounds if bounds is None else bounds))
    if not all(math.isfinite(v) for v in (xmin, ymin, xmax, ymax)) or xmax <= xmin or ymax <= ymin:
        raise ValueError(f"rasterize: bounds must be finite (xmin, ymin, xmax, ymax) with max > min, got {bounds}")
    # The small tolerance keeps 9.8 / 0.05 = 196.00000000000003 from growing an extra column.
    width = max(1, math.ceil((xmax - xmin) / res - 1e-6))
    height = max(1, math.ceil((ymax - ymin) / res - 1e-6))
    if width * height > _MAX_CELLS:
        raise ValueError(
            f"rasterize: a {width} x {height} grid is too large; use a coarser resolution than {res} m/cell"
        )
    xs = xmin + (np.arange(width) + 0.5) * res
    ys = ymin + (np.arange(height) + 0.5) * res
    occ = np.zeros((height, width), dtype=np.bool_)
    circles = np.asarray(geometry.circles, dtype=np.float64).reshape(-1, 3)
    capsules = np.asarray(geometry.capsules, dtype=np.float64).reshape(-1, 5).copy()
    thin = np.flatnonzero(capsules[:, 4] == 0.0)
    keep = np.ones(len(capsules), dtype=bool)
    if len(thin):
        # Zero-radius capsules that are polygon edges are covered by their polygon; the others are
        # free-standing thin walls, drawn one cell thick.
        edges = [np.hstack([v, np.roll(v, -1, axis=0)]) for v in map(np.asarray, geometry.polygons)]
        polygon_edges = set(map(tuple, _edge_keys(np.vstack(edges)).tolist())) if edges else set()
        is_edge = np.array([key in polygon_edges for key in map(tuple, _edge_keys(capsules[thin, :4]).tolist())])
        keep[thin[is_edge]] = False
        capsules[thin[~is_edge], 4] = 0.5 * res
    vertices, starts = [], [0]
    for poly in geometry.polygons:
        v = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        vertices.append(v[::-1] if area2 < 0 else v)  # counter-clockwise
        starts.append(starts[-1] + len(v))
    flat = np.vstack(vertices) if vertices else np.zeros((0, 2))
    _rasterize_kernel(occ, xs, ys, xmin, ymin, res, circles, capsules[keep], flat, np.array(starts, dtype=np.int64))

    data = np.where(occ, np.int8(OCCUPIED), np.int8(FREE)).astype(np.int8)
    if unknown_outside:
        gx0, gy0, gx1, gy1 = geometry.bounds
        outside = (xs[None, :] < gx0) | (xs[None, :] > gx1) | (ys[:, None] < gy0) | (ys[:, None] > gy1)
        data[outside] = UNKNOWN
    return OccupancyGrid(data=data, resolution=res, origin=(xmin, ymin, 0.0))


# --------------------------------------------------------------------------------------------------
# ROS map files
# --------------------------------------------------------------------------------------------------


def save_ros_map(grid: OccupancyGrid, yaml_path: PathLike, image_name: str | None = None) -> Path:
    """Write a map as ``map_saver`` does: a binary (P5) PGM and its YAML description.

    Pixels (trinary): occupancy ``>= 65`` -> 0 (black), ``0 ..< 20`` -> 254 (white), anything else,
    unknown included -> 205 (grey). The YAML holds ``image``, ``resolution``, ``origin [x, y, yaw]``,
    ``negate: 0``, ``occupied_thresh: 0.65``, ``free_thresh: 0.196`` and ``mode: trinary``.

    Args:
        grid: The map.
        yaml_path: Where to write the YAML; the image goes next to it.
        image_name: File name of the image, relative to the YAML's folder; defaults to the YAML's name with
            a ``.pgm`` suffix.

    Returns:
        The path of the written image.

    Raises:
        ValueError: If ``image_name`` is not a ``.pgm`` file name.
    """
    yaml_path = Path(yaml_path)
    name = image_name if image_name is not None else yaml_path.with_suffix(".pgm").name
    if not name.lower().endswith(".pgm"):
        raise ValueError(f"save_ros_map: image_name must end in .pgm, got {name!r}")
    image_path = yaml_path.parent / name
    d = grid.data
    pixels = np.full(d.shape, PGM_UNKNOWN, dtype=np.uint8)
    pixels[d >= round(100 * DEFAULT_OCCUPIED_THRESH)] = PGM_OCCUPIED
    pixels[(d >= 0) & (d < round(100 * DEFAULT_FREE_THRESH))] = PGM_FREE
    header = f"P5\n# CREATOR: agri_envs.sim2d.gridmap {grid.resolution:.3f} m/pix\n{grid.width} {grid.height}\n255\n"
    image_path.parent.mkdir(parents=True, exist_ok=True)
    with open(image_path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(pixels[::-1]).tobytes())  # image row 0 is the top (highest y)
    meta = {
        "image": name,
        "mode": "trinary",
        "resolution": grid.resolution,
        "origin": [float(v) for v in grid.origin],
        "negate": 0,
        "occupied_thresh": DEFAULT_OCCUPIED_THRESH,
        "free_thresh": DEFAULT_FREE_THRESH,
    }
    with open(yaml_path, "w", encoding="utf-8") as f:
        yaml.safe_dump(meta, f, sort_keys=False, default_flow_style=None)
    return image_path


def _read_netpbm(path: Path) -> tuple[np.ndarray, int]:
    """Read a greyscale PGM (binary P5 or ASCII P2); returns ``(pixels (H, W) int64, maxval)``."""
    raw = path.read_bytes()
    magic = raw[:2]
    if magic not in (b"P5", b"P2"):
        raise ValueError(f"{path}: not a PGM image (magic {magic!r}, expected P5 or P2)")
    # Header: magic, width, height, maxval, separated by whitespace, with '#' comments to end of line.
    fields: list[int] = []
    pos = 2
    while len(fields) < 3:
        while pos < len(raw) and raw[pos : pos + 1].isspace():
            pos += 1
        if pos >= len(raw):
            raise ValueError(f"{path}: truncated PGM header")
        if raw[pos : pos + 1] == b"#":
            end = raw.find(b"\n", pos)
            pos = len(raw) if end < 0 else end + 1
            continue
        start = pos
        while pos < len(raw) and not raw[pos : pos + 1].isspace() and raw[pos : pos + 1] != b"#":
            pos += 1
        try:
            fields.append(int(raw[start:pos]))
        except ValueError:
            raise ValueError(f"{path}: bad PGM header field {raw[start:pos]!r}") from None
    width, height, maxval = fields
    if width <= 0 or height <= 0 or not 0 < maxval < 65536:
        raise ValueError(f"{path}: bad PGM size {width} x {height} or maxval {maxval}")
    n = width * height
    if magic == b"P5":
        pos += 1  # exactly one whitespace byte separates the header from the pixels
        dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
        body = raw[pos : pos + n * dtype.itemsize]
        if len(body) < n * dtype.itemsize:
            raise ValueError(f"{path}: PGM pixel data truncated ({len(body)} of {n * dtype.itemsize} bytes)")
        pixels = np.frombuffer(body, dtype=dtype).astype(np.int64)
    else:
        text = b"\n".join(line.split(b"#", 1)[0] for line in raw[pos:].splitlines())
        try:
            values = [int(tok) for tok in text.split()]
        except ValueError:
            raise ValueError(f"{path}: non-integer pixel value in ASCII PGM") from None
        if len(values) < n:
            raise ValueError(f"{path}: PGM pixel data truncated ({len(values)} of {n} values)")
        pixels = np.array(values[:n], dtype=np.int64)
    if pixels.max(initial=0) > maxval:
        raise ValueError(f"{path}: pixel values exceed maxval {maxval}")
    return pixels.reshape(height, width), maxval


def _read_image(path: Path) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Read a map image; returns ``(grey levels (H, W) float64, maxval, alpha mask or None)``."""
    if not path.is_file():
        raise ValueError(f"map image {path} does not exist")
    with open(path, "rb") as f:
        magic = f.read(2)
    if magic in (b"P5", b"P2"):
        pixels, maxval = _read_netpbm(path)
        return pixels.astype(np.float64), maxval, None
    from PIL import Image, UnidentifiedImageError  # only for PNG and friends

    try:
        with Image.open(path) as opened:
            img: Image.Image = opened
            if img.mode in ("1", "P", "PA", "CMYK", "YCbCr", "LAB", "HSV"):
                img = img.convert("RGBA" if "transparency" in img.info or img.mode == "PA" else "RGB")
            arr = np.asarray(img)
            mode = img.mode
    except (UnidentifiedImageError, OSError) as exc:
        raise ValueError(f"{path}: cannot read the map image ({exc})") from exc
    # 16-bit greyscale PNGs open as "I;16" or (older Pillow) "I".
    maxval = 65535 if mode.startswith("I") else 255
    if mode == "F" or (mode == "I" and (arr.min(initial=0) < 0 or arr.max(initial=0) > 65535)):
        raise ValueError(f"{path}: 32-bit images are not supported; save the map as 8- or 16-bit greyscale")
    alpha = None
    if arr.ndim == 3:
        if mode in ("LA", "RGBA"):
            alpha = arr[..., -1] == 0
            arr = arr[..., :-1]
        grey = arr.astype(np.float64).mean(axis=-1)  # map_server averages the colour channels
    else:
        grey = arr.astype(np.float64)
    return grey, maxval, alpha


def _require(meta: dict[str, Any], key: str, path: Path) -> Any:
    """``meta[key]``, or a ValueError naming the missing key."""
    if key not in meta:
        raise ValueError(f"{path}: map YAML lacks the required key {key!r} (needs image, resolution, origin)")
    return meta[key]


def load_ros_map(yaml_path: PathLike) -> OccupancyGrid:
    """Read a ROS ``map_server`` map (YAML + PGM/PNG image).

    The image path is relative to the YAML's folder (or absolute). Each pixel ``v`` (of ``maxval``,
    255 for 8-bit images; colour images are averaged) becomes an occupancy probability
    ``p = (maxval - v) / maxval``, or ``p = v / maxval`` when ``negate`` is 1. In ``trinary`` mode (the
    default) a cell is occupied (100) if ``p > occupied_thresh``, free (0) if ``p < free_thresh`` and
    unknown (-1) otherwise; in ``scale`` mode the in-between cells get ``99 * (p - free) / (occ - free)``;
    in ``raw`` mode the value itself is the occupancy (values above 100 are unknown). Fully transparent
    pixels are unknown. The image's top row is the map's highest y.

    Args:
        yaml_path: The map's YAML file. Required keys: ``image``, ``resolution``, ``origin``; ``negate``
            (0), ``occupied_thresh`` (0.65), ``free_thresh`` (0.196) and ``mode`` (trinary) default as shown.

    Returns:
        The grid.

    Raises:
        ValueError: If the YAML or the image is missing, unreadable, or has missing or invalid keys.
    """
    path = Path(yaml_path)
    if not path.is_file():
        raise ValueError(f"map YAML {path} does not exist")
    try:
        meta = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid YAML ({exc})") from exc
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: a map YAML must be a mapping with image, resolution and origin")
    image = _require(meta, "image", path)
    if not isinstance(image, str) or not image:
        raise ValueError(f"{path}: 'image' must be a file name, got {image!r}")
    resolution_raw = _require(meta, "resolution", path)
    origin_raw = _require(meta, "origin", path)
    try:
        resolution = float(resolution_raw)
        origin = tuple(float(v) for v in origin_raw)
        negate = int(meta.get("negate", 0))
        occ_t = float(meta.get("occupied_thresh", DEFAULT_OCCUPIED_THRESH))
        free_t = float(meta.get("free_thresh", DEFAULT_FREE_THRESH))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: resolution, origin, negate and thresholds must be numbers ({exc})") from exc
    mode = str(meta.get("mode", "trinary"))
    if len(origin) != 3:
        raise ValueError(f"{path}: origin must be [x, y, yaw], got {origin_raw!r}")
    if not (math.isfinite(resolution) and resolution > 0):
        raise ValueError(f"{path}: resolution must be positive, got {resolution}")
    if negate not in (0, 1):
        raise ValueError(f"{path}: negate must be 0 or 1, got {negate}")
    if not 0.0 <= free_t <= occ_t <= 1.0:
        raise ValueError(f"{path}: need 0 <= free_thresh <= occupied_thresh <= 1, got {free_t} and {occ_t}")
    if mode not in ("trinary", "scale", "raw"):
        raise ValueError(f"{path}: mode must be trinary, scale or raw, got {mode!r}")

    image_path = Path(image) if Path(image).is_absolute() else path.parent / image
    grey, maxval, transparent = _read_image(image_path)
    if mode == "raw":
        data = np.where(grey <= 100, grey, UNKNOWN).astype(np.int8)
    else:
        p = grey / maxval if negate else (maxval - grey) / maxval
        data = np.full(grey.shape, UNKNOWN, dtype=np.int8)
        if mode == "scale" and occ_t > free_t:
            mid = (p >= free_t) & (p <= occ_t)
            data[mid] = np.rint(99.0 * (p[mid] - free_t) / (occ_t - free_t)).astype(np.int8)
        data[p > occ_t] = OCCUPIED
        data[p < free_t] = FREE
    if transparent is not None:
        data[transparent] = UNKNOWN
    return OccupancyGrid(data=data[::-1], resolution=resolution, origin=origin)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------------
# Back to geometry
# --------------------------------------------------------------------------------------------------


def occupied_rectangles(mask: np.ndarray) -> np.ndarray:
    """Cover a boolean mask with few axis-aligned rectangles of cells (greedy, exact, non-overlapping).

    Each row is split into maximal horizontal runs of ``True``; a run identical (same columns) to a run
    of the previous row extends that rectangle upwards, otherwise it starts a new one.

    Args:
        mask: ``(H, W)`` boolean.

    Returns:
        ``(k, 4)`` int64 ``(i0, j0, i1, j1)``: rows ``i0..i1-1`` and columns ``j0..j1-1`` (half-open).
    """
    m = np.asarray(mask, dtype=bool)
    if m.ndim != 2:
        raise ValueError(f"occupied_rectangles: mask must be 2D, got shape {m.shape}")
    padded = np.zeros((m.shape[0], m.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = m
    steps = np.diff(padded, axis=1)  # +1 where a run starts, -1 one past where it ends
    rows_s, cols_s = np.nonzero(steps == 1)
    _, cols_e = np.nonzero(steps == -1)  # row-major order pairs starts and ends up
    rects: list[list[int]] = []
    open_runs: dict[tuple[int, int], int] = {}
    current_row = -1
    next_open: dict[tuple[int, int], int] = {}
    for i, j0, j1 in zip(rows_s.tolist(), cols_s.tolist(), cols_e.tolist(), strict=True):
        if i != current_row:
            # Runs of the previous row only continue into the row right above it.
            open_runs = next_open if i == current_row + 1 else {}
            next_open = {}
            current_row = i
        k = open_runs.get((j0, j1))
        if k is None:
            k = len(rects)
            rects.append([i, j0, i + 1, j1])
        else:
            rects[k][2] = i + 1
        next_open[(j0, j1)] = k
    return np.array(rects, dtype=np.int64).reshape(-1, 4)


def grid_to_geometry(grid: OccupancyGrid, kind: Kind = Kind.OBSTACLE, unknown_occupied: bool = False) -> Geometry:
    """Turn a map's occupied cells into box obstacles that the sensors and the physics see.

    Occupied cells (see :meth:`OccupancyGrid.occupied_mask`) are merged into few axis-aligned rectangles
    by :func:`occupied_rectangles` and added with :meth:`GeometryBuilder.box` (rotated boxes via
    :meth:`GeometryBuilder.polygon` when the origin has a yaw); their edges become zero-radius capsules,
    which the LIDAR and sonar kernels scan. Unknown cells are treated as free unless ``unknown_occupied``.

    Args:
        grid: The map.
        kind: :class:`Kind` given to every box.
        unknown_occupied: Treat unknown cells (-1) as obstacles too (e.g. to fence in unexplored space).

    Returns:
        The geometry, with ``bounds`` = the grid's extent.
    """
    mask = grid.occupied_mask()
    if unknown_occupied:
        mask = mask | (grid.data < 0)
    res = grid.resolution
    builder = GeometryBuilder()
    rotated = grid.origin[2] != 0.0
    for i0, j0, i1, j1 in occupied_rectangles(mask).tolist():
        if rotated:
            corners = np.array([[j0, i0], [j1, i0], [j1, i1], [j0, i1]], dtype=np.float64) * res
            builder.polygon(grid._grid_to_world(corners), kind)
        else:
            ox, oy, _ = grid.origin
            builder.box(ox + j0 * res, oy + i0 * res, ox + j1 * res, oy + i1 * res, kind)
    return builder.build(grid.bounds)
