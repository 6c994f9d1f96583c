"""Multi-robot chains (PettingZoo): ``from agri_envs.chain import robot_chain_v0``."""

from __future__ import annotations

__all__ = ["robot_chain_v0"]
