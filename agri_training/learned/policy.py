"""Trained policies, loaded weights-only and evaluated exactly like the scripted baselines.

A run directory written by ``agri train`` (see :mod:`agri_training.train`) holds everything needed to
rebuild a policy without unpickling anything:

| file | content |
|---|---|
| ``config.yaml`` | the resolved training config: env id and arguments, algorithm, policy, wrappers |
| ``policy.pt`` | the acting layers' ``state_dict`` (older runs: all), read with ``torch.load(weights_only=True)`` |
| ``normalize.json`` | the ``VecNormalize`` observation statistics (mean, variance, clip), when used |

:class:`LearnedPolicy` exports the acting layers of the weights to :class:`~agri_training.inference.
PolicyNetwork` (a forward pass that computes the same bits on every CPU, so that leaderboard entries
reproduce anywhere), and replays the training wrappers and the normalisation on each observation, so that
it implements SB3's ``predict`` on the env's raw observations, like every baseline. Checkpoints that need
unpickling (pickle files, tensors stored with code) are refused with a clear message; SB3 ``.zip`` files are read
without unpickling by :mod:`agri_training.learned.sb3_zip`.
"""

from __future__ import annotations

import collections
import dataclasses
import importlib
import json
import pickle
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

import agri_envs
from agri_training.core.filecache import FileCache
from agri_training.learned.arm_observation import NearestBoxes
from agri_training.learned.goal_zoom import GoalZoom
from agri_training.learned.homing import JointHoming
from agri_training.learned.inference import PolicyNetwork
from agri_training.learned.parameter_sharing import predict_shared
from agri_training.learned.range_features import Differences, Ramp
from agri_training.learned.robot_limits import RobotLimits
from agri_training.learned.safety import make_safety_layer
from agri_training.learned.slam_pose import SlamWaypoint

#: Algorithms ``agri train`` knows: name -> (module, class).
ALGORITHMS: dict[str, tuple[str, str]] = {
    "ppo": ("stable_baselines3", "PPO"),
    "sac": ("stable_baselines3", "SAC"),
    "td3": ("stable_baselines3", "TD3"),
    "tqc": ("sb3_contrib", "TQC"),
}
#: Activation functions a config may name in ``policy_kwargs.activation_fn``.
ACTIVATIONS = ("ReLU", "Tanh", "ELU", "LeakyReLU", "SiLU", "GELU")
CONFIG_FILE = "config.yaml"
WEIGHTS_FILE = "policy.pt"
NORMALIZE_FILE = "normalize.json"


class ActionRepeat(gym.Wrapper[Any, Any, Any, Any]):
    """Apply each action for ``repeat`` env steps (a policy acting at 1 / repeat of the env's rate).

    The reward is the sum over the held steps; the episode ends as soon as one of them ends it.
    """

    def __init__(self, env: gym.Env[Any, Any], repeat: int) -> None:
        if repeat < 1:
            raise ValueError(f"action_repeat must be >= 1, got {repeat}")
        super().__init__(env)
        self.repeat = repeat

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Step the env up to ``repeat`` times with ``action``."""
        total = 0.0
        for _ in range(self.repeat):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        return obs, total, terminated, truncated, info


class HeldActions:
    """The evaluation side of :class:`ActionRepeat`: ask the network every ``repeat`` steps, hold its action.

    ``episode_start`` (as the evaluator passes it) restarts the count, so episode i is driven the same way
    whatever ran before it.
    """

    def __init__(self, repeat: int) -> None:
        if repeat < 1:
            raise ValueError(f"action_repeat must be >= 1, got {repeat}")
        self.repeat = repeat
        self._count = 0
        self._held: tuple[np.ndarray, Any] | None = None
        #: Whether the last call asked the network (False: it held the action).
        self.decided = False

    def __call__(self, decide: Any, episode_start: Any) -> tuple[np.ndarray, Any]:
        """The held action, or ``decide()`` when it is time for a new one."""
        if episode_start is not None and bool(np.asarray(episode_start).any()):
            self._count = 0
        self.decided = self._held is None or self._count % self.repeat == 0
        if self.decided:
            self._held = decide()
        self._count += 1
        assert self._held is not None
        return self._held


class ObservationHistory(gym.ObservationWrapper[np.ndarray, Any, np.ndarray]):
    """The last ``frames`` (flat) observations side by side, oldest first: motion the network can see.

    One scan cannot tell a person who stands in the robot's way from one who walks off; two scans a
    decision apart can. Put it after ``FlattenObservation`` (and after ``ActionRepeat`` in training, so the
    frames are one decision apart). A new episode fills every slot with its first observation.
    :class:`LearnedPolicy` replays it once per decision and clears it when an episode starts.
    """

    def __init__(self, env: gym.Env[Any, Any], frames: int = 2) -> None:
        space = env.observation_space
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ValueError(f"ObservationHistory needs a flat Box observation (FlattenObservation first), got {space}")
        if int(frames) < 1:
            raise ValueError(f"ObservationHistory frames must be >= 1, got {frames}")
        super().__init__(env)
        self.frames = int(frames)
        self.observation_space = gym.spaces.Box(
            np.tile(space.low, self.frames), np.tile(space.high, self.frames), dtype=space.dtype
        )
        self._history: collections.deque[np.ndarray] = collections.deque(maxlen=self.frames)

    def clear(self) -> None:
        """Forget the history (the next observation starts a new episode)."""
        self._history.clear()

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the env and fill the history with its first observation."""
        self.clear()
        return super().reset(**kwargs)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """Push ``observation`` and return the stacked history."""
        obs = np.asarray(observation)
        if not self._history:
            self._history.extend([obs] * self.frames)
        else:
            self._history.append(obs)
        return np.concatenate(self._history).astype(self.observation_space.dtype, copy=False)


def proximity_space(space: gym.spaces.Dict, lengths: Mapping[str, float]) -> gym.spaces.Dict:
    """``space`` with a ``<key>_proximity`` Box beside each range key of ``lengths`` (see :class:`Proximity`).

    Raises:
        ValueError: For a space that is not a Dict, a key it lacks or that is not a non-negative Box, or a
            length that is not positive.
    """
    if not isinstance(space, gym.spaces.Dict):
        raise ValueError(f"Proximity needs a Dict observation (put it before FlattenObservation), got {space}")
    if not lengths:
        raise ValueError("Proximity needs at least one key: {key: length}")
    spaces = dict(space.spaces)
    for key, length in lengths.items():
        box = spaces.get(key)
        if not isinstance(box, gym.spaces.Box) or not np.all(box.low >= 0.0):
            raise ValueError(f"Proximity: {key!r} must be a Box of ranges (>= 0) in {list(spaces)}")
        if not float(length) > 0.0:
            raise ValueError(f"Proximity: the length of {key!r} must be > 0, got {length}")
        x = np.float32(length)
        spaces[f"{key}_proximity"] = gym.spaces.Box(
            (x / (x + box.high.astype(np.float32))), (x / (x + box.low.astype(np.float32))), dtype=np.float32
        )
    return gym.spaces.Dict(spaces)


def add_proximity(observation: Mapping[str, Any], lengths: Mapping[str, float]) -> dict[str, Any]:
    """``observation`` with ``<key>_proximity = length / (length + range)`` beside each key of ``lengths``.

    Works on one observation or a batch alike; float32 division and addition only, so every CPU and every
    batch size computes the same bits.
    """
    out = dict(observation)
    for key, length in lengths.items():
        x = np.float32(length)
        out[f"{key}_proximity"] = x / (x + np.asarray(observation[key], dtype=np.float32))
    return out


class Proximity(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """Range keys read again as proximity, ``length / (length + range)``: resolution where obstacles are near.

    A range scaled to [0, 1] by the sensor's reach (GreenhouseNav's LIDAR: 10 m) spends 0.035 of its span
    on the 35 cm in front of the body in which harik-apf-gt's safety stop acts, and normalisation keeps that
    spread small beside the metres of a free corridor. The proximity of a range key rises from
    ``length / (1 + length)`` far away to 1 at contact, and halves at ``range == length`` (in the key's
    units). The range keys stay as they are; each gains a ``<key>_proximity`` key beside it. Stateless.
    Put it before ``FlattenObservation``; in a config: ``{Proximity: {lidar: 0.05, sonar: 0.1}}``.

    Raises:
        ValueError: See :func:`proximity_space`.
    """

    def __init__(self, env: gym.Env[Any, Any], **lengths: float) -> None:
        space = proximity_space(env.observation_space, lengths)  # type: ignore[arg-type]
        super().__init__(env)
        self.lengths = {key: float(length) for key, length in lengths.items()}
        self.observation_space = space

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with its proximity keys."""
        return add_proximity(observation, self.lengths)


#: Observation wrappers a config may declare (by name; nothing is imported from a string).
WRAPPERS: dict[str, type[gym.ObservationWrapper[Any, Any, Any]]] = {
    "FlattenObservation": gym.wrappers.FlattenObservation,
    "FilterObservation": gym.wrappers.FilterObservation,
    "ObservationHistory": ObservationHistory,
    "NearestBoxes": NearestBoxes,
    "Proximity": Proximity,
    "Differences": Differences,
    "Ramp": Ramp,
    "SlamWaypoint": SlamWaypoint,
    "RobotLimits": RobotLimits,
}


#: Wrappers that remember the episode (cleared by :class:`ObservationReplay` when one starts).
EPISODE_MEMORY = (ObservationHistory, SlamWaypoint)


class UnsafeCheckpointError(ValueError):
    """A checkpoint that can only be read by unpickling it (which could run arbitrary code)."""


def algorithm_class(name: str) -> Any:
    """The SB3 (or sb3-contrib) algorithm class for ``ppo``, ``sac``, ``td3`` or ``tqc``.

    Raises:
        ValueError: For an unknown name, or when sb3-contrib is missing for TQC.
    """
    if name not in ALGORITHMS:
        raise ValueError(f"algo must be one of {', '.join(ALGORITHMS)}, got {name!r}")
    module, attr = ALGORITHMS[name]
    try:
        return getattr(importlib.import_module(module), attr)
    except ImportError as exc:
        raise ValueError(f"algo {name!r} needs {module}: pip install -e '.[train]'") from exc


def wrap_by_name(
    env: Any,
    wrappers: Sequence[str | Mapping[str, Any]],
    allowed: Mapping[str, Callable[..., Any]],
    kind: str = "wrapper",
) -> Any:
    """Wrap ``env`` in wrappers declared by name, innermost first; only names in ``allowed`` are built.

    Args:
        env: The env (or vector env) to wrap.
        wrappers: Names from ``allowed``, or one-key mappings ``{name: {kwarg: value}}``.
        allowed: The allow-list, name -> wrapper class or factory (nothing is imported from a string).
        kind: What the list holds, for error messages.

    Raises:
        ValueError: For a name that is not allowed, or an entry that is neither a name nor a one-key mapping.
    """
    for item in wrappers:
        kwargs: dict[str, Any] = {}
        if isinstance(item, str):
            name = item
        elif isinstance(item, Mapping) and len(item) == 1:
            name, given = next(iter(item.items()))
            kwargs = dict(given or {})
        else:
            raise ValueError(f"a {kind} is a name or a one-key mapping {{name: kwargs}}, got {item!r}")
        if name not in allowed:
            raise ValueError(f"{kind} {name!r} is not allowed; allowed: {', '.join(allowed)}")
        env = allowed[name](env, **kwargs)
    return env


def apply_wrappers(env: gym.Env[Any, Any], wrappers: Sequence[str | Mapping[str, Any]]) -> gym.Env[Any, Any]:
    """Wrap ``env`` in the declared observation wrappers (names from :data:`WRAPPERS`), innermost first.

    Raises:
        ValueError: For a wrapper that is not in :data:`WRAPPERS`, or a malformed entry.
    """
    wrapped: gym.Env[Any, Any] = wrap_by_name(env, wrappers, WRAPPERS)
    return wrapped


def observation_chain(
    env: gym.Env[Any, Any], wrappers: Sequence[str | Mapping[str, Any]]
) -> tuple[gym.Env[Any, Any], list[gym.ObservationWrapper[Any, Any, Any]]]:
    """The env wrapped as declared, and its observation wrappers innermost first (to replay on raw obs)."""
    wrapped = apply_wrappers(env, wrappers)
    chain: list[gym.ObservationWrapper[Any, Any, Any]] = []
    layer: gym.Env[Any, Any] = wrapped
    while isinstance(layer, gym.ObservationWrapper):
        chain.append(layer)
        layer = layer.env
    return wrapped, chain[::-1]


def schedule(value: Any) -> Any:
    """``lin_X`` -> a linear decay from X to 0 (rl-zoo3's notation); numbers pass through."""
    if isinstance(value, str) and value.startswith("lin_"):
        start = float(value[4:])

        def linear(progress_remaining: float) -> float:
            return progress_remaining * start

        return linear
    return value


def resolve_algo_kwargs(algo_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """Config ``algo_kwargs`` with schedules given as ``lin_X`` turned into functions (see :func:`schedule`)."""
    return {key: schedule(value) for key, value in algo_kwargs.items()}


def resolve_policy_kwargs(policy_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """Config ``policy_kwargs`` with ``activation_fn`` and ``features_extractor_class`` named, turned into classes.

    Raises:
        ValueError: For an activation that is not in :data:`ACTIVATIONS`, or a features extractor that is not
            in :data:`agri_training.learned.extractors.EXTRACTORS`.
    """
    out = dict(policy_kwargs)
    if "activation_fn" in out:
        import torch

        name = out["activation_fn"]
        if name not in ACTIVATIONS:
            raise ValueError(f"policy_kwargs.activation_fn must be one of {', '.join(ACTIVATIONS)}, got {name!r}")
        out["activation_fn"] = getattr(torch.nn, name)
    if "features_extractor_class" in out:
        from agri_training.learned.extractors import EXTRACTORS  # needs torch: only where a policy is built

        name = out["features_extractor_class"]
        if name not in EXTRACTORS:
            raise ValueError(
                f"policy_kwargs.features_extractor_class must be one of {', '.join(EXTRACTORS)}, got {name!r}"
            )
        out["features_extractor_class"] = EXTRACTORS[name]
    return out


def load_weights(path: Path) -> dict[str, Any]:
    """A ``state_dict`` read with ``torch.load(weights_only=True)``: tensors only, nothing is executed.

    Raises:
        UnsafeCheckpointError: When the file holds anything but plain tensors and containers (it would
            need unpickling, which can run code).
    """
    import torch

    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, AttributeError, TypeError) as exc:
        raise UnsafeCheckpointError(
            f"{path} cannot be loaded weights-only (it needs unpickling, which could run code), so it is refused: "
            f"{str(exc).splitlines()[0]}"
        ) from None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise UnsafeCheckpointError(f"{path} is not a state_dict of tensors")
    return state


@dataclasses.dataclass(frozen=True)
class ObsNormalization:
    """``VecNormalize``'s observation normalisation, as plain arrays (saved as JSON, not pickled).

    Attributes:
        mean: Running mean per observation key (``""`` for a non-dict observation).
        var: Running variance per key.
        clip_obs: Normalised observations are clipped to ``[-clip_obs, clip_obs]``.
        epsilon: Added to the variance before the square root.
    """

    mean: Mapping[str, np.ndarray]
    var: Mapping[str, np.ndarray]
    clip_obs: float
    epsilon: float

    def normalize(self, obs: Any) -> Any:
        """Normalise one (dict or array) observation as ``VecNormalize.normalize_obs`` does."""
        if isinstance(obs, Mapping):
            out = dict(obs)
            for key in self.mean:
                out[key] = self._one(np.asarray(obs[key]), key)
            return out
        return self._one(np.asarray(obs), "")

    def _one(self, x: np.ndarray, key: str) -> np.ndarray:
        z = (x - self.mean[key]) / np.sqrt(self.var[key] + self.epsilon)
        return np.clip(z, -self.clip_obs, self.clip_obs).astype(np.float32)

    @classmethod
    def from_vec_normalize(cls, venv: Any) -> ObsNormalization | None:
        """The statistics of a live ``VecNormalize`` (None when it does not normalise observations)."""
        if not venv.norm_obs:
            return None
        rms = venv.obs_rms
        if isinstance(rms, dict):
            keys = list(venv.norm_obs_keys)
            mean = {k: np.array(rms[k].mean, dtype=np.float64) for k in keys}
            var = {k: np.array(rms[k].var, dtype=np.float64) for k in keys}
        else:
            mean, var = {"": np.array(rms.mean, dtype=np.float64)}, {"": np.array(rms.var, dtype=np.float64)}
        return cls(mean=mean, var=var, clip_obs=float(venv.clip_obs), epsilon=float(venv.epsilon))

    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict."""
        return {
            "mean": {k: v.tolist() for k, v in self.mean.items()},
            "var": {k: v.tolist() for k, v in self.var.items()},
            "clip_obs": self.clip_obs,
            "epsilon": self.epsilon,
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ObsNormalization:
        """Inverse of :meth:`to_json`."""
        return cls(
            mean={k: np.asarray(v, dtype=np.float64) for k, v in data["mean"].items()},
            var={k: np.asarray(v, dtype=np.float64) for k, v in data["var"].items()},
            clip_obs=float(data["clip_obs"]),
            epsilon=float(data["epsilon"]),
        )


class ObservationReplay:
    """The training's observation path replayed on raw env observations: the wrappers, then normalisation.

    Call it once per decision (as the network saw observations in training). Wrappers with a memory of the
    episode (a ``clear`` method: :class:`ObservationHistory`, :class:`~agri_training.learned.slam_pose.
    SlamWaypoint`) are cleared when ``new_episode`` is true.

    Args:
        chain: Observation wrappers, innermost first (:func:`observation_chain`).
        normalization: ``VecNormalize``'s observation statistics, or None.
    """

    def __init__(
        self, chain: Sequence[gym.ObservationWrapper[Any, Any, Any]], normalization: ObsNormalization | None = None
    ) -> None:
        self.chain = list(chain)
        self.normalization = normalization

    def __call__(self, observation: Any, new_episode: bool = False) -> Any:
        """``observation`` as the network saw it in training."""
        for w in self.chain:
            if new_episode and isinstance(w, EPISODE_MEMORY):
                w.clear()
            observation = w.observation(observation)
        if self.normalization is not None:
            observation = self.normalization.normalize(observation)
        return observation

    def see(self, observation: Any) -> None:
        """A raw observation of a step whose action is held, for the wrappers that read every scan."""
        for w in self.chain:
            if isinstance(w, SlamWaypoint):
                w.see(observation)


def find_run_dir(path: Path) -> Path:
    """The run directory whose ``config.yaml`` applies to ``path`` (the folder itself or a parent)."""
    for folder in (path, *path.parents):
        if (folder / CONFIG_FILE).is_file():
            return folder
    raise ValueError(f"{path} is not inside an `agri train` run directory (no {CONFIG_FILE} found)")


def read_config(path: Path) -> dict[str, Any]:
    """The resolved training config of the run that ``path`` (a run folder or checkpoint folder) belongs to."""
    return dict(yaml.safe_load((find_run_dir(path) / CONFIG_FILE).read_text()))


def with_wrapper_settings(
    wrappers: Sequence[str | Mapping[str, Any]], settings: Mapping[str, Mapping[str, Any]]
) -> list[str | dict[str, Any]]:
    """A config's ``wrappers`` with some wrappers' arguments changed: ``{name: {argument: value}}``.

    Raises:
        ValueError: For a name that is not among the wrappers.
    """
    names = [w if isinstance(w, str) else next(iter(w)) for w in wrappers]
    unknown = sorted(set(settings) - set(names))
    if unknown:
        raise ValueError(f"wrapper settings for {unknown}, which the run does not use (its wrappers: {names})")
    out: list[str | dict[str, Any]] = []
    for name, entry in zip(names, wrappers, strict=True):
        arguments = {} if isinstance(entry, str) else dict(entry[name] or {})
        out.append({name: {**arguments, **settings[name]}} if name in settings else entry)  # type: ignore[arg-type]
    return out


def is_run_path(name_or_path: str) -> bool:
    """True when ``name_or_path`` names a folder holding (or inside) a run directory."""
    p = Path(name_or_path)
    return p.is_dir() and any((f / CONFIG_FILE).is_file() for f in (p, *p.parents))


def refuse_pickled(name_or_path: str) -> None:
    """Raise for checkpoint formats that can only be loaded by unpickling.

    Raises:
        UnsafeCheckpointError: For pickle files (``.pkl``, ``.pickle``).
    """
    if name_or_path.endswith((".pkl", ".pickle")):
        raise UnsafeCheckpointError(
            f"{name_or_path}: pickle checkpoints are not loaded, because unpickling can run code. Pass an "
            "`agri train` run directory (weights only), an SB3 model.zip (read without unpickling) or an ONNX file."
        )


#: Networks and observation statistics read in this process, by folder, file stamps, config and spaces.
#: Runs' acting networks and observation statistics (:func:`_network_of`).
_NETWORKS: FileCache[tuple[PolicyNetwork, ObsNormalization | None]] = FileCache()


def _network_of(
    folder: Path, config: Mapping[str, Any], observation_space: gym.Space[Any], action_space: gym.Space[Any]
) -> tuple[PolicyNetwork, ObsNormalization | None]:
    """A run's acting network and observation statistics, read once per process while its files are unchanged.

    Both are immutable, so the fresh policy of every episode shares them (reading the weights takes
    milliseconds, and a batch of episodes builds a policy each); what a policy keeps of an episode (its
    observation history, its held action) is its own.
    """
    weights, norm = folder / WEIGHTS_FILE, folder / NORMALIZE_FILE

    def make() -> tuple[PolicyNetwork, ObsNormalization | None]:
        network = PolicyNetwork.from_state_dict(
            load_weights(weights), config["algo"], config.get("policy_kwargs", {}), observation_space, action_space
        )
        normalization = ObsNormalization.from_json(json.loads(norm.read_text())) if norm.is_file() else None
        return network, normalization

    extra = (repr(sorted(config.items())), repr(observation_space), repr(action_space))
    return _NETWORKS.get([weights, norm], extra, make)


class LearnedPolicy:
    """A trained policy rebuilt weights-only from a run (or checkpoint) folder; SB3's ``predict`` on raw obs.

    Args:
        path: A run directory, its ``best/`` folder or one of its ``checkpoints/step_N`` folders.
        env: The env the policy will drive (made with the run's env arguments); used for its spaces. A
            PettingZoo parallel env (the robot chain) gets the parameter-shared policy of the run.
        goal_zoom: A goal-conditioned arm policy's :class:`~agri_training.learned.goal_zoom.GoalZoom`, between
            the env and the network (one env at a time, decisions every step), or None.
        homing: Whether the arm drives its last stretch home along the joint line
            (:class:`~agri_training.learned.homing.JointHoming`, replacing the network's action there); it needs
            what a goal zoom needs (one goal-conditioned env, a decision every step) and end-effector control.
        wrapper_settings: Deployment settings that change some of the run's observation wrappers' arguments,
            ``{name: {argument: value}}`` (:func:`with_wrapper_settings`), such as ``{"SlamWaypoint": {"odometry":
            True}}``; the network is the run's.

    Raises:
        ValueError: When the folder or the config is not a run's, or the env's spaces do not match.
        UnsafeCheckpointError: When the weights need unpickling.
    """

    def __init__(
        self,
        path: str | Path,
        env: Any,
        goal_zoom: GoalZoom | None = None,
        homing: bool = False,
        wrapper_settings: Mapping[str, Mapping[str, Any]] | None = None,
    ) -> None:
        folder = Path(path)
        self.config = read_config(folder)
        if wrapper_settings:
            self.config["wrappers"] = with_wrapper_settings(self.config.get("wrappers", []), wrapper_settings)
        self.folder = folder
        #: True on a PettingZoo parallel env: one shared network acts for every agent (per-agent dicts).
        self.multiagent = agri_envs.is_parallel_env(env)
        chain: list[gym.ObservationWrapper[Any, Any, Any]] = []
        if self.multiagent:
            if self.config.get("wrappers"):
                raise ValueError(f"{folder}: a multi-agent run has no observation wrappers")
            agent = env.possible_agents[0]
            observation_space, action_space = env.observation_space(agent), env.action_space(agent)
        else:
            # The training wrappers, rebuilt around the env only to transform its observations the same way.
            wrapped, chain = observation_chain(env, self.config.get("wrappers", []))
            observation_space, action_space = wrapped.observation_space, env.action_space
        weights = folder / WEIGHTS_FILE
        if not weights.is_file():
            raise ValueError(f"{folder} holds no {WEIGHTS_FILE}")
        #: The acting network, evaluated the same way on every CPU (:mod:`agri_training.inference`).
        self.network, self.normalization = _network_of(folder, self.config, observation_space, action_space)
        self._replay = ObservationReplay(chain, self.normalization)
        self._hold = HeldActions(int(self.config.get("action_repeat", 1)))
        #: The run's safety layer (``safety_layer`` in its config), between the network and the robot, or None.
        self.safety = make_safety_layer(self.config.get("safety_layer"), env, self.config["env_id"])
        layers = "a goal zoom or joint homing"
        if (goal_zoom is not None or homing) and not _has_goals(env):
            raise ValueError(f"{folder}: {layers} needs an env that observes achieved_goal and desired_goal")
        if (goal_zoom is not None or homing) and (self.multiagent or self._hold.repeat != 1):
            raise ValueError(f"{folder}: {layers} needs a single-agent run deciding every step")
        #: The goal zoom between the env and the network, or None.
        self.zoom = goal_zoom
        #: The joint homing that replaces the network's action on the last stretch home, or None.
        self.homing = JointHoming.for_env(env) if homing else None

    def transform(self, observation: Any, new_episode: bool = False) -> Any:
        """The raw env observation as the network saw it in training (wrappers, then normalisation)."""
        return self._replay(observation, new_episode)

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[Any, Any]:
        """SB3's ``predict`` on the env's raw (unwrapped, unnormalised) observation.

        On a multi-agent env the observation is the per-agent dict of one step, and so are the actions. A
        run trained with ``action_repeat`` k holds each action for k calls, as in training.
        """
        if self.multiagent:
            return predict_shared(self.network, observation, self.transform, deterministic), state
        if self.zoom is None and self.homing is None:
            action, state = decide_held(
                self._hold, self._replay, self.network, observation, state, episode_start, deterministic
            )
            return guarded(self.safety, observation, action, episode_start), state
        if np.ndim(observation["desired_goal"]) != 1:
            shape = np.shape(observation["desired_goal"])
            raise ValueError(f"a goal zoom or joint homing acts on one env at a time, got {shape}")
        start = episode_start is not None and bool(np.asarray(episode_start).any())
        seen, factors = (observation, (1.0, 1.0)) if self.zoom is None else self.zoom.observe(observation, start)
        action, state = decide_held(self._hold, self._replay, self.network, seen, state, episode_start, deterministic)
        if self.zoom is not None:
            action = self.zoom.act(action, factors)
        if self.homing is not None:
            action = self.homing.decide(observation, action, start)
        return guarded(self.safety, observation, action, episode_start), state

    def episode_metrics(self, index: int = 0) -> dict[str, float]:
        """The safety layer's, the goal zoom's and the joint homing's counts of the episode (none without them)."""
        return {
            **({} if self.safety is None else self.safety.episode_metrics()),
            **({} if self.zoom is None else self.zoom.episode_metrics()),
            **({} if self.homing is None else self.homing.episode_metrics()),
        }


def _has_goals(env: Any) -> bool:
    """The env observes ``achieved_goal`` and ``desired_goal`` (a goal-conditioned env, as HER needs)."""
    spaces = getattr(env.observation_space, "spaces", {})
    return "achieved_goal" in spaces and "desired_goal" in spaces


def guarded(safety: Any, observation: Any, action: Any, episode_start: Any) -> Any:
    """``action`` through the safety layer ``safety`` (None: as it is), for one env's observation.

    Raises:
        ValueError: For a batch of observations (a layer keeps one robot's safety state).
    """
    if safety is None:
        return action
    if np.ndim(action) != 1:
        raise ValueError(f"a run with safety_layer {safety.name!r} acts on one env at a time, got {np.shape(action)}")
    return safety.apply(observation, action, episode_start is not None and bool(np.asarray(episode_start).any()))


def decide_held(
    hold: HeldActions,
    replay: ObservationReplay,
    model: Any,
    observation: Any,
    state: Any,
    episode_start: Any,
    deterministic: bool,
) -> tuple[Any, Any]:
    """One step of a single-agent learned policy: the held action, or the network's on a decision step.

    The observation goes through ``replay`` only on decision steps, as it did once per decision in training;
    on the others the wrappers that read every scan see it (:meth:`ObservationReplay.see`).
    """
    new_episode = episode_start is not None and bool(np.asarray(episode_start).any())

    def decide() -> tuple[Any, Any]:
        return model.predict(replay(observation, new_episode), state, episode_start, deterministic)

    result = hold(decide, episode_start)
    if not hold.decided:
        replay.see(observation)
    return result
