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
from collections.abc import Mapping, Sequence
from typing import Any, TypeVar

T = TypeVar("T", bound="StrictConfig")


def param(
    default: Any,
    doc: str,
    *,
    unit: str = "",
    low: float | None = None,
    high: float | None = None,
    choices: Sequence[Any] | None = None,
    valid: str | None = None,
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
        values = value if isinstance(value, tuple) else (value,)
        for v in values:
            if isinstance(v, bool) or v is None or isinstance(v, str):
                continue
            if isinstance(v, (int, float)):
                if not math.isfinite(float(v)):
                    raise ValueError(f"{cls.__name__}: {name}={value!r} must be finite ({_range_text(meta)}).")
                low, high = meta.get("low"), meta.get("high")
                if (low is not None and v < low) or (high is not None and v > high):
                    unit = f" {meta['unit']}" if meta.get("unit") else ""
                    raise ValueError(
                        f"{cls.__name__}: {name}={value!r}{unit} is out of range; expected {_range_text(meta)}."
                    )
        default = f.default
        if isinstance(default, bool) and not isinstance(value, bool):
            raise ValueError(f"{cls.__name__}: {name}={value!r} must be a bool.")
        if isinstance(default, int) and not isinstance(default, bool):
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"{cls.__name__}: {name}={value!r} must be an integer ({_range_text(meta)}).")

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
        converted: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            if f.name not in kwargs:
                continue
            value = kwargs[f.name]
            if isinstance(f.default, tuple) and isinstance(value, list):
                value = tuple(tuple(v) if isinstance(v, list) else v for v in value)
            if isinstance(f.default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            converted[f.name] = value
        return cls(**converted)

    def describe(self) -> list[tuple[str, Any, str, str, str]]:
        """Rows (name, default, unit, valid range, description) for documentation tables."""
        rows = []
        for f in dataclasses.fields(self):
            m = f.metadata
            valid = "True or False" if isinstance(f.default, bool) else _range_text(m)
            rows.append((f.name, f.default, m.get("unit", ""), valid, m.get("doc", "")))
        return rows

    def replace(self: T, **changes: Any) -> T:
        """Return a copy with some fields changed (validated like the original)."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict of all fields (JSON-friendly)."""
        return dataclasses.asdict(self)
