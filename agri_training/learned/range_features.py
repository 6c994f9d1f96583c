"""Range keys read as features that do not change with the size of the place: differences and ramps.

A policy cloned in corridors of 1.4-1.6 m learns what a centred robot's side sonars read there, and a wider
corridor then reads like a row's end. Two stateless transforms take the width out of what it sees:

* :class:`Differences`: ``x[i] - x[j]`` for pairs of elements (or of groups, read as their nearest) of a range
  key (left minus right sonar: twice the offset from a corridor's centre line, whatever its width);
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


#: A pair of a :class:`Differences` key: two members, each an index or a list of indices (their nearest reading).
Pair = Sequence[int | Sequence[int]]


def differences_space(space: gym.spaces.Dict, pairs: Mapping[str, Sequence[Pair]]) -> gym.spaces.Dict:
    """``space`` with a ``<key>_difference`` Box beside each key of ``pairs`` (see :class:`Differences`).

    Raises:
        ValueError: For a space that is not a Dict, a key that is not a 1-D Box, no pairs, or a pair that is
            not two members of indices of the key, different from each other.
    """
    if not pairs:
        raise ValueError("Differences needs at least one key: {key: [[i, j], ...]}")
    added = {}
    for key, key_pairs in pairs.items():
        box = _range_box(space, key, "Differences")
        members = _members(key, key_pairs, box.shape[0])
        low = box.low.astype(np.float32)
        high = box.high.astype(np.float32)
        # The nearest of a group lies between the least low and the least high of its elements.
        added[f"{key}_difference"] = gym.spaces.Box(
            np.array([low[a].min() - high[b].min() for a, b in members], dtype=np.float32),
            np.array([high[a].min() - low[b].min() for a, b in members], dtype=np.float32),
            dtype=np.float32,
        )
    return gym.spaces.Dict({**space.spaces, **added})


def _members(key: str, pairs: Sequence[Pair], size: int) -> list[tuple[list[int], list[int]]]:
    """The pairs of ``key`` as ``(indices of a, indices of b)``, checked against the key's ``size``."""
    if not isinstance(pairs, Sequence) or isinstance(pairs, str) or not pairs:
        raise ValueError(f"Differences: {key!r} needs a list of pairs [[i, j], ...], got {pairs!r}")
    members = []
    for pair in pairs:
        if not isinstance(pair, Sequence) or isinstance(pair, str) or len(pair) != 2:
            raise ValueError(f"Differences: {key!r} needs a list of pairs [[i, j], ...], got {pairs!r}")
        a, b = ([m] if isinstance(m, int) else list(m) for m in pair)
        if not a or not b or not all(isinstance(i, int) and 0 <= i < size for i in a + b) or set(a) == set(b):
            raise ValueError(
                f"Differences: each pair of {key!r} must be two different members, each an index in [0, {size})"
                f" or a list of them, got {pair!r}"
            )
        members.append((a, b))
    return members


def add_differences(observation: Mapping[str, Any], pairs: Mapping[str, Sequence[Pair]]) -> dict[str, Any]:
    """``observation`` with ``<key>_difference[k] = min(x[..., a_k]) - min(x[..., b_k])`` for each pair ``(a, b)``.

    A member that is one index is that element itself.
    """
    out = dict(observation)
    for key, key_pairs in pairs.items():
        x = np.asarray(observation[key], dtype=np.float32)
        nearest = [
            x[..., [a] if isinstance(a, int) else list(a)].min(axis=-1)
            - x[..., [b] if isinstance(b, int) else list(b)].min(axis=-1)
            for a, b in key_pairs
        ]
        out[f"{key}_difference"] = np.stack(nearest, axis=-1).astype(np.float32, copy=False)
    return out


class Differences(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """Differences between elements of a range key, beside it: ``<key>_difference[k] = x[i_k] - x[j_k]``.

    For the Fitorobot's sonars (front; left front, middle, rear; right front, middle, rear),
    ``{Differences: {sonar: [[1, 4], [2, 5], [3, 6]]}}`` gives left minus right at the front, middle and rear
    of the robot: 0 on a corridor's centre line and twice the offset beside it, in any corridor width. A
    member may also be a list of indices, read as their nearest (least) range: ``[[1, 2, 3], [4, 5, 6]]``
    is the nearest echo on the left minus the nearest on the right, which one echo that slips long through
    the foliage does not swing. Stateless. Put it before ``FilterObservation`` and ``FlattenObservation``.

    Raises:
        ValueError: See :func:`differences_space`.
    """

    def __init__(self, env: gym.Env[Any, Any], **pairs: Sequence[Pair]) -> None:
        space = differences_space(env.observation_space, pairs)  # type: ignore[arg-type]
        super().__init__(env)
        self.pairs = dict(pairs)
        self.observation_space = space

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with its difference keys."""
        return add_differences(observation, self.pairs)


#: What a :class:`Ramp` key is given: one ramp ``{low: ..., high: ...}`` or a list of them.
RampSpec = Mapping[str, float | Sequence[float]] | Sequence[Mapping[str, float | Sequence[float]]]


def ramp_bounds(space: gym.spaces.Dict, bounds: Mapping[str, RampSpec]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``{key: (low, high)}`` as float32 arrays, the key's shape once per ramp, end to end (see :class:`Ramp`).

    Raises:
        ValueError: For a space that is not a Dict, a key that is not a 1-D Box, a ramp other than ``{low,
            high}``, bounds that are neither one number nor one per element, or a ``high`` not above its
            ``low``.
    """
    if not bounds:
        raise ValueError("Ramp needs at least one key: {key: {low: ..., high: ...}}")
    out = {}
    for key, given in bounds.items():
        box = _range_box(space, key, "Ramp")
        ramps = [given] if isinstance(given, Mapping) else list(given) if isinstance(given, Sequence) else [given]
        lows, highs = [], []
        for ramp in ramps:
            if not isinstance(ramp, Mapping) or set(ramp) != {"low", "high"}:
                raise ValueError(f"Ramp: {key!r} needs {{low: ..., high: ...}} or a list of them, got {given!r}")
            try:
                lows.append(np.broadcast_to(np.asarray(ramp["low"], dtype=np.float32), box.shape))
                highs.append(np.broadcast_to(np.asarray(ramp["high"], dtype=np.float32), box.shape))
            except ValueError as exc:
                raise ValueError(f"Ramp: the bounds of {key!r} must be one number or {box.shape[0]}") from exc
        if not ramps:
            raise ValueError(f"Ramp: {key!r} needs {{low: ..., high: ...}} or a list of them, got {given!r}")
        low, high = np.concatenate(lows), np.concatenate(highs)
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
    """``observation`` with ``<key>_ramp = clip((x - low) / (high - low), 0, 1)`` beside each key of ``bounds``.

    With several ramps of a key, ``<key>_ramp`` holds the first ramp's elements, then the second's, and so on.
    """
    out = dict(observation)
    for key, (low, high) in bounds.items():
        x = np.asarray(observation[key], dtype=np.float32)
        x = np.concatenate([x] * (low.shape[0] // x.shape[-1]), axis=-1)  # once per ramp
        out[f"{key}_ramp"] = np.clip((x - low) / (high - low), np.float32(0.0), np.float32(1.0))
    return out


class Ramp(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """A range key read again through a clipped ramp per element: 0 up to ``low``, 1 from ``high`` on.

    For the Fitorobot's sonars (ranges / 4 m), a far ramp with ``low: 0.15, high: 0.75`` per side sonar
    reads 0 for any row within 0.6 m (every corridor width looks the same) and rises through a row's end
    (about 2 m) to a corridor's mouth (beyond 2.5 m), which it must keep apart: a ramp that saturated at 2 m
    made the two equal, and the cloned robot parked at a mouth. ``low`` and ``high`` are one number or one per
    element, in the key's units. A list of ramps reads the key through each in turn, end to end in
    ``<key>_ramp`` (GreenhouseCoverage's recipe adds a near ramp, 0.1-0.45 m, for the walls of a headland
    turn). Stateless. Put it before ``FilterObservation`` and ``FlattenObservation``; in a config:
    ``{Ramp: {sonar: {low: 0.15, high: 0.75}}}``.

    Raises:
        ValueError: See :func:`ramp_bounds`.
    """

    def __init__(self, env: gym.Env[Any, Any], **bounds: RampSpec) -> None:
        self.bounds = ramp_bounds(env.observation_space, bounds)  # type: ignore[arg-type]
        super().__init__(env)
        self.observation_space = ramp_space(env.observation_space, self.bounds)  # type: ignore[arg-type]

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with its ramp keys."""
        return add_ramps(observation, self.bounds)
