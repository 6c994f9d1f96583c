"""Watch or record any policy on any env: ``agri watch`` (a window) and ``agri record`` (a GIF or MP4 clip).

The episode is the evaluator's (:func:`agri_training.evaluation.episode.run_episode`, same env arguments
as ``agri evaluate`` resolves them, same seed), rendered after the reset and after every step: headless
with ``render_mode="rgb_array"`` for a clip, in a window with ``render_mode="human"``. GIFs are written
with Pillow; MP4s need the ``video`` extra (``pip install -e ".[video]"``: imageio with its ffmpeg).

The same in Python::

    import agri_envs
    import numpy as np
    from agri_training.evaluation.policies import EvalRequest, load_policy, resolve_env_kwargs

    # the env arguments the policy needs (harik-apf-gt: full scan, true pose), as agri evaluate resolves them
    kwargs, _ = resolve_env_kwargs(EvalRequest("agri_envs/GreenhouseNav-v2", "harik-apf-gt"))
    env = agri_envs.make("agri_envs/GreenhouseNav-v2", **kwargs, render_mode="rgb_array")
    policy = load_policy("harik-apf-gt", env)  # a name, a run folder, a .onnx or SB3 .zip file
    obs, info = env.reset(seed=0)
    frames, state, start, done = [env.render()], None, True, False
    while not done:
        action, state = policy.predict(obs, state=state, episode_start=np.array([start]), deterministic=True)
        obs, reward, terminated, truncated, info = env.step(action)
        frames.append(env.render())
        start, done = False, terminated or truncated
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

import agri_envs
from agri_training.core.progress import Heartbeat, format_duration
from agri_training.evaluation.episode import run_episode
from agri_training.evaluation.policies import EvalRequest, resolve_env_kwargs
from agri_training.evaluation.reference import build_policy

#: Clip formats and what writes them.
FORMATS = (".gif", ".mp4")


@dataclasses.dataclass(frozen=True)
class ClipRequest:
    """What to record or watch.

    Attributes:
        env_id: Env id (Gymnasium or the PettingZoo chain).
        policy: Any policy :func:`~agri_training.evaluation.reference.resolve_policy` takes (name, path, file).
        seed: Seed of the first episode (episode i runs seed + i).
        out: ``.gif`` or ``.mp4`` file to write; None opens a window (``render_mode="human"``).
        scenario: Named preset of env arguments, or None.
        env_kwargs: Extra env arguments (as ``agri evaluate --env-kwargs``).
        episodes: Episodes, one after another in the same clip.
        max_steps: Stop each episode after this many steps (None: at its end).
        every: Keep every k-th frame (a shorter clip of a long episode).
        fps: Frames per second of the clip (None: the env's ``render_fps`` divided by ``every``, at least 1).
        scale: Shrink factor of the frames (0 < scale <= 1), for small GIFs.
    """

    env_id: str
    policy: str
    seed: int = 0
    out: Path | None = None
    scenario: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    episodes: int = 1
    max_steps: int | None = None
    every: int = 1
    fps: float | None = None
    scale: float = 1.0

    def __post_init__(self) -> None:
        if self.out is not None and Path(self.out).suffix.lower() not in FORMATS:
            raise ValueError(f"--out must end in {' or '.join(FORMATS)}, got {str(self.out)!r}")
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.max_steps is not None and self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if self.every < 1:
            raise ValueError(f"every must be >= 1, got {self.every}")
        if not 0.0 < self.scale <= 1.0:
            raise ValueError(f"scale must be in (0, 1], got {self.scale}")
        if self.fps is not None and self.fps <= 0:
            raise ValueError(f"fps must be > 0, got {self.fps}")


def record(request: ClipRequest, progress_s: float | None = None) -> dict[str, Any]:
    """Run the episodes, rendering every step; write the clip (or show the window).

    Args:
        request: What to record.
        progress_s: When given, print a line when recording starts and then every ``progress_s`` seconds
            (episode, step, frames kept, elapsed time; then the writing of the clip), and one at the end:
            a long episode at full frame rate takes minutes and writes a large file.

    Returns:
        ``{"records": [...], "frames": n, "size": (width, height), "fps": f, "out": path or None}``.

    Raises:
        ValueError: For a bad request (unknown policy or env argument, wrong file type); an ImportError
            names the extra for an MP4 without imageio's ffmpeg.
    """
    evaluation = EvalRequest(
        request.env_id, request.policy, seed=request.seed, scenario=request.scenario,
        env_kwargs=dict(request.env_kwargs), env_kwargs_from="--env-kwargs",
    )  # fmt: skip
    kwargs, _ = resolve_env_kwargs(evaluation)
    headless = request.out is not None
    if request.out is not None and Path(request.out).suffix.lower() == ".mp4":  # fail before the episode, not after it
        _mp4_writer_module()
    env = agri_envs.make(request.env_id, **{**kwargs, "render_mode": "rgb_array" if headless else "human"})
    frames: list[np.ndarray] = []
    records = []
    now = {"episode": 1, "step": 0, "writing": False, "done": False}

    def status(elapsed: float) -> str:
        if now["done"]:
            return f"recording: done, {len(frames)} frames in {format_duration(elapsed)}"
        if now["writing"]:
            return f"recording: writing {request.out} ({len(frames)} frames), {format_duration(elapsed)} elapsed"
        return (
            f"recording: episode {now['episode']}/{request.episodes}, step {now['step']}, {len(frames)} frames "
            f"kept, {format_duration(elapsed)} elapsed"
        )

    heartbeat = None
    if progress_s is not None:
        where = f" into {request.out}" if request.out is not None else ""
        print(f"recording {evaluation.ref.name} on {request.env_id}, seed {request.seed}{where}", flush=True)
        heartbeat = Heartbeat(status, progress_s)

    def on_step(step: int) -> bool:
        now["step"] = step
        if step % request.every == 0:
            frame = env.render()
            if headless and frame is not None:
                frames.append(shrink_frame(np.asarray(frame, dtype=np.uint8), request.scale))
        return request.max_steps is not None and step >= request.max_steps

    out = None
    try:
        try:
            for i in range(request.episodes):
                now["episode"] = i + 1
                policy = build_policy(evaluation.ref, env)  # a fresh policy per episode, as the evaluator does
                records.append(run_episode(env, policy, request.seed + i, None, on_step)["record"])
            fps = request.fps or max(1.0, float(_render_fps(env)) / request.every)
        finally:
            env.close()
        if request.out is not None:
            if not frames:
                raise ValueError(f"{request.env_id} rendered no frames")
            out = Path(request.out)
            out.parent.mkdir(parents=True, exist_ok=True)
            now["writing"] = True
            write_clip(frames, out, fps)
        now["done"] = True
    finally:
        if heartbeat is not None:
            heartbeat.stop()
    size = (int(frames[0].shape[1]), int(frames[0].shape[0])) if frames else None
    return {"records": records, "frames": len(frames), "size": size, "fps": fps, "out": out}


def _render_fps(env: Any) -> float:
    metadata = getattr(getattr(env, "unwrapped", env), "metadata", {}) or {}
    return float(metadata.get("render_fps") or 15)


def shrink_frame(frame: np.ndarray, scale: float) -> np.ndarray:
    """An RGB frame shrunk by ``scale`` (bilinear) to even width and height, as H.264 needs."""
    if scale >= 1.0:
        return frame
    from PIL import Image

    h, w = frame.shape[:2]
    size = (max(2, round(w * scale) // 2 * 2), max(2, round(h * scale) // 2 * 2))  # even: what H.264 needs
    return np.asarray(Image.fromarray(frame).resize(size, Image.Resampling.BILINEAR))


def _mp4_writer_module() -> Any:
    try:
        import imageio.v2 as iio
        import imageio_ffmpeg  # noqa: F401
    except ImportError as exc:
        raise ImportError(
            'writing MP4 needs imageio with its ffmpeg: pip install -e ".[video]" (or write a .gif)'
        ) from exc
    return iio


def write_clip(frames: list[np.ndarray], out: Path, fps: float) -> None:
    """Write RGB frames (one size) as a looping GIF (Pillow) or an H.264 MP4 (imageio-ffmpeg)."""
    if out.suffix.lower() == ".gif":
        from PIL import Image

        images = [Image.fromarray(f) for f in frames]
        images[0].save(
            out, save_all=True, append_images=images[1:], duration=max(20, round(1000 / fps)), loop=0, optimize=True
        )
        return
    iio = _mp4_writer_module()
    h, w = frames[0].shape[:2]
    pad = ((0, h % 2), (0, w % 2), (0, 0))  # H.264 wants even sizes
    with iio.get_writer(out, fps=fps, codec="libx264", pixelformat="yuv420p", macro_block_size=1) as writer:
        for f in frames:
            writer.append_data(np.pad(f[..., :3], pad, mode="edge"))
