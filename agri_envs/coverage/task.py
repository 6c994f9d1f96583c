"""The coverage mission: drive every corridor end to end; coverage, cross-track error and reward terms.

Each corridor's centre line is cut into bins of ``bin_length`` metres along the rows. A bin is covered when
the robot's centre passes over it inside that corridor (the corridor whose centre line is nearest). The
mission succeeds when every bin of every corridor is covered. One :meth:`CoverageTask.evaluate` call per
step produces the dict that termination, reward and ``info`` all read.

The reward also pays progress along the serpentine that covers the corridors in order (the route González's
planner draws, Fig. 5): through each corridor to a subgoal ``subgoal_offset`` metres past its far end (the
env puts it mid-headland, with room for the 1.5 m robot's turn on either side), then to the next corridor's
mouth on the same side. Progress toward the current subgoal counts turning toward it
(:class:`~agri_envs.sim2d.route.RouteProgress`), so the U-turn through the headland into the next corridor
pays as it is driven, not only once the next corridor's first bin is covered. The robot is not told the
subgoals: they shape the reward only.
"""

from __future__ import annotations

import bisect
import dataclasses
import math

import numpy as np

from agri_envs.sim2d.route import RouteProgress


@dataclasses.dataclass(frozen=True)
class CoverageWeights:
    """Weights of the named reward terms (see the env docstring's Rewards section)."""

    coverage: float = 1.0
    success: float = 10.0
    contact: float = 10.0
    cross_track: float = 0.0
    time: float = 0.001
    progress: float = 0.0


def covering_legs(corridors: tuple[np.ndarray, ...], offset: float) -> list[np.ndarray]:
    """Each centre line extended ``offset`` metres past both ends, in the direction the serpentine drives it.

    Corridor ``k`` is driven toward high x when ``k`` is even and back when it is odd. The legs of the reward's
    subgoals and of the route observation (:func:`serpentine_subgoals`, :func:`serpentine_path`), and of the
    training teacher ``coverage-half-circle`` (:mod:`agri_baselines.coverage_teacher`).
    """
    legs = []
    for k, c in enumerate(corridors):
        line = np.vstack([c[:1] - (offset, 0.0), c, c[-1:] + (offset, 0.0)])
        legs.append(line if k % 2 == 0 else line[::-1])
    return legs


def serpentine_subgoals(corridors: tuple[np.ndarray, ...], offset: float) -> np.ndarray:
    """The points the covering serpentine passes, after its start at the first corridor's low-x mouth.

    Each corridor contributes its mouth and its far end, ``offset`` metres past the ends of its centre line, in
    the order the serpentine drives them (:func:`covering_legs`). The first point (the mouth of corridor 0,
    where the robot starts) is left out.

    Args:
        corridors: Centre lines, ``(k, 2)`` polylines with increasing x, one per corridor, in order across
            the rows.
        offset: Distance of each point past the end of its corridor's centre line (m).

    Returns:
        ``(2 * len(corridors) - 1, 2)`` points (m).
    """
    ends = [p for leg in covering_legs(corridors, offset) for p in (leg[0], leg[-1])]
    return np.array(ends[1:], dtype=np.float64)


def serpentine_path(corridors: tuple[np.ndarray, ...], offset: float) -> np.ndarray:
    """The covering serpentine as one polyline: every centre line, ``offset`` metres past its ends, joined in order.

    From the point ``offset`` metres past one corridor's far end the path crosses the headland to the point as
    far past the next corridor's end on the same side. The subgoals of :func:`serpentine_subgoals` are its
    corners.

    Returns:
        ``(m, 2)`` vertices (m), from the point ``offset`` metres before corridor 0's low-x end.
    """
    return np.vstack(covering_legs(corridors, offset))


class CoverageTask:
    """Which corridor the robot is in, how far off its centre line, and how much of each corridor is covered.

    Args:
        corridors: Centre lines, ``(k, 2)`` polylines with increasing x, one per corridor.
        bin_length: Length of a coverage bin along the rows (m).
        weights: Reward weights.
        turn_distance: Metres of distance to go per radian of heading error, for the progress term (m/rad).
        subgoal_offset: Distance of the serpentine's subgoals past the corridor ends (m).
        subgoal_radius: A subgoal counts as passed within this distance of the robot centre (m).
    """

    def __init__(
        self,
        corridors: tuple[np.ndarray, ...],
        bin_length: float,
        weights: CoverageWeights,
        turn_distance: float = 0.0,
        subgoal_offset: float = 1.3,
        subgoal_radius: float = 0.3,
    ) -> None:
        if not corridors:
            raise ValueError("CoverageTask needs at least one corridor")
        self.corridors = tuple(np.asarray(c, dtype=np.float64) for c in corridors)
        self.weights = weights
        self.x0 = np.array([c[0, 0] for c in self.corridors])
        self.x1 = np.array([c[-1, 0] for c in self.corridors])
        self.n_bins = np.maximum(1, np.ceil((self.x1 - self.x0) / bin_length - 1e-9).astype(np.int64))
        self.covered = [np.zeros(int(n), dtype=bool) for n in self.n_bins]
        self.max_cross_track = 0.0
        self.route = RouteProgress(serpentine_subgoals(self.corridors, subgoal_offset), subgoal_radius, turn_distance)
        # Plain floats for the per-step lookups (the same arithmetic as numpy's, without its call overhead).
        self._lines = [([float(v) for v in c[:, 0]], [float(v) for v in c[:, 1]]) for c in self.corridors]
        self._spans = [(float(a), float(b)) for a, b in zip(self.x0, self.x1, strict=True)]
        self._total_bins = int(self.n_bins.sum())
        self._n_covered = 0
        self._done_corridors = 0

    @property
    def n_corridors(self) -> int:
        """Number of corridors."""
        return len(self.corridors)

    def reset(self, pose: np.ndarray | None = None) -> None:
        """Forget what was covered; with ``pose``, start the serpentine's progress from there."""
        for c in self.covered:
            c[:] = False
        self.max_cross_track = 0.0
        self._n_covered = 0
        self._done_corridors = 0
        if pose is not None:
            self.route.reset(pose)

    def corridor_fractions(self) -> np.ndarray:
        """Covered fraction of each corridor."""
        return np.array([c.mean() for c in self.covered])

    @property
    def coverage(self) -> float:
        """Covered fraction of all bins."""
        return self._n_covered / self._total_bins

    @property
    def done(self) -> bool:
        """True once every corridor is covered end to end."""
        return self._n_covered == self._total_bins

    def locate(self, x: float, y: float) -> tuple[int, float]:
        """Corridor the point ``(x, y)`` is in (-1 in the headlands) and its distance to that centre line (m)."""
        best, best_d = -1, math.inf
        for k, (xs, ys) in enumerate(self._lines):
            lo, hi = self._spans[k]
            if not lo <= x <= hi:
                continue
            seg = min(max(bisect.bisect_left(xs, x) - 1, 0), len(xs) - 2)
            ax, ay, bx, by = xs[seg], ys[seg], xs[seg + 1], ys[seg + 1]
            t = (x - ax) / (bx - ax) if bx != ax else 0.0
            dy = y - (ay + t * (by - ay))
            d = abs(dy) * math.cos(math.atan2(by - ay, bx - ax))  # perpendicular distance to the segment
            if d < best_d:
                best, best_d = k, d
        return best, (best_d if best >= 0 else 0.0)

    def evaluate(self, pose: np.ndarray, crop_contact: bool, other_contact: bool) -> dict[str, float | bool | int]:
        """Update coverage for the robot's new pose and return the step's outcome and reward terms."""
        w = self.weights
        x, y = float(pose[0]), float(pose[1])
        k, cross = self.locate(x, y)
        gained = 0
        if k >= 0:
            lo, hi = self._spans[k]
            n = int(self.n_bins[k])
            b = min(n - 1, int((x - lo) / (hi - lo) * n))
            if not self.covered[k][b]:
                self.covered[k][b] = True
                gained = 1
                self._n_covered += 1
                if self.covered[k].all():
                    self._done_corridors += 1
            self.max_cross_track = max(self.max_cross_track, cross)
        progress, _, _, _ = self.route.advance(pose)
        success = self.done
        terms = {
            "reward_coverage": w.coverage * (gained / self._total_bins) * self.n_corridors,
            "reward_progress": w.progress * progress,
            "reward_success": w.success * float(success),
            "reward_contact": -w.contact * float(crop_contact or other_contact),
            "reward_cross_track": -w.cross_track * cross,
            "reward_time": -w.time,
        }
        reward = 0.0
        for value in terms.values():  # added left to right, as the batched env adds them (not sum()'s algorithm)
            reward += value
        return {
            **terms,
            "reward": reward,
            "is_success": success,
            "corridor": k,
            "cross_track": cross,
            "max_cross_track": self.max_cross_track,
            "coverage": self.coverage,
            "corridors_covered": self._done_corridors,
            "subgoal_index": self.route.index,
        }
