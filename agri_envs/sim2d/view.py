"""The rendering side of a 2D env, written once: render-mode check, one cached renderer, ``close()``.

Each env owns one :class:`SceneView` (composition, as Gymnasium's ``MujocoEnv`` owns its renderer). The
view draws every scene of the env into one canvas whose size is fixed when the env is made, from the
largest scene the env's arguments can generate, so frames keep their shape across episodes (vector-env
tiling and video writers need that); a smaller scene is letterboxed, centred in the canvas.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from agri_envs.sim2d.geometry import Geometry
from agri_envs.sim2d.render import TopDownRenderer  # pygame loads only when a renderer is made

RENDER_MODES = ("rgb_array", "human")


class SceneView:
    """Render mode, renderer and window of one env.

    Args:
        render_mode: ``None`` (no rendering, nothing imported), ``"rgb_array"`` or ``"human"``.
        canvas: ``(xmin, ymin, xmax, ymax)`` (m) of the largest scene the env can generate: sets the frame's
            aspect ratio.
        width_px: Frame width (px); the height follows ``canvas``'s aspect ratio.
        fps: Frame rate of the ``"human"`` window.

    Raises:
        ValueError: For a render mode other than those above.
    """

    def __init__(self, render_mode: str | None, canvas: Sequence[float], width_px: int, fps: float) -> None:
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode must be one of {list(RENDER_MODES)} or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.canvas = tuple(float(b) for b in canvas)
        self.width_px = int(width_px)
        self.fps = fps
        self._renderer: TopDownRenderer | None = None
        self._scene: Geometry | None = None

    def render(self, geometry: Geometry | None, draw: Callable[[TopDownRenderer], Sequence[str]]) -> np.ndarray | None:
        """One frame: the scene ``geometry``, then ``draw(renderer)``'s moving parts and its status lines.

        Args:
            geometry: The episode's static scene; None before ``reset()``.
            draw: Draws robots, sensors, paths on the renderer and returns the status lines to print.

        Returns:
            The ``(H, W, 3)`` frame (``rgb_array``); None after showing it (``human``) or, with a warning,
            when the env was made without a render mode.

        Raises:
            RuntimeError: When there is no scene yet (``reset()`` was not called).
        """
        if self.render_mode is None:
            warnings.warn(
                "render() called with render_mode=None; pass render_mode='rgb_array' to gym.make",
                UserWarning,
                stacklevel=3,
            )
            return None
        if geometry is None:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            self._renderer = TopDownRenderer(self.canvas, self.width_px)
        rd = self._renderer
        if self._scene is not geometry:  # a new episode's scene: letterbox it and draw its static part once
            rd.fit(geometry.bounds)
            rd.draw_geometry(geometry)
            self._scene = geometry
        rd.begin()
        rd.text(draw(rd))
        return rd.present(self.render_mode, self.fps)

    def close(self, *others: Any) -> None:
        """Close the window, drop the renderer, and close each of ``others`` that is not None (idempotent).

        Args:
            others: What else the env releases with its view (its pymunk world, ...): objects with ``close()``.
        """
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
            self._scene = None
        for other in others:
            if other is not None:
                other.close()

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the renderer (pygame surfaces do not pickle); a copy makes its own."""
        state = self.__dict__.copy()
        state["_renderer"] = None
        state["_scene"] = None
        return state
