"""YAML as users write it: ``1e-4`` is a float (YAML 1.2), not the string PyYAML's YAML 1.1 rules make of it."""

from __future__ import annotations

import re
from typing import Any

import yaml


class NumberFriendlyLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads ``1e-4``, ``5E3`` and ``-2e+1`` as floats (nothing else changes)."""


NumberFriendlyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\d+\.?\d*|\.\d+)[eE][-+]?\d+$"),
    list("-+0123456789."),
)


def load_yaml(text: str) -> Any:
    """``yaml.safe_load`` with YAML 1.2 exponent floats (``learning_rate: 1e-4`` is 0.0001)."""
    return yaml.load(text, Loader=NumberFriendlyLoader)  # noqa: S506 (a SafeLoader subclass)
