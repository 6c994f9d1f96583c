"""Offscreen top-down renderer (pygame) for the 2D worlds.

Draws the static scene, people, robots, LIDAR rays, sonar cones, waypoints and the driven path into an
offscreen surface and returns it as an ``(H, W, 3)`` uint8 array. pygame is imported only when a renderer
is created, so envs made with ``render_mode=None`` never load it. The library sets no environment
variables: headless callers set ``SDL_VIDEODRIVER=dummy`` themselves (only ``"human"`` mode needs it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from agri_envs.sim2d.geometry import Geometry, Kind

COLOURS = {
    "background": (245, 243, 235),
    "floor": (235, 228, 212),
    Kind.WALL: (90, 90, 95),
    Kind.POST: (40, 40, 45),
    Kind.PLANT: (60, 150, 60),
    Kind.LEAF: (120, 190, 90),
    Kind.TREE: (30, 110, 45),
    Kind.PERSON: (220, 120, 30),
    Kind.OBSTACLE: (70, 70, 70),
    Kind.ROBOT: (40, 90, 200),
    "lidar": (230, 40, 40),
    "sonar": (250, 200, 60),
    "waypoint": (210, 30, 30),
    "path": (40, 90, 200),
    "text": (20, 20, 20),
}


class TopDownRenderer:
    """Draws a 2D world seen from above.

    Args:
        bounds: ``(xmin, ymin, xmax, ymax)`` of the area to draw (m); with the margin it sets the canvas's
            aspect ratio, fixed for the renderer's life (see :meth:`fit` for other areas).
        width_px: Image width; the height follows the aspect ratio.
        margin: Extra border around ``bounds`` (m).
    """

    def __init__(self, bounds: Sequence[float], width_px: int = 800, margin: float = 0.3) -> None:
        import pygame  # local import: only renderers need pygame

        self._pg = pygame
        if not pygame.font.get_init():
            pygame.font.init()
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        self.margin = margin
        span_x, span_y = xmax - xmin + 2 * margin, ymax - ymin + 2 * margin
        self.size = (int(width_px), int(math.ceil(span_y * width_px / span_x)))
        self.fit(bounds)
        self.surface = pygame.Surface(self.size)
        self._overlay = pygame.Surface(self.size, pygame.SRCALPHA)
        self._font = pygame.font.Font(None, max(14, int(0.035 * self.size[1])))
        self._static: Any = None
        self._window: Any = None

    def fit(self, bounds: Sequence[float]) -> None:
        """Show the area ``bounds`` (m, plus the margin) as large as the fixed canvas allows, centred in it.

        Later drawing calls use this mapping; the canvas keeps its size, so frames of areas of other shapes
        (another episode's scene) have the same shape, letterboxed.
        """
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        m = self.margin
        span_x, span_y = xmax - xmin + 2 * m, ymax - ymin + 2 * m
        self.scale = min(self.size[0] / span_x, self.size[1] / span_y)
        self.xmin = xmin - m - 0.5 * (self.size[0] / self.scale - span_x)
        self.ymin = ymin - m - 0.5 * (self.size[1] / self.scale - span_y)

    def to_px(self, x: float, y: float) -> tuple[int, int]:
        """World point (m) to pixel (y up in the world, down in the image)."""
        return (int(round((x - self.xmin) * self.scale)), int(round(self.size[1] - (y - self.ymin) * self.scale)))

    def _px_len(self, length: float) -> int:
        return max(1, int(round(length * self.scale)))

    def draw_geometry(self, geometry: Geometry) -> None:
        """Draw (and cache) the static scene as the background of every frame."""
        pg = self._pg
        bg = pg.Surface(self.size)
        bg.fill(COLOURS["background"])
        xmin, ymin, xmax, ymax = geometry.bounds
        tl = self.to_px(xmin, ymax)
        br = self.to_px(xmax, ymin)
        pg.draw.rect(bg, COLOURS["floor"], pg.Rect(tl[0], tl[1], br[0] - tl[0], br[1] - tl[1]))
        for poly, kind in zip(geometry.polygons, geometry.polygon_kinds, strict=True):
            pg.draw.polygon(bg, COLOURS[Kind(kind)], [self.to_px(*p) for p in poly])
        for (x0, y0, x1, y1, r), kind in zip(geometry.capsules, geometry.capsule_kinds, strict=True):
            if r <= 0:
                continue
            colour = COLOURS[Kind(int(kind))]
            pg.draw.line(bg, colour, self.to_px(x0, y0), self.to_px(x1, y1), max(1, 2 * self._px_len(r)))
            for x, y in ((x0, y0), (x1, y1)):
                pg.draw.circle(bg, colour, self.to_px(x, y), self._px_len(r))
        for (x, y, r), kind in zip(geometry.circles, geometry.circle_kinds, strict=True):
            pg.draw.circle(bg, COLOURS[Kind(int(kind))], self.to_px(x, y), self._px_len(r))
        self._static = bg

    def begin(self) -> None:
        """Start a frame from the cached static scene."""
        if self._static is None:
            self.surface.fill(COLOURS["background"])
        else:
            self.surface.blit(self._static, (0, 0))
        self._overlay.fill((0, 0, 0, 0))

    def circles(self, circles: np.ndarray, kind: Kind) -> None:
        """Draw moving circles (people, round robots)."""
        for x, y, r in circles:
            self._pg.draw.circle(self.surface, COLOURS[kind], self.to_px(x, y), self._px_len(r))
            self._pg.draw.circle(self.surface, (0, 0, 0), self.to_px(x, y), self._px_len(r), 1)

    def robot(self, pose: np.ndarray, length: float, width: float) -> None:
        """Draw a rectangular robot with a heading mark."""
        x, y, th = (float(v) for v in pose[:3])
        c, s = math.cos(th), math.sin(th)
        corners = [
            (x + c * dx - s * dy, y + s * dx + c * dy)
            for dx, dy in (
                (length / 2, width / 2),
                (-length / 2, width / 2),
                (-length / 2, -width / 2),
                (length / 2, -width / 2),
            )
        ]
        pts = [self.to_px(*p) for p in corners]
        self._pg.draw.polygon(self.surface, COLOURS[Kind.ROBOT], pts)
        self._pg.draw.polygon(self.surface, (0, 0, 0), pts, 2)
        nose = (x + c * length / 2, y + s * length / 2)
        self._pg.draw.line(self.surface, (255, 255, 255), self.to_px(x, y), self.to_px(*nose), 3)

    def rays(
        self,
        origin: tuple[float, float, float],
        angles: np.ndarray,
        ranges: np.ndarray,
        max_range: float,
        every: int = 4,
    ) -> None:
        """Draw LIDAR beams with an echo (every ``every``-th beam) and a dot at each hit.

        Beams without an echo (nothing in range, or a dropout) are not drawn, as in RViz.
        """
        ox, oy, oth = origin
        start = self.to_px(ox, oy)
        for a, r in zip(angles[::every], ranges[::every], strict=True):
            if r >= max_range - 1e-6:
                continue
            end = self.to_px(ox + r * math.cos(oth + a), oy + r * math.sin(oth + a))
            self._pg.draw.line(self._overlay, (*COLOURS["lidar"], 60), start, end, 1)
            self._pg.draw.circle(self.surface, COLOURS["lidar"], end, 2)

    def cones(self, poses: np.ndarray, ranges: np.ndarray, aperture: float) -> None:
        """Draw sonar cones as translucent wedges out to each measured range."""
        for (x, y, th), r in zip(poses, ranges, strict=True):
            pts = [self.to_px(x, y)]
            for a in np.linspace(th - aperture / 2, th + aperture / 2, 7):
                pts.append(self.to_px(x + r * math.cos(a), y + r * math.sin(a)))
            self._pg.draw.polygon(self._overlay, (*COLOURS["sonar"], 110), pts)

    def path(self, points: np.ndarray) -> None:
        """Draw the driven path."""
        if len(points) >= 2:
            self._pg.draw.lines(self.surface, COLOURS["path"], False, [self.to_px(*p[:2]) for p in points], 2)

    def waypoints(self, points: np.ndarray, current: int) -> None:
        """Draw numbered waypoints with the current target ringed (``current < 0``: none)."""
        colour = COLOURS["waypoint"]
        for i, (x, y) in enumerate(points):
            p = self.to_px(x, y)
            self._pg.draw.circle(self.surface, colour, p, 6)
            if i == current:
                self._pg.draw.circle(self.surface, colour, p, 11, 2)
            label = self._font.render(str(i), True, COLOURS["text"])
            self.surface.blit(label, (p[0] + 8, p[1] - 18))

    def polyline(self, points: np.ndarray, colour: tuple[int, int, int], width: int = 2) -> None:
        """Draw an open polyline ``(k, 2)`` (m) in an RGB colour (planned paths, the elastic strip)."""
        if len(points) >= 2:
            self._pg.draw.lines(self.surface, colour, False, [self.to_px(*p[:2]) for p in points], width)

    def ring(self, x: float, y: float, radius: float, colour: tuple[int, int, int], width: int = 2) -> None:
        """Draw a circle outline of ``radius`` (m) at ``(x, y)`` (goals, ghost points)."""
        self._pg.draw.circle(self.surface, colour, self.to_px(x, y), self._px_len(radius), width)

    def round_robots(self, poses: np.ndarray, radius: float) -> None:
        """Draw round robots ``(n, 3)`` with a heading mark; the first (a leader) in a darker shade."""
        for k, (x, y, th) in enumerate(np.asarray(poses, dtype=np.float64).reshape(-1, 3)):
            colour = (20, 50, 130) if k == 0 else COLOURS[Kind.ROBOT]
            centre = self.to_px(x, y)
            self._pg.draw.circle(self.surface, colour, centre, self._px_len(radius))
            self._pg.draw.circle(self.surface, (0, 0, 0), centre, self._px_len(radius), 1)
            nose = self.to_px(x + radius * math.cos(th), y + radius * math.sin(th))
            self._pg.draw.line(self.surface, (255, 255, 255), centre, nose, 2)

    def text(self, lines: Sequence[str]) -> None:
        """Write status lines in the top-left corner."""
        for i, line in enumerate(lines):
            label = self._font.render(line, True, COLOURS["text"], COLOURS["background"])
            self.surface.blit(label, (6, 4 + i * (label.get_height() + 2)))

    def finish(self) -> np.ndarray:
        """Compose the frame and return it as an ``(H, W, 3)`` uint8 array."""
        self.surface.blit(self._overlay, (0, 0))
        return np.transpose(np.array(self._pg.surfarray.pixels3d(self.surface)), (1, 0, 2)).copy()

    def present(self, render_mode: str | None, fps: float) -> np.ndarray | None:
        """Compose the frame: return it (``"rgb_array"``), or show it in the window and return None (``"human"``)."""
        frame = self.finish()
        if render_mode == "human":
            self.show(fps)
            return None
        return frame

    def show(self, fps: float) -> None:
        """Show the current frame in a window ("human" render mode)."""
        pg = self._pg
        if self._window is None:
            pg.display.init()
            self._window = pg.display.set_mode(self.size)
            self._clock = pg.time.Clock()
        pg.event.pump()
        self._window.blit(self.surface, (0, 0))
        pg.display.flip()
        self._clock.tick(fps)

    def close(self) -> None:
        """Close the window if one was opened."""
        if self._window is not None:
            self._pg.display.quit()
            self._window = None
