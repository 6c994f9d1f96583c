"""The rendering side of a 2D env, written once: render-mode check, one cached renderer, ``close()``.

Each env owns one :class:`SceneView` (composition, as Gymnasium's ``MujocoEnv`` owns its renderer). The
view draws every scene of the env into one canvas whose size is fixed when the env is made, from the
largest scene the env's arguments can generate, so frames keep their shape across episodes (vector-env
tiling and video writers need that); a smaller scene is letterboxed, centred in the canvas.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from agri_envs.sim2d.geometry import Geometry

if TYPE_CHECKING:  # pygame loads only when a renderer is made
    from agri_envs.sim2d.render import TopDownRenderer

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

    def begin(self, geometry: Geometry | None) -> TopDownRenderer | None:
        """Start a frame of ``geometry``'s scene; None (after a warning) when the env renders nothing.

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
            from agri_envs.sim2d.render import TopDownRenderer

            self._renderer = TopDownRenderer(self.canvas, self.width_px)
        if self._scene is not geometry:  # a new episode's scene: letterbox it and draw its static part once
            self._renderer.fit(geometry.bounds)
            self._renderer.draw_geometry(geometry)
            self._scene = geometry
        self._renderer.begin()
        return self._renderer

    def present(self) -> np.ndarray | None:
        """Finish the frame: the ``(H, W, 3)`` array (``rgb_array``), or None after showing it (``human``)."""
        assert self._renderer is not None, "begin() first"
        return self._renderer.present(self.render_mode, self.fps)

    def close(self) -> None:
        """Close the window and drop the renderer (idempotent)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
            self._scene = None

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the renderer (pygame surfaces do not pickle); a copy makes its own."""
        state = self.__dict__.copy()
        state["_renderer"] = None
        state["_scene"] = None
        return state
