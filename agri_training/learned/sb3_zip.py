"""Stable-Baselines3 ``model.zip`` files, read without unpickling anything, acting through the float64 path.

An SB3 zip holds ``data`` (JSON; objects it could not write as JSON are cloudpickle blobs under
``":serialized:"``, beside a few of their attributes as plain text) and ``policy.pth`` (``torch.save`` of the
policy's ``state_dict``). :class:`Sb3ZipPolicy` reads only this:

- from ``data``: the policy class's name and module (the text of its ``__init__`` and ``__module__``), the plain
  fields of ``policy_kwargs`` (an ``activation_fn`` from its text ``<class 'torch.nn...ReLU'>``), and the spaces'
  plain ``_shape`` and key names, to check that the policy was made for the env; never a ``":serialized:"`` blob;
- from ``policy.pth``: the tensors, through :func:`~agri_training.learned.torch_zip.read_state_dict` (no
  unpickler, no torch).

The architecture comes from the tensors' names and shapes, and the acting layers go to
:class:`~agri_training.learned.inference.PolicyNetwork`, which computes SB3's deterministic action (PPO's mean,
clipped to the bounds; SAC's and TQC's squashed mean and TD3's actor, scaled from [-1, 1] to the bounds) the same
way on every CPU. SB3 preprocesses observations the way ``PolicyNetwork`` does for ``MlpPolicy`` and
``MultiInputPolicy`` on Box observations: a Dict's keys in the space's (sorted) order, each flattened, concatenated,
not normalised. What cannot be rebuilt that way (CNN features extractors, image observations, custom classes,
recurrent policies, gSDE) is refused with a message that says to export the actor as ONNX.
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import agri_envs
from agri_training.core.filecache import FileCache
from agri_training.learned.inference import ACTIVATION_FUNCTIONS, ACTOR_LAYERS, DEFAULT_ACTIVATION, PolicyNetwork
from agri_training.learned.sidecar import read_sidecar
from agri_training.learned.torch_zip import read_state_dict

#: Policy classes rebuilt from their tensors: (module, class) -> the acting path of :class:`PolicyNetwork`.
POLICY_CLASSES: dict[tuple[str, str], str] = {
    ("stable_baselines3.common.policies", "ActorCriticPolicy"): "ppo",
    ("stable_baselines3.common.policies", "MultiInputActorCriticPolicy"): "ppo",
    ("stable_baselines3.sac.policies", "SACPolicy"): "sac",
    ("stable_baselines3.sac.policies", "MultiInputPolicy"): "sac",
    ("stable_baselines3.td3.policies", "TD3Policy"): "td3",
    ("stable_baselines3.td3.policies", "MultiInputPolicy"): "td3",
    ("sb3_contrib.tqc.policies", "TQCPolicy"): "tqc",
    ("sb3_contrib.tqc.policies", "MultiInputPolicy"): "tqc",
}
#: Activation classes that may be named in ``policy_kwargs.activation_fn``.
_ACTIVATIONS = tuple(ACTIVATION_FUNCTIONS)
#: What to do instead, said by every refusal.
EXPORT_HINT = (
    "export the actor to ONNX instead (torch.onnx.export of a network from the flattened observation to the "
    "action; see agri_training.learned.onnx_policy)"
)
#: Policy keyword arguments that change the network beyond its tensors' shapes, or the observations it sees.
_UNSUPPORTED_KWARGS = (
    "features_extractor_class", "features_extractor_kwargs", "use_sde", "squash_output", "use_expln",
)  # fmt: skip
_INIT_TEXT = re.compile(r"<function (\w+)\.__init__ at ")
_ACTIVATION_TEXT = re.compile(r"<class 'torch\.nn\.modules\.activation\.(\w+)'>")


@dataclasses.dataclass(frozen=True)
class Sb3Zip:
    """What an SB3 zip says about its policy, read from plain JSON fields and tensors only.

    Attributes:
        algo: The acting path (``ppo``, ``sac``, ``td3``, ``tqc``).
        policy_class: ``module.Class`` of the policy.
        activation: Activation class name (SB3's default for the algorithm when not given).
        state: The policy's tensors, float64.
        observation_shape: The plain ``_shape`` of a Box observation space, or None.
        observation_keys: The key names of a Dict observation space, or None.
        action_shape: The plain ``_shape`` of a Box action space, or None.
    """

    algo: str
    policy_class: str
    activation: str
    state: Mapping[str, np.ndarray]
    observation_shape: tuple[int, ...] | None
    observation_keys: tuple[str, ...] | None
    action_shape: tuple[int, ...] | None


def _refuse(path: Path | str, what: str) -> ValueError:
    return ValueError(f"{path}: {what}; {EXPORT_HINT}")


def read_sb3_zip(path: Path) -> Sb3Zip:
    """Read an SB3 zip's policy class, keyword arguments, spaces' shapes and tensors (nothing is unpickled).

    Raises:
        ValueError: For a file that is not an SB3 zip, one without ``data`` or ``policy.pth``, an unknown policy
            class, options or tensors that the float64 path cannot rebuild (each message says what to export
            instead).
    """
    try:
        archive = zipfile.ZipFile(io.BytesIO(Path(path).read_bytes()))
    except zipfile.BadZipFile:
        raise ValueError(f"{path} is not a zip file (an SB3 model.zip was expected)") from None
    names = archive.namelist()
    for member in ("data", "policy.pth"):
        if member not in names:
            raise ValueError(f"{path} has no {member!r}: not an SB3 model.zip (members: {', '.join(names) or 'none'})")
    try:
        data = json.loads(archive.read("data"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: 'data' is not JSON ({exc}); it is never unpickled") from None
    if not isinstance(data, Mapping):
        raise ValueError(f"{path}: 'data' is not a JSON object")
    module, cls = _policy_class(data, path)
    if (module, cls) not in POLICY_CLASSES:
        known = ", ".join(f"{m}.{c}" for m, c in POLICY_CLASSES)
        raise _refuse(path, f"the policy class {module}.{cls} cannot be rebuilt from its tensors (known: {known})")
    algo = POLICY_CLASSES[(module, cls)]
    kwargs = data.get("policy_kwargs") or {}
    if not isinstance(kwargs, Mapping):
        raise _refuse(path, "policy_kwargs is not a mapping")
    for option in _UNSUPPORTED_KWARGS:
        value = kwargs.get(option)
        if value not in (None, False, {}):
            raise _refuse(path, f"policy_kwargs.{option} = {value!r} is not supported by the float64 path")
    if data.get("use_sde"):
        raise _refuse(path, "gSDE (use_sde) is not supported by the float64 path")
    activation = _activation(kwargs.get("activation_fn"), algo, path)
    state = {
        k: np.asarray(v, dtype=np.float64) for k, v in read_state_dict(archive.read("policy.pth"), str(path)).items()
    }
    _check_tensors(state, algo, path)
    obs = data.get("observation_space")
    act = data.get("action_space")
    return Sb3Zip(
        algo=algo,
        policy_class=f"{module}.{cls}",
        activation=activation,
        state=state,
        observation_shape=_plain_shape(obs),
        observation_keys=_plain_keys(obs),
        action_shape=_plain_shape(act),
    )


def _policy_class(data: Mapping[str, Any], path: Path) -> tuple[str, str]:
    """``(module, class)`` of the policy from the plain text SB3 writes beside the pickled class."""
    entry = data.get("policy_class")
    if not isinstance(entry, Mapping):
        raise ValueError(f"{path}: 'data' names no policy_class: not an SB3 model.zip")
    module = entry.get("__module__")
    match = _INIT_TEXT.match(str(entry.get("__init__", "")))
    if not isinstance(module, str) or match is None:
        raise _refuse(path, "its policy class is not one of SB3's (no plain __module__ and __init__ text)")
    return module, match.group(1)


def _activation(value: Any, algo: str, path: Path) -> str:
    if value is None:
        return DEFAULT_ACTIVATION[algo]
    match = _ACTIVATION_TEXT.match(str(value))
    if match is None or match.group(1) not in _ACTIVATIONS:
        raise _refuse(path, f"policy_kwargs.activation_fn {value!r} is not one of {', '.join(_ACTIVATIONS)}")
    return match.group(1)


def _check_tensors(state: Mapping[str, np.ndarray], algo: str, path: Path) -> None:
    """Refuse tensors of parts the float64 path does not rebuild (features extractors, recurrent layers)."""
    for key in state:
        if "features_extractor" in key or "lstm" in key or key.startswith(("cnn", "extractors")):
            raise _refuse(path, f"its network has a learned features extractor or recurrent layers ({key})")
        if key.startswith("mlp_extractor.shared_net"):  # SB3 < 1.8's shared layers
            raise _refuse(path, f"its actor shares layers with the critic ({key}), as SB3 before 1.8 built it")
    hidden, output = ACTOR_LAYERS[algo]
    needed = f"{output}.weight" if output else f"{hidden}.0.weight"  # TD3's actor: one Sequential
    if needed not in state:
        raise _refuse(path, f"policy.pth lacks {needed!r}, which a {algo} policy has")


def _plain_shape(space: Any) -> tuple[int, ...] | None:
    if isinstance(space, Mapping) and isinstance(space.get("_shape"), list):
        return tuple(int(n) for n in space["_shape"])
    return None


def _plain_keys(space: Any) -> tuple[str, ...] | None:
    if isinstance(space, Mapping) and "gymnasium.spaces.dict.Dict" in str(space.get(":type:", "")):
        return tuple(re.findall(r"'([^']+)': \w+\(", str(space.get("spaces", ""))))
    return None


def check_sb3_zip(path: Path) -> None:
    """Read and check an SB3 zip and its sidecar without an env (see :func:`read_sb3_zip`)."""
    load_sb3_zip(path)
    sidecar = read_sidecar(path)
    if sidecar.normalization is not None:
        raise ValueError(f"{sidecar.path}: observation_normalization applies to ONNX policies only")


#: Zips read in this process, by file and stamps.
_ZIPS: FileCache[Sb3Zip] = FileCache()
#: The acting networks of zips, built for the spaces they drive (a fresh policy per episode shares one).
_NETWORKS: FileCache[PolicyNetwork] = FileCache()


def load_sb3_zip(path: Path) -> Sb3Zip:
    """:func:`read_sb3_zip`, once per process while the file is unchanged."""
    return _ZIPS.get([Path(path)], None, lambda: read_sb3_zip(Path(path)))


class Sb3ZipPolicy:
    """An SB3 ``model.zip`` acting on an env's raw observations through the float64 path: SB3's ``predict``.

    Args:
        path: The zip file.
        env: The env it drives (its spaces).

    Raises:
        ValueError: When the zip is refused (:func:`read_sb3_zip`) or was made for other spaces (both named).
    """

    #: Its actions are the same bits on every x86-64 CPU.
    cpu_independent = True

    def __init__(self, path: Path, env: Any) -> None:
        self.path = Path(path)
        if agri_envs.is_parallel_env(env):
            raise ValueError(f"{self.path}: SB3 zips drive single-agent envs, not the PettingZoo env {env}")
        model = load_sb3_zip(self.path)
        observation_space, action_space = env.observation_space, env.action_space
        env_name = getattr(getattr(env, "spec", None), "id", None) or type(getattr(env, "unwrapped", env)).__name__
        if isinstance(observation_space, gym.spaces.Dict):
            keys = tuple(observation_space.spaces)
            if model.observation_keys is not None and sorted(model.observation_keys) != sorted(keys):
                raise ValueError(
                    f"{self.path} observes {list(model.observation_keys)}, {env_name} gives {list(keys)}: "
                    "the policy was made for another env or other env arguments"
                )
        elif model.observation_shape is not None and model.observation_shape != tuple(observation_space.shape or ()):
            raise ValueError(
                f"{self.path} observes shape {model.observation_shape}, {env_name} gives {observation_space.shape}"
            )
        if model.action_shape is not None and isinstance(action_space, gym.spaces.Box):
            if model.action_shape != tuple(action_space.shape):
                raise ValueError(
                    f"{self.path} acts with shape {model.action_shape}, {env_name} takes {action_space.shape}"
                )
        self.network = _NETWORKS.get(
            [self.path],
            (repr(observation_space), repr(action_space)),
            lambda: PolicyNetwork.from_state_dict(
                model.state, model.algo, {"activation_fn": model.activation}, observation_space, action_space
            ),
        )
        width = int(sum(int(np.prod(s.shape or (1,))) for s in _boxes(observation_space)))
        first = self.network.hidden[0][0] if self.network.hidden else self.network.output[0]
        if first.shape[1] != width:
            raise ValueError(
                f"{self.path}: the network takes {first.shape[1]} observation values, {env_name} gives {width}"
            )
        out = self.network.output[0].shape[0]
        want = (
            int(action_space.n) if isinstance(action_space, gym.spaces.Discrete) else int(np.prod(action_space.shape))
        )
        if out != want:
            raise ValueError(f"{self.path}: the network outputs {out} action values, {env_name} takes {want}")

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[np.ndarray, Any]:
        """SB3's ``predict(observation, deterministic=True)``, computed the same way on every CPU."""
        return self.network.predict(observation, state, episode_start, True)


def _boxes(space: gym.Space[Any]) -> list[gym.Space[Any]]:
    return list(space.spaces.values()) if isinstance(space, gym.spaces.Dict) else [space]
