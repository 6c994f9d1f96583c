"""Strict, typed configuration shared by every env.

Each env has one frozen dataclass whose fields are its ``gym.make`` arguments. Fields are declared with
:func:`param`, which records the unit, the valid range (or choices) and a one-line description;
:class:`StrictConfig` validates every field in ``__post_init__`` and :meth:`StrictConfig.from_kwargs`
rejects unknown keys with the list of valid ones, so a misspelled argument never passes silently.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import numbers
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T", bound="StrictConfig")


def _expected_type(default: Any) -> str | None:
    """What a field with this default accepts, in words (None: no type check)."""
    if isinstance(default, bool):
        return "a bool (True or False)"
    if isinstance(default, int):
        return "an integer"
    if isinstance(default, float):
        return "a number"
    if isinstance(default, str):
        return "a string"
    if isinstance(default, tuple):
        return "a tuple (or list) of numbers"
    return None


def _flat(value: tuple[Any, ...]) -> Iterator[Any]:
    """The leaves of a nested tuple."""
    for v in value:
        if isinstance(v, tuple):
            yield from _flat(v)
        else:
            yield v


def _is_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _has_type(value: Any, default: Any) -> bool:
    """Whether ``value`` has the type of the field whose default is ``default``."""
    if isinstance(default, bool):
        return isinstance(value, bool)
    if isinstance(default, int):
        return isinstance(value, int) and not isinstance(value, bool)
    if isinstance(default, float):
        return _is_number(value)
    if isinstance(default, str):
        return isinstance(value, str)
    if isinstance(default, tuple):
        return isinstance(value, tuple) and all(_is_number(v) for v in _flat(value))
    return True


def _converted(default: Any, value: Any) -> Any:
    """A ``gym.make`` value in the field's own type: lists to tuples, numbers to float for float fields."""
    if isinstance(default, tuple) and isinstance(value, list):
        return tuple(tuple(v) if isinstance(v, list) else v for v in value)
    if isinstance(default, float) and _is_number(value) and type(value) is not float:
        return float(value)
    return value


def param(
    default: Any,
    doc: str,
    *,
    unit: str = "",
    low: float | None = None,
    high: float | None = None,
    choices: Sequence[Any] | None = None,
    valid: str | None = None,
    adds_observation: bool = False,
) -> Any:
    """Declare a config field with its documentation and validated range.

    Args:
        default: Default value (immutable: use tuples, not lists).
        doc: One-line description, shown in errors and docs.
        unit: Unit of the value ("m", "s", "rad", ...), empty when dimensionless.
        low: Inclusive lower bound for numbers (or for every element of a tuple).
        high: Inclusive upper bound for numbers (or for every element of a tuple).
        choices: Allowed values for categorical fields.
        valid: Description of the valid values when no range or choice list says it (checked in ``validate``).
        adds_observation: The field only adds observation keys (a full-resolution scan): an env made with
            either value steps alike and shows the same values under every other key.

    Returns:
        A ``dataclasses.field`` carrying the metadata.
    """
    meta = {
        "doc": doc,
        "unit": unit,
        "low": low,
        "high": high,
        "choices": tuple(choices) if choices else None,
        "valid": valid,
        "adds_observation": adds_observation,
    }
    return dataclasses.field(default=default, metadata=meta)


def _range_text(meta: Mapping[str, Any]) -> str:
    if meta.get("valid"):
        return str(meta["valid"])
    if meta.get("choices"):
        return "one of " + ", ".join(repr(c) for c in meta["choices"])
    low, high = meta.get("low"), meta.get("high")
    if low is not None and high is not None:
        return f"in [{low}, {high}]"
    if low is not None:
        return f">= {low}"
    if high is not None:
        return f"<= {high}"
    return "any value"


@dataclasses.dataclass(frozen=True)
class StrictConfig:
    """Base class of env configs: validates ranges, choices and types of every field."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            self._check_field(f, getattr(self, f.name))
        self.validate()

    def validate(self) -> None:
        """Check constraints between fields; subclasses override and raise ``ValueError``."""

    @classmethod
    def _check_field(cls, f: dataclasses.Field[Any], value: Any) -> None:
        meta = f.metadata
        name = f.name
        choices = meta.get("choices")
        if choices:
            if value not in choices:
                raise ValueError(f"{cls.__name__}: {name}={value!r} is invalid; expected {_range_text(meta)}.")
            return
        expected = _expected_type(f.default)
        if expected is not None and not _has_type(value, f.default):
            valid = "" if isinstance(f.default, bool) else f" {_range_text(meta)}"
            got = type(value).__name__
            if isinstance(value, tuple):
                got = "a tuple holding " + next(type(v).__name__ for v in _flat(value) if not _is_number(v))
            raise ValueError(f"{cls.__name__}: {name}={value!r} must be {expected}{valid}, not {got}.")
        values = _flat(value) if isinstance(value, tuple) else (value,)
        for v in values:
            if isinstance(v, (bool, np.bool_)) or v is None or isinstance(v, str):
                continue
            if isinstance(v, numbers.Real):
                if not math.isfinite(float(v)):
                    raise ValueError(f"{cls.__name__}: {name}={value!r} must be finite ({_range_text(meta)}).")
                low, high = meta.get("low"), meta.get("high")
                if (low is not None and v < low) or (high is not None and v > high):
                    unit = f" {meta['unit']}" if meta.get("unit") else ""
                    raise ValueError(
                        f"{cls.__name__}: {name}={value!r}{unit} is out of range; expected {_range_text(meta)}."
                    )

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of all fields, i.e. the valid ``gym.make`` arguments."""
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def from_kwargs(cls: type[T], kwargs: Mapping[str, Any]) -> T:
        """Build a config from ``gym.make`` keyword arguments, rejecting unknown keys.

        Args:
            kwargs: Argument names and values; missing ones take their defaults.

        Returns:
            The validated config.

        Raises:
            ValueError: For an unknown key (the message lists close matches and all valid keys) or a value
                outside its documented range.
        """
        valid = cls.field_names()
        unknown = [k for k in kwargs if k not in valid]
        if unknown:
            hints = []
            for k in unknown:
                close = difflib.get_close_matches(k, valid, n=1)
                hints.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
            raise ValueError(
                f"{cls.__name__}: unknown argument(s) {', '.join(hints)}. Valid arguments: {', '.join(valid)}."
            )
        fields = dataclasses.fields(cls)
        return cls(**{f.name: _converted(f.default, kwargs[f.name]) for f in fields if f.name in kwargs})

    def with_options(self: T, options: Mapping[str, Any] | None, allowed: Sequence[str]) -> T:
        """This config with the per-episode overrides of ``reset(options=...)`` applied and validated.

        Args:
            options: The ``reset`` options that override config fields (other options removed first).
            allowed: Names of the fields that ``reset`` lets an episode override.

        Returns:
            The config itself when there is nothing to override, else a validated copy.

        Raises:
            ValueError: For an option not in ``allowed`` (the message lists them), or a value of the wrong
                type or out of range (the message names the option and what it accepts).
        """
        if not options:
            return self
        unknown = sorted(k for k in options if k not in allowed)
        if unknown:
            raise ValueError(f"reset options {unknown} unknown; allowed: {sorted(allowed)}")
        fields = {f.name: f for f in dataclasses.fields(self)}
        changes = {k: _converted(fields[k].default, v) for k, v in options.items()}
        try:
            return dataclasses.replace(self, **changes)
        except ValueError as exc:
            raise ValueError(f"reset option: {exc}") from None

    def describe(self) -> list[tuple[str, Any, str, str, str]]:
        """Rows (name, default, unit, valid range, description) for documentation tables."""
        rows = []
        for f in dataclasses.fields(self):
            m = f.metadata
            valid = "True or False" if isinstance(f.default, bool) else _range_text(m)
            rows.append((f.name, f.default, m.get("unit", ""), valid, m.get("doc", "")))
        return rows

    def differences(self, kwargs: Mapping[str, Any]) -> list[str]:
        """The names in ``kwargs`` whose value differs from this config's and that do more than add observation keys.

        Empty: an env made with ``kwargs`` on top of this config steps like this config's and shows the same
        values under this config's observation keys. A name that is not a field counts as a difference.
        """
        fields = {f.name: f for f in dataclasses.fields(self)}
        return [
            name
            for name, value in kwargs.items()
            if name not in fields
            or (getattr(self, name) != value and not fields[name].metadata.get("adds_observation", False))
        ]

    def replace(self: T, **changes: Any) -> T:
        """Return a copy with some fields changed (validated like the original)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of all fields (JSON-friendly)."""
        return dataclasses.asdict(self)
