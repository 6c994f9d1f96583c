"""robot_chain_v1: a chain of small round robots led along an A* path to a goal (Apoorva, Gautam & Kala 2018).

PettingZoo module, like PettingZoo's own ``pistonball_v6``: ``parallel_env`` (the native
:class:`~agri_envs.chain.env.RobotChainEnv`), ``raw_env`` (its AEC form through ``parallel_to_aec``) and
``env`` (the AEC form with PettingZoo's order-enforcing wrapper)::

    from agri_envs.chain import robot_chain_v1

    env = robot_chain_v1.parallel_env(n_robots=4, n_dynamic_obstacles=1)
    observations, infos = env.reset(seed=0)
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils import parallel_to_aec, wrappers

from agri_envs.chain.config import RobotChainConfig
from agri_envs.chain.env import RobotChainEnv
from agri_envs.chain.observation import OBS_SIZE

__all__ = ["OBS_SIZE", "RobotChainConfig", "RobotChainEnv", "env", "parallel_env", "raw_env"]


def parallel_env(render_mode: str | None = None, **kwargs: Any) -> RobotChainEnv:
    """The native parallel env (see :class:`RobotChainEnv` for the arguments)."""
    return RobotChainEnv(render_mode=render_mode, **kwargs)


def raw_env(render_mode: str | None = None, **kwargs: Any) -> Any:
    """The AEC form, derived with PettingZoo's ``parallel_to_aec``."""
    return parallel_to_aec(parallel_env(render_mode=render_mode, **kwargs))


def env(render_mode: str | None = None, **kwargs: Any) -> Any:
    """The AEC form with PettingZoo's order-enforcing wrapper (the usual ``env()`` of a PettingZoo module)."""
    return wrappers.OrderEnforcingWrapper(raw_env(render_mode=render_mode, **kwargs))
