"""Training distributions over scene arguments: what a learner trains on, and what lies outside it.

An env declares its training distribution as a :class:`SceneDistribution`: one or more scene families
(greenhouse, office corridor, ...), each with a weight, the arguments every scene of the family has, and
the ranges the others are drawn from. With ``scene_distribution="training"`` the env draws one scene per
episode from it, with the episode's own Generator, before it builds the scene; training uses seeds below
100000, held-out suites 100000 and up.

The same object answers the question the held-out protocol needs: does a set of env arguments lie inside
the distribution (some family could draw it), or outside it, and why (:meth:`SceneDistribution.outside`)?
A generalization suite must lie outside: for every family, at least one argument it pins lies outside
that family's range.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from typing import Any, Protocol, TypeVar

import numpy as np


@dataclasses.dataclass(frozen=True)
class Uniform:
    """A real argument drawn uniformly from ``[low, high]``."""

    low: float
    high: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low <= self.high):
            raise ValueError(f"Uniform needs finite low <= high, got [{self.low}, {self.high}]")

    def sample(self, rng: np.random.Generator) -> float:
        """One draw."""
        return float(rng.uniform(self.low, self.high))

    def contains(self, value: Any) -> bool:
        """Whether ``value`` lies in the range."""
        return isinstance(value, (int, float)) and not isinstance(value, bool) and bool(self.low <= value <= self.high)

    def largest(self) -> float:
        """The largest value (scenes grow with it)."""
        return self.high

    def describe(self) -> str:
        """The range in words, e.g. ``[1.1, 1.5]``."""
        return f"[{self.low:g}, {self.high:g}]"


@dataclasses.dataclass(frozen=True)
class IntRange:
    """An integer argument drawn uniformly from ``low .. high`` (both included)."""

    low: int
    high: int

    def __post_init__(self) -> None:
        if not self.low <= self.high:
            raise ValueError(f"IntRange needs low <= high, got {self.low}..{self.high}")

    def sample(self, rng: np.random.Generator) -> int:
        """One draw."""
        return int(rng.integers(self.low, self.high + 1))

    def contains(self, value: Any) -> bool:
        """Whether ``value`` is an integer in the range."""
        is_int = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
        return is_int and bool(self.low <= value <= self.high)

    def largest(self) -> int:
        """The largest value."""
        return self.high

    def describe(self) -> str:
        """The range in words, e.g. ``2..4``."""
        return f"{self.low}..{self.high}"


@dataclasses.dataclass(frozen=True)
class Choice:
    """A categorical argument drawn uniformly from ``values``."""

    values: tuple[Any, ...]

    def __post_init__(self) -> None:
        if not self.values:
            raise ValueError("Choice needs at least one value")

    def sample(self, rng: np.random.Generator) -> Any:
        """One draw."""
        return self.values[int(rng.integers(len(self.values)))]

    def contains(self, value: Any) -> bool:
        """Whether ``value`` is one of the values."""
        return bool(value in self.values)

    def largest(self) -> Any:
        """The first value (a choice has no order; scenes do not grow with it)."""
        return self.values[0]

    def describe(self) -> str:
        """The values in words."""
        return "{" + ", ".join(repr(v) for v in self.values) + "}"


ArgumentRange = Uniform | IntRange | Choice


@dataclasses.dataclass(frozen=True)
class SceneFamily:
    """One kind of scene in a training distribution.

    Attributes:
        name: Family name (``greenhouse``, ``corridor``, ...).
        weight: Relative chance that an episode draws this family, > 0.
        fixed: Arguments every scene of the family has (e.g. ``{"scene": "corridor"}``).
        ranges: Arguments drawn per episode, in this order, each from its range.
    """

    name: str
    weight: float
    fixed: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    ranges: Mapping[str, ArgumentRange] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.weight > 0:
            raise ValueError(f"SceneFamily {self.name!r}: weight must be > 0, got {self.weight}")
        both = sorted(set(self.fixed) & set(self.ranges))
        if both:
            raise ValueError(f"SceneFamily {self.name!r}: {both} are both fixed and drawn")

    @property
    def arguments(self) -> tuple[str, ...]:
        """Every argument the family sets, fixed or drawn."""
        return (*self.fixed, *self.ranges)

    def sample(self, rng: np.random.Generator) -> dict[str, Any]:
        """The fixed arguments and one draw of each range, in declaration order."""
        return {**self.fixed, **{name: r.sample(rng) for name, r in self.ranges.items()}}

    def largest(self) -> dict[str, Any]:
        """The family's largest scene: every range at its top (for canvases and observation scales)."""
        return {**self.fixed, **{name: r.largest() for name, r in self.ranges.items()}}

    def same_kind(self, kwargs: Mapping[str, Any], defaults: Mapping[str, Any]) -> bool:
        """Whether ``kwargs`` has every fixed argument of the family (the same kind of scene, say)."""
        return all(kwargs.get(name, defaults.get(name)) == value for name, value in self.fixed.items())

    def excludes(self, kwargs: Mapping[str, Any], defaults: Mapping[str, Any]) -> list[str]:
        """Why this family never draws a scene with ``kwargs`` (empty: it can).

        Args:
            kwargs: Env arguments (a suite's, say).
            defaults: The env's default arguments, for those that ``kwargs`` leaves out.
        """
        reasons = []
        for name, value in self.fixed.items():
            given = kwargs.get(name, defaults.get(name))
            if given != value:
                reasons.append(f"{name}={given!r} (family {self.name!r} has {value!r})")
        for name, r in self.ranges.items():
            given = kwargs.get(name, defaults.get(name))
            if not r.contains(given):
                reasons.append(f"{name}={given!r} outside {r.describe()}")
        return reasons


@dataclasses.dataclass(frozen=True)
class SceneDistribution:
    """A distribution over an env's scene arguments: families of scenes, each drawn with its weight.

    Attributes:
        name: Name an env argument selects it by (``scene_distribution="training"``).
        families: The scene families (at least one).
        description: What the distribution covers, in a sentence.
    """

    name: str
    families: tuple[SceneFamily, ...]
    description: str = ""

    def __post_init__(self) -> None:
        if not self.families:
            raise ValueError(f"SceneDistribution {self.name!r} needs at least one family")
        names = [f.name for f in self.families]
        if len(set(names)) != len(names):
            raise ValueError(f"SceneDistribution {self.name!r}: family names repeat: {names}")

    @property
    def arguments(self) -> frozenset[str]:
        """Every argument some family sets (an env refuses them as ``gym.make`` arguments beside it)."""
        return frozenset(a for f in self.families for a in f.arguments)

    def refuse_given(self, given: Iterable[str], owner: str) -> None:
        """Refuse env arguments that this distribution draws per episode (they would be silently replaced).

        Args:
            given: The arguments given to ``gym.make``.
            owner: Who asks, for the message (``"GreenhouseNav: scene_distribution='training'"``).

        Raises:
            ValueError: Naming the arguments to leave out and all that the distribution draws.
        """
        drawn = sorted(set(given) & self.arguments)
        if drawn:
            raise ValueError(
                f"{owner} draws {drawn} per episode; leave them out (it draws {sorted(self.arguments)})."
            )

    def family(self, name: str) -> SceneFamily:
        """The family called ``name``.

        Raises:
            ValueError: For an unknown name.
        """
        for f in self.families:
            if f.name == name:
                return f
        raise ValueError(f"unknown family {name!r}; known: {', '.join(f.name for f in self.families)}")

    def sample(self, rng: np.random.Generator) -> tuple[str, dict[str, Any]]:
        """``(family name, arguments)`` of one scene: a family by weight, then its arguments.

        The draws come from ``rng`` alone, in a fixed order, so one seed gives one scene.
        """
        weights = np.array([f.weight for f in self.families], dtype=np.float64)
        u = float(rng.random()) * float(weights.sum())
        k = min(int(np.searchsorted(np.cumsum(weights), u, side="right")), len(self.families) - 1)
        family = self.families[k]
        return family.name, family.sample(rng)

    def outside(self, kwargs: Mapping[str, Any], defaults: Mapping[str, Any]) -> dict[str, list[str]]:
        """Why each family never draws a scene with ``kwargs``; a family that can draw it maps to ``[]``.

        ``kwargs`` lies outside the distribution when every family has a reason (:meth:`lies_outside`).

        Args:
            kwargs: Env arguments (a suite's, say).
            defaults: The env's default arguments, for those that ``kwargs`` leaves out.
        """
        return {f.name: f.excludes(kwargs, defaults) for f in self.families}

    def nearest(self, kwargs: Mapping[str, Any], defaults: Mapping[str, Any]) -> tuple[str, list[str]]:
        """The family most like ``kwargs`` and why it cannot draw them (``[]``: it can).

        Families of the same kind (their fixed arguments match) come first, then those with fewer reasons.
        """
        ranked = sorted(
            self.families,
            key=lambda f: (not f.same_kind(kwargs, defaults), len(f.excludes(kwargs, defaults))),
        )
        return ranked[0].name, ranked[0].excludes(kwargs, defaults)

    def lies_outside(self, kwargs: Mapping[str, Any], defaults: Mapping[str, Any]) -> bool:
        """True when no family of the distribution can draw a scene with these arguments."""
        return all(self.outside(kwargs, defaults).values())

    def describe(self) -> list[str]:
        """One line per family: weight, fixed arguments and ranges."""
        total = sum(f.weight for f in self.families)
        lines = []
        for f in self.families:
            parts = [f"{k}={v!r}" for k, v in f.fixed.items()] + [f"{k} {r.describe()}" for k, r in f.ranges.items()]
            lines.append(f"{f.name} ({f.weight / total:.0%}): " + ", ".join(parts))
        return lines


C = TypeVar("C", bound="_Config")


class _Config(Protocol):
    """An env's arguments: a frozen config with ``replace`` (:class:`agri_envs._config.StrictConfig`)."""

    def replace(self: C, **changes: Any) -> C: ...


def largest_scenes(distribution: SceneDistribution | None, config: C) -> list[C]:
    """The env arguments of the largest scenes an env must make room for (its canvas, its observation scales).

    Args:
        distribution: The env's distribution, or None (``scene_distribution="off"``).
        config: The env's arguments.

    Returns:
        ``[config]`` without a distribution, else ``config`` with each family's largest scene.
    """
    if distribution is None:
        return [config]
    return [config.replace(**f.largest()) for f in distribution.families]
