"""The action contract every agri_envs env shares (DESIGN.md): clip to [-1, 1], refuse NaN and inf."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def checked_action(action: Any, size: int) -> np.ndarray:
    """The action as a float64 vector of ``size`` values, clipped to ``[-1, 1]``.

    Args:
        action: What was passed to ``step`` (array-like).
        size: Number of action dimensions of the env.

    Raises:
        ValueError: For something that is not ``size`` numbers (a dict, a string, a shape other than
            ``(size,)``), or NaN / inf values (which clipping would hide).
    """
    try:
        a = np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):  # a dict, a string, ragged lists: say what was expected
        raise ValueError(
            f"action must be an array of {size} numbers, shape ({size},), got {type(action).__name__} {action!r}"
        ) from None
    if a.shape != (size,):
        raise ValueError(f"action must have shape ({size},), got {a.shape}")
    if not math.isfinite(a.sum()):  # one scalar test: NaN or inf anywhere makes the sum non-finite
        raise ValueError(f"action contains NaN or inf: {action}")
    return np.minimum(np.maximum(a, -1.0), 1.0)
