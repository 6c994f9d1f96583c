"""Named scenarios: presets of env arguments for the papers' experiments.

A scenario is data only (env id, arguments, a description), so users can build the same env by hand::

    kwargs = scenario("agri_envs/GreenhouseNav-v0", "sim-loop").env_kwargs
    env = gym.make("agri_envs/GreenhouseNav-v0", **kwargs)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A named preset of env arguments.

    Attributes:
        env_id: The env the preset applies to.
        name: Scenario name (``agri evaluate --scenario NAME``).
        env_kwargs: Arguments passed to ``gym.make``.
        description: What the scenario reproduces (paper section / figure).
        default_episodes: Episodes the report runs by default.
    """

    env_id: str
    name: str
    env_kwargs: Mapping[str, Any]
    description: str = ""
    default_episodes: int = 20


_SCENARIOS: dict[tuple[str, str], Scenario] = {}


def register_scenario(sc: Scenario) -> None:
    """Add a scenario (the pair env id, name is unique)."""
    _SCENARIOS[(sc.env_id, sc.name)] = sc


def scenario(env_id: str, name: str) -> Scenario:
    """Look up a scenario.

    Raises:
        ValueError: For an unknown name, listing the scenarios of that env.
    """
    try:
        return _SCENARIOS[(env_id, name)]
    except KeyError:
        names = sorted(n for (e, n) in _SCENARIOS if e == env_id)
        raise ValueError(f"unknown scenario {name!r} for {env_id}; known: {', '.join(names) or 'none'}") from None


def list_scenarios(env_id: str | None = None) -> list[Scenario]:
    """All scenarios, optionally of one env."""
    return [s for (e, _), s in _SCENARIOS.items() if env_id is None or e == env_id]


register_scenario(
    Scenario(
        env_id="agri_envs/GreenhouseNav-v0",
        name="default",
        env_kwargs={},
        description="The default greenhouse: three rows, two people walking, loop 0->1->...->7->0.",
    )
)
