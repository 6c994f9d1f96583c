"""One episode of any policy on any env of the package, Gymnasium or PettingZoo, as one record.

:func:`run_episode` is the episode loop and the reference: evaluation, the leaderboard, the report and
training's periodic evaluation call it. The two env kinds differ only in what an adapter hides: a Gymnasium
env steps one agent; a PettingZoo parallel env (the robot chain) steps per-agent dicts, its policy takes and
returns such dicts, and the team's metrics come from the first agent's ``info`` (every agent carries them).
What an episode keeps and records is :class:`EpisodeBook`'s, which the batched loop of
:mod:`agri_training.evaluation.batched` (several episodes stepped together in an env's batched form) shares.

The record holds the seed, the return, the steps, whether the episode was truncated, ``is_success``, the
wall time, and the env's ``metadata["episode_metric_keys"]`` from the final ``info``; a policy may add its
own through ``episode_metrics(index)``, and a policy that localizes itself (``pose_estimate``) gets its
trajectory error against the true pose. With ``trace_keys`` the output also holds those ``info`` keys at
every step, for plots.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

import agri_envs
from agri_training.core.documents import EpisodeOutput, jsonable


class _SingleAgent:
    """A Gymnasium env as the loop sees it."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.info: dict[str, Any] = {}
        self.done = False
        self.truncated = False

    def reset(self, seed: int) -> Any:
        obs, self.info = self.env.reset(seed=seed)
        return obs

    def step(self, action: Any) -> tuple[Any, float]:
        obs, reward, terminated, truncated, self.info = self.env.step(action)
        self.done = bool(terminated or truncated)
        self.truncated = bool(truncated)
        return obs, float(reward)

    def trace_step(self, trace: dict[str, list[Any]]) -> None:
        for k in trace:
            trace[k].append(self.info.get(k))

    def finish(self, record: dict[str, Any], trace: dict[str, Any]) -> None:
        """Nothing beyond the shared keys."""


class _Team:
    """A PettingZoo parallel env as the loop sees it: the first agent's ``info`` speaks for the team."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.first = env.possible_agents[0]
        self.infos: Mapping[str, Mapping[str, Any]] = {}
        self.truncated = False

    @property
    def info(self) -> Mapping[str, Any]:
        return self.infos[self.first]

    @property
    def done(self) -> bool:
        return not self.env.agents

    def reset(self, seed: int) -> Any:
        obs, self.infos = self.env.reset(seed=seed)
        return obs

    def step(self, actions: Any) -> tuple[Any, float]:
        obs, rewards, terms, truncs, self.infos = self.env.step(actions)
        self.truncated = bool(truncs[self.first]) and not bool(terms[self.first])
        return obs, float(rewards[self.first])

    def trace_step(self, trace: dict[str, list[Any]]) -> None:
        for k in trace:
            if k == "positions":  # every robot's position
                trace[k].append([[round(i["x"], 4), round(i["y"], 4)] for i in self.infos.values()])
            else:
                trace[k].append(self.info.get(k))

    def finish(self, record: dict[str, Any], trace: dict[str, Any]) -> None:
        record["collision"] = bool(self.info.get("collisions", 0))
        if trace:
            raw = self.env.unwrapped
            if hasattr(raw, "path"):
                trace["astar_path"] = np.round(raw.path.points, 4).tolist()
            if getattr(raw, "world", None) is not None:  # obstacles dropped during the episode
                movers = raw.world.mover_circles
                trace["obstacles"] = movers[np.abs(movers[:, 0]) < 1e5].tolist()


class EpisodeBook:
    """What the episode loop keeps of one episode, fed step by step; its output (record and trace) at the end.

    :func:`run_episode` drives one env with it; the batched loop (:mod:`.batched`) drives one per sub-env of a
    vector env, so both produce their records and traces in one place. A driver is what the loop sees of the
    env: its latest ``info`` (a mapping), ``done``, ``truncated``, ``trace_step(trace)`` and ``finish(record,
    trace)`` (:class:`_SingleAgent`, :class:`_Team`).

    Args:
        policy: SB3's ``predict`` (per-agent dicts in and out on a parallel env).
        seed: The episode's reset seed.
        trace_keys: ``info`` keys to record at every step, or None.
        metric_keys: The env's ``metadata["episode_metric_keys"]``.
        single: A single-agent env (policies that localize themselves are scored only there).
    """

    def __init__(
        self, policy: Any, seed: int, trace_keys: tuple[str, ...] | None, metric_keys: tuple[str, ...], single: bool
    ) -> None:
        self.policy = policy
        self.seed = seed
        self.metric_keys = metric_keys
        self.single = single
        self.trace: dict[str, list[Any]] = {k: [] for k in trace_keys} if trace_keys else {}
        self.localizes = False
        self.truth: list[tuple[float, float, float]] = []
        self.estimate: list[np.ndarray] = []
        self.state: Any = None
        self.first = True
        self.total = 0.0
        self.steps = 0

    def started(self, driver: Any) -> None:
        """After the reset: the first trace row; whether the policy's own pose estimate is scored."""
        driver.trace_step(self.trace)
        self.localizes = self.single and hasattr(self.policy, "pose_estimate") and "x" in driver.info

    def act(self, observation: Any, info: Mapping[str, Any]) -> Any:
        """The policy's action for ``observation`` (``info``: the env's latest, paired with the pose estimate)."""
        action, self.state = self.policy.predict(
            observation, state=self.state, episode_start=np.array([self.first]), deterministic=True
        )
        self.first = False
        if self.localizes:  # the estimate for this observation, paired with the true pose it was taken at
            self.truth.append((info["x"], info["y"], info["yaw"]))
            self.estimate.append(np.asarray(self.policy.pose_estimate(0), dtype=np.float64))
        return action

    def stepped(self, reward: float, driver: Any) -> None:
        """After a step: its reward, and a trace row."""
        self.total += reward
        self.steps += 1
        driver.trace_step(self.trace)

    def output(self, driver: Any, wall_time_s: float) -> EpisodeOutput:
        """The episode's record (and trace), from the driver's final ``info``."""
        record: dict[str, Any] = {
            "seed": self.seed,
            "return": self.total,
            "steps": self.steps,
            "truncated": driver.truncated,
            "is_success": bool(driver.info.get("is_success", False)),
            "wall_time_s": wall_time_s,
        }
        for key in self.metric_keys:
            record[key] = driver.info.get(key)
        if self.single and hasattr(self.policy, "episode_metrics"):
            record.update(self.policy.episode_metrics(0))
        trace = self.trace
        driver.finish(record, trace)
        if self.localizes and self.truth:
            world_est = start_frame_to_world(np.array(self.truth[0]), np.array(self.estimate))
            record.update(localization_errors(np.array(self.truth), world_est))
            if trace:
                trace.update(
                    slam_x=world_est[:, 0].tolist(), slam_y=world_est[:, 1].tolist(), slam_yaw=world_est[:, 2].tolist()
                )
        return {"record": jsonable(record), "trace": jsonable(trace) if trace else None}


def run_episode(
    env: Any,
    policy: Any,
    seed: int,
    trace_keys: tuple[str, ...] | None,
    on_step: Callable[[int], bool] | None = None,
) -> EpisodeOutput:
    """One episode from ``reset(seed=seed)``: its record and, with ``trace_keys``, its per-step trace.

    Args:
        env: A Gymnasium env or a PettingZoo parallel env.
        policy: SB3's ``predict(observation, state, episode_start, deterministic)``; per-agent dicts in and
            out on a parallel env.
        seed: Reset seed.
        trace_keys: ``info`` keys to record at every step (a parallel env also knows ``positions``).
        on_step: Called with the step count after the reset (0) and after every step (a recorder renders a
            frame there); returning True ends the episode early.
    """
    driver: _SingleAgent | _Team = _Team(env) if agri_envs.is_parallel_env(env) else _SingleAgent(env)
    metric_keys = tuple(env.unwrapped.metadata.get("episode_metric_keys", ()))
    book = EpisodeBook(policy, seed, trace_keys, metric_keys, isinstance(driver, _SingleAgent))
    obs = driver.reset(seed)
    book.started(driver)
    t0 = time.perf_counter()
    stop = on_step(0) if on_step is not None else False
    while not (book.steps and driver.done) and not stop:
        obs, reward = driver.step(book.act(obs, driver.info))
        book.stepped(reward, driver)
        if on_step is not None:
            stop = bool(on_step(book.steps))
    return book.output(driver, time.perf_counter() - t0)


def start_frame_to_world(start: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses ``(n, 3)`` given in the frame of the robot's start pose, expressed in the world frame."""
    c, s = np.cos(start[2]), np.sin(start[2])
    out = np.empty_like(poses)
    out[:, 0] = start[0] + c * poses[:, 0] - s * poses[:, 1]
    out[:, 1] = start[1] + s * poses[:, 0] + c * poses[:, 1]
    out[:, 2] = np.arctan2(np.sin(poses[:, 2] + start[2]), np.cos(poses[:, 2] + start[2]))
    return out


def localization_errors(truth: np.ndarray, estimate: np.ndarray) -> dict[str, float]:
    """Absolute trajectory error and final-pose error of a pose estimate against the ground truth.

    Both trajectories share the start pose (the estimate's map frame is anchored there, as on the robot),
    so no alignment is fitted: the ATE is what the controller actually drove on.

    Returns:
        ``ate_rmse`` (m), ``ate_max`` (m), ``final_position_error`` (m), ``final_heading_error`` (rad).
    """
    err = np.hypot(estimate[:, 0] - truth[:, 0], estimate[:, 1] - truth[:, 1])
    dyaw = np.arctan2(np.sin(estimate[-1, 2] - truth[-1, 2]), np.cos(estimate[-1, 2] - truth[-1, 2]))
    return {
        "ate_rmse": float(np.sqrt(np.mean(err**2))),
        "ate_max": float(err.max()),
        "final_position_error": float(err[-1]),
        "final_heading_error": float(abs(dyaw)),
    }
