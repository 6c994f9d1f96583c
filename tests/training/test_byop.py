"""Bring your own policy: ONNX, SB3 zips read without unpickling, module:attribute, the Python API, env arguments."""

from __future__ import annotations

import io
import json
import pickle
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
import yaml

import agri_envs
import agri_training
import agri_training.leaderboard as lb
from agri_training.cli import main
from agri_training.evaluation.policies import EvalRequest, load_policy, resolve_env_kwargs
from agri_training.evaluation.reference import resolve_policy
from agri_training.learned.inference import dense_layer
from agri_training.learned.onnx_policy import OnnxPolicy
from agri_training.learned.sb3_zip import Sb3ZipPolicy

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")  # torch.onnx.export(dynamo=False)

NAV = "agri_envs/GreenhouseNav-v2"
TINY = {"n_rows": 1, "row_length": 3.0, "n_people": 0, "max_episode_steps": 30, "localization": "ground_truth"}


@pytest.fixture(scope="module")
def env():
    e = agri_envs.make(NAV, **TINY)
    yield e
    e.close()


def _observations(env, n=4):
    obs, _ = env.reset(seed=3)
    out = [obs]
    for _ in range(n - 1):
        obs, *_ = env.step(env.action_space.sample())
        out.append(obs)
    return out


def _mlp(n_in: int, n_out: int, *layers: torch.nn.Module) -> torch.nn.Module:
    torch.manual_seed(0)
    return torch.nn.Sequential(torch.nn.Linear(n_in, 32), *layers, torch.nn.Linear(32, 16), torch.nn.Tanh(),
                               torch.nn.Linear(16, n_out)).eval()  # fmt: skip


def _export(net: torch.nn.Module, n_in: int, path: Path) -> Path:
    torch.onnx.export(net, (torch.zeros(1, n_in),), str(path), dynamo=False, input_names=["obs"],
                      output_names=["action"], dynamic_axes={"obs": {0: "batch"}})  # fmt: skip
    return path


# ---------------------------------------------------------------- env arguments


def test_a_policy_need_that_contradicts_the_scenario_is_refused_with_both_values(tmp_path, capsys):
    request = EvalRequest("agri_envs/GrapeHarvest-v1", "sac-her-grape-reach-strict", scenario="table2")
    with pytest.raises(ValueError, match=r"needs min_clusters=1, but scenario table2 sets min_clusters=2"):
        resolve_env_kwargs(request)
    out = tmp_path / "x.json"
    args = ["--policy", "sac-her-grape-reach-strict", "--scenario", "table2", "--out", str(out), "--quiet"]
    assert main(["evaluate", "--env", "agri_envs/GrapeHarvest-v1", *args]) == 2
    assert "min_clusters=2" in capsys.readouterr().err and not out.exists()
    with pytest.raises(ValueError, match=r"suite grape-table2 sets min_clusters=2"):
        agri_training.evaluate_suite("sac-her-grape-reach-strict", "grape-table2")
    with pytest.raises(ValueError, match=r"needs localization='ground_truth', but --env-kwargs sets localization="):
        resolve_env_kwargs(EvalRequest(NAV, "harik-apf-gt", env_kwargs={"localization": "none"},
                                       env_kwargs_from="--env-kwargs"))  # fmt: skip
    # a need may add an argument: the document holds what was asked for, plus the additions
    kwargs, privileged = resolve_env_kwargs(EvalRequest(NAV, "harik-apf-gt", scenario="sim-loop"))
    asked = agri_envs.scenarios.scenario(NAV, "sim-loop").env_kwargs
    assert privileged and all(kwargs[k] == v for k, v in asked.items()) and kwargs["full_scan"] is True


def test_a_policy_is_resolved_once_into_a_typed_reference():
    ref = resolve_policy("ppo-greenhouse-nav")
    assert ref.kind == "zoo" and ref.sha256 and ref.env_id == NAV and ref.observation_only
    # the reference an entry records keeps the committed entries' format
    committed = json.loads((lb.ENTRIES_DIR / "greenhouse-corridor" / "ppo-greenhouse-nav.json").read_text())
    assert ref.to_entry() == committed["policy"]
    request = EvalRequest(NAV, "harik-apf-gt")
    assert request.ref.kind == "baseline" and EvalRequest(NAV, request.ref).ref is request.ref
    with pytest.raises(ValueError, match="unknown policy 'nope'.*module:attribute"):
        resolve_policy("nope")


def test_an_evaluation_looks_its_policy_up_once(monkeypatch):
    import agri_baselines
    from agri_training.evaluation import reference
    from agri_training.evaluation.evaluate import evaluate

    calls = {"policy_spec": 0, "is_run_path": 0}

    def counted(name, real):
        def wrapper(*args, **kwargs):
            calls[name] += 1
            return real(*args, **kwargs)

        return wrapper

    for name in calls:
        monkeypatch.setattr(reference, name, counted(name, getattr(reference, name)))
    monkeypatch.setattr(agri_baselines, "policy_spec", counted("policy_spec", agri_baselines.policy_spec))
    small = {k: v for k, v in TINY.items() if k != "localization"}
    doc = evaluate(EvalRequest(NAV, "harik-apf-gt", episodes=3, env_kwargs=small), progress=False, batch=2)
    assert doc["summary"]["episodes"] == 3 and calls == {"policy_spec": 1, "is_run_path": 1}


# ---------------------------------------------------------------- ONNX


def test_onnx_mlp_acts_as_the_torch_network_and_the_same_twice(env, tmp_path):
    width = gym.spaces.flatdim(env.observation_space)
    net = _mlp(width, 2, torch.nn.ReLU(), torch.nn.Linear(32, 32), torch.nn.ELU(), torch.nn.Linear(32, 32),
               torch.nn.Sigmoid(), torch.nn.Linear(32, 32), torch.nn.LeakyReLU(0.1), torch.nn.Hardtanh())  # fmt: skip
    path = _export(net, width, tmp_path / "nav.onnx")
    policy = load_policy(str(path), env)
    assert isinstance(policy, OnnxPolicy)
    for obs in _observations(env):
        flat = torch.as_tensor(gym.spaces.flatten(env.observation_space, obs))[None]
        want = np.clip(net(flat).detach().numpy()[0], -1.0, 1.0)
        got, _ = policy.predict(obs)
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        again, _ = load_policy(str(path), env).predict(obs)
        assert got.dtype == np.float32 and got.tobytes() == again.tobytes()
    batch = {k: np.stack([o[k] for o in _observations(env, 2)]) for k in env.observation_space.spaces}
    assert policy.predict(batch)[0].shape == (2, 2)


_BITS = """
import hashlib, sys
from pathlib import Path
import numpy as np
from agri_training.learned.onnx_policy import load_graph
x = np.random.default_rng(0).random((64, int(sys.argv[2]))).astype(np.float32).astype(np.float64)
print(hashlib.sha256(load_graph(Path(sys.argv[1])).run(x).tobytes()).hexdigest())
"""


def test_onnx_actions_are_the_same_bits_whatever_numpy_dispatches(env, tmp_path):
    """numpy's SIMD loops chosen freely (AVX-512 where the CPU has it), pinned as `agri` pins them, or SSE only.

    What the dispatch can change here are the numpy steps of the graph (ELU, Sigmoid, the additions); the compiled
    matrix products (numba) do not follow numpy's dispatch, and are the same bits by construction
    (``agri_training.learned.inference``).
    """
    import hashlib
    import os
    import subprocess
    import sys

    from agri_training.learned.onnx_policy import load_graph

    width = gym.spaces.flatdim(env.observation_space)
    net = _mlp(width, 2, torch.nn.ELU(), torch.nn.Linear(32, 32), torch.nn.Sigmoid())
    path = _export(net, width, tmp_path / "m.onnx")
    root = str(Path(__file__).resolve().parents[2])
    x = np.random.default_rng(0).random((64, width)).astype(np.float32).astype(np.float64)
    digests = {hashlib.sha256(load_graph(path).run(x).tobytes()).hexdigest()}  # pinned, as `agri` runs
    for disabled in ("", "X86_V4 AVX512_ICL AVX512_SPR X86_V3 AVX2 FMA3 AVX F16C"):
        environ = {**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled, "PYTHONPATH": root}
        out = subprocess.run([sys.executable, "-c", _BITS, str(path), str(width)], env=environ, capture_output=True,
                             text=True, check=True)  # fmt: skip
        digests.add(out.stdout.strip())
    assert len(digests) == 1


def test_onnx_sidecar_normalises_and_names_env_arguments(env, tmp_path):
    width = gym.spaces.flatdim(env.observation_space)
    path = _export(_mlp(width, 2, torch.nn.Tanh()), width, tmp_path / "p.onnx")
    mean, var = np.linspace(0, 1, width), np.linspace(1, 2, width)
    side = {"env_id": NAV, "env_kwargs": {"localization": "ground_truth"}, "privileged": True,
            "observation_normalization": {"mean": mean.tolist(), "var": var.tolist(), "clip": 5.0}}  # fmt: skip
    Path(f"{path}.yaml").write_text(yaml.safe_dump(side))
    ref = resolve_policy(str(path))
    assert ref.env_id == NAV and ref.privileged and ref.sidecar_sha256
    assert ref.env_kwargs == {"localization": "ground_truth"}
    obs = _observations(env, 1)[0]
    flat = gym.spaces.flatten(env.observation_space, obs).astype(np.float64)
    normalised = np.clip((flat - mean) / np.sqrt(var + 1e-8), -5, 5).astype(np.float32)
    policy = load_policy(str(path), env)
    want = policy.graph.run(normalised[None].astype(np.float64))[0]
    np.testing.assert_array_equal(policy.predict(obs)[0], np.clip(want, -1, 1).astype(np.float32))
    Path(f"{path}.yaml").write_text("env_id: x\nbogus: 1\n")
    with pytest.raises(ValueError, match="unknown key.*bogus"):
        resolve_policy(str(path))


def test_onnx_bad_input_gets_a_named_error(env, tmp_path):
    width = gym.spaces.flatdim(env.observation_space)
    softplus = _export(_mlp(width, 2, torch.nn.Softplus()), width, tmp_path / "softplus.onnx")
    with pytest.raises(ValueError, match="ONNX operator 'Softplus'.*not supported"):
        resolve_policy(str(softplus))
    narrow = _export(_mlp(width - 3, 2, torch.nn.ReLU()), width - 3, tmp_path / "narrow.onnx")
    with pytest.raises(ValueError, match=rf"input has {width - 3} values, .*observation has {width}"):
        load_policy(str(narrow), env)
    wide_out = _export(_mlp(width, 3, torch.nn.ReLU()), width, tmp_path / "three.onnx")
    with pytest.raises(ValueError, match="outputs 3 values.*needs 2"):
        load_policy(str(wide_out), env)
    import onnx
    from onnx import TensorProto, helper

    node = helper.make_node("RunShell", ["obs"], ["action"], domain="evil.ops")
    graph = helper.make_graph([node], "g", [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, width])],
                              [helper.make_tensor_value_info("action", TensorProto.FLOAT, [1, 2])])  # fmt: skip
    custom = tmp_path / "custom.onnx"
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17), helper.make_opsetid("evil.ops", 1)]),
              str(custom))  # fmt: skip
    with pytest.raises(ValueError, match="custom operator domain 'evil.ops'"):
        resolve_policy(str(custom))
    outside = tmp_path / "outside.onnx"
    onnx.save_model(onnx.load(str(softplus)), str(outside), save_as_external_data=True, size_threshold=0)
    with pytest.raises(ValueError, match="stored outside the file.*external_data=False"):
        resolve_policy(str(outside))
    (tmp_path / "junk.onnx").write_bytes(b"\x00not a model" * 10)
    with pytest.raises(ValueError, match="not an ONNX model"):
        resolve_policy(str(tmp_path / "junk.onnx"))


def test_onnx_interpreter_runs_the_shape_operators_as_numpy_does():
    from onnx import TensorProto, helper, numpy_helper

    from agri_training.learned.onnx_policy import OnnxGraph

    rng = np.random.default_rng(0)
    w = rng.normal(size=(6, 4))
    nodes = [
        helper.make_node("Unsqueeze", ["x", "axes"], ["x3"]),  # (b, 6) -> (b, 1, 6)
        helper.make_node("Squeeze", ["x3", "axes"], ["x2"]),
        helper.make_node("MatMul", ["x2", "w"], ["h"]),
        helper.make_node("Sub", ["h", "c"], ["h1"]),
        helper.make_node("Mul", ["h1", "c"], ["h2"]),
        helper.make_node("Div", ["h2", "d"], ["h3"]),
        helper.make_node("Concat", ["h3", "h"], ["cat"], axis=1),
        helper.make_node("Reshape", ["cat", "shape"], ["r"]),
        helper.make_node("Flatten", ["r"], ["flat"], axis=1),
        helper.make_node("Clip", ["flat", "lo", "hi"], ["y"]),
    ]
    inits = [numpy_helper.from_array(a, n) for n, a in (
        ("axes", np.array([1])), ("w", w.astype(np.float32)), ("c", np.full(4, 0.5, np.float32)),
        ("d", np.full(4, 3.0, np.float32)), ("shape", np.array([0, 2, 4])), ("lo", np.array(-1.0, np.float32)),
        ("hi", np.array(1.0, np.float32)))]  # fmt: skip
    graph = helper.make_graph(nodes, "g", [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["b", 6])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)], inits)  # fmt: skip
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    parsed = OnnxGraph.parse(model.SerializeToString())
    x = rng.normal(size=(3, 6)).astype(np.float32).astype(np.float64)
    h = x @ w.astype(np.float32).astype(np.float64)
    want = np.clip(np.concatenate([(h - 0.5) * 0.5 / 3.0, h], axis=1), -1, 1)
    np.testing.assert_allclose(parsed.run(x), want, rtol=1e-12, atol=1e-12)
    assert parsed.input_width == 6


# ---------------------------------------------------------------- SB3 zips


class _Payload:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "code ran"))


@pytest.fixture
def no_unpickling(monkeypatch):
    """Any unpickler, pickle.load(s) or torch.load raises: nothing may resolve a global."""

    def refuse(*args, **kwargs):
        raise AssertionError("something was unpickled")

    for name in ("Unpickler", "load", "loads"):
        monkeypatch.setattr(pickle, name, refuse)
    monkeypatch.setattr(pickle._Unpickler, "find_class", refuse)
    monkeypatch.setattr(torch, "load", refuse)


@pytest.mark.parametrize(
    "algo, policy",
    [("PPO", "MultiInputPolicy"), ("SAC", "MultiInputPolicy"), ("TD3", "MultiInputPolicy"),
     ("TQC", "MultiInputPolicy"), ("SAC", "MlpPolicy")],
)  # fmt: skip
def test_sb3_zip_predicts_what_sb3_predicts_without_unpickling(env, tmp_path, monkeypatch, algo, policy):
    if policy == "MlpPolicy":  # a Box observation: the env's, flattened
        env = gym.wrappers.FlattenObservation(env)
    import sb3_contrib
    import stable_baselines3

    cls = getattr(sb3_contrib if algo == "TQC" else stable_baselines3, algo)
    kwargs = {"buffer_size": 10} if algo != "PPO" else {"n_steps": 16, "batch_size": 16}
    model = cls(policy, env, seed=0, device="cpu", policy_kwargs={"net_arch": [24, 24]}, **kwargs)
    if algo == "PPO":
        model.learn(16)
    path = tmp_path / f"{algo.lower()}.zip"
    model.save(path)
    observations = _observations(env)
    want = [model.predict(obs, deterministic=True)[0] for obs in observations]

    def refuse(*args, **kwargs):
        raise AssertionError("something was unpickled")

    dense_layer(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros(1), 0)  # numba reads its own cache index with pickle
    for name in ("Unpickler", "load", "loads"):
        monkeypatch.setattr(pickle, name, refuse)
    monkeypatch.setattr(pickle._Unpickler, "find_class", refuse)
    monkeypatch.setattr(torch, "load", refuse)
    ref = resolve_policy(str(path))
    assert ref.kind == "sb3-zip" and ref.sha256 == lb.sha256_file(path)
    mine = load_policy(str(path), env)
    assert isinstance(mine, Sb3ZipPolicy)
    for obs, action in zip(observations, want, strict=True):
        np.testing.assert_allclose(mine.predict(obs)[0], action, rtol=1e-5, atol=1e-6)


def _sb3_zip(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def test_crafted_sb3_zips_run_nothing_and_are_refused(env, tmp_path, no_unpickling):
    marker = tmp_path / "ran.txt"
    payload = pickle.dumps(_Payload(marker))
    buffer = io.BytesIO()
    torch.save({"action_net.weight": torch.zeros(2, 2), "payload": _Payload(marker)}, buffer)  # torch.save pickles
    init = "<function ActorCriticPolicy.__init__ at 0>"
    ppo_class = {"__module__": "stable_baselines3.common.policies", "__init__": init}
    good_data = json.dumps({"policy_class": ppo_class}).encode()
    cases = {
        "pickled-data.zip": ({"data": payload, "policy.pth": buffer.getvalue()}, "'data' is not JSON"),
        "pickled-pth.zip": ({"data": good_data, "policy.pth": buffer.getvalue()}, "calls __main__|refers to|calls"),
        "raw-pickle-pth.zip": ({"data": good_data, "policy.pth": payload}, "not a torch.save zip"),
        "no-pth.zip": ({"data": good_data}, "has no 'policy.pth'"),
        "custom-class.zip": (
            {"data": json.dumps({"policy_class": {**ppo_class, "__init__": init.replace("ActorCritic", "")}}).encode(),
             "policy.pth": buffer.getvalue()},
            r"\.Policy cannot be rebuilt.*export the actor to ONNX",
        ),
    }  # fmt: skip
    for name, (members, message) in cases.items():
        path = _sb3_zip(tmp_path / name, members)
        with pytest.raises(ValueError, match=message):
            load_policy(str(path), env)
        with pytest.raises(ValueError):
            resolve_policy(str(path))
    assert not marker.exists()


# ---------------------------------------------------------------- module:attribute and objects


def test_module_attribute_policies_and_their_errors(env, tmp_path, monkeypatch):
    (tmp_path / "my_policies.py").write_text(
        "import numpy as np\n"
        "def forward(env):\n"
        "    return lambda obs: np.array([0.5, 0.0], dtype=np.float32)\n"
        "forward.env_id = 'agri_envs/GreenhouseNav-v2'\n"
        "forward.env_kwargs = {'localization': 'ground_truth'}\n"
    )
    (tmp_path / "broken_policies.py").write_text("raise RuntimeError('no such robot')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    ref = resolve_policy("my_policies:forward")
    assert ref.kind == "callable" and not ref.reverifiable and ref.to_entry()["reverifiable"] is False
    assert lb.markdown.policy_kind(ref.to_entry()) == "callable, not re-verifiable on another CPU"
    action, _ = load_policy("my_policies:forward", env).predict(_observations(env, 1)[0])
    assert action.tolist() == [0.5, 0.0]
    with pytest.raises(ValueError, match=r"module 'broken_policies' does not import \(RuntimeError: no such robot\)"):
        resolve_policy("broken_policies:forward")
    with pytest.raises(ValueError, match="has no attribute 'nothing'"):
        resolve_policy("my_policies:nothing")
    with pytest.raises(ValueError, match=r"drives agri_envs/GreenhouseNav-v2, not agri_envs/GrapeHarvest-v1"):
        resolve_env_kwargs(EvalRequest("agri_envs/GrapeHarvest-v1", "my_policies:forward"))


# ---------------------------------------------------------------- the Python API


def test_evaluate_suite_reproduces_the_committed_entry():
    committed = json.loads((lb.ENTRIES_DIR / "greenhouse-sim-loop" / "harik-apf-gt.json").read_text())
    fresh = agri_training.evaluate_suite("harik-apf-gt", "greenhouse-sim-loop")
    drop = ("git_commit", "command", "package_version")
    assert lb.compare_documents({k: v for k, v in committed.items() if k not in drop},
                                {k: v for k, v in fresh.items() if k not in drop}) == []  # fmt: skip


def test_evaluate_suite_takes_live_objects(tmp_path):
    suite = _tiny_suite(tmp_path)
    doc = agri_training.evaluate_suite(lambda obs: np.zeros(2, dtype=np.float32), suite, episodes=1)
    assert doc["policy"]["kind"] == "object" and doc["summary"]["episodes"] == 1
    assert doc["levels"][0]["env_kwargs"] == dict(suite.env_kwargs)
    with pytest.raises(ValueError, match="live Python object"):
        agri_training.evaluate_suite(lambda obs: np.zeros(2), suite, workers=2)
    with pytest.raises(ValueError, match="needs localization='odometry', but suite tiny-nav sets localization="):
        agri_training.evaluate_suite(lambda obs: np.zeros(2), suite, env_kwargs={"localization": "odometry"})


def _tiny_suite(tmp_path: Path) -> lb.Suite:
    folder = tmp_path / "suites"
    folder.mkdir(exist_ok=True)
    doc = {"name": "tiny-nav", "version": 1, "env_id": NAV, "env_kwargs": TINY,
           "seeds": {"start": 100000, "episodes": 2},
           "fewer_episodes": "a test", "traces": 0, "rank_by": [{"metric": "success_rate"}]}  # fmt: skip
    (folder / "tiny-nav.yaml").write_text(yaml.safe_dump(doc))
    return lb.load_suite(folder / "tiny-nav.yaml")


def test_onnx_and_sb3_zip_entries_submit_and_verify_bit_for_bit(env, tmp_path, capsys):
    from stable_baselines3 import PPO

    _tiny_suite(tmp_path)
    width = gym.spaces.flatdim(env.observation_space)
    onnx_file = _export(_mlp(width, 2, torch.nn.Tanh()), width, tmp_path / "nav-mlp.onnx")
    zip_file = tmp_path / "nav-ppo.zip"
    PPO("MultiInputPolicy", env, seed=1, device="cpu", policy_kwargs={"net_arch": [16]}).save(zip_file)
    common = ["--suites", str(tmp_path / "suites"), "--entries", str(tmp_path / "entries"),
              "--markdown", str(tmp_path / "LB.md")]  # fmt: skip
    for policy in (onnx_file, zip_file):
        submit = ["submit", "--suite", "tiny-nav", "--policy", str(policy), "--workers", "1", "--quiet"]
        assert main(["leaderboard", *common, *submit]) == 0, capsys.readouterr().err
    entries = lb.load_entries(tmp_path / "entries")
    assert {e["policy"]["kind"] for e in entries} == {"onnx", "sb3-zip"}
    assert all(e["policy"]["sha256"] and e["levels"][0]["env_kwargs"] == TINY for e in entries)
    page = (tmp_path / "LB.md").read_text()
    assert "| onnx (`" in page and "| sb3-zip (`" in page
    assert main(["leaderboard", *common, "verify", "--workers", "1", "--quiet"]) == 0, capsys.readouterr().err
    coverage = agri_envs.make("agri_envs/GreenhouseCoverage-v2")
    with pytest.raises(ValueError, match="made for another env"):
        load_policy(str(zip_file), coverage)
    with pytest.raises(ValueError, match=r"input has \d+ values, .* has \d+"):
        load_policy(str(onnx_file), coverage)
    coverage.close()
    assert "verified 2 entries exactly" in capsys.readouterr().out
    onnx_file.write_bytes(onnx_file.read_bytes() + b"\x00")
    assert main(["leaderboard", *common, "verify", "--workers", "1", "--quiet"]) == 1
    assert "changed" in capsys.readouterr().err
