"""The action contract every agri_envs env shares (DESIGN.md): clip to [-1, 1], refuse NaN and inf.

Multi-agent envs check a dict of per-agent actions with :func:`checked_agent_actions`, which names the agent.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
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


def checked_agent_actions(actions: Mapping[str, Any], agents: Sequence[str], size: int) -> np.ndarray:
    """Every live agent's action, in ``agents`` order, as a ``(len(agents), size)`` float64 array clipped to [-1, 1].

    Args:
        actions: One action per live agent, keyed by agent name.
        agents: The live agents, in the order of the rows returned.
        size: Number of action dimensions of one agent.

    Raises:
        ValueError: When ``actions`` does not name every live agent exactly once, or for an agent whose action
            is malformed (see :func:`checked_action`; the message starts with the agent's name).
    """
    if len(actions) != len(agents) or any(a not in actions for a in agents):
        unknown = sorted(a for a in actions if a not in agents)
        missing = sorted(a for a in agents if a not in actions)
        raise ValueError(f"actions must name every live agent exactly once: unknown {unknown}, missing {missing}")
    try:
        a = np.array([actions[name] for name in agents], dtype=np.float64)
    except (ValueError, TypeError):
        a = np.empty(0)
    if a.shape != (len(agents), size) or not math.isfinite(a.sum()):
        # One of them is malformed: let the single-agent check name it and say why.
        for name in agents:
            try:
                checked_action(actions[name], size)
            except ValueError as exc:
                raise ValueError(f"{name}: {exc}") from None
    np.minimum(a, 1.0, out=a)
    np.maximum(a, -1.0, out=a)
    return a
