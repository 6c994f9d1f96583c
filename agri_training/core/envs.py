"""Envs of both kinds by id, through :func:`agri_envs.make`: Gymnasium ids and PettingZoo parallel envs.

Every layer above asks this module, never a registry of its own.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import agri_envs


def is_multiagent(env_id: str) -> bool:
    """Whether ``env_id`` names a PettingZoo env of this package."""
    return agri_envs.is_parallel_id(env_id)


def make_env(env_id: str, kwargs: Mapping[str, Any]) -> Any:
    """The env of ``env_id`` (:func:`agri_envs.make`): a Gymnasium env, or the native parallel env.

    Raises:
        ValueError: For an unknown id or a bad env argument (the env's own message).
    """
    return agri_envs.make(env_id, **dict(kwargs))


def is_parallel_env(env: Any) -> bool:
    """Whether ``env`` is a PettingZoo parallel env (per-agent dicts) rather than a Gymnasium one."""
    return hasattr(env, "possible_agents") and hasattr(env, "state")
