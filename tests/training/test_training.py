"""agri train and weights-only loading: run directories, hyperparameter YAML, refusal of pickled checkpoints."""

import json
import shlex
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
import yaml
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv
from tiny_runs import TINY_ENV, TINY_HP

import agri_envs  # noqa: F401
import agri_training.learned.zoo as zoo
from agri_baselines import list_policies
from agri_training.evaluation.evaluate import evaluate
from agri_training.evaluation.policies import EvalRequest, load_policy
from agri_training.learned.inference import LEARNING_ONLY
from agri_training.learned.policy import (
    ALGORITHMS,
    LearnedPolicy,
    UnsafeCheckpointError,
    load_weights,
    resolve_policy_kwargs,
)
from agri_training.train import (
    HYPERPARAMS_DIR,
    TrainRequest,
    check_same_spaces,
    load_hyperparams,
    resolve_config,
    train,
)

ENV_ID = "agri_envs/GreenhouseNav-v2"

@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "tiny"
    train(TrainRequest(ENV_ID, "ppo", out, seed=3, timesteps=128, overrides=TINY_HP, progress=False), "test")
    return out


def test_run_directory_holds_everything(tiny_run):
    for name in ("policy.pt", "normalize.json", "config.yaml", "meta.json", "curve.csv", "command.txt"):
        assert (tiny_run / name).is_file(), name
    assert (tiny_run / "best" / "policy.pt").is_file()
    assert any((tiny_run / "checkpoints").iterdir())
    assert any((tiny_run / "tb").rglob("events.out.tfevents*"))
    meta = json.loads((tiny_run / "meta.json").read_text())
    assert meta["command"] == "test" and meta["timesteps_done"] >= 128 and meta["wall_time_s"] > 0
    assert "stable-baselines3" in meta["packages"] and meta["git_commit"]
    config = yaml.safe_load((tiny_run / "config.yaml").read_text())
    assert config["env_kwargs"]["localization"] == "ground_truth" and config["privileged"]
    curve = (tiny_run / "curve.csv").read_text().splitlines()
    assert curve[0].startswith("timesteps,wall_time_s,success_rate") and len(curve) >= 3


def test_loaded_policy_acts_like_the_trained_network(tiny_run):
    env = gym.make(ENV_ID, localization="ground_truth", **TINY_ENV)
    policy = load_policy(str(tiny_run), env)
    assert isinstance(policy, LearnedPolicy)
    saved = torch.load(tiny_run / "policy.pt", weights_only=True)
    policy_kwargs = resolve_policy_kwargs(policy.config["policy_kwargs"])
    model = PPO("MlpPolicy", DummyVecEnv([lambda: _Spaces(policy.network)]), device="cpu", policy_kwargs=policy_kwargs)
    missing, unexpected = model.policy.load_state_dict(saved, strict=False)  # a run writes its acting layers only
    assert missing and not unexpected and all(k.startswith(LEARNING_ONLY["ppo"]) for k in missing)
    obs, _ = env.reset(seed=5)
    stats = json.loads((tiny_run / "normalize.json").read_text())
    # The YAML's ObservationHistory: a new episode fills every frame with the first observation.
    (frames,) = [w["ObservationHistory"]["frames"] for w in policy.config["wrappers"] if "ObservationHistory" in w]
    flat = np.tile(gym.spaces.flatten(env.observation_space, obs), frames)
    z = np.clip((flat - np.array(stats["mean"][""])) / np.sqrt(np.array(stats["var"][""]) + stats["epsilon"]), -10, 10)
    np.testing.assert_allclose(policy.transform(obs, new_episode=True), z, rtol=1e-5, atol=1e-5)
    with torch.no_grad():
        mean = model.policy.get_distribution(torch.as_tensor(z[None], dtype=torch.float32)).distribution.mean
    action, _ = policy.predict(obs, episode_start=np.array([True]), deterministic=True)
    np.testing.assert_allclose(action, np.clip(mean.numpy()[0], -1, 1), rtol=1e-5, atol=1e-6)


class _Spaces(gym.Env):
    """An env with the spaces a network acts on (for rebuilding the torch policy beside the loaded one)."""

    def __init__(self, network):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (network.hidden[0][0].shape[1],), np.float32)
        self.action_space = gym.spaces.Box(network.low.astype(np.float32), network.high.astype(np.float32))

    def reset(self, *, seed=None, options=None):
        return self.observation_space.sample(), {}


def test_evaluate_a_run_like_a_baseline(tiny_run):
    result = evaluate(EvalRequest(ENV_ID, str(tiny_run), episodes=2, seed=100_000), progress=False)
    assert result["summary"]["episodes"] == 2 and result["privileged"]
    assert result["env_kwargs"]["localization"] == "ground_truth"
    with pytest.raises(ValueError, match="needs localization='ground_truth', but the request's env_kwargs sets"):
        evaluate(EvalRequest(ENV_ID, str(tiny_run), episodes=1, env_kwargs={"localization": "none"}), progress=False)


class _Payload:
    """Pickles to a call that writes a marker file: what a malicious checkpoint would run."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "code ran"))


def test_pickled_code_in_a_checkpoint_never_runs(tiny_run, tmp_path):
    marker = tmp_path / "ran.txt"
    evil = tmp_path / "evil"
    evil.mkdir()
    (evil / "config.yaml").write_text((tiny_run / "config.yaml").read_text())
    torch.save({"weight": torch.zeros(1), "payload": _Payload(marker)}, evil / "policy.pt")
    env = gym.make(ENV_ID, localization="ground_truth", **TINY_ENV)
    with pytest.raises(UnsafeCheckpointError, match="weights-only"):
        LearnedPolicy(evil, env)
    with pytest.raises(UnsafeCheckpointError):
        load_weights(evil / "policy.pt")
    assert not marker.exists()
    with pytest.raises(UnsafeCheckpointError, match="unpickling"):
        load_policy(str(tmp_path / "model.pkl"), env)


@pytest.mark.parametrize("path", sorted(HYPERPARAMS_DIR.glob("*.yml")), ids=lambda p: p.name)
def test_every_recipe_file_resolves_for_each_env_it_names(path, tmp_path):
    # A recipe a docstring or a zoo command.txt points at must still resolve (keys, wrappers, env arguments as
    # train() checks them before it writes anything), not only the configs the shipped policies froze.
    algo = path.stem if path.stem in ALGORITHMS else "ppo"
    env_ids = [key for key in yaml.safe_load(path.read_text()) if key != "default"]
    assert env_ids, f"{path.name} names no env"
    for env_id in env_ids:
        config = resolve_config(TrainRequest(env_id, algo, tmp_path / "run", hyperparams_file=path))
        assert config["env_id"] == env_id and config["algo"] == algo
        check_same_spaces(config)


def test_hyperparameters_resolve_and_stay_strict(tmp_path):
    hp = load_hyperparams(ENV_ID, "ppo")
    assert hp["wrappers"][0] == "FlattenObservation" and hp["n_envs"] * hp["algo_kwargs"]["n_steps"] == 8192
    assert load_hyperparams(ENV_ID, "ppo", overrides={"n_envs": 2})["n_envs"] == 2
    assert load_hyperparams("agri_envs/GrapeHarvest-v1", "sac")["policy"] == "MultiInputPolicy"
    with pytest.raises(ValueError, match="unknown hyperparameter keys"):
        load_hyperparams(ENV_ID, "ppo", overrides={"n_env": 2})
    bad = tmp_path / "bad.yml"
    bad.write_text("default:\n  wrappers: [os.system]\n")
    request = TrainRequest(ENV_ID, "ppo", tmp_path / "r", hyperparams_file=bad)
    with pytest.raises(ValueError, match="not allowed"):
        train(request)
    with pytest.raises(ValueError, match="seed"):
        TrainRequest(ENV_ID, "ppo", tmp_path, seed=100_000)
    with pytest.raises(ValueError, match="off-policy"):
        TrainRequest(ENV_ID, "ppo", tmp_path, her=True)
    with pytest.raises(ValueError, match="eval seeds"):
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path, overrides={"eval_seed": 99_995}))
    with pytest.raises(ValueError, match="vec_env must be one of dummy, subproc, vector"):
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path, overrides={"vec_env": "batched"}))
    with pytest.raises(ValueError, match="update_threads must be >= 1"):
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path, overrides={"update_threads": 0}))
    # GreenhouseCoverage's batched form cannot hold an action for 2 periods: refused by name, before training.
    coverage = {"vec_env": "vector", "action_repeat": 2, "train_wrappers": []}
    with pytest.raises(ValueError, match="GreenhouseCoverage-v2: action_repeat 2 on vec_env: vector"):
        resolve_config(TrainRequest("agri_envs/GreenhouseCoverage-v2", "ppo", tmp_path, overrides=coverage))
    held_once = {**coverage, "action_repeat": 1}
    resolve_config(TrainRequest("agri_envs/GreenhouseCoverage-v2", "ppo", tmp_path, overrides=held_once))
    resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path, overrides=coverage))  # GreenhouseNav's takes frame_skip


def test_a_registered_trained_policy_loads_by_name(tiny_run, monkeypatch, capsys):
    import agri_baselines
    from agri_training.cli import main

    monkeypatch.setattr(zoo, "ZOO_DIR", tiny_run.parent)
    spec = agri_baselines.PolicySpec(
        name=tiny_run.name,
        env_id=ENV_ID,
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="test",
    )
    monkeypatch.setitem(agri_baselines._REGISTRY, spec.name, spec)
    env = gym.make(ENV_ID, localization="ground_truth", **TINY_ENV)
    assert isinstance(load_policy(spec.name, env), LearnedPolicy)
    assert main(["list"]) == 0
    assert f"{spec.name} [{ENV_ID}] (privileged) (learned: PPO)" in capsys.readouterr().out


def test_each_shipped_policy_names_the_run_that_made_its_weights():
    """A registered train_command agrees with its zoo folder's command.txt on every flag that shapes the run."""
    shaping = ("--env", "--algo", "--seed", "--hyperparams", "--scenario", "--her")

    def flags(command: str) -> dict[str, str]:
        words = shlex.split(command)
        return {w: "" if w == "--her" else words[i + 1] for i, w in enumerate(words) if w in shaping}

    shipped = [s for s in list_policies() if s.learned]
    assert len(shipped) >= 17
    for spec in shipped:
        recorded = (zoo.zoo_path(spec.name) / "command.txt").read_text()
        assert flags(spec.train_command) == flags(recorded), spec.name


def test_train_env_kwargs_reach_the_training_envs_only(tmp_path):
    from agri_training.train import _env_factory

    hp = {**TINY_HP, "train_env_kwargs": {"scene_distribution": "off", "n_people": 2, "people_tease_prob": 0.9}}
    config = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", overrides=hp))
    training = _env_factory(config, 0)().unwrapped.config
    assert (training.n_people, training.people_tease_prob) == (2, 0.9)
    assert config["env_kwargs"]["n_people"] == 0  # what evaluation and loading use
    bad = {**TINY_HP, "train_env_kwargs": {"scene_distribution": "off", "localization": "none"}}  # other spaces
    with pytest.raises(ValueError, match="spaces"):
        train(TrainRequest(ENV_ID, "ppo", tmp_path / "bad", timesteps=64, overrides=bad, progress=False), "test")
    assert not (tmp_path / "bad" / "config.yaml").exists()


def test_a_run_with_a_decaying_learning_rate_loads(tmp_path):
    """``lin_X`` schedules are functions in training and must not reach the inference model as strings."""
    hp = {**TINY_HP, "algo_kwargs": {**TINY_HP["algo_kwargs"], "learning_rate": "lin_1e-3", "clip_range": "lin_0.2"}}
    out = tmp_path / "lin"
    train(TrainRequest(ENV_ID, "ppo", out, seed=1, timesteps=64, overrides=hp, progress=False), "test")
    result = evaluate(EvalRequest(ENV_ID, str(out), episodes=1, seed=100_000), progress=False)
    assert result["summary"]["episodes"] == 1


def test_exponent_numbers_in_overrides_are_floats():
    """``1e-4`` is a float as users write it (PyYAML's YAML 1.1 rules alone read it as a string), nested too."""
    from agri_training.cli import parse_env_kwargs

    hp = parse_env_kwargs(["algo_kwargs={learning_rate: 1e-4, clip_range: lin_2e-1}", "eval_freq=5E3"])
    assert hp == {"algo_kwargs": {"learning_rate": 1e-4, "clip_range": "lin_2e-1"}, "eval_freq": 5000.0}
    assert isinstance(hp["algo_kwargs"]["learning_rate"], float)


def test_timesteps_are_rounded_up_to_whole_rollouts_and_said_so(tmp_path, capsys):
    out = tmp_path / "rounded"
    # n_steps 32 x 2 envs: 100 steps cannot be trained; SB3 trains 128 and the run says so
    train(TrainRequest(ENV_ID, "ppo", out, seed=3, timesteps=100, overrides=TINY_HP, progress=False), "test")
    meta = json.loads((out / "meta.json").read_text())
    assert meta["timesteps_requested"] == 100 and meta["timesteps_planned"] == 128 == meta["timesteps_done"]
    assert meta["timesteps_rounding"] == "whole rollouts of n_steps 32 x 2 env slot(s) = 64 steps"
    assert "training 128 steps, not 100" in capsys.readouterr().err


def test_eval_env_kwargs_reach_the_periodic_evaluation_and_validation(tiny_run, tmp_path):
    from agri_training.evaluation.validation import VALIDATION_SEED, candidates, validate
    from agri_training.train import make_eval_env

    hp = {**TINY_HP, "eval_env_kwargs": {"scene_distribution": "off", "growth": 0.5}}
    out, other = tmp_path / "grown", tmp_path / "grown-too"
    train(TrainRequest(ENV_ID, "ppo", out, seed=2, timesteps=128, overrides=hp, progress=False), "test")
    train(TrainRequest(ENV_ID, "ppo", other, seed=5, timesteps=64, overrides=hp, progress=False), "test")
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert make_eval_env(config).unwrapped.config.growth == 0.5 and "growth" not in config["env_kwargs"]
    found = candidates(out)
    assert found[-1] == out and found[-2] == out / "best" and all(p.name.startswith("step_") for p in found[:-2])
    doc = validate(found, episodes=2, progress=False, command="test")
    assert doc["env_kwargs"]["growth"] == 0.5 and doc["seeds"] == {"start": VALIDATION_SEED, "episodes": 2}
    assert [row["path"] for row in doc["candidates"]] == [str(p) for p in found]
    assert all(row["summary"]["episodes"] == 2 and row["seed"] == 2 for row in doc["candidates"])

    # The chosen candidate ranks first by success, then fewer collisions, then return.
    def score(row):
        s = row["summary"]
        return (s["success_rate"], -s["collision_rate"], s["mean_return"])

    best = max(doc["candidates"], key=score)
    assert doc["chosen"] == best["path"] and doc["best_per_run"] == {str(out): best["path"]}
    assert list(doc["episodes"]) == [best["path"]] and len(doc["episodes"][best["path"]]) == 2
    # Two runs: each keeps its best, and the choice is the better of the two bests.
    both = validate([*found, other], episodes=2, progress=False, command="test")
    by_path = {c["path"]: c for c in both["candidates"]}
    bests = {run: by_path[path] for run, path in both["best_per_run"].items()}
    assert set(bests) == {str(out), str(other)} and bests[str(out)]["path"] == best["path"]
    assert both["chosen"] == max(bests.values(), key=score)["path"]
    assert score(bests[str(out)]) != score(bests[str(other)])  # the choice is not a tie
    with pytest.raises(ValueError, match="validation seeds"):
        validate([out], episodes=2, seed=VALIDATION_SEED - 1, progress=False)
    with pytest.raises(ValueError, match="its periodic evaluation used seeds 20001..20001"):
        overlap = tmp_path / "overlap"
        hp_overlap = {**hp, "eval_seed": VALIDATION_SEED + 1}
        train(TrainRequest(ENV_ID, "ppo", overlap, seed=2, timesteps=64, overrides=hp_overlap, progress=False), "t")
        validate([overlap], episodes=2, progress=False)
    with pytest.raises(ValueError, match="validates on"):  # another validation env: not comparable
        validate([out, tiny_run], episodes=2, progress=False)



def test_validation_env_kwargs_go_over_the_periodic_evaluations_and_never_change_what_the_weights_need(tiny_run):
    """A recipe whose periodic evaluation ran other scenes than its training distribution validates on that."""
    from agri_training.evaluation.validation import validate

    doc = validate([tiny_run], episodes=2, progress=False, command="test", env_kwargs={"growth": 0.5, "n_people": 0})
    assert doc["env_kwargs_given"] == {"growth": 0.5, "n_people": 0}
    plain = validate([tiny_run], episodes=2, progress=False, command="test")
    assert "growth" not in plain["env_kwargs"] and plain["env_kwargs_given"] == {}
    assert doc["env_kwargs"] == {**plain["env_kwargs"], "growth": 0.5}
    # the episodes ran the grown plants: the records differ from the plain validation's on the same seeds
    def returns(d):
        return [r["return"] for r in d["episodes"][d["chosen"]]]

    assert returns(doc) != returns(plain)
    with pytest.raises(ValueError, match=r"its weights need \{'row_length': 3.0\}"):
        validate([tiny_run], episodes=2, progress=False, env_kwargs={"row_length": 5.0})


def test_pretrain_clones_a_baseline_before_ppo(tmp_path):
    import math

    from agri_training.learned.pretrain import PretrainSpec, demonstrate

    hp = {**TINY_HP, "pretrain": {"policy": "harik-apf-gt", "episodes": 2, "epochs": 40, "seed": 50000}}
    out = tmp_path / "cloned"
    train(TrainRequest(ENV_ID, "ppo", out, seed=4, timesteps=64, overrides=hp, progress=False), "test")
    meta = json.loads((out / "meta.json").read_text())["pretrain"]
    config = yaml.safe_load((out / "config.yaml").read_text())
    demos = demonstrate(PretrainSpec.from_config(config["pretrain"]), config)
    # Every action_repeat-th control period of the two demonstrations is a learner decision.
    assert meta["decisions"] == len(demos.actions) == 2 * math.ceil(40 / config["action_repeat"])
    assert meta["action_mse_first_last"][1] < 0.5 * meta["action_mse_first_last"][0]
    # The cloned weights are checkpoint step_0, with the demonstrations' observation statistics; the
    # action noise keeps its configured value.
    stats = json.loads((out / "checkpoints" / "step_0" / "normalize.json").read_text())
    seen = demos.observations.reshape(len(demos.actions), -1).astype(np.float64)
    np.testing.assert_allclose(stats["mean"][""], seen.mean(axis=0))
    state = torch.load(out / "checkpoints" / "step_0" / "policy.pt", weights_only=True)
    assert np.allclose(state["log_std"].numpy(), config["policy_kwargs"]["log_std_init"])
    with pytest.raises(ValueError, match="pretrain: unknown keys"):
        bad = {**hp, "pretrain": {"policy": "a", "n": 1}}
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "x", overrides=bad))
    with pytest.raises(ValueError, match="clones a baseline into a PPO policy"):
        resolve_config(TrainRequest(ENV_ID, "sac", tmp_path / "y", overrides=hp))


def test_in_a_dagger_round_the_learner_drives_and_the_baseline_labels(tmp_path):
    import math

    from agri_training.learned.pretrain import PretrainSpec, demonstrate

    hp = {**TINY_HP, "pretrain": {"policy": "harik-apf-gt", "episodes": 1, "seed": 50000}}
    config = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", seed=4, overrides=hp))
    spec = PretrainSpec.from_config(config["pretrain"])
    driven = demonstrate(spec, config)
    standing = demonstrate(spec, config, learner=lambda batch: np.zeros((len(batch), 2), np.float32))
    # Standing still, the robot never arrives: every decision until the step limit is labelled with what
    # harik-apf-gt would do there (drive on), the first one as in the baseline's own run.
    assert len(standing.actions) == math.ceil(TINY_ENV["max_episode_steps"] / config["action_repeat"])
    assert standing.successes == 0 and np.all(standing.actions[:, 0] > 0.1)
    np.testing.assert_allclose(standing.actions[0], driven.actions[0])
    np.testing.assert_allclose(standing.observations[0], driven.observations[0])
    last = min(len(driven.actions), len(standing.actions)) - 1
    assert not np.allclose(standing.observations[last], driven.observations[last])


def test_dagger_noise_perturbs_the_driving_policy_within_the_action_box():
    from agri_training.learned.pretrain import PretrainSpec, _mean_action

    class Fixed:
        """A policy whose mean action is 0.9 forward and 0 turn for every observation."""

        def predict(self, obs, deterministic):
            return np.tile(np.array([0.9, 0.0], np.float32), (len(obs), 1)), None

    batch = np.zeros((2000, 3), np.float32)
    np.testing.assert_array_equal(_mean_action(Fixed(), None)(batch)[0], np.array([0.9, 0.0], np.float32))
    noisy = _mean_action(Fixed(), None, 0.3, np.random.default_rng(5))(batch)
    again = _mean_action(Fixed(), None, 0.3, np.random.default_rng(5))(batch)
    np.testing.assert_array_equal(noisy, again)  # reproducible from the run's generator
    assert noisy.dtype == np.float32 and noisy.min() >= -1.0 and noisy.max() == 1.0  # clipped at the box
    assert abs(float(np.std(noisy[:, 1])) - 0.3) < 0.02 and abs(float(np.mean(noisy[:, 1]))) < 0.03
    with pytest.raises(ValueError, match="dagger_noise must be >= 0"):
        PretrainSpec.from_config({"policy": "harik-apf-gt", "dagger_noise": -0.1})


def test_an_episode_the_baseline_cannot_act_in_is_left_out(tmp_path, monkeypatch):
    import agri_training.learned.pretrain as pretrain

    hp = {**TINY_HP, "pretrain": {"policy": "harik-apf-gt", "episodes": 3, "seed": 50000}}
    config = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", seed=4, overrides=hp))
    spec = pretrain.PretrainSpec.from_config(config["pretrain"])
    kept = pretrain.demonstrate(spec, config, seeds=[50000, 50002])
    make = pretrain.make_policy

    class NoPlanIn:
        """The baseline, except that it raises (as a planner finding no plan does) in the episodes of ``bad``."""

        def __init__(self, env, bad):
            self.expert, self.env, self.bad, self.step = make("harik-apf-gt", env), env, bad, 0

        def predict(self, obs, episode_start, deterministic):
            self.step = 0 if episode_start[0] else self.step + 1
            if self.env.unwrapped.np_random_seed in self.bad and self.step == 3:  # mid-episode: drop what it has
                raise ValueError("no plan")
            return self.expert.predict(obs, episode_start=episode_start, deterministic=deterministic)

    monkeypatch.setattr(pretrain, "make_policy", lambda name, env: NoPlanIn(env, {50001}))
    demos = pretrain.demonstrate(spec, config)
    assert (demos.episodes, demos.skipped, demos.successes) == (3, 1, kept.successes)
    np.testing.assert_array_equal(demos.actions, kept.actions)
    np.testing.assert_array_equal(demos.observations, kept.observations)
    np.testing.assert_array_equal(demos.episode_ends, kept.episode_ends)
    monkeypatch.setattr(pretrain, "make_policy", lambda name, env: NoPlanIn(env, {50000, 50001, 50002}))
    with pytest.raises(ValueError, match="could not act in any of the 3 episodes"):
        pretrain.demonstrate(spec, config)


def test_a_learner_with_odometry_sees_its_odometry_while_a_privileged_baseline_demonstrates(tmp_path):
    from agri_training.learned.pretrain import PretrainSpec, demonstrate

    coverage = "agri_envs/GreenhouseCoverage-v2"
    hp = {
        "env_kwargs": {"max_episode_steps": 150},
        "wrappers": [],
        "action_repeat": 1,
        "pretrain": {"policy": "gonzalez-deliberative", "episodes": 1, "seed": 50000},
    }
    config = resolve_config(TrainRequest(coverage, "ppo", tmp_path / "run", seed=0, overrides=hp))
    demos = demonstrate(PretrainSpec.from_config(config["pretrain"]), config)
    scene = {**config["env_kwargs"], **config["train_env_kwargs"]}
    # gonzalez-deliberative drives on the true pose; the learner (the default odometry) is shown what an
    # odometry env shows under the same seed and actions, replayed here as the oracle.
    env = gym.make(coverage, **scene)
    obs, _ = env.reset(seed=50000)
    for i, action in enumerate(demos.actions):
        for key in obs:
            np.testing.assert_array_equal(demos.observations[key][i], obs[key], err_msg=f"{key} at {i}")
        obs, *_ = env.step(action)
    truth = gym.make(coverage, localization="ground_truth", **scene)
    true_obs, _ = truth.reset(seed=50000)
    for action in demos.actions[:-1]:
        true_obs, *_ = truth.step(action)
    assert not np.array_equal(demos.observations["pose"][-1], true_obs["pose"])  # odometry has drifted


def test_a_baseline_whose_arguments_change_the_dynamics_is_refused(tmp_path, monkeypatch):
    import dataclasses

    import agri_training.learned.pretrain as pretrain

    hp = {**TINY_HP, "pretrain": {"policy": "harik-apf-gt", "episodes": 1, "seed": 50000}}
    config = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", seed=4, overrides=hp))
    spec = pretrain.policy_spec("harik-apf-gt")
    faster = dataclasses.replace(spec, env_kwargs={**spec.env_kwargs, "max_speed": 1.2})
    monkeypatch.setattr(pretrain, "policy_spec", lambda name: faster)
    with pytest.raises(ValueError, match="change agri_envs/GreenhouseNav-v2's dynamics"):
        pretrain.demonstrate(pretrain.PretrainSpec.from_config(config["pretrain"]), config)


def test_a_learner_without_localization_learns_from_a_teacher_on_the_true_pose(tmp_path):
    # harik-apf-gt needs localization='ground_truth'; the learner's env has none. The teacher drives its own env,
    # the learner's runs beside it in lockstep, and the learner is shown its own keys (target, no waypoint).
    import agri_training.learned.pretrain as pretrain
    from agri_baselines import make_policy

    blind = {**TINY_ENV, "n_people": 1, "localization": "none", "full_scan": True}
    hp = {**TINY_HP, "env_kwargs": blind, "wrappers": [], "action_repeat": 1,
          "pretrain": {"policy": "harik-apf-gt", "episodes": 1, "seed": 50000}}
    config = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", seed=4, overrides=hp))
    demos = pretrain.demonstrate(pretrain.PretrainSpec.from_config(config["pretrain"]), config)
    assert "target" in demos.observations and "waypoint" not in demos.observations
    # The oracle: harik-apf-gt alone on the true pose takes the same actions, and the learner's env shows what
    # an env made with its own arguments shows when driven by them.
    trained_on = {**config["env_kwargs"], **config["train_env_kwargs"]}
    truth = gym.make(ENV_ID, **{**trained_on, "localization": "ground_truth"})
    own = gym.make(ENV_ID, **trained_on)
    teacher = make_policy("harik-apf-gt", truth)
    obs, _ = truth.reset(seed=50000)
    shown, _ = own.reset(seed=50000)
    for k, label in enumerate(demos.actions):
        np.testing.assert_array_equal(demos.observations["target"][k], shown["target"])
        action, _ = teacher.predict(obs, episode_start=np.array([k == 0]))
        np.testing.assert_array_equal(label, np.clip(action, -1, 1), err_msg=f"decision {k}")
        obs, *_ = truth.step(action)
        shown, *_ = own.step(action)
    assert len(demos.actions) == 40


def test_emphasized_decisions_count_as_copies_in_the_action_loss():
    from agri_training.learned.pretrain import PretrainSpec, action_loss_of

    spec = PretrainSpec.from_config({"policy": "harik-apf-gt", "emphasize": {"action": 0, "below": 0.0, "weight": 3}})
    actions = np.array([[0.8, 0.1], [-0.3, 0.0], [0.5, -0.2], [-0.1, 0.4]], np.float32)
    weights = spec.loss_weights(actions)
    np.testing.assert_array_equal(weights, [1.0, 3.0, 1.0, 3.0])  # the two step-backs
    assert PretrainSpec.from_config({"policy": "harik-apf-gt"}).loss_weights(actions) is None
    rng = np.random.default_rng(0)
    mean = torch.as_tensor(rng.normal(size=actions.shape).astype(np.float32))
    weighted = action_loss_of(mean, torch.as_tensor(actions), torch.as_tensor(weights))
    copies = np.repeat(np.arange(len(actions)), weights.astype(int))  # oracle: each step-back three times
    repeated = action_loss_of(mean[copies], torch.as_tensor(actions[copies]))
    assert abs(float(weighted) - float(repeated)) < 1e-6
    assert abs(float(weighted) - float(action_loss_of(mean, torch.as_tensor(actions)))) > 1e-3
    with pytest.raises(ValueError, match="action, below, weight"):
        PretrainSpec.from_config({"policy": "harik-apf-gt", "emphasize": {"action": 0, "weight": 3}})
    with pytest.raises(ValueError, match="weight > 0"):
        PretrainSpec.from_config({"policy": "harik-apf-gt", "emphasize": {"action": 0, "below": 0, "weight": 0}})
    with pytest.raises(ValueError, match="2 components"):
        PretrainSpec.from_config(
            {"policy": "harik-apf-gt", "emphasize": {"action": 2, "below": 0, "weight": 2}}
        ).loss_weights(actions)


def test_zero_timesteps_with_pretrain_ships_the_clone(tmp_path):
    hp = {**TINY_HP, "pretrain": {"policy": "harik-apf-gt", "episodes": 1, "epochs": 2, "seed": 50000}}
    out = tmp_path / "clone"
    train(TrainRequest(ENV_ID, "ppo", out, seed=4, timesteps=0, overrides=hp, progress=False), "test")
    meta = json.loads((out / "meta.json").read_text())
    assert meta["timesteps_done"] == 0 and meta["pretrain"]["decisions"] > 0
    final = torch.load(out / "policy.pt", weights_only=True)
    cloned = torch.load(out / "checkpoints" / "step_0" / "policy.pt", weights_only=True)
    assert all(torch.equal(final[k], cloned[k]) for k in final)  # no RL step moved the weights
    stats = (out / "checkpoints" / "step_0" / "normalize.json").read_text()
    assert (out / "normalize.json").read_text() == stats  # nor the observation statistics
    curve = (out / "curve.csv").read_text().splitlines()
    assert len(curve) == 2 and curve[1].startswith("0,")  # one evaluation, of the clone
    with pytest.raises(ValueError, match="or 0 with a pretrain block"):
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "x", timesteps=0, overrides=TINY_HP))
    with pytest.raises(ValueError, match="or 0 with a pretrain block"):  # a negative count from the YAML
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "z", overrides={**hp, "n_timesteps": -8}))
    with pytest.raises(ValueError, match="timesteps must be >= 0"):
        TrainRequest(ENV_ID, "ppo", tmp_path / "y", timesteps=-1)


def test_fit_clipped_lets_a_mean_past_the_bound_of_its_label_go_free_and_nothing_else():
    from agri_training.learned.pretrain import PretrainSpec, action_loss_of

    assert PretrainSpec.from_config({"policy": "harik-apf-gt", "fit_clipped": True}).fit_clipped
    bounds = (torch.tensor([-1.0, -1.0]), torch.tensor([1.0, 1.0]))
    target = torch.tensor([[1.0, 0.2], [1.0, -1.0], [0.5, -1.0], [-1.0, 1.0]])
    mean = torch.tensor([[1.3, 0.2], [0.9, -1.4], [1.2, -0.8], [-1.0, 1.0]], requires_grad=True)
    # oracle, by hand: (1.3 past label 1 -> 0), (0.9 short of 1 -> 0.01), (-1.4 past -1 -> 0), (1.2 vs 0.5 -> 0.49,
    # the label is inside: clipping would hide it), (-0.8 short of -1 -> 0.04)
    loss = action_loss_of(mean, target, None, bounds)
    assert float(loss) == pytest.approx((0.01 + 0.49 + 0.04) / 8)
    loss.backward()
    assert mean.grad is not None
    assert float(mean.grad[0, 0]) == 0.0 and float(mean.grad[1, 1]) == 0.0  # past the bound of its label: free
    assert float(mean.grad[1, 0]) < 0 and float(mean.grad[2, 0]) > 0  # pulled up to 1, down to 0.5
    plain = action_loss_of(mean.detach(), target)
    assert float(plain) == pytest.approx((0.09 + 0.01 + 0.16 + 0.49 + 0.04) / 8)
