"""The coverage mission: drive every corridor end to end; coverage, cross-track error and reward terms.

Each corridor's centre line is cut into bins of ``bin_length`` metres along the rows. A bin is covered when
the robot's centre passes over it inside that corridor (the corridor whose centre line is nearest). The
mission succeeds when every bin of every corridor is covered. One :meth:`CoverageTask.evaluate` call per
step produces the dict that termination, reward and ``info`` all read.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class CoverageWeights:
    """Weights of the named reward terms (see the env docstring's Rewards section)."""

    coverage: float = 1.0
    success: float = 10.0
    contact: float = 10.0
    cross_track: float = 0.0
    time: float = 0.001


class CoverageTask:
    """Which corridor the robot is in, how far off its centre line, and how much of each corridor is covered.

    Args:
        corridors: Centre lines, ``(k, 2)`` polylines with increasing x, one per corridor.
        bin_length: Length of a coverage bin along the rows (m).
        weights: Reward weights.
    """

    def __init__(self, corridors: tuple[np.ndarray, ...], bin_length: float, weights: CoverageWeights) -> None:
        if not corridors:
            raise ValueError("CoverageTask needs at least one corridor")
        self.corridors = tuple(np.asarray(c, dtype=np.float64) for c in corridors)
        self.weights = weights
        self.x0 = np.array([c[0, 0] for c in self.corridors])
        self.x1 = np.array([c[-1, 0] for c in self.corridors])
        self.n_bins = np.maximum(1, np.ceil((self.x1 - self.x0) / bin_length - 1e-9).astype(np.int64))
        self.covered = [np.zeros(int(n), dtype=bool) for n in self.n_bins]
        self.max_cross_track = 0.0

    @property
    def n_corridors(self) -> int:
        """Number of corridors."""
        return len(self.corridors)

    def reset(self) -> None:
        """Forget what was covered."""
        for c in self.covered:
            c[:] = False
        self.max_cross_track = 0.0

    def corridor_fractions(self) -> np.ndarray:
        """Covered fraction of each corridor."""
        return np.array([c.mean() for c in self.covered])

    @property
    def coverage(self) -> float:
        """Covered fraction of all bins."""
        return float(sum(int(c.sum()) for c in self.covered) / float(self.n_bins.sum()))

    @property
    def done(self) -> bool:
        """True once every corridor is covered end to end."""
        return all(bool(c.all()) for c in self.covered)

    def locate(self, x: float, y: float) -> tuple[int, float]:
        """Corridor the point ``(x, y)`` is in (-1 in the headlands) and its distance to that centre line (m)."""
        best, best_d = -1, math.inf
        for k, c in enumerate(self.corridors):
            if not self.x0[k] <= x <= self.x1[k]:
                continue
            seg = int(np.clip(np.searchsorted(c[:, 0], x) - 1, 0, len(c) - 2))
            (ax, ay), (bx, by) = c[seg], c[seg + 1]
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
        before = self.coverage
        k, cross = self.locate(x, y)
        if k >= 0:
            b = min(int(self.n_bins[k]) - 1, int((x - self.x0[k]) / (self.x1[k] - self.x0[k]) * self.n_bins[k]))
            self.covered[k][b] = True
            self.max_cross_track = max(self.max_cross_track, cross)
        gained = self.coverage - before
        success = self.done
        terms = {
            "reward_coverage": w.coverage * gained * self.n_corridors,
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
            "corridors_covered": sum(bool(c.all()) for c in self.covered),
        }
