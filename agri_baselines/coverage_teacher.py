"""A training teacher for ``agri_envs/GreenhouseCoverage-v2`` that covers the greenhouse faster than the paper.

``gonzalez-deliberative`` drives the corridors at the Fitorobot's speed limit and turns from one corridor into
the next on the Voronoi diagram of the headland, about 1.3 m out past the row ends. The straights cannot get
faster; the turns can. ``coverage-half-circle`` (PRIVILEGED: the true corridor centre lines from
``env.unwrapped.corridor_lines()``, the true pose) drives every corridor's centre line to its end and turns into
the next one on a half circle that starts right there, its diameter the distance between the two centre lines,
with the same Pure Pursuit tracker and limits as the planner (:data:`~agri_baselines.gonzalez_policies.
TRACKING_SPEED`, :data:`~agri_baselines.gonzalez_policies.TRACKING_TURN_RATE`, the look-ahead shortened before
bends). On the paper's greenhouse it takes 16 % less time than the planner. In 1.2 m corridors (half circles of
0.85-0.9 m, about the radius the Fitorobot turns at 0.5 m/s) it touched the greenhouse's side wall in 11 of 20
validation greenhouses, each time turning out of or into the corridor beside that wall; the planner, which sees the
wall on its map, does not.

It is no paper's controller: it is registered as a training teacher (``PolicySpec.teacher``), which
``pretrain`` may clone and ``agri evaluate`` may run, without leaderboard entries of its own.
``benchmarks/bound_time_gains.py`` runs it to bound the time a coverage policy can gain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from agri_baselines.gonzalez import PurePursuit
from agri_baselines.gonzalez_policies import MIN_LOOKAHEAD, CoveragePolicyBase
from agri_envs.coverage.task import covering_legs
from agri_envs.sim2d.polyline import Polyline


def serpentine_with_half_circles(corridors: Sequence[np.ndarray], start: np.ndarray, extend: float) -> np.ndarray:
    """Points every 10 cm from ``start``: the corridor centre lines in serpentine order, joined by half circles.

    The legs are the covering serpentine's (:func:`agri_envs.coverage.task.covering_legs`: corridor 0 driven
    along its points, the next against them, and so on, each extended ``extend`` m past its ends); each half circle
    runs from one leg's last point to the next leg's first, across the headland. The first leg starts at its
    corridor's end, not ``extend`` m before it.
    """
    legs = covering_legs(tuple(np.asarray(c, dtype=np.float64) for c in corridors), extend)
    points: list[np.ndarray] = [np.asarray(start, dtype=np.float64), *legs[0][1:]]
    for k, leg in enumerate(legs[1:]):
        end, mouth = points[-1], leg[0]
        out = 1.0 if k % 2 == 0 else -1.0  # the turn bulges past the far end of leg k: high x after an even leg
        centre, radius = (end + mouth) / 2.0, abs(mouth[1] - end[1]) / 2.0
        side = math.copysign(1.0, end[1] - centre[1])
        for t in np.linspace(0.0, math.pi, 24)[1:-1]:
            points.append(centre + (out * radius * math.sin(t), side * radius * math.cos(t)))
        points.extend(leg)
    path = Polyline(np.array(points))
    return path.at_many(np.append(np.arange(0.0, path.length, 0.1), path.length))


class HalfCircleTeacher(CoveragePolicyBase):
    """``coverage-half-circle`` (PRIVILEGED: the true corridor lines and pose; a training teacher, see module doc).

    Args:
        env: A GreenhouseCoverage env made with ``localization="ground_truth"``.
        extend: How far past the row ends the half circles start and end (m).
        lookahead: Pure Pursuit look-ahead on straight stretches (m), the planner's 1 m.
    """

    def __init__(self, env: Any, extend: float = 0.0, lookahead: float = 1.0) -> None:
        super().__init__(env)
        if env.unwrapped.config.localization != "ground_truth":
            raise ValueError("coverage-half-circle needs gym.make(..., localization='ground_truth')")
        self.extend = extend
        self.lookahead = lookahead
        self.tracker: PurePursuit | None = None

    def act(self, obs: dict[str, np.ndarray], start: bool) -> np.ndarray:
        """Lay the path on the episode's first observation, then follow it."""
        pose, _, _ = self.decode(obs)
        if start or self.tracker is None:
            path = serpentine_with_half_circles(self.env.unwrapped.corridor_lines(), pose[:2], self.extend)
            self.tracker = PurePursuit(path, lookahead=self.lookahead, min_lookahead=MIN_LOOKAHEAD)
        return self.to_action(*self.tracker.command(pose, *self.tracking))


def make_half_circle_teacher(env: Any) -> HalfCircleTeacher:
    """``coverage-half-circle``. Env: ``localization="ground_truth"`` (privileged: true corridor lines and pose)."""
    return HalfCircleTeacher(env)
