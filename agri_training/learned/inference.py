"""Acting with a trained network so that every x86-64 CPU computes the same bits.

Torch's float32 CPU kernels (MKL, oneDNN, its own vectorised loops) pick their instruction set, blocking
and summation order from the CPU they run on, so a policy evaluated on two machines drifts apart in the
last bits of its actions, and over a long episode the trajectories part (one leaderboard episode ran 407
steps on one machine and 408 on another). Training keeps torch; acting does not use it.

:class:`PolicyNetwork` is the deterministic-action path of an SB3 policy (PPO's mean action, SAC's and
TQC's squashed mean, TD3's actor), exported to float64 numpy arrays and evaluated with these rules, each
of which makes the result a function of the inputs alone:

- Only numpy's element-wise ``+``, ``-``, ``*``, ``/``, ``sqrt``, ``maximum``, ``minimum``, ``where``,
  ``rint`` and ``ldexp``. IEEE 754 rounds each of them correctly, so a SIMD lane (SSE, AVX2, AVX-512)
  computes the same bits as a scalar instruction; and no two of them can be fused into a multiply-add,
  because each numpy call materialises its rounded result.
- No BLAS: a matrix-vector product is the element-wise products followed by a fixed pairwise fold over
  the inputs (:func:`fold_sum`), the same order on every machine whatever its threads or cache sizes.
- No libm: ``exp`` (and with it ``tanh``, ``ELU``, ``SiLU``) is our own range reduction and polynomial
  (:func:`exp`), because glibc's and numpy's ``exp`` and ``tanh`` dispatch on the CPU (FMA and AVX-512
  variants that differ in the last bit).

Float64 throughout leaves the result within float32 rounding of torch's forward pass (tested), so the
network acts as trained. The observation is rounded to float32 first, as SB3 feeds it to torch. A features
extractor other than SB3's flattening is covered when it follows the same rules: the goal-error features of
:mod:`agri_training.learned.goal_features` (``features_extractor_class: GoalErrorExtractor``).

The functions below (:func:`fold_sum`, :func:`linear`, :func:`exp`, :func:`tanh` and the activations) state
these rules in numpy and are the reference. The network runs them compiled (:func:`dense_layer`, numba): the
same operations on the same operands in the same order, one row at a time, where numpy pays its call
overhead once per operation (about 40 calls per layer; 0.3-0.5 ms a decision for the zoo's networks).
Numba rounds every ``+``, ``-``, ``*`` and ``/`` as IEEE 754 says and forms no fused multiply-adds without
``fastmath``, so the two give the same bits; the tests compare them on random and special values and on
every zoo network.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numba
import numpy as np

from agri_training.learned.goal_features import GOAL_ERROR, GOAL_LENGTH, goal_error_features

#: Default activation of each algorithm's policy in SB3 (``policy_kwargs.activation_fn`` overrides it).
DEFAULT_ACTIVATION = {"ppo": "Tanh", "sac": "ReLU", "td3": "ReLU", "tqc": "ReLU"}
#: Where each algorithm keeps its acting layers in the ``state_dict``: (hidden layers, output layer); TD3's
#: actor is one ``nn.Sequential`` whose last linear layer is the output.
ACTOR_LAYERS = {
    "ppo": ("mlp_extractor.policy_net", "action_net"),
    "sac": ("actor.latent_pi", "actor.mu"),
    "tqc": ("actor.latent_pi", "actor.mu"),
    "td3": ("actor.mu", None),
}

#: What each algorithm's ``state_dict`` holds only to learn, never to act: the value network or the critics and
#: target networks. :func:`acting_state` leaves them out of the weights a run writes.
LEARNING_ONLY = {
    "ppo": ("mlp_extractor.value_net.", "value_net.", "vf_features_extractor."),
    "sac": ("critic.", "critic_target."),
    "tqc": ("critic.", "critic_target."),
    "td3": ("critic.", "critic_target.", "actor_target."),
}


def acting_state(state: Mapping[str, Any], algo: str) -> dict[str, Any]:
    """``state`` without what only learning reads (:data:`LEARNING_ONLY`; an unknown algorithm keeps everything).

    The acting layers (:data:`ACTOR_LAYERS`), a PPO policy's ``log_std`` and SAC's ``actor.log_std`` stay, so
    :meth:`PolicyNetwork.from_state_dict` exports the same network from it as from the whole ``state_dict``.
    """
    dropped = LEARNING_ONLY.get(algo, ())
    return {k: v for k, v in state.items() if not k.startswith(dropped)}


_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that k * _LN2_HI is exact for |k| < 2**20 (fdlibm)
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
#: 1/n! for n = 0..13: |r| <= ln2 / 2 leaves a Taylor remainder below 1e-17 relative.
_EXP_TAYLOR = tuple(1.0 / float(np.prod(np.arange(1, n + 1, dtype=np.float64))) for n in range(14))


def fold_sum(terms: np.ndarray) -> np.ndarray:
    """Sum over the last axis in a fixed order: fold the halves onto each other until one term is left.

    With ``n`` terms and ``h = n // 2``, term ``i < h`` becomes ``t[i] + t[h + i]``; an odd last term is
    carried over unchanged. The order depends on ``n`` only.
    """
    t = np.asarray(terms, dtype=np.float64)
    while t.shape[-1] > 1:
        n = t.shape[-1]
        h = n // 2
        folded = t[..., :h] + t[..., h : 2 * h]
        t = np.concatenate([folded, t[..., 2 * h :]], axis=-1) if n % 2 else folded
    return t[..., 0]


def linear(x: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """``x @ weight.T + bias`` for a ``(batch, n_in)`` input without BLAS (:func:`fold_sum` order)."""
    products = x[:, None, :] * weight[None, :, :]
    return fold_sum(products) + bias


def exp(x: np.ndarray) -> np.ndarray:
    """``e**x`` in float64 from correctly rounded operations only (same bits on every CPU).

    ``x = k ln2 + r`` with ``|r| <= ln2 / 2`` (Cody and Waite's two-part ln 2, exact for the ``k`` that
    occur), a degree-13 Taylor polynomial of ``e**r`` by Horner's rule, then ``ldexp`` (exact). Inputs are
    clipped to ``[-700, 700]``; relative error about 1e-16 (tested against ``math.exp``).
    """
    x = np.clip(np.asarray(x, dtype=np.float64), -700.0, 700.0)
    k = np.rint(x * _INV_LN2)
    r = (x - k * _LN2_HI) - k * _LN2_LO
    p = np.full_like(r, _EXP_TAYLOR[-1])
    for c in _EXP_TAYLOR[-2::-1]:
        p = p * r + c
    return np.ldexp(p, k.astype(np.int64))


def tanh(x: np.ndarray) -> np.ndarray:
    """``tanh(x) = sign(x) (1 - 2 / (e**(2|x|) + 1))`` on :func:`exp`; absolute error about 1e-16."""
    x = np.asarray(x, dtype=np.float64)
    a = np.minimum(np.abs(x), 40.0)  # tanh(40) is 1 in float64
    t = 1.0 - 2.0 / (exp(2.0 * a) + 1.0)
    return np.where(x < 0, -t, t)


def _relu(x: np.ndarray) -> np.ndarray:
    return np.maximum(x, 0.0)


def _leaky_relu(x: np.ndarray) -> np.ndarray:
    return np.where(x >= 0, x, 0.01 * x)  # torch's default negative_slope


def _elu(x: np.ndarray) -> np.ndarray:
    return np.where(x > 0, x, exp(np.minimum(x, 0.0)) - 1.0)


def _silu(x: np.ndarray) -> np.ndarray:
    return x / (1.0 + exp(-x))


#: Activations with a CPU-independent implementation, by torch class name.
ACTIVATION_FUNCTIONS = {"ReLU": _relu, "Tanh": tanh, "LeakyReLU": _leaky_relu, "ELU": _elu, "SiLU": _silu}
#: The compiled layer's code of each activation (0: none, the output layer).
ACTIVATION_CODES = {"ReLU": 1, "Tanh": 2, "LeakyReLU": 3, "ELU": 4, "SiLU": 5}
_TAYLOR = np.array(_EXP_TAYLOR)


# ---- the same operations, compiled: one scalar at a time, in the order of the numpy functions above -------


@numba.njit(cache=True)
def _exp_scalar(x: float) -> float:
    """:func:`exp` of one value: ``np.clip`` (NaN stays NaN), ``np.rint``, the same Horner steps, ``np.ldexp``."""
    if x != x:
        return x
    x = -700.0 if x < -700.0 else (700.0 if x > 700.0 else x)
    k = np.rint(x * _INV_LN2)
    r = (x - k * _LN2_HI) - k * _LN2_LO
    p = _TAYLOR[13]
    for i in range(12, -1, -1):
        p = p * r + _TAYLOR[i]
    return math.ldexp(p, int(k))


@numba.njit(cache=True)
def _activate(v: float, code: int) -> float:
    """One value through the activation of ``code`` (:data:`ACTIVATION_CODES`), as its numpy function computes it."""
    if code == 1:  # np.maximum(x, 0.0): NaN propagates, -0.0 becomes +0.0
        return v if (v > 0.0 or v != v) else 0.0
    if code == 2:  # tanh: np.minimum(np.abs(x), 40.0) propagates NaN like the comparison below
        a = abs(v)
        a = 40.0 if a > 40.0 else a
        t = 1.0 - 2.0 / (_exp_scalar(2.0 * a) + 1.0)
        return -t if v < 0 else t
    if code == 3:
        return v if v >= 0 else 0.01 * v
    if code == 4:  # exp(np.minimum(x, 0.0)) - 1.0 where x <= 0: the sign of a zero does not change exp's result
        return v if v > 0 else _exp_scalar(v if v < 0.0 or v != v else 0.0) - 1.0
    if code == 5:
        return v / (1.0 + _exp_scalar(-v))
    return v


@numba.njit(cache=True)
def dense_layer(x: np.ndarray, weight: np.ndarray, bias: np.ndarray, code: int) -> np.ndarray:
    """``activation(linear(x, weight, bias))`` compiled, bit for bit (:data:`ACTIVATION_CODES`; 0: none).

    Each output is the products of :func:`linear`, folded in :func:`fold_sum`'s order in a scratch row (term
    ``i < h`` becomes ``t[i] + t[h + i]``, an odd last term moves to ``h``), plus the bias.
    """
    batch, n_in = x.shape
    n_out = weight.shape[0]
    out = np.empty((batch, n_out))
    terms = np.empty(n_in)
    for b in range(batch):
        for j in range(n_out):
            for k in range(n_in):
                terms[k] = x[b, k] * weight[j, k]
            n = n_in
            while n > 1:
                h = n // 2
                for i in range(h):
                    terms[i] = terms[i] + terms[h + i]
                if n % 2:
                    terms[h] = terms[2 * h]
                n = h + n % 2
            out[b, j] = _activate(terms[0] + bias[j], code)
    return out


def _sequential_layers(state: Mapping[str, np.ndarray], prefix: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``(weight, bias)`` pairs of an ``nn.Sequential`` stored under ``prefix``, in order."""
    pattern = re.compile(rf"^{re.escape(prefix)}\.(\d+)\.weight$")
    indices = sorted(int(m.group(1)) for key in state if (m := pattern.match(key)))
    return [(state[f"{prefix}.{i}.weight"], state[f"{prefix}.{i}.bias"]) for i in indices]


@dataclasses.dataclass(frozen=True)
class PolicyNetwork:
    """A trained policy's deterministic action, computed the same way on every CPU (module docstring).

    Attributes:
        hidden: ``(weight, bias)`` of each hidden layer, float64, each followed by ``activation``.
        output: ``(weight, bias)`` of the action layer (no activation).
        activation: Name in :data:`ACTIVATION_FUNCTIONS`.
        squash: ``tanh`` the output and map ``[-1, 1]`` onto the action bounds (SAC, TQC, TD3); otherwise
            clip the output to the bounds (PPO), as SB3's ``predict`` does.
        low: Lower action bounds (float64).
        high: Upper action bounds (float64).
        discrete: Discrete action space: the argmax of the output layer (PPO).
        obs_keys: Keys of a dict observation, concatenated in this order (SB3's ``CombinedExtractor``).
        obs_ndim: Dimensions of one observation (of the first key of a dict).
        goal_columns: Where ``achieved_goal`` and ``desired_goal`` start in the flattened observation when the
            network appends the goal-error features (``GoalErrorExtractor``); None for plain flattening.
    """

    hidden: tuple[tuple[np.ndarray, np.ndarray], ...]
    output: tuple[np.ndarray, np.ndarray]
    activation: str
    squash: bool
    low: np.ndarray
    high: np.ndarray
    discrete: bool = False
    obs_keys: tuple[str, ...] | None = None
    obs_ndim: int = 1
    goal_columns: tuple[int, int] | None = None

    @classmethod
    def from_state_dict(
        cls,
        state: Mapping[str, Any],
        algo: str,
        policy_kwargs: Mapping[str, Any],
        observation_space: gym.Space[Any],
        action_space: gym.Space[Any],
    ) -> PolicyNetwork:
        """Export the acting layers of an SB3 policy ``state_dict`` (torch tensors or arrays).

        Raises:
            ValueError: For an algorithm, activation, policy option or space this path does not cover.
        """
        if algo not in ACTOR_LAYERS:
            raise ValueError(f"algo must be one of {', '.join(ACTOR_LAYERS)}, got {algo!r}")
        for option in ("use_sde", "squash_output", "normalize_images", "features_extractor_kwargs"):
            if policy_kwargs.get(option):
                raise ValueError(f"policy_kwargs.{option} is not supported by the CPU-independent inference path")
        extractor = policy_kwargs.get("features_extractor_class")
        if extractor is not None and str(extractor) != GOAL_ERROR:
            raise ValueError(
                f"policy_kwargs.features_extractor_class {extractor!r} is not supported by the CPU-independent "
                f"inference path (supported: {GOAL_ERROR})"
            )
        activation = str(policy_kwargs.get("activation_fn", DEFAULT_ACTIVATION[algo]))
        if activation not in ACTIVATION_FUNCTIONS:
            raise ValueError(
                f"activation {activation!r} has no CPU-independent implementation; "
                f"use one of {', '.join(ACTIVATION_FUNCTIONS)}"
            )
        arrays = {key: _as_float64(value) for key, value in state.items()}
        hidden_prefix, output_prefix = ACTOR_LAYERS[algo]
        hidden = _sequential_layers(arrays, hidden_prefix)
        if output_prefix is not None:
            output = (arrays[f"{output_prefix}.weight"], arrays[f"{output_prefix}.bias"])
        elif hidden:  # TD3: the actor's last linear layer is its output, followed by tanh
            output = hidden.pop()
        else:
            raise ValueError(f"no layers under {hidden_prefix!r} in the state_dict")
        obs_keys: tuple[str, ...] | None = None
        goal_columns: tuple[int, int] | None = None
        if isinstance(observation_space, gym.spaces.Dict):
            obs_keys = tuple(observation_space.spaces)
            first = observation_space.spaces[obs_keys[0]]
            if not all(isinstance(s, gym.spaces.Box) for s in observation_space.spaces.values()):
                raise ValueError(f"observation space {observation_space} is not a Dict of Boxes")
            obs_ndim = len(first.shape or ())
            if extractor is not None:
                goal_columns = _goal_columns(observation_space)
        elif extractor is not None:
            raise ValueError(f"{GOAL_ERROR} needs a Dict observation, got {observation_space}")
        elif isinstance(observation_space, gym.spaces.Box):
            obs_ndim = len(observation_space.shape)
        else:
            raise ValueError(f"observation space {observation_space} is not a Box or a Dict of Boxes")
        if isinstance(action_space, gym.spaces.Discrete):
            if algo != "ppo":
                raise ValueError(f"{algo} needs a Box action space")
            none = np.zeros(0)
            return cls(tuple(hidden), output, activation, False, none, none, True, obs_keys, obs_ndim, goal_columns)
        if not isinstance(action_space, gym.spaces.Box):
            raise ValueError(f"action space {action_space} is not a Box or Discrete")
        low = np.asarray(action_space.low, dtype=np.float64).ravel()
        high = np.asarray(action_space.high, dtype=np.float64).ravel()
        squash = algo != "ppo"
        return cls(tuple(hidden), output, activation, squash, low, high, False, obs_keys, obs_ndim, goal_columns)

    @classmethod
    def from_model(cls, model: Any, algo: str, policy_kwargs: Mapping[str, Any]) -> PolicyNetwork:
        """Export a live SB3 algorithm's current policy (``policy_kwargs`` as the config names them)."""
        return cls.from_state_dict(
            model.policy.state_dict(), algo, policy_kwargs, model.observation_space, model.action_space
        )

    def is_batch(self, observation: Any) -> bool:
        """True when ``observation`` holds a batch (one more axis than the observation space has)."""
        first = observation[self.obs_keys[0]] if self.obs_keys is not None else observation
        return bool(np.ndim(first) > self.obs_ndim)

    def flatten(self, observation: Any) -> np.ndarray:
        """A ``(batch, n_in)`` float64 input: dict keys concatenated, rounded to float32 as SB3 feeds torch."""
        batch = self.is_batch(observation)
        keys = self.obs_keys if self.obs_keys is not None else (None,)
        parts = [np.asarray(observation if k is None else observation[k], dtype=np.float32) for k in keys]
        rows = [p.reshape(len(p) if batch else 1, -1) for p in parts]
        return np.concatenate(rows, axis=1).astype(np.float64)

    def features(self, observation: Any) -> np.ndarray:
        """The network's float64 input for a batch of observations: flattened, plus the goal error if it has one."""
        x = self.flatten(observation)
        if self.goal_columns is None:
            return x
        a, d = self.goal_columns
        return np.concatenate([x, goal_error_features(x[:, a : a + GOAL_LENGTH], x[:, d : d + GOAL_LENGTH])], axis=1)

    def output_layer(self, observation: Any) -> np.ndarray:
        """The float64 output layer for a batch of observations, before squashing or clipping."""
        x = self.features(observation)
        code = ACTIVATION_CODES[self.activation]
        for weight, bias in self.hidden:
            if x.shape[1] != weight.shape[1]:
                raise ValueError(f"observation has {x.shape[1]} values, the network expects {weight.shape[1]}")
            x = dense_layer(x, weight, bias, code)
        return dense_layer(x, self.output[0], self.output[1], 0)

    def reference_output_layer(self, observation: Any) -> np.ndarray:
        """:meth:`output_layer` through the numpy reference functions (:func:`linear`, the activations)."""
        x = self.flatten(observation)
        function = ACTIVATION_FUNCTIONS[self.activation]
        for weight, bias in self.hidden:
            x = function(linear(x, weight, bias))
        return linear(x, *self.output)

    def act(self, observation: Any) -> np.ndarray:
        """Deterministic actions for a batch of observations (``(batch, ...)``, or a dict of such arrays).

        Returns a ``(batch, action_dim)`` float32 array (``(batch,)`` int64 for a discrete action).
        """
        x = self.output_layer(observation)
        if self.discrete:
            return np.argmax(x, axis=1)
        if self.squash:
            action = self.low + (0.5 * (tanh(x) + 1.0)) * (self.high - self.low)
        else:
            action = np.minimum(np.maximum(x, self.low), self.high)
        return action.astype(np.float32)

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[np.ndarray, Any]:
        """SB3's ``predict`` on a normalised observation or batch: the deterministic action, always.

        Raises:
            ValueError: For ``deterministic=False`` (sampling would need a random stream of its own).
        """
        if not deterministic:
            raise ValueError("learned policies act deterministically (the mean action); pass deterministic=True")
        actions = self.act(observation)
        return (actions if self.is_batch(observation) else actions[0]), state


def _goal_columns(space: gym.spaces.Dict) -> tuple[int, int]:
    """Where ``achieved_goal`` and ``desired_goal`` start in the flattened observation (keys in space order).

    Raises:
        ValueError: When the space lacks either goal, or a goal is not 9 numbers.
    """
    starts, k = {}, 0
    for key, sub in space.spaces.items():
        starts[key] = k
        k += int(np.prod(sub.shape or (1,)))
        if key in ("achieved_goal", "desired_goal") and int(np.prod(sub.shape or (1,))) != GOAL_LENGTH:
            raise ValueError(f"{GOAL_ERROR} needs {GOAL_LENGTH}-number goals, {key} has shape {sub.shape}")
    if "achieved_goal" not in starts or "desired_goal" not in starts:
        raise ValueError(f"{GOAL_ERROR} needs achieved_goal and desired_goal in the observation, got {list(starts)}")
    return starts["achieved_goal"], starts["desired_goal"]


def _as_float64(value: Any) -> np.ndarray:
    """A tensor or array as a float64 numpy array (exact: float32 -> float64 loses nothing)."""
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    return np.asarray(value, dtype=np.float64)
