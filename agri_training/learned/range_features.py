"""Range keys read as features that do not change with the size of the place: differences and ramps.

A policy cloned in corridors of 1.4-1.6 m learns what a centred robot's side sonars read there, and a wider
corridor then reads like a row's end. Two stateless transforms take the width out of what it sees:

* :class:`Differences`: ``x[i] - x[j]`` for pairs of elements of a range key (left minus right sonar: twice
  the offset from a corridor's centre line, whatever its width);
* :class:`Ramp`: ``clip((x - low) / (high - low), 0, 1)`` per element (a side sonar's reading turned into
  "a row is beside me" (0) or "it is open" (1), flat across every corridor width below ``low``).

Both use float32 subtraction, division and clipping only, so every CPU and every batch size computes the
same bits, and both work on one observation or a batch alike (their batch forms are in
:mod:`agri_training.learned.vector`). Put them before ``FilterObservation``, which can then drop the raw key.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np


def _range_box(space: gym.Space[Any], key: str, who: str) -> gym.spaces.Box:
    if not isinstance(space, gym.spaces.Dict):
        raise ValueError(f"{who} needs a Dict observation (put it before FlattenObservation), got {space}")
    box = space.spaces.get(key)
    if not isinstance(box, gym.spaces.Box) or len(box.shape) != 1:
        raise ValueError(f"{who}: {key!r} must be a 1-D Box in {list(space.spaces)}")
    return box


def differences_space(space: gym.spaces.Dict, pairs: Mapping[str, Sequence[Sequence[int]]]) -> gym.spaces.Dict:
    """``space`` with a ``<key>_difference`` Box beside each key of ``pairs`` (see :class:`Differences`).

    Raises:
        ValueError: For a space that is not a Dict, a key that is not a 1-D Box, no pairs, or a pair that is
            not two distinct indices of the key.
    """
    if not pairs:
        raise ValueError("Differences needs at least one key: {key: [[i, j], ...]}")
    added = {}
    for key, key_pairs in pairs.items():
        box = _range_box(space, key, "Differences")
        index = _pairs(key, key_pairs, box.shape[0])
        low = box.low.astype(np.float32)
        high = box.high.astype(np.float32)
        added[f"{key}_difference"] = gym.spaces.Box(
            low[index[:, 0]] - high[index[:, 1]], high[index[:, 0]] - low[index[:, 1]], dtype=np.float32
        )
    return gym.spaces.Dict({**space.spaces, **added})


def _pairs(key: str, pairs: Sequence[Sequence[int]], size: int) -> np.ndarray:
    index = np.asarray(pairs)
    if index.ndim != 2 or index.shape[0] == 0 or index.shape[1] != 2 or not np.issubdtype(index.dtype, np.integer):
        raise ValueError(f"Differences: {key!r} needs a list of index pairs [[i, j], ...], got {pairs!r}")
    if np.any(index < 0) or np.any(index >= size) or np.any(index[:, 0] == index[:, 1]):
        raise ValueError(
            f"Differences: each pair of {key!r} must be two distinct indices in [0, {size}), got {pairs!r}"
        )
    return index


def add_differences(observation: Mapping[str, Any], pairs: Mapping[str, Sequence[Sequence[int]]]) -> dict[str, Any]:
    """``observation`` with ``<key>_difference = x[..., i] - x[..., j]`` for each pair ``(i, j)`` of each key."""
    out = dict(observation)
    for key, key_pairs in pairs.items():
        x = np.asarray(observation[key], dtype=np.float32)
        index = np.asarray(key_pairs)
        out[f"{key}_difference"] = x[..., index[:, 0]] - x[..., index[:, 1]]
    return out


class Differences(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """Differences between elements of a range key, beside it: ``<key>_difference[k] = x[i_k] - x[j_k]``.

    For the Fitorobot's sonars (front; left front, middle, rear; right front, middle, rear),
    ``{Differences: {sonar: [[1, 4], [2, 5], [3, 6]]}}`` gives left minus right at the front, middle and rear
    of the robot: 0 on a corridor's centre line and twice the offset beside it, in any corridor width.
    Stateless. Put it before ``FilterObservation`` and ``FlattenObservation``.

    Raises:
        ValueError: See :func:`differences_space`.
    """

    def __init__(self, env: gym.Env[Any, Any], **pairs: Sequence[Sequence[int]]) -> None:
        space = differences_space(env.observation_space, pairs)  # type: ignore[arg-type]
        super().__init__(env)
        self.pairs = {key: [[int(i), int(j)] for i, j in key_pairs] for key, key_pairs in pairs.items()}
        self.observation_space = space

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with its difference keys."""
        return add_differences(observation, self.pairs)


def ramp_bounds(
    space: gym.spaces.Dict, bounds: Mapping[str, Mapping[str, float | Sequence[float]]]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{key: (low, high)}`` as float32 arrays of the key's shape (see :class:`Ramp`).

    Raises:
        ValueError: For a space that is not a Dict, a key that is not a 1-D Box, bounds other than ``low``
            and ``high``, or a ``high`` not above its ``low``.
    """
    if not bounds:
        raise ValueError("Ramp needs at least one key: {key: {low: ..., high: ...}}")
    out = {}
    for key, given in bounds.items():
        box = _range_box(space, key, "Ramp")
        if not isinstance(given, Mapping) or set(given) != {"low", "high"}:
            raise ValueError(f"Ramp: {key!r} needs {{low: ..., high: ...}}, got {given!r}")
        try:
            low = np.broadcast_to(np.asarray(given["low"], dtype=np.float32), box.shape).copy()
            high = np.broadcast_to(np.asarray(given["high"], dtype=np.float32), box.shape).copy()
        except ValueError as exc:
            raise ValueError(f"Ramp: the bounds of {key!r} must be one number or {box.shape[0]}") from exc
        if not np.all(high > low):
            raise ValueError(f"Ramp: each high of {key!r} must be above its low, got {given!r}")
        out[key] = (low, high)
    return out


def ramp_space(space: gym.spaces.Dict, bounds: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> gym.spaces.Dict:
    """``space`` with a ``<key>_ramp`` Box in [0, 1] beside each key of ``bounds`` (from :func:`ramp_bounds`)."""
    spaces = dict(space.spaces)
    for key, (low, _) in bounds.items():
        spaces[f"{key}_ramp"] = gym.spaces.Box(0.0, 1.0, low.shape, dtype=np.float32)
    return gym.spaces.Dict(spaces)


def add_ramps(observation: Mapping[str, Any], bounds: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> dict[str, Any]:
    """``observation`` with ``<key>_ramp = clip((x - low) / (high - low), 0, 1)`` beside each key of ``bounds``."""
    out = dict(observation)
    for key, (low, high) in bounds.items():
        x = np.asarray(observation[key], dtype=np.float32)
        out[f"{key}_ramp"] = np.clip((x - low) / (high - low), np.float32(0.0), np.float32(1.0))
    return out


class Ramp(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """A range key read again through a clipped ramp per element: 0 up to ``low``, 1 from ``high`` on.

    For the Fitorobot's sonars (ranges / 4 m), ``low: [0.0, 0.25, ...], high: [0.3, 0.5, ...]`` keeps the
    front sonar's last 1.2 m and turns each side sonar into "a row within 1 m" (0) against "open beyond 2 m"
    (1): every corridor width reads the same, and a row's end still shows. ``low`` and ``high`` are one
    number or one per element, in the key's units. Stateless. Put it before ``FilterObservation`` and
    ``FlattenObservation``; in a config: ``{Ramp: {sonar: {low: 0.25, high: 0.5}}}``.

    Raises:
        ValueError: See :func:`ramp_bounds`.
    """

    def __init__(self, env: gym.Env[Any, Any], **bounds: Mapping[str, float | Sequence[float]]) -> None:
        self.bounds = ramp_bounds(env.observation_space, bounds)  # type: ignore[arg-type]
        super().__init__(env)
        self.observation_space = ramp_space(env.observation_space, self.bounds)  # type: ignore[arg-type]

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with its ramp keys."""
        return add_ramps(observation, self.bounds)
