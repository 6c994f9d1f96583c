"""González et al. (2009) deliberative planner: a Voronoi diagram of the greenhouse and a search through every corridor.

Sec. 3.1 of the paper: the generalized Voronoi diagram (GVD) of the free space is computed on the map,
the edges that run inside the plants are eliminated, and a search builds the shortest path that leaves no
corridor untracked (Figs. 4-5): start at the vertex nearest the start, run along a corridor (greater or
lesser value along the rows) to its end, and when that is no longer possible move across to the next
corridor (greater value across the rows), serpentine-wise.

On the occupancy grid the GVD is the skeleton of the free space (scikit-image), and the clearance of each
skeleton cell comes from the Euclidean distance transform (SciPy, which scikit-image builds on). Edges
"inside the plants" are the skeleton cells whose clearance is below ``min_clearance``: the narrow gaps
between plants of a row and the space inside a row bed, where the robot cannot pass. Eroding the free
space by that clearance before skeletonising removes exactly those edges (the medial axis of the eroded
set is the part of the medial axis with at least that clearance) and leaves a smaller image to thin.

The corridors are the long skeleton branches that run along the dominant direction of the diagram (the
rows); the search orders them across the rows, enters each at the end nearer to where the robot is, and
joins them by shortest paths on the diagram (Dijkstra on the skeleton's 8-connected cell graph).

Pure algorithms only: numpy, SciPy and scikit-image, no Gymnasium.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import ndimage as ndi
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from skimage.morphology import skeletonize


@dataclasses.dataclass(frozen=True)
class CoveragePlannerParams:
    """Parameters of :func:`coverage_path`.

    Attributes:
        min_clearance: Skeleton cells closer than this to an obstacle are removed as edges inside plants
            (m); about half the robot's width plus a margin.
        min_corridor_length: Skeleton branches shorter than this are not corridors (m).
        direction_tolerance: A branch is a corridor when its direction is within this angle of the rows
            (rad).
        junction_radius: Cells within this distance of a skeleton junction are cut off when the skeleton
            is split into branches (m).
        sample_spacing: Spacing of the returned path points (m); the paper samples the path "depending on
            the desired speed".
        smoothing: Half-width of the moving average applied to the skeleton's staircase (m); 0 keeps it.
        turn_clearance: A headland turn's corner with less room than this around it (m) is rounded: the
            Fitorobot, 1.5 m long and 0.7 m wide, sweeps 0.83 m around its centre when it turns on the spot.
        turn_radius: Radius of a rounded corner of a headland turn (m): there the robot turns as it drives.
        max_cells: Grids with more cells than this are max-pooled by the smallest integer factor that
            brings them under it (a work cell is blocked when any of its cells is, so the path stays on free
            cells of the given grid; the corridor runs are then re-centred on the given grid). This keeps a
            50 x 30 m greenhouse at 5 cm under 100 ms; smaller maps are planned at their own resolution.
    """

    min_clearance: float = 0.3
    min_corridor_length: float = 2.0
    direction_tolerance: float = math.radians(30.0)
    junction_radius: float = 0.15
    sample_spacing: float = 0.1
    smoothing: float = 0.3
    turn_clearance: float = 0.9
    turn_radius: float = 0.8
    max_cells: int = 250_000

    def __post_init__(self) -> None:
        for name in ("min_clearance", "min_corridor_length", "junction_radius", "sample_spacing"):
            if not getattr(self, name) > 0:
                raise ValueError(f"CoveragePlannerParams: {name} must be > 0, got {getattr(self, name)}")
        if not 0 < self.direction_tolerance < math.pi / 2:
            raise ValueError("CoveragePlannerParams: direction_tolerance must be in (0, pi/2) rad")
        if self.smoothing < 0 or self.turn_radius < 0 or self.turn_clearance < 0:
            raise ValueError("CoveragePlannerParams: smoothing, turn_clearance and turn_radius must be >= 0 m")
        if self.max_cells < 100:
            raise ValueError(f"CoveragePlannerParams: max_cells must be >= 100, got {self.max_cells}")


@dataclasses.dataclass
class CoveragePlan:
    """Everything :func:`plan_coverage` found, for plots and tests.

    Attributes:
        path: ``(N, 2)`` path points (m), from the start through every corridor.
        part: ``(N,)`` what each path point belongs to: :data:`APPROACH` (from the start to the first
            corridor), :data:`CORRIDOR` (along a corridor) or :data:`TURN` (across a headland from one corridor
            to the next).
        skeleton: Boolean grid of the pruned Voronoi diagram (the part the search uses), on the work grid.
        resolution: Cell size of the work grid (m).
        corridors: Per corridor, its two end points ``(2, 2)`` (m) in the order the path drives it.
        row_direction: Angle of the rows (rad) found from the diagram.
    """

    path: np.ndarray
    part: np.ndarray
    skeleton: np.ndarray
    resolution: float
    corridors: list[np.ndarray]
    row_direction: float


#: Values of :attr:`CoveragePlan.part`.
APPROACH, CORRIDOR, TURN = 0, 1, 2


_NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def _cell_graph(mask: np.ndarray) -> tuple[csr_matrix, np.ndarray]:
    """8-connected graph of the True cells of ``mask`` (edge weights 1 and sqrt 2, in cells)."""
    h, w = mask.shape
    index = np.full(mask.shape, -1, dtype=np.int64)
    ii, jj = np.nonzero(mask)
    index[ii, jj] = np.arange(len(ii))
    rows, cols, weights = [], [], []
    for di, dj in _NEIGHBOURS[4:]:  # each undirected edge once
        ni, nj = ii + di, jj + dj
        ok = (ni >= 0) & (ni < h) & (nj >= 0) & (nj < w)
        src = np.nonzero(ok)[0]
        dst = index[ni[ok], nj[ok]]
        keep = dst >= 0
        rows.append(src[keep])
        cols.append(dst[keep])
        weights.append(np.full(int(keep.sum()), math.hypot(di, dj)))
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    wgt = np.concatenate(weights)
    n = len(ii)
    graph = csr_matrix((np.concatenate([wgt, wgt]), (np.concatenate([r, c]), np.concatenate([c, r]))), shape=(n, n))
    return graph, np.column_stack([ii, jj])


def _neighbour_count(mask: np.ndarray) -> np.ndarray:
    """Number of 8-neighbours of every True cell of ``mask`` (0 elsewhere), counted at the True cells only."""
    ii, jj = np.nonzero(mask)
    padded = np.pad(mask, 1)
    deg = np.zeros(mask.shape, dtype=np.int8)
    deg[ii, jj] = sum(padded[ii + 1 + di, jj + 1 + dj].astype(np.int8) for di, dj in _NEIGHBOURS)
    return deg


def _branches(pieces: np.ndarray, res: float) -> tuple[np.ndarray, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Connected pieces of a skeleton: labels of their cells, principal direction and length of each.

    Returns:
        ``(label per cell, count, cell rows, cell columns, angle per piece (rad), length per piece (m))``.
    """
    labels, n = ndi.label(pieces, structure=np.ones((3, 3), bool))
    bi, bj = np.nonzero(labels)
    lab = labels[bi, bj] - 1
    if n == 0:
        return lab, 0, bi, bj, np.zeros(0), np.zeros(0)
    count = np.bincount(lab, minlength=n).astype(np.float64)
    dx = bj - (np.bincount(lab, bj, n) / count)[lab]
    dy = bi - (np.bincount(lab, bi, n) / count)[lab]
    sxx = np.bincount(lab, dx * dx, n)
    syy = np.bincount(lab, dy * dy, n)
    sxy = np.bincount(lab, dx * dy, n)
    angle = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # principal direction of each piece
    spread = np.sqrt(np.maximum(0.0, 0.5 * (sxx + syy) + np.hypot(0.5 * (sxx - syy), sxy)) / count)
    length = 2.0 * math.sqrt(3.0) * spread * res  # a straight piece of length L has std L / sqrt(12)
    return lab, n, bi, bj, angle, length


def _aligned_cells(mask: np.ndarray, direction: float, tolerance: float, block: int) -> np.ndarray:
    """Cells of ``mask`` whose surroundings (3 x 3 blocks of ``block`` cells) run within ``tolerance`` of ``direction``.

    The second moments of the mask's cells are summed per block (on the few mask cells only) and over each
    block's 3 x 3 neighbourhood, which gives every cell the principal direction of the skeleton around it.
    """
    ii, jj = np.nonzero(mask)
    out = np.zeros_like(mask)
    if len(ii) == 0:
        return out
    shape = (mask.shape[0] // block + 1, mask.shape[1] // block + 1)
    flat = (ii // block) * shape[1] + (jj // block)
    size = shape[0] * shape[1]
    x, y = jj.astype(np.float64), ii.astype(np.float64)
    moments = [np.bincount(flat, w, size).reshape(shape) for w in (np.ones_like(x), x, y, x * x, y * y, x * y)]
    n, sx, sy, sxx, syy, sxy = (ndi.uniform_filter(m, size=3, mode="constant") for m in moments)
    with np.errstate(invalid="ignore", divide="ignore"):
        cxx = sxx / n - (sx / n) ** 2
        cyy = syy / n - (sy / n) ** 2
        cxy = sxy / n - (sx / n) * (sy / n)
        theta = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
    dev = np.abs(np.arctan2(np.sin(2 * (theta - direction)), np.cos(2 * (theta - direction)))) / 2
    ok = np.nan_to_num(dev, nan=np.pi) <= tolerance
    out[ii, jj] = ok[ii // block, jj // block]
    return out


def _centre_across(
    points: np.ndarray, normal: tuple[float, float], occ: np.ndarray, res: float, reach: float, max_shift: float
) -> np.ndarray:
    """Move each point across the rows to midway between the nearest blocked cells on either side.

    Along a corridor the Voronoi diagram is the mid-line between its two rows; this finds it on the given
    (fine) grid, ``reach`` metres to each side at most, moving no point by more than ``max_shift`` metres.
    """
    if len(points) == 0:
        return points
    t = np.arange(1, int(reach / res) + 1) * res
    h, w = occ.shape
    gaps = []
    for sign in (1.0, -1.0):
        px = points[:, 0:1] + sign * t[None, :] * normal[0]
        py = points[:, 1:2] + sign * t[None, :] * normal[1]
        jj = np.floor(px / res).astype(np.int64)
        ii = np.floor(py / res).astype(np.int64)
        outside = (ii < 0) | (ii >= h) | (jj < 0) | (jj >= w)
        blocked = outside | occ[np.clip(ii, 0, h - 1), np.clip(jj, 0, w - 1)]
        first = np.where(blocked.any(axis=1), np.argmax(blocked, axis=1), len(t) - 1)
        gaps.append(t[first])
    shift = np.clip(0.5 * (gaps[0] - gaps[1]), -max_shift, max_shift)
    return points + shift[:, None] * np.asarray(normal)[None, :]


def _line_fit(a: np.ndarray, c: np.ndarray) -> tuple[float, float]:
    """Least-squares line ``c = slope * a + intercept`` (a flat line through the mean for a single point)."""
    ma, mc = float(a.mean()), float(c.mean())
    va = float(np.dot(a - ma, a - ma))
    slope = float(np.dot(a - ma, c - mc)) / va if va > 0 else 0.0
    return slope, mc - slope * ma


def _square_turn(
    start: np.ndarray,
    link: np.ndarray,
    row: tuple[float, float],
    clear: np.ndarray,
    res: float,
    room: np.ndarray,
    params: CoveragePlannerParams,
) -> np.ndarray:
    """A headland turn as Fig. 5 draws it: straight out of the corridor, across, straight into the next.

    ``link`` is the diagram's route from the end of one corridor (``start``) to the beginning of the next
    (its last point). Where the diagram rounds the headland off (a sensory map, whose free space is a band
    around the first run's trajectory), a robot that follows it leaves the turn at the corridor's mouth
    still turning. The square turn runs along the rows to the route's farthest reach into the headland,
    across, and back along the rows. Its corners are sharp (the robot turns on the spot there, then drives
    straight into the corridor) where the map leaves ``params.turn_clearance`` around them, and rounded to
    ``params.turn_radius`` (or less where a leg is shorter) where it does not, so that a long robot turns
    while it drives rather than on the spot beside a wall. It replaces the route when every point of it
    lies in ``clear`` (the cells at least ``min_clearance`` from an obstacle); otherwise the route is kept.

    Args:
        start: End of the corridor just driven (m).
        link: ``(n, 2)`` route to the next corridor (m), excluding ``start``.
        row: Unit vector along the rows.
        clear: Cells where the robot's centre may be.
        res: Cell size (m).
        room: Distance from every cell to the nearest blocked one (m).
        params: Planner parameters.
    """
    u = np.asarray(row, dtype=np.float64)
    end = link[-1]
    along = link @ u
    a0, a1 = float(start @ u), float(end @ u)
    outward = 1.0 if along.max() - max(a0, a1) > min(a0, a1) - along.min() else -1.0
    reach = float(along.max()) if outward > 0 else float(along.min())
    if outward * (reach - a0) <= res or outward * (reach - a1) <= res:
        return link  # not a U-turn into a headland
    c1, c2 = start + (reach - a0) * u, end + (reach - a1) * u
    legs = [float(np.hypot(*(c1 - start))), float(np.hypot(*(c2 - c1))), float(np.hypot(*(end - c2)))]
    d1, d2, d3 = ((b - a) / max(n, 1e-9) for a, b, n in ((start, c1, legs[0]), (c1, c2, legs[1]), (c2, end, legs[2])))

    def radius(corner: np.ndarray, before: float, after: float) -> float:
        i, j = (int(v) for v in np.clip(np.floor(corner[::-1] / res), 0, np.array(room.shape) - 1))
        return 0.0 if room[i, j] >= params.turn_clearance else min(params.turn_radius, before, after)

    r1, r2 = radius(c1, legs[0], 0.5 * legs[1]), radius(c2, 0.5 * legs[1], legs[2])
    pieces = [_segment(start, c1 - r1 * d1, res)]
    if r1 > 0:
        pieces.append(_arc(c1 - r1 * d1, d1, d2, r1, res))
    pieces.append(_segment(c1 + r1 * d2, c2 - r2 * d2, res))
    if r2 > 0:
        pieces.append(_arc(c2 - r2 * d2, d2, d3, r2, res))
    pieces.append(_segment(c2 + r2 * d3, end, res))
    square = np.vstack(pieces)
    ij = np.floor(square[:, ::-1] / res).astype(np.int64)
    inside = (ij >= 0).all(axis=1) & (ij[:, 0] < clear.shape[0]) & (ij[:, 1] < clear.shape[1])
    if not inside.all() or not clear[ij[:, 0], ij[:, 1]].all():
        return link
    return square


def _segment(a: np.ndarray, b: np.ndarray, res: float) -> np.ndarray:
    """Points every ``res`` metres or less from ``a`` (excluded) to ``b`` (included)."""
    n = max(1, int(math.ceil(float(np.hypot(*(b - a))) / res)))
    return a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a)


def _arc(a: np.ndarray, d_in: np.ndarray, d_out: np.ndarray, r: float, res: float) -> np.ndarray:
    """A quarter circle of radius ``r`` from ``a`` (heading ``d_in``) to heading ``d_out`` (at right angles)."""
    centre = a + r * d_out
    t = np.linspace(0.0, math.pi / 2, max(2, int(math.ceil(r * math.pi / 2 / res))) + 1)[1:]
    return centre - r * np.cos(t)[:, None] * d_out + r * np.sin(t)[:, None] * d_in


def _visible(free: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the straight segment between cells ``a`` and ``b`` crosses free cells only."""
    n = int(max(abs(b[0] - a[0]), abs(b[1] - a[1]))) * 2 + 2
    t = np.linspace(0.0, 1.0, n)
    ii = np.round(a[0] + t * (b[0] - a[0])).astype(np.int64)
    jj = np.round(a[1] + t * (b[1] - a[1])).astype(np.int64)
    return bool(np.all(free[ii, jj]))


def _resample(points: np.ndarray, spacing: float, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``spacing`` metres along a polyline (keeps both ends), each with the label of its nearest vertex."""
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0:
        return points[:1].copy(), labels[:1].copy()
    n = max(2, int(math.ceil(s[-1] / spacing)) + 1)
    t = np.linspace(0.0, s[-1], n)
    k = np.clip(np.searchsorted(s, t), 1, len(s) - 1)
    nearest = np.where(t - s[k - 1] <= s[k] - t, k - 1, k)
    return np.column_stack([np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])]), labels[nearest]


def _smooth(points: np.ndarray, half_width: int) -> np.ndarray:
    """Moving average of a polyline with fixed end points (removes the skeleton's one-cell staircase)."""
    if half_width <= 0 or len(points) < 3:
        return points
    k = 2 * half_width + 1
    pad = np.vstack([np.repeat(points[:1], half_width, 0), points, np.repeat(points[-1:], half_width, 0)])
    kernel = np.ones(k) / k
    out = np.column_stack([np.convolve(pad[:, 0], kernel, "valid"), np.convolve(pad[:, 1], kernel, "valid")])
    out[0], out[-1] = points[0], points[-1]
    return out


def plan_coverage(
    occupancy: np.ndarray,
    resolution: float,
    start: tuple[float, float] | np.ndarray,
    params: CoveragePlannerParams | None = None,
) -> CoveragePlan:
    """Plan the corridor-covering path and return it with the diagram it was built on.

    Args:
        occupancy: ``(H, W)`` boolean grid, True = blocked. Cell ``[i, j]`` covers x in
            ``[j*res, (j+1)*res)`` and y in ``[i*res, (i+1)*res)``.
        resolution: Cell size ``res`` (m).
        start: Start ``(x, y)`` (m), on a free cell.
        params: Planner parameters (defaults: :class:`CoveragePlannerParams`).

    Returns:
        The plan; its path starts at ``start`` and runs through free cells along every corridor.

    Raises:
        ValueError: For a malformed grid, a non-positive resolution, a start outside the grid or on a
            blocked cell, or a map without corridors reachable from the start.
    """
    p = params or CoveragePlannerParams()
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or occ.dtype != np.bool_ or min(occ.shape) < 3:
        raise ValueError(f"occupancy must be a 2-D boolean array of at least 3 x 3 cells, got {occ.dtype} {occ.shape}")
    res = float(resolution)
    if not (math.isfinite(res) and res > 0):
        raise ValueError(f"resolution must be a positive number of metres per cell, got {resolution}")
    sx, sy = (float(v) for v in np.asarray(start, dtype=np.float64).reshape(2))
    si, sj = int(math.floor(sy / res)), int(math.floor(sx / res))
    h, w = occ.shape
    if not (0 <= si < h and 0 <= sj < w):
        raise ValueError(f"start ({sx}, {sy}) lies outside the {w * res:.2f} x {h * res:.2f} m grid")
    if occ[si, sj]:
        raise ValueError(f"start ({sx}, {sy}) lies on a blocked cell")
    fine_occ, fine_res = occ, res
    f = max(1, int(math.ceil(math.sqrt(h * w / p.max_cells))))
    if f > 1:  # max-pool to the work resolution; cells past the grid's edge count as blocked
        hh, ww = -(-h // f), -(-w // f)
        padded = np.ones((hh * f, ww * f), dtype=bool)
        padded[:h, :w] = occ
        occ = padded[0::f, 0::f].copy()
        for di in range(f):
            for dj in range(f):
                if di or dj:
                    occ |= padded[di::f, dj::f]
        res, si, sj, h, w = res * f, si // f, sj // f, hh, ww
        if occ[si, sj]:
            raise ValueError(f"start ({sx}, {sy}) lies within {res:.2f} m of an obstacle; move it or raise max_cells")
    free = ~occ
    # Cells outside the grid count as blocked (the map's border is the workspace boundary).
    # GVD minus the edges inside the plants: the skeleton of the free space eroded by min_clearance, i.e. of
    # the cells whose Euclidean distance transform is at least min_clearance (an erosion by the digital disk
    # of that radius is the same set, computed without the full transform).
    r = p.min_clearance / res
    k = int(math.ceil(r))
    oy, ox = np.mgrid[-k : k + 1, -k : k + 1]
    disk = ox * ox + oy * oy < r * r
    clear = ndi.binary_erosion(free, structure=disk, border_value=0)  # where the robot's centre may go
    room = ndi.distance_transform_edt(np.pad(free, 1)).astype(np.float32)[1:-1, 1:-1] * res  # to the nearest block
    skel = skeletonize(clear)
    if not skel.any():
        raise ValueError(f"no free corridor is wider than 2 * min_clearance = {2 * p.min_clearance:.2f} m")
    graph, cells = _cell_graph(skel)
    # The diagram's part reachable from the start: the skeleton cell nearest to the start that it can see.
    d2 = (cells[:, 0] - si) ** 2 + (cells[:, 1] - sj) ** 2
    entry = -1
    for k in np.argsort(d2)[:400]:
        if _visible(free, np.array([si, sj]), cells[k]):
            entry = int(k)
            break
    if entry < 0:
        raise ValueError(f"start ({sx}, {sy}) cannot see the Voronoi diagram of the free space")
    dist0 = dijkstra(graph, indices=entry, min_only=True)
    reach = np.isfinite(dist0)
    main = np.zeros_like(skel)
    main[cells[reach, 0], cells[reach, 1]] = True

    # Branches: the diagram with its junctions cut out, one connected component per branch.
    deg = _neighbour_count(main)
    junction = main & (deg >= 3)
    cut_r = max(1, int(round(p.junction_radius / res)))
    near_junction = ndi.binary_dilation(junction, structure=np.ones((3, 3), bool), iterations=cut_r)
    pieces = main & ~near_junction
    lab, n_branches, bi, bj, angle, length = _branches(pieces, res)
    long = length >= p.min_corridor_length
    if not long.any():
        raise ValueError(f"no corridor of at least min_corridor_length = {p.min_corridor_length} m was found")
    # Dominant direction of the rows: length-weighted mean of the long branches' doubled angles.
    wts = length[long] ** 2
    row_dir = 0.5 * math.atan2(
        float(np.sum(wts * np.sin(2 * angle[long]))), float(np.sum(wts * np.cos(2 * angle[long])))
    )
    # A corridor beside a wall turns into the headland without a junction: keep only the cells whose
    # neighbourhood runs along the rows, and split the branches again.
    pieces &= _aligned_cells(pieces, row_dir, p.direction_tolerance, max(2, int(round(0.4 / res))))
    lab, n_branches, bi, bj, angle, length = _branches(pieces, res)
    if n_branches == 0:
        raise ValueError("the Voronoi diagram has no branch along the rows")
    dev = np.abs(np.arctan2(np.sin(2 * (angle - row_dir)), np.cos(2 * (angle - row_dir)))) / 2
    is_corr = (length >= p.min_corridor_length) & (dev <= p.direction_tolerance)
    if not is_corr.any():
        raise ValueError(f"no corridor of at least min_corridor_length = {p.min_corridor_length} m was found")
    count = np.bincount(lab, minlength=n_branches).astype(np.float64)
    ux, uy = math.cos(row_dir), math.sin(row_dir)
    along = bj * ux + bi * uy  # in cells
    across = -bj * uy + bi * ux

    # Group corridor branches by their position across the rows (a corridor split by a junction is one).
    corr_ids = np.nonzero(is_corr)[0]
    across_mean = np.bincount(lab, across, n_branches) / count
    along_mean = np.bincount(lab, along, n_branches) / count
    order = corr_ids[np.argsort(across_mean[corr_ids])]
    groups: list[list[int]] = []
    tol = min(0.35 * p.min_corridor_length, 0.5) / res
    for b in order:
        if groups and abs(across_mean[b] - across_mean[groups[-1][-1]]) < tol:
            groups[-1].append(int(b))
        else:
            groups.append([int(b)])
    # Shorter pieces along the rows (a corridor cut by a gap in a row near its end) join the corridor
    # whose centre line they continue.
    group_of = np.full(n_branches, -1, dtype=np.int64)
    for k, g in enumerate(groups):
        group_of[g] = k
    lines = [_line_fit(along[group_of[lab] == k], across[group_of[lab] == k]) for k in range(len(groups))]
    short = np.nonzero(~is_corr & (dev <= p.direction_tolerance) & (length >= 2 * p.junction_radius))[0]
    for b in short:
        resid = [abs(across_mean[b] - (line[0] * along_mean[b] + line[1])) for line in lines]
        k = int(np.argmin(resid))
        if resid[k] < tol:
            groups[k].append(int(b))
            group_of[b] = k
    # A corridor whose diagram is cut into pieces all shorter than min_corridor_length (grown plants with
    # gaps in both rows: a junction at every gap) is a corridor still when its pieces together are that long.
    loose = sorted((int(b) for b in short if group_of[b] < 0), key=lambda b: float(across_mean[b]))
    pending: list[list[int]] = []
    for b in loose:
        if pending and abs(across_mean[b] - across_mean[pending[-1][-1]]) < tol:
            pending[-1].append(b)
        else:
            pending.append([b])
    for g in pending:
        if float(length[g].sum()) >= p.min_corridor_length:
            group_of[g] = len(groups)
            groups.append(g)
    # Index of each skeleton cell in the graph, for the two extreme cells of every corridor.
    index = np.full(main.shape, -1, dtype=np.int64)
    index[cells[:, 0], cells[:, 1]] = np.arange(len(cells))
    ends = []
    chains: list[list[int]] = []
    spans: list[tuple[float, float, float, float]] = []
    for k in range(len(groups)):
        sel = group_of[lab] == k
        a_vals, c_vals = along[sel], across[sel]
        ci, cj = bi[sel], bj[sel]
        # The corridor proper: drop the cells that bend away into the headlands (a corridor beside a wall
        # runs into the headland without a junction), by a line fit with outlier rejection.
        keep = np.ones(len(a_vals), dtype=bool)
        for _ in range(3):
            slope, icpt = _line_fit(a_vals[keep], c_vals[keep])
            resid = np.abs(c_vals - (slope * a_vals + icpt))
            keep = resid <= max(0.3 / res, 3.0 * float(np.median(resid[keep])))
        idx = np.nonzero(keep)[0]
        idx = idx[np.argsort(a_vals[idx], kind="stable")]
        chains.append([int(v) for v in index[ci[idx], cj[idx]]])  # the corridor's cells, along the rows
        spans.append((slope, icpt, float(a_vals[idx[0]]), float(a_vals[idx[-1]])))
        k_lo, k_hi = idx[int(np.argmin(a_vals[idx]))], idx[int(np.argmax(a_vals[idx]))]
        ends.append((int(index[ci[k_lo], cj[k_lo]]), int(index[ci[k_hi], cj[k_hi]])))
    # Serpentine from the side of the greenhouse nearer to the start.
    s_across = -sj * uy + si * ux
    g_across = [float(np.mean([across_mean[b] for b in g])) for g in groups]
    seq = list(np.argsort(g_across))
    if abs(s_across - g_across[seq[-1]]) < abs(s_across - g_across[seq[0]]):
        seq = seq[::-1]

    def route(a: int, b: int) -> list[int]:
        """Shortest path on the diagram from node a to node b (a search bounded near the straight line first)."""
        straight = math.hypot(*(cells[a] - cells[b]).tolist())
        for limit in (1.5 * straight + 2.0 / res, np.inf):
            dist, pred = dijkstra(graph, indices=a, return_predecessors=True, limit=limit)
            if math.isfinite(dist[b]):
                break
        else:
            raise ValueError("a corridor is not connected to the start through the Voronoi diagram")
        out = [b]
        while out[-1] != a:
            out.append(int(pred[out[-1]]))
        return out[::-1]

    def centres(nodes: list[int]) -> np.ndarray:
        return (cells[nodes][:, ::-1] + 0.5) * res

    legs: list[np.ndarray] = [centres([entry])]
    in_corridor: list[bool] = [False]
    driven: list[np.ndarray] = []
    current = entry
    for g in seq:
        lo, hi = ends[g]
        # Enter at the end nearer to the robot (in a greenhouse the nearer end is also nearer on the diagram).
        d_lo, d_hi = (float(np.hypot(*(cells[e] - cells[current]).tolist())) for e in (lo, hi))
        first, last = (lo, hi) if d_lo <= d_hi else (hi, lo)
        chain = chains[g] if first == chains[g][0] else chains[g][::-1]
        slope, icpt, a_lo, a_hi = spans[g]
        ei, ej = cells[entry]
        a_e, c_e = ej * ux + ei * uy, -ej * uy + ei * ux
        if current == entry and a_lo < a_e < a_hi and abs(c_e - (slope * a_e + icpt)) < tol:
            # The start already lies on this corridor: drive it from there on instead of going back to its
            # end (the robot is placed at the corridor's beginning).
            chain_a = (cells[chain][:, 1] * ux + cells[chain][:, 0] * uy).tolist()
            k = int(np.argmin(np.abs(np.asarray(chain_a) - a_e)))
            link, run = route(current, chain[k])[1:], chain[k + 1 :]
        else:
            link, run = route(current, first)[1:], chain[1:]
        link_xy = centres(link) if link else np.zeros((0, 2))
        if current != entry and len(link) > 1:
            link_xy = _square_turn(centres([current])[0], link_xy, (ux, uy), clear, res, room, p)
        legs += [link_xy, centres(run)]
        in_corridor += [False] * len(link_xy) + [True] * len(run)
        driven.append(centres([first, last]))
        current = last
    xy = np.vstack(legs)
    if f > 1:  # back to the given grid's precision along the corridors
        sel = np.asarray(in_corridor)
        xy[sel] = _centre_across(xy[sel], (-uy, ux), fine_occ, fine_res, reach=1.5, max_shift=res)
    # The start joins the diagram where the robot stands, often a few centimetres to the side of it: the
    # smoothing spreads that step over its width instead of asking the robot to step sideways.
    xy = _smooth(np.vstack([[sx, sy], xy]), int(round(p.smoothing / res)))
    corridor = np.concatenate([[False], in_corridor])
    first = int(np.argmax(corridor))
    part = np.where(corridor, CORRIDOR, np.where(np.arange(len(corridor)) < first, APPROACH, TURN))
    path, part = _resample(xy, p.sample_spacing, part)
    return CoveragePlan(
        path=path, part=part, skeleton=main, resolution=res, corridors=driven, row_direction=row_dir
    )


def coverage_path(occupancy: np.ndarray, resolution: float, start: tuple[float, float] | np.ndarray) -> np.ndarray:
    """The shortest path through every corridor of a greenhouse map (González 2009, sec. 3.1).

    Args:
        occupancy: ``(H, W)`` boolean array, True = blocked. Cell ``[i, j]`` covers x in
            ``[j*res, (j+1)*res)`` and y in ``[i*res, (i+1)*res)``.
        resolution: Cell size ``res`` (m).
        start: Start ``(x, y)`` in metres.

    Returns:
        ``(N, 2)`` path points in metres: from ``start``, through free space only, along every corridor.

    Raises:
        ValueError: See :func:`plan_coverage`.
    """
    return plan_coverage(occupancy, resolution, start).path


def corridor_runs(part: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last + 1)`` index ranges of the plan's contiguous :data:`CORRIDOR` stretches, in driving order."""
    inside = np.concatenate([[False], np.asarray(part) == CORRIDOR, [False]])
    edges = np.flatnonzero(np.diff(inside.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _row_faces(
    run: np.ndarray, pts: np.ndarray, reach: float, depth: float, extent: float
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray, np.ndarray, np.ndarray] | None:
    """The echoes of the two row faces beside a corridor stretch ``run`` of a plan (None: a side has none).

    Echoes from 0 to ``extent`` metres along the stretch's chord and within ``reach`` across it are split
    into the two sides of the planned line; on each side only those from the row's face (where the nearest
    tenth of the side's echoes lie) to ``depth`` beyond it count (deeper ones are the far side of the row or
    the next corridor's).

    Returns:
        ``(a, c, (left, right), a_run, c_run, n)``: the echoes' distances along the chord and across from the
        planned line, the masks of each side's face echoes, the stretch's own coordinates along and across
        the chord, and the chord's left normal.
    """
    chord = run[-1] - run[0]
    u = chord / float(np.hypot(*chord))
    n = np.array([-u[1], u[0]])
    a_run, c_run = (run - run[0]) @ u, (run - run[0]) @ n
    a, c = (pts - run[0]) @ u, (pts - run[0]) @ n
    inside = (a >= 0) & (a <= extent) & (np.abs(c) <= reach)
    a, c = a[inside], c[inside] - np.interp(a[inside], a_run, c_run)
    sides = []
    for sign in (1.0, -1.0):
        d = sign * c
        on_side = d > 0
        if not on_side.any():
            return None
        sides.append(on_side & (d <= np.quantile(d[on_side], 0.1) + depth))
    return a, c, sides, a_run, c_run, n


def row_ends(
    plan: CoveragePlan, echoes: np.ndarray, reach: float = 3.0, depth: float = 0.4, past: float = 2.0, gap: float = 0.5
) -> list[tuple[int, int, np.ndarray]]:
    """Where the rows beside each corridor stretch of a plan end, on the echoes of a sensory map.

    The face echoes of each side (as :func:`anchor_corridors` picks them, up to ``past`` metres beyond the
    stretch's end) are walked along the stretch's chord from their median on: the row ends at the last echo
    before a gap longer than ``gap`` (an echo beyond such a gap is a post or a stray).

    Args:
        plan: A plan from :func:`plan_coverage`.
        echoes: ``(n, 2)`` echo positions in the plan's frame (m).
        reach: Echoes farther than this across from the chord are not of this corridor's rows (m).
        depth: Echoes deeper than this behind a row's face are the far side of the row or beyond (m).
        past: How far beyond the stretch's end a row may end (m).
        gap: A longer stretch without echoes ends a row (m).

    Returns:
        Per corridor stretch ``(first, last + 1, ends)``: its index range in ``plan.path`` and the distances
        along its chord (from its first point, in the driving direction) at which its left and right rows
        end (m; NaN where a side has no face echoes).
    """
    pts = np.asarray(echoes, dtype=np.float64).reshape(-1, 2)
    out = []
    for lo, hi in corridor_runs(plan.part):
        run = plan.path[lo:hi]
        length = float(np.hypot(*(run[-1] - run[0])))
        ends = np.full(2, np.nan)
        faces = _row_faces(run, pts, reach, depth, length + past) if length > 0 and len(pts) else None
        if faces is not None:
            a, _, sides, _, _, _ = faces
            for k, side in enumerate(sides):
                along = np.sort(a[side])
                start = len(along) // 2
                breaks = np.flatnonzero(np.diff(along[start:]) > gap)
                ends[k] = along[start + breaks[0]] if len(breaks) else along[-1]
        out.append((lo, hi, ends))
    return out


def anchor_corridors(
    plan: CoveragePlan,
    echoes: np.ndarray,
    reach: float = 3.0,
    depth: float = 0.4,
    bin_length: float = 0.5,
    degree: int = 2,
    blend: float = 1.0,
    face_quantile: float = 0.25,
) -> CoveragePlan:
    """Re-anchor each corridor of a plan on the mid-line of its two rows, fitted to the echoes beside it.

    On a sensory map (eq. 2) the Voronoi mid-line of a corridor follows every leaf that reaches into it and
    every echo that slipped through a row from the next corridor, so it wavers by several centimetres, and
    beside a wall it lies toward the row (the sonars see into the row between the plants, not into the wall).
    For each corridor stretch of the plan this fits the rows instead. The echoes within ``reach`` of the
    stretch's chord are split into the two sides of the planned line; on each side only those from the row's
    face (where the nearest tenth of the side's echoes lie) to ``depth`` beyond it count. Per
    ``bin_length`` bin along the chord, each side's face is the ``face_quantile`` of its echoes' distances
    from the line, and the bins seen on both sides give a mid-point. A polynomial of ``degree`` in the
    distance along the chord is fitted to the mid-points (least squares, refitted without the bins more than
    2.5 robust standard deviations off), and the stretch's points are moved across onto it. The ``blend``
    metres of path before and after the stretch are shifted by a share of its end's move that falls off
    linearly, so the turns join the re-anchored corridor without a step.

    Args:
        plan: A plan from :func:`plan_coverage`.
        echoes: ``(n, 2)`` echo positions in the plan's frame (m).
        reach: Echoes farther than this across from the chord are not of this corridor's rows (m).
        depth: Echoes deeper than this behind a row's face are the far side of the row or beyond (m).
        bin_length: Length of the bins along the corridor (m).
        degree: Degree of the fitted mid-line (2: a row bowed at mid-length).
        blend: Length of path over which a turn joins the moved corridor (m).
        face_quantile: Share of a bin's echoes on one side that lie nearer the line than its face (echoes
            that slip into the foliage read long; leaves reach out between the plants).

    Returns:
        The plan with its corridor stretches moved (stretches with fewer than ``degree + 2`` two-sided bins
        are left as they were).

    Raises:
        ValueError: For echoes that are not ``(n, 2)`` finite positions, or an argument out of its range.
    """
    pts = np.asarray(echoes, dtype=np.float64)
    if pts.size and (pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all()):
        raise ValueError(f"anchor_corridors: echoes must be (n, 2) finite positions, got shape {pts.shape}")
    for name, value in (("reach", reach), ("depth", depth), ("bin_length", bin_length)):
        if not value > 0:
            raise ValueError(f"anchor_corridors: {name} must be > 0 (m), got {value}")
    if not 0.0 < face_quantile < 1.0:
        raise ValueError(f"anchor_corridors: face_quantile must be in (0, 1), got {face_quantile}")
    if not (0 <= degree <= 4 and blend >= 0):
        raise ValueError(f"anchor_corridors: degree must be in [0, 4] and blend >= 0 (m), got {degree}, {blend}")
    pts = pts.reshape(-1, 2)
    path = plan.path.copy()
    s_path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(plan.path, axis=0).T))])
    for lo, hi in corridor_runs(plan.part):
        run = plan.path[lo:hi]
        chord = run[-1] - run[0]
        length = float(np.hypot(*chord))
        if length < 2 * bin_length or len(pts) == 0:
            continue
        faces = _row_faces(run, pts, reach, depth, length)
        if faces is None:
            continue
        a, c, sides, a_run, c_run, n = faces
        edges = np.arange(0.0, length + bin_length, bin_length)
        k = np.digitize(a, edges) - 1
        mids, centres = [], []
        for b in range(len(edges) - 1):
            left, right = c[(k == b) & sides[0]], c[(k == b) & sides[1]]
            if len(left) and len(right):
                centre = 0.5 * (edges[b] + edges[b + 1])
                faces = np.quantile(left, face_quantile) + np.quantile(right, 1.0 - face_quantile)
                mids.append(0.5 * faces + np.interp(centre, a_run, c_run))
                centres.append(centre)
        if len(mids) < degree + 2:
            continue
        x, y = np.array(centres), np.array(mids)
        keep = np.ones(len(x), dtype=bool)
        for _ in range(2):
            coef = np.polyfit(x[keep], y[keep], degree)
            resid = y - np.polyval(coef, x)
            scale = 1.4826 * float(np.median(np.abs(resid[keep]))) + 1e-3
            keep = np.abs(resid) <= 2.5 * scale
            if keep.sum() < degree + 2:
                break
        move = np.polyval(coef, np.clip(a_run, x.min(), x.max())) - c_run
        path[lo:hi] += move[:, None] * n[None, :]
        for end, shift, side in ((lo, move[0], -1), (hi - 1, move[-1], 1)):
            k_out = np.arange(end + side, -1 if side < 0 else len(path), side)
            k_out = k_out[np.abs(s_path[k_out] - s_path[end]) < blend]
            k_out = k_out[plan.part[k_out] != CORRIDOR]
            weight = 1.0 - np.abs(s_path[k_out] - s_path[end]) / blend
            path[k_out] += (weight * shift)[:, None] * n[None, :]
    return dataclasses.replace(plan, path=path)
