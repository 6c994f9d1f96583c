"""A policy resolved once, at the entry: one typed :class:`PolicyRef` that every layer below is handed.

A policy is named in one of six ways; :func:`resolve_policy` tells them apart and reads what each needs once
(the registry, a run's ``config.yaml``, a file's sha256 and sidecar), and :func:`build_policy` builds the acting
object from the reference alone, in whatever process runs the episode:

| kind | named by | acts through |
|---|---|---|
| ``baseline`` | a registered scripted policy's name (``harik-apf-gt``) | its factory in :mod:`agri_baselines` |
| ``zoo`` | a registered trained policy's name (``ppo-greenhouse-nav``) | :class:`~.policy.LearnedPolicy` |
| ``learned-run`` | an ``agri train`` run folder (or its ``best/``, ``checkpoints/step_N``) | the same |
| ``onnx`` | a ``.onnx`` file (:mod:`agri_training.learned.onnx_policy`) | the float64 graph interpreter |
| ``sb3-zip`` | an SB3 ``model.zip`` (:mod:`agri_training.learned.sb3_zip`) | the float64 SB3 network |
| ``callable`` | ``module:attribute``, a factory taking the env; or, in Python, any object | the object itself |

The network formats act through the CPU-independent float64 path (:mod:`agri_training.learned.inference`), so
their entries verify bit for bit on any x86-64 CPU; a ``callable`` does not, unless its factory says it does
(``cpu_independent = True``), and its entries say so (``reverifiable: false``).

:func:`merge_env_kwargs` merges the env arguments of one evaluation, also once: what the scenario, the suite and
the user ask for, plus what the policy needs. A need may add an argument; one that contradicts an argument that
was asked for is refused, with both values named.
"""

from __future__ import annotations

import dataclasses
import importlib
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agri_baselines import policy_spec
from agri_training.core.documents import sha256_file
from agri_training.learned import zoo
from agri_training.learned.onnx_policy import OnnxPolicy, check_onnx_file
from agri_training.learned.policy import LearnedPolicy, is_run_path, read_config, refuse_pickled
from agri_training.learned.sb3_zip import Sb3ZipPolicy, check_sb3_zip
from agri_training.learned.sidecar import Sidecar, read_sidecar

#: The ways a policy can be named (:class:`PolicyRef.kind`).
KINDS = ("baseline", "zoo", "learned-run", "onnx", "sb3-zip", "callable")
#: ``module:attribute`` (dotted names on both sides).
_CALLABLE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


@dataclasses.dataclass(frozen=True)
class PolicyRef:
    """A policy, resolved: what it is, where its weights are, what it needs of the env.

    Attributes:
        kind: One of :data:`KINDS`.
        name: Display name (leaderboard entries, progress, file names of entries).
        spec: What names it: the registered name, the path as given, or ``module:attribute``.
        format: The weights' format: ``registry`` (baselines), ``agri-run`` (``policy.pt`` + ``config.yaml``),
            ``onnx``, ``sb3-zip`` or ``python``.
        path: The weights (a run folder, a ``.onnx`` or ``.zip`` file), absolute; None for registered names
            and callables.
        shown_path: The path as an entry records it (relative to the repository when inside it).
        sha256: The sha256 of the weights file (None for scripted baselines and callables).
        privileged: The policy uses information a real robot would not have.
        env_id: The env it drives, when known (registered policies, runs, a sidecar's ``env_id``).
        env_kwargs: Env arguments it needs (added to the evaluation's; a contradiction is an error).
        observation_only: It acts on its observations alone (episodes may run in an env's batched form).
        needs_torch: Building it imports torch (worker processes preload it).
        reverifiable: Its actions are the same bits on every x86-64 CPU, so its entries verify anywhere.
        sidecar_sha256: The sha256 of an ONNX or SB3 file's sidecar, when it has one.
        entry_point: A registered policy's factory, ``module:callable`` (baselines and zoo policies).
        instance: A live policy object (the Python API's ``evaluate_suite(model, ...)``); runs in this process.
    """

    kind: str
    name: str
    spec: str
    format: str
    path: str | None = None
    shown_path: str | None = None
    sha256: str | None = None
    privileged: bool = False
    env_id: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    observation_only: bool = False
    needs_torch: bool = False
    reverifiable: bool = True
    sidecar_sha256: str | None = None
    entry_point: str | None = None
    instance: Any = dataclasses.field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"policy kind must be one of {', '.join(KINDS)}, got {self.kind!r}")

    def key(self) -> str:
        """Identity of the policy for caches (kind, spec, weights' sha256; a live object by its id)."""
        own = f"|object {id(self.instance)}" if self.instance is not None else ""
        return f"{self.kind}|{self.spec}|{self.sha256}|{self.sidecar_sha256}{own}"

    def to_entry(self) -> dict[str, Any]:
        """What a leaderboard entry records about the policy (the format of existing entries for old kinds).

        Raises:
            ValueError: For a training teacher (``PolicySpec.teacher``): it has no entries.
        """
        if self.kind == "baseline":
            if policy_spec(self.spec).teacher:
                raise ValueError(
                    f"{self.spec} is a training teacher, not a baseline: the leaderboard compares learned policies "
                    f"with the papers' controllers (run it with agri evaluate --policy {self.spec})"
                )
            return {"kind": "baseline", "name": self.name, "privileged": self.privileged}
        if self.kind == "zoo":
            ref: dict[str, Any] = {"kind": "learned", "name": self.name, "privileged": self.privileged}
            if self.sha256:
                ref["sha256"] = self.sha256
            return ref
        if self.kind == "learned-run":
            return {
                "kind": "learned",
                "name": self.name,
                "path": self.shown_path,
                "sha256": self.sha256,
                "privileged": self.privileged,
            }
        if self.kind in ("onnx", "sb3-zip"):
            ref = {"kind": self.kind, "name": self.name, "path": self.shown_path, "sha256": self.sha256}
            if self.sidecar_sha256:
                ref["sidecar_sha256"] = self.sidecar_sha256
            ref["privileged"] = self.privileged
            return ref
        if self.instance is not None:  # a document of the Python API, not an entry others can re-run
            return {
                "kind": "object",
                "name": self.name,
                "spec": self.spec,
                "privileged": self.privileged,
                "reverifiable": False,
            }
        return {
            "kind": "callable",
            "name": self.name,
            "spec": self.spec,
            "privileged": self.privileged,
            "reverifiable": self.reverifiable,
        }


def shown_path(path: Path, root: Path) -> str:
    """``path`` relative to ``root`` when inside it, else absolute (what an entry records)."""
    try:
        return str(path.resolve().relative_to(root))
    except ValueError:
        return str(path.resolve())


def resolve_policy(policy: str | PolicyRef | Any, name: str | None = None, root: Path | None = None) -> PolicyRef:
    """The one typed reference of a policy named by the user (CLI or Python API).

    Args:
        policy: A registered name, an ``agri train`` run folder, a ``.onnx`` or SB3 ``.zip`` file, a
            ``module:attribute`` factory, a :class:`PolicyRef` (returned as it is), or a live policy object (with
            SB3's ``predict``, or a callable from observation to action).
        name: Display name (default: the registered name, the run folder's or file's name, the attribute).
        root: Paths inside this folder are recorded relative to it (default: the current directory).

    Raises:
        ValueError: For an unknown name, a file that is not there or not of its format, a module that does not
            import; :class:`~agri_training.learned.policy.UnsafeCheckpointError` for pickle files.
    """
    if isinstance(policy, PolicyRef):
        return policy if name is None else dataclasses.replace(policy, name=name)
    if not isinstance(policy, (str, Path)):
        return _object_reference(policy, name)
    text = str(policy)
    base = Path.cwd() if root is None else root
    refuse_pickled(text)
    path = Path(text)
    if text.endswith(".onnx") or text.endswith(".zip"):
        if not path.is_file():
            raise ValueError(f"policy file {text!r} not found")
        return _file_reference(path, name, base)
    if is_run_path(text):
        config = read_config(path)
        return PolicyRef(
            kind="learned-run",
            name=name or path.name,
            spec=text,
            format="agri-run",
            path=str(path.resolve()),
            shown_path=shown_path(path, base),
            sha256=_run_weights_sha(path),
            privileged=bool(config.get("privileged", False)),
            env_id=str(config["env_id"]),
            env_kwargs=dict(config.get("env_kwargs") or {}),
            observation_only=True,
            needs_torch=True,
        )
    if _CALLABLE.match(text) and not path.exists():
        return _callable_reference(text, name)
    try:
        spec = policy_spec(text)
    except ValueError as exc:
        raise ValueError(
            f"{exc}; a policy is also an `agri train` run folder, a .onnx or SB3 .zip file, or module:attribute"
        ) from None
    if spec.learned:
        weights = zoo.zoo_path(spec.name) / "policy.pt"
        return PolicyRef(
            kind="zoo",
            name=name or spec.name,
            spec=spec.name,
            format="agri-run",
            sha256=sha256_file(weights) if weights.is_file() else None,
            privileged=spec.privileged,
            env_id=spec.env_id,
            env_kwargs=dict(spec.env_kwargs),
            observation_only=True,
            needs_torch=True,
            entry_point=spec.entry_point,
        )
    return PolicyRef(
        kind="baseline",
        name=name or spec.name,
        spec=spec.name,
        format="registry",
        privileged=spec.privileged,
        env_id=spec.env_id,
        env_kwargs=dict(spec.env_kwargs),
        observation_only=spec.observation_only,
        entry_point=spec.entry_point,
    )


def _run_weights_sha(path: Path) -> str | None:
    weights = path / "policy.pt"
    return sha256_file(weights) if weights.is_file() else None


def _file_reference(path: Path, name: str | None, base: Path) -> PolicyRef:
    """An ONNX or SB3 zip file, checked (operators, zip members) without building it."""
    sidecar: Sidecar = read_sidecar(path)
    if path.suffix == ".onnx":
        check_onnx_file(path)
        kind = "onnx"
    else:
        check_sb3_zip(path)
        kind = "sb3-zip"
    return PolicyRef(
        kind=kind,
        name=name or sidecar.name or path.stem,
        spec=str(path),
        format=kind,
        path=str(path.resolve()),
        shown_path=shown_path(path, base),
        sha256=sha256_file(path),
        privileged=sidecar.privileged,
        env_id=sidecar.env_id,
        env_kwargs=dict(sidecar.env_kwargs),
        observation_only=True,  # it acts on its observation alone; needs_torch stays False: files are read here
        sidecar_sha256=sha256_file(sidecar.path) if sidecar.path is not None else None,
    )


def import_attribute(spec: str) -> Any:
    """The attribute named by ``module:attribute`` (dotted on both sides), imported.

    Raises:
        ValueError: When the module does not import or lacks the attribute (the message names which).
    """
    module_name, _, attr = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except Exception as exc:  # a user's module: any error it raises on import is theirs to fix
        raise ValueError(
            f"policy {spec!r}: module {module_name!r} does not import ({type(exc).__name__}: {exc}); "
            "is its folder on PYTHONPATH?"
        ) from None
    target: Any = module
    for part in attr.split("."):
        if not hasattr(target, part):
            raise ValueError(f"policy {spec!r}: module {module_name!r} has no attribute {attr!r}")
        target = getattr(target, part)
    if not callable(target):
        raise ValueError(f"policy {spec!r}: {attr!r} is not callable (a factory taking the env is expected)")
    return target


def _callable_reference(spec: str, name: str | None) -> PolicyRef:
    factory = import_attribute(spec)
    return PolicyRef(
        kind="callable",
        name=name or spec.partition(":")[2],
        spec=spec,
        format="python",
        privileged=bool(getattr(factory, "privileged", False)),
        env_id=getattr(factory, "env_id", None),
        env_kwargs=dict(getattr(factory, "env_kwargs", None) or {}),
        reverifiable=bool(getattr(factory, "cpu_independent", False)),
    )


def _object_reference(policy: Any, name: str | None) -> PolicyRef:
    if not (hasattr(policy, "predict") or callable(policy)):
        raise ValueError(
            f"a policy is a name, a path, module:attribute, an object with SB3's predict or a callable from "
            f"observation to action; got {type(policy).__name__}"
        )
    kind = type(policy)
    return PolicyRef(
        kind="callable",
        name=name or str(getattr(policy, "__name__", kind.__name__)),
        spec=f"{kind.__module__}:{kind.__qualname__}",
        format="python",
        reverifiable=bool(getattr(policy, "cpu_independent", False)),
        instance=policy,
    )


class FunctionPolicy:
    """SB3's ``predict`` over a function from one observation to one action.

    Args:
        function: ``observation -> action``.
    """

    def __init__(self, function: Callable[[Any], Any]) -> None:
        self.function = function

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[np.ndarray, Any]:
        """``(function(observation), state)``."""
        return np.asarray(self.function(observation)), state


def _as_policy(obj: Any, what: str) -> Any:
    if hasattr(obj, "predict"):
        return obj
    if callable(obj):
        return FunctionPolicy(obj)
    raise ValueError(f"{what} returned {type(obj).__name__}, neither an object with predict nor a callable")


def build_policy(ref: PolicyRef, env: Any) -> Any:
    """The acting object of a resolved policy on ``env`` (built afresh; a live object is returned as it is).

    Raises:
        ValueError: When the policy cannot act on ``env`` (its spaces, its format).
    """
    if ref.kind in ("baseline", "zoo"):  # as agri_baselines.make_policy builds it, without looking it up again
        factory = import_attribute(str(ref.entry_point))
        return factory(env, ref.spec) if ref.kind == "zoo" else factory(env)
    if ref.kind == "learned-run":
        return LearnedPolicy(str(ref.path), env)
    if ref.kind == "onnx":
        return OnnxPolicy(Path(str(ref.path)), env)
    if ref.kind == "sb3-zip":
        return Sb3ZipPolicy(Path(str(ref.path)), env)
    if ref.instance is not None:
        return _as_policy(ref.instance, f"policy object {ref.name!r}")
    return _as_policy(import_attribute(ref.spec)(env), f"factory {ref.spec!r}")


def merge_env_kwargs(env_id: str, ref: PolicyRef, asked: Sequence[tuple[str, Mapping[str, Any]]]) -> dict[str, Any]:
    """The env arguments of an evaluation: those asked for (later sources override earlier), plus the policy's needs.

    Args:
        env_id: The env evaluated.
        ref: The policy.
        asked: ``(where, arguments)`` in order, e.g. ``[("scenario table2", {...}), ("--env-kwargs", {...})]``.

    Raises:
        ValueError: When the policy drives another env, or needs an argument that contradicts one asked for
            (the message names both values and where the other came from).
    """
    if ref.env_id is not None and ref.env_id != env_id:
        raise ValueError(f"policy {ref.name!r} drives {ref.env_id}, not {env_id}")
    merged: dict[str, Any] = {}
    origin: dict[str, str] = {}
    for where, kwargs in asked:
        merged.update(kwargs)
        origin.update(dict.fromkeys(kwargs, where))
    for key, value in ref.env_kwargs.items():
        if key in merged and merged[key] != value:
            raise ValueError(
                f"policy {ref.name!r} needs {key}={value!r}, but {origin[key]} sets {key}={merged[key]!r}: "
                f"it cannot be evaluated there (a policy's needs may add env arguments, never change one asked for)"
            )
        merged[key] = value
    return merged
