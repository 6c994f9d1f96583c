"""Envs of both kinds by id: Gymnasium ids (``agri_envs/...``) and PettingZoo parallel envs (the robot chain).

The chain is a PettingZoo env, not a Gymnasium id; every layer above asks this module, not the registries.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

import gymnasium as gym

import agri_envs  # noqa: F401  (registers the Gymnasium ids)

#: Multi-agent env ids and the module that provides ``parallel_env``.
MULTIAGENT_ENVS = {"robot_chain_v0": "agri_envs.chain.robot_chain_v0"}


def is_multiagent(env_id: str) -> bool:
    """Whether ``env_id`` names a PettingZoo env of this package."""
    return env_id in MULTIAGENT_ENVS


def make_env(env_id: str, kwargs: Mapping[str, Any]) -> Any:
    """The env of ``env_id``: ``gym.make`` for a Gymnasium id, the native parallel env for a multi-agent one.

    Raises:
        ValueError: For a bad env argument (the env's own message).
    """
    if env_id in MULTIAGENT_ENVS:
        return importlib.import_module(MULTIAGENT_ENVS[env_id]).parallel_env(**dict(kwargs))
    return gym.make(env_id, **dict(kwargs))


def is_parallel_env(env: Any) -> bool:
    """Whether ``env`` is a PettingZoo parallel env (per-agent dicts) rather than a Gymnasium one."""
    return hasattr(env, "possible_agents") and hasattr(env, "state")
