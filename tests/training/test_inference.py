"""The CPU-independent forward pass: bit for bit against a plain-Python reference, close to torch's."""

import json
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch

import agri_envs  # noqa: F401  (registers the env ids)
from agri_training.learned import goal_features
from agri_training.learned.inference import (
    _EXP_TAYLOR,
    _INV_LN2,
    _LN2_HI,
    _LN2_LO,
    ACTIVATION_CODES,
    ACTIVATION_FUNCTIONS,
    LEARNING_ONLY,
    PolicyNetwork,
    acting_state,
    dense_layer,
    exp,
    fold_sum,
    linear,
    tanh,
)
from agri_training.learned.policy import LearnedPolicy, load_weights, observation_chain, read_config
from agri_training.learned.zoo import ZOO_DIR

GOLDEN = Path(__file__).parents[1] / "data" / "inference_golden.json"


# ---- an obviously written reference: Python floats, one operation at a time -----------------------------


def ref_exp(x: float) -> float:
    x = min(max(x, -700.0), 700.0)
    k = round(x * _INV_LN2)  # Python rounds halves to even, like np.rint
    r = (x - k * _LN2_HI) - k * _LN2_LO
    p = _EXP_TAYLOR[-1]
    for c in reversed(_EXP_TAYLOR[:-1]):
        p = p * r + c
    return math.ldexp(p, k)


def ref_tanh(x: float) -> float:
    a = min(abs(x), 40.0)
    t = 1.0 - 2.0 / (ref_exp(2.0 * a) + 1.0)
    return -t if x < 0 else t


def ref_fold(terms: list[float]) -> float:
    """Fold the halves onto each other; an odd last term is carried."""
    while len(terms) > 1:
        h = len(terms) // 2
        terms = [terms[i] + terms[h + i] for i in range(h)] + terms[2 * h :]
    return terms[0]


def ref_goal_error(a: list[float], d: list[float]) -> list[float]:
    """The goal-error features written out one Python float operation at a time (module goal_features)."""

    def clip(v):
        return min(max(v, -1.0), 1.0)

    def cross(u, v):
        return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]

    dp = [d[i] - a[i] for i in range(3)]
    tz, tx = cross(a[3:6], d[3:6]), cross(a[6:9], d[6:9])
    return (
        [v * 10.0 for v in dp]
        + [clip(v * 50.0) for v in dp]
        + tz
        + tx
        + [clip(v * 5.0) for v in tz + tx]
        + [(a[3] * d[3] + a[4] * d[4]) + a[5] * d[5], (a[6] * d[6] + a[7] * d[7]) + a[8] * d[8]]
    )


def ref_input(net: PolicyNetwork, obs) -> list[float]:
    """The network's input: the flattened observation, plus the goal error when the network has it."""
    x = net.flatten(obs)[0].tolist()
    if net.goal_columns is not None:
        a, d = net.goal_columns
        x = x + ref_goal_error(x[a : a + 9], x[d : d + 9])
    return x


def ref_output_layer(net: PolicyNetwork, x: list[float]) -> list[float]:
    act = {"Tanh": ref_tanh, "ReLU": lambda v: max(v, 0.0)}[net.activation]

    def layer(values, weight, bias):
        return [
            ref_fold([values[i] * float(w[i]) for i in range(len(values))]) + float(b)
            for w, b in zip(weight, bias, strict=False)
        ]

    for weight, bias in net.hidden:
        x = [act(v) for v in layer(x, weight, bias)]
    return layer(x, *net.output)


def ref_forward(net: PolicyNetwork, x: list[float]) -> list[float]:
    out = ref_output_layer(net, x)
    if net.squash:
        return [
            float(lo) + (0.5 * (ref_tanh(v) + 1.0)) * (float(hi) - float(lo))
            for v, lo, hi in zip(out, net.low, net.high, strict=False)
        ]
    return [min(max(v, float(lo)), float(hi)) for v, lo, hi in zip(out, net.low, net.high, strict=False)]


# ---- tests --------------------------------------------------------------------------------------------------


def test_exp_and_tanh_are_accurate_and_match_the_reference_bit_for_bit():
    xs = np.concatenate([np.linspace(-50, 50, 20001), np.random.default_rng(0).normal(0, 3, 5000), [0.0, -0.0]])
    ours_exp, ours_tanh = exp(xs), tanh(xs)
    for x, e, t in zip(xs, ours_exp, ours_tanh, strict=False):
        assert e == ref_exp(float(x)) and t == ref_tanh(float(x)), x
    rel = np.abs(ours_exp - np.exp(xs)) / np.exp(xs)
    assert rel.max() < 5e-16
    assert np.abs(ours_tanh - np.tanh(xs)).max() < 5e-16
    assert exp(np.array([800.0]))[0] == ref_exp(800.0) and np.isfinite(exp(np.array([800.0]))[0])


def test_fold_sum_order_is_the_reference_and_ignores_the_batch():
    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 7, 64, 65, 129, 300):
        terms = rng.normal(size=(5, n)) * 10.0 ** rng.integers(-8, 8, size=(5, n))
        folded = fold_sum(terms)
        for row, value in zip(terms, folded, strict=False):
            assert value == ref_fold(row.tolist())
            assert fold_sum(row[None])[0] == value  # alone or in a batch: the same bits
    # Not the sequential sum: the order is a stated one, not whatever a BLAS picks.
    terms = np.array([1e16, 1.0, -1e16, 1.0])
    assert fold_sum(terms[None])[0] == (1e16 + -1e16) + (1.0 + 1.0) == 2.0


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a.view(np.int64), b.view(np.int64)))


def test_the_compiled_layer_computes_the_numpy_reference_bit_for_bit():
    """Every activation, layer sizes odd and even, inputs over 7 decades, zeros of both signs, special values."""
    rng = np.random.default_rng(5)
    for _ in range(60):
        n_in, n_out, batch = int(rng.integers(1, 320)), int(rng.integers(1, 40)), int(rng.integers(1, 6))
        weight = rng.normal(size=(n_out, n_in)) * 10.0 ** rng.integers(-3, 3)
        bias = rng.normal(size=n_out)
        x = rng.normal(size=(batch, n_in)) * 10.0 ** rng.integers(-3, 4)
        x[rng.random(x.shape) < 0.03] = 0.0
        x[rng.random(x.shape) < 0.03] = -0.0
        assert _same_bits(dense_layer(x, weight, bias, 0), linear(x, weight, bias))
        for name, function in ACTIVATION_FUNCTIONS.items():
            assert _same_bits(dense_layer(x, weight, bias, ACTIVATION_CODES[name]), function(linear(x, weight, bias)))
    special = np.array([[0.0, -0.0, np.nan, np.inf, -np.inf, 1e-320, -1e-320, 40.0, -40.0, 700.0, -710.0, 1e308]]).T
    one, minus_zero = np.ones((1, 1)), np.array([-0.0])  # x * 1 + -0.0 is x, -0.0 included: the activation alone
    for name, function in ACTIVATION_FUNCTIONS.items():
        out = dense_layer(special, one, minus_zero, ACTIVATION_CODES[name])
        with np.errstate(invalid="ignore", over="ignore"):
            assert _same_bits(out, function(linear(special, one, minus_zero))), name


def test_zoo_networks_run_compiled_as_the_reference_on_their_own_observations():
    for folder in sorted(p for p in ZOO_DIR.iterdir() if (p / "policy.pt").is_file()):
        config = read_config(folder)
        state = load_weights(folder / "policy.pt")
        n_actions = len(state["action_net.bias" if config["algo"] == "ppo" else "actor.mu.bias"])
        unit = gym.spaces.Box(-1.0, 1.0, (n_actions,), np.float32)
        # the dense layers alone: a features extractor's inputs (the goal error) are tested with their own spaces
        layers = {k: v for k, v in config.get("policy_kwargs", {}).items() if k != "features_extractor_class"}
        net = PolicyNetwork.from_state_dict(state, config["algo"], layers, gym.spaces.Box(-np.inf, np.inf, (1,)), unit)
        x = np.random.default_rng(11).normal(0.0, 2.0, size=(64, net.hidden[0][0].shape[1])).astype(np.float32)
        assert _same_bits(net.output_layer(x), net.reference_output_layer(x)), folder.name


def _sb3_model(algo, obs_space, act_space, seed, **policy_kwargs):
    """An SB3 algorithm on an env that only carries the spaces (its policy is what is compared)."""
    import stable_baselines3
    from stable_baselines3.common.vec_env import DummyVecEnv

    class Spaces(gym.Env):
        observation_space, action_space = obs_space, act_space

        def reset(self, *, seed=None, options=None):
            return obs_space.sample(), {}

        def step(self, action):
            return obs_space.sample(), 0.0, True, False, {}

    torch.manual_seed(seed)
    kwargs = {"buffer_size": 1, "learning_starts": 0} if algo != "ppo" else {}
    policy = "MultiInputPolicy" if isinstance(obs_space, gym.spaces.Dict) else "MlpPolicy"
    cls = getattr(stable_baselines3, algo.upper())
    return cls(policy, DummyVecEnv([Spaces]), seed=seed, device="cpu", policy_kwargs=policy_kwargs, **kwargs)


def _toy_network(algo, activation, obs_space, act_space, seed, extractor=None):
    from agri_training.learned.extractors import EXTRACTORS

    kwargs = {} if extractor is None else {"features_extractor_class": EXTRACTORS[extractor]}
    model = _sb3_model(
        algo, obs_space, act_space, seed, net_arch=[24, 17], activation_fn=getattr(torch.nn, activation), **kwargs
    )
    with torch.no_grad():  # larger weights than the initialisation, so that the activations saturate too
        for p in model.policy.parameters():
            p.mul_(3.0)
    config_kwargs = {"activation_fn": activation} | (
        {} if extractor is None else {"features_extractor_class": extractor}
    )
    net = PolicyNetwork.from_model(model, algo, config_kwargs)
    return model, net


BOX = gym.spaces.Box(-5, 5, (11,), np.float32)
DICT = gym.spaces.Dict(
    {
        "observation": gym.spaces.Box(-5, 5, (7,), np.float32),
        "desired_goal": gym.spaces.Box(-5, 5, (3,), np.float32),
        "achieved_goal": gym.spaces.Box(-5, 5, (3,), np.float32),
    }
)
#: Goals of 9 numbers (position, two unit axes) for the goal-error features; a goal near the achieved one as
#: often as not, so that the fine (clipped) features are exercised on both sides of their knee.
GOALS = gym.spaces.Dict(
    {
        "observation": gym.spaces.Box(-2, 2, (5,), np.float32),
        "desired_goal": gym.spaces.Box(-1, 1, (9,), np.float32),
        "achieved_goal": gym.spaces.Box(-1, 1, (9,), np.float32),
    }
)
ACT = gym.spaces.Box(np.array([-1, -2, 0.5], np.float32), np.array([1, 3, 2.5], np.float32))


def _near_goals(batch):
    rng = np.random.default_rng(5)
    for obs in batch[::2]:
        obs["desired_goal"] = (obs["achieved_goal"] + rng.normal(0, 0.01, 9)).astype(np.float32)
    return batch


@pytest.mark.parametrize(
    ("algo", "activation", "obs_space", "extractor"),
    [
        ("ppo", "Tanh", BOX, None),
        ("ppo", "ReLU", BOX, None),
        ("sac", "ReLU", DICT, None),
        ("td3", "ReLU", BOX, None),
        ("sac", "Tanh", BOX, None),
        ("sac", "ReLU", GOALS, goal_features.GOAL_ERROR),
    ],
)
def test_actions_match_torch_within_float32_and_the_reference_exactly(algo, activation, obs_space, extractor):
    model, net = _toy_network(algo, activation, obs_space, ACT, seed=7, extractor=extractor)
    obs_space.seed(3)
    batch = (
        _near_goals([obs_space.sample() for _ in range(20)]) if extractor else [obs_space.sample() for _ in range(20)]
    )
    for obs in batch:
        ours, _ = net.predict(obs)
        theirs, _ = model.predict(obs, deterministic=True)
        assert ours.dtype == np.float32 and ours.shape == ACT.shape
        np.testing.assert_allclose(ours, theirs, rtol=2e-5, atol=2e-5)
        x = ref_input(net, obs)
        assert net.output_layer(obs)[0].tolist() == ref_output_layer(net, x)  # float64, bit for bit
        np.testing.assert_array_equal(ours, np.float32(ref_forward(net, x)))
    stacked = (
        {k: np.stack([o[k] for o in batch]) for k in batch[0]}
        if isinstance(obs_space, gym.spaces.Dict)
        else np.stack(batch)
    )
    together, _ = net.predict(stacked)
    np.testing.assert_array_equal(together, np.stack([net.predict(o)[0] for o in batch]))


@pytest.mark.parametrize(("algo", "obs_space"), [("ppo", BOX), ("sac", DICT), ("td3", BOX)])
def test_the_weights_a_run_writes_hold_what_acting_needs_and_no_critic(algo, obs_space):
    """acting_state drops the value network or critics, and the network exported from what is left is the one
    exported from the whole state_dict (the oracle), so a run's smaller policy.pt acts the same."""
    model, whole = _toy_network(algo, "ReLU", obs_space, ACT, seed=11)
    state = model.policy.state_dict()
    kept = acting_state(state, algo)
    assert any(k.startswith(LEARNING_ONLY[algo]) for k in state)  # there was something to drop
    assert kept and not any(k.startswith(LEARNING_ONLY[algo]) for k in kept)
    part = PolicyNetwork.from_state_dict(kept, algo, {"activation_fn": "ReLU"}, obs_space, ACT)
    obs_space.seed(2)
    for obs in [obs_space.sample() for _ in range(5)]:
        np.testing.assert_array_equal(part.predict(obs)[0], whole.predict(obs)[0])
    assert acting_state(state, "unknown") == dict(state)


def test_what_the_path_cannot_compute_is_refused():
    state = {
        "mlp_extractor.policy_net.0.weight": np.ones((2, 11)),
        "mlp_extractor.policy_net.0.bias": np.zeros(2),
        "action_net.weight": np.ones((3, 2)),
        "action_net.bias": np.zeros(3),
    }
    with pytest.raises(ValueError, match="GELU"):
        PolicyNetwork.from_state_dict(state, "ppo", {"activation_fn": "GELU"}, BOX, ACT)
    with pytest.raises(ValueError, match="use_sde"):
        PolicyNetwork.from_state_dict(state, "ppo", {"use_sde": True}, BOX, ACT)
    with pytest.raises(ValueError, match="NatureCNN"):
        PolicyNetwork.from_state_dict(state, "ppo", {"features_extractor_class": "NatureCNN"}, BOX, ACT)
    with pytest.raises(ValueError, match="needs a Dict"):
        PolicyNetwork.from_state_dict(state, "ppo", {"features_extractor_class": goal_features.GOAL_ERROR}, BOX, ACT)
    with pytest.raises(ValueError, match="9-number goals"):
        PolicyNetwork.from_state_dict(state, "ppo", {"features_extractor_class": goal_features.GOAL_ERROR}, DICT, ACT)
    with pytest.raises(ValueError, match="algo"):
        PolicyNetwork.from_state_dict(state, "a2c", {}, BOX, ACT)
    net = PolicyNetwork.from_state_dict(state, "ppo", {}, BOX, ACT)
    with pytest.raises(ValueError, match="deterministic"):
        net.predict(np.zeros(11), deterministic=False)
    with pytest.raises(ValueError, match="expects 11"):
        net.predict(np.zeros(12))


def _golden_inputs(net: PolicyNetwork, n: int = 8) -> Any:
    """Normalised-looking inputs, the same on every machine (numpy's PCG64 stream is platform-independent).

    A network with goal-error features gets dict observations (the goals near each other in half the rows).
    """
    width = net.hidden[0][0].shape[1]
    if net.goal_columns is None:
        return np.random.default_rng(2026).normal(0.0, 1.5, size=(n, width)).astype(np.float32)
    flat = np.random.default_rng(2026).normal(0.0, 0.5, size=(n, width - goal_features.N_GOAL_ERROR_FEATURES))
    a, d = net.goal_columns
    flat[::2, d : d + 9] = flat[::2, a : a + 9] + 0.01 * flat[::2, d : d + 9]
    obs, k = {}, 0
    for key, size in zip(net.obs_keys, _key_sizes(net, flat.shape[1]), strict=True):
        obs[key] = flat[:, k : k + size].astype(np.float32)
        k += size
    return obs


def _key_sizes(net: PolicyNetwork, total: int) -> list[int]:
    """Sizes of the dict keys in flattening order: the two goals are 9 numbers, the observation the rest."""
    return [9 if key in ("achieved_goal", "desired_goal") else total - 18 for key in net.obs_keys]


def golden_actions() -> dict[str, list[list[str]]]:
    """Every zoo policy's float64 output layer on fixed inputs, as float hex strings (exact)."""
    out = {}
    for folder in sorted(p for p in ZOO_DIR.iterdir() if (p / "policy.pt").is_file()):
        config = read_config(folder)
        state = load_weights(folder / "policy.pt")
        n_actions = len(state["action_net.bias" if config["algo"] == "ppo" else "actor.mu.bias"])
        unit = gym.spaces.Box(
            -1.0, 1.0, (n_actions,), np.float32
        )  # spaces matter only for the bounds and the dict keys
        policy_kwargs = config.get("policy_kwargs", {})
        if policy_kwargs.get("features_extractor_class"):  # its features read the goals: the real dict space
            obs = observation_chain(gym.make(config["env_id"], **config["env_kwargs"]), config["wrappers"])[0]
            obs = obs.observation_space
        else:
            obs = gym.spaces.Box(-np.inf, np.inf, (1,))
        net = PolicyNetwork.from_state_dict(state, config["algo"], policy_kwargs, obs, unit)
        x = _golden_inputs(net)
        out[folder.name] = [[float(v).hex() for v in row] for row in net.output_layer(x)]
    return out


def test_zoo_actions_are_the_committed_bits():
    """Written once (``python tests/training/test_inference.py``); any CPU must compute the same bits."""
    committed = json.loads(GOLDEN.read_text())
    assert golden_actions() == committed


def test_a_loaded_zoo_policy_acts_like_torch():
    # frame_skip = the run's action_repeat: every step is a decision, whose observation goes through the
    # run's wrappers and statistics once (transform), then through the numpy network and through torch.
    env = gym.make("agri_envs/GreenhouseNav-v2", localization="ground_truth", frame_skip=4)
    policy = LearnedPolicy(ZOO_DIR / "ppo-greenhouse-nav", env)
    kwargs = policy.config["policy_kwargs"]
    assert kwargs["activation_fn"] == "ReLU" and policy.config["action_repeat"] == 4
    flat = policy.transform(env.reset(seed=3)[0], new_episode=True)
    space = gym.spaces.Box(-np.inf, np.inf, flat.shape, np.float32)
    model = _sb3_model("ppo", space, env.action_space, 0, net_arch=kwargs["net_arch"], activation_fn=torch.nn.ReLU)
    # the zoo keeps the acting layers only: the value network is all that torch's policy misses
    missing, unexpected = model.policy.load_state_dict(
        load_weights(ZOO_DIR / "ppo-greenhouse-nav" / "policy.pt"), strict=False
    )
    assert missing and not unexpected and all(k.startswith(LEARNING_ONLY["ppo"]) for k in missing)
    for _ in range(30):
        action, _ = policy.network.predict(flat, deterministic=True)
        expected, _ = model.predict(flat, deterministic=True)
        np.testing.assert_allclose(action, expected, rtol=1e-5, atol=1e-6)
        obs, _, terminated, truncated, _ = env.step(action)
        assert not (terminated or truncated)
        flat = policy.transform(obs)


if __name__ == "__main__":
    GOLDEN.parent.mkdir(exist_ok=True)
    GOLDEN.write_text(json.dumps(golden_actions(), indent=1) + "\n")
    print(f"wrote {GOLDEN}")
