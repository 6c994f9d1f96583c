"""Multi-robot chains (PettingZoo): ``from agri_envs.chain import robot_chain_v1``.

``config``, ``robot`` (body, limits, sonar mounts), ``maps`` (scenes with planning grids), ``mission``
(start, goal, A* path, formation), ``task`` (the ghost robot and ``evaluate()``), ``observation``, ``env``
(composition and API) and the versioned module ``robot_chain_v1``.
"""

from __future__ import annotations

__all__ = ["robot_chain_v1"]
