"""The optional sidecar of an ONNX or SB3 ``.zip`` policy: what the file cannot say about itself.

Next to ``policy.onnx`` (or ``model.zip``), a file ``policy.onnx.yaml`` or ``policy.onnx.json`` may hold::

    name: my-nav-policy                 # display name (default: the file's stem)
    env_id: agri_envs/GreenhouseNav-v2  # the env it drives (lets `agri leaderboard submit --suite all` pick suites)
    env_kwargs: {localization: ground_truth}   # env arguments it needs (added to the evaluation's)
    privileged: true                    # it uses information a real robot would not have
    observation_normalization:          # ONNX only: applied to the flattened observation before the graph
      mean: [...]                       # one value per flat observation entry
      var: [...]
      clip: 10.0                        # normalised values are clipped to [-clip, clip] (default 10)
      epsilon: 1.0e-8                   # added to var before the square root (default 1e-8)

Unknown keys are errors that list the valid ones. YAML is read with ``yaml.safe_load`` (no tags, no code).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from agri_training.learned.policy import ObsNormalization

SIDECAR_KEYS = ("name", "env_id", "env_kwargs", "privileged", "observation_normalization")
NORMALIZATION_KEYS = ("mean", "var", "clip", "epsilon")


@dataclasses.dataclass(frozen=True)
class Sidecar:
    """A policy file's sidecar (all defaults when there is none).

    Attributes:
        path: The sidecar file, or None.
        name: Display name, or None.
        env_id: The env the policy drives, or None.
        env_kwargs: Env arguments the policy needs.
        privileged: The policy uses privileged information.
        normalization: Observation normalisation, or None.
    """

    path: Path | None = None
    name: str | None = None
    env_id: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    privileged: bool = False
    normalization: ObsNormalization | None = None


def sidecar_path(policy_file: Path) -> Path | None:
    """``<file>.yaml`` or ``<file>.json`` beside ``policy_file``, or None.

    Raises:
        ValueError: When both exist (which one would apply is not obvious).
    """
    found = [p for p in (Path(f"{policy_file}.yaml"), Path(f"{policy_file}.json")) if p.is_file()]
    if len(found) > 1:
        raise ValueError(f"{policy_file} has two sidecars ({found[0].name}, {found[1].name}): keep one")
    return found[0] if found else None


def read_sidecar(policy_file: Path) -> Sidecar:
    """The sidecar of ``policy_file``, checked (defaults when there is none).

    Raises:
        ValueError: For a sidecar that does not parse, an unknown key, or a value of the wrong type.
    """
    path = sidecar_path(policy_file)
    if path is None:
        return Sidecar()
    text = path.read_text()
    try:
        doc = json.loads(text) if path.suffix == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        raise ValueError(f"sidecar {path} does not parse: {str(exc).splitlines()[0]}") from None
    doc = {} if doc is None else doc
    if not isinstance(doc, Mapping):
        raise ValueError(f"sidecar {path} must be a mapping of {', '.join(SIDECAR_KEYS)}")
    unknown = sorted(set(doc) - set(SIDECAR_KEYS))
    if unknown:
        raise ValueError(
            f"sidecar {path}: unknown key(s) {', '.join(map(str, unknown))}; valid: {', '.join(SIDECAR_KEYS)}"
        )
    env_kwargs = doc.get("env_kwargs") or {}
    if not isinstance(env_kwargs, Mapping):
        raise ValueError(f"sidecar {path}: env_kwargs must be a mapping, got {env_kwargs!r}")
    for key in ("name", "env_id"):
        if doc.get(key) is not None and not isinstance(doc[key], str):
            raise ValueError(f"sidecar {path}: {key} must be a string, got {doc[key]!r}")
    if not isinstance(doc.get("privileged", False), bool):
        raise ValueError(f"sidecar {path}: privileged must be true or false, got {doc['privileged']!r}")
    norm = doc.get("observation_normalization")
    return Sidecar(
        path=path,
        name=doc.get("name"),
        env_id=doc.get("env_id"),
        env_kwargs=dict(env_kwargs),
        privileged=bool(doc.get("privileged", False)),
        normalization=_normalization(norm, path) if norm is not None else None,
    )


def _normalization(doc: Any, path: Path) -> ObsNormalization:
    """The sidecar's normalisation of the flattened observation (``VecNormalize``'s, on one flat key)."""
    if not isinstance(doc, Mapping) or "mean" not in doc or "var" not in doc:
        raise ValueError(f"sidecar {path}: observation_normalization needs mean and var (and optionally clip, epsilon)")
    unknown = sorted(set(doc) - set(NORMALIZATION_KEYS))
    if unknown:
        raise ValueError(
            f"sidecar {path}: unknown observation_normalization key(s) {', '.join(map(str, unknown))}; "
            f"valid: {', '.join(NORMALIZATION_KEYS)}"
        )
    try:
        mean = np.asarray(doc["mean"], dtype=np.float64).ravel()
        var = np.asarray(doc["var"], dtype=np.float64).ravel()
        clip, epsilon = float(doc.get("clip", 10.0)), float(doc.get("epsilon", 1e-8))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"sidecar {path}: observation_normalization must hold numbers ({exc})") from None
    if mean.shape != var.shape:
        raise ValueError(f"sidecar {path}: mean has {mean.size} values, var {var.size}")
    if not (np.all(np.isfinite(mean)) and np.all(var >= 0.0) and clip > 0.0 and epsilon >= 0.0):
        raise ValueError(
            f"sidecar {path}: observation_normalization needs finite mean, var >= 0, clip > 0, epsilon >= 0"
        )
    return ObsNormalization(mean={"": mean}, var={"": var}, clip_obs=clip, epsilon=epsilon)
