"""Parameter-shared PPO for the robot chain: the SuperSuit vector env, a tiny run, weights-only reloading."""

import json

import numpy as np
import pytest
import torch
import yaml

import agri_envs
from agri_training.cli import main
from agri_training.evaluation.policies import load_policy
from agri_training.learned.parameter_sharing import make_shared_vec_env
from agri_training.learned.policy import LearnedPolicy
from agri_training.train import TrainRequest, resolve_config, train

ENV_ID = "robot_chain_v1"
# A short chain on a small office floor: the run and its evaluation take seconds.
TINY_ENV = {"n_robots": 3, "office_width": 8.0, "office_height": 6.0, "min_goal_distance": 3.0, "max_cycles": 40}
TINY_HP = {
    "n_envs": 2,
    "env_kwargs": TINY_ENV,
    "train_wrappers": [{"ShortMissions": {"goal_distance": [1.0, 2.0], "ramp_steps": 50}}],
    "algo_kwargs": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
    "policy_kwargs": {"net_arch": {"pi": [16], "vf": [16]}},
    "eval_freq": 10_000,
    "eval_episodes": 1,
    "checkpoint_freq": 0,
}


@pytest.fixture(scope="module")
def chain_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "chain"
    request = TrainRequest(ENV_ID, "ppo", out, seed=2, timesteps=300, overrides=TINY_HP, progress=False)
    train(request, "test")
    return out


def _tiny_vec_env(n_envs=2):
    return make_shared_vec_env(lambda: agri_envs.make(ENV_ID, **TINY_ENV), n_envs)


def test_one_slot_per_robot_seeded_like_sb3():
    venv = _tiny_vec_env()
    assert venv.num_envs == 2 * TINY_ENV["n_robots"]
    venv.seed(7)
    first = venv.reset()
    venv.seed(7)
    again = venv.reset()
    np.testing.assert_array_equal(first, again)
    # copy i resets from seed + i, like SB3's own vector envs
    env = agri_envs.make(ENV_ID, **TINY_ENV)
    obs, _ = env.reset(seed=8)
    np.testing.assert_array_equal(first[3:6], np.stack([obs[a] for a in env.possible_agents]))
    venv.seed(9)
    assert not np.array_equal(venv.reset(), first)


def test_max_cycles_is_a_truncation_and_the_chain_resets_whole():
    venv = _tiny_vec_env(n_envs=1)
    venv.seed(0)
    venv.reset()
    stay = np.zeros((venv.num_envs, 2), np.float32)  # standing still: no contact, no arrival
    for _ in range(TINY_ENV["max_cycles"] - 1):
        _, _, dones, _ = venv.step(stay)
        assert not dones.any()
    obs, rewards, dones, infos = venv.step(stay)
    assert dones.all() and rewards.shape == (venv.num_envs,)
    assert all(i["TimeLimit.truncated"] for i in infos)
    assert all(i["terminal_observation"].shape == (29,) for i in infos)
    assert not np.array_equal(obs[0], infos[0]["terminal_observation"])  # a fresh episode began


def test_a_tiny_run_writes_a_weights_only_run_directory(chain_run):
    for name in ("policy.pt", "normalize.json", "config.yaml", "meta.json", "curve.csv", "command.txt"):
        assert (chain_run / name).is_file(), name
    config = yaml.safe_load((chain_run / "config.yaml").read_text())
    assert config["env_id"] == ENV_ID and config["wrappers"] == [] and config["normalize"]["norm_obs"]
    assert json.loads((chain_run / "meta.json").read_text())["timesteps_done"] >= 300
    curve = (chain_run / "curve.csv").read_text().splitlines()
    assert curve[0].startswith("timesteps,wall_time_s,success_rate") and len(curve) >= 3


def test_agri_evaluate_drives_every_robot_with_the_run(chain_run, tmp_path, capsys):
    out = tmp_path / "r.json"
    argv = ["evaluate", "--env", ENV_ID, "--policy", str(chain_run), "--episodes", "1", "--seed", "100000"]
    assert main([*argv, "--workers", "1", "--quiet", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    (record,) = result["levels"][0]["episodes"] if "levels" in result else result["episodes"]
    assert record["seed"] == 100_000 and record["steps"] >= 1
    assert result["env_kwargs"]["max_cycles"] == TINY_ENV["max_cycles"]  # the run's env arguments


def test_the_reloaded_shared_policy_acts_like_the_model_in_memory(tmp_path):
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from agri_training.train import save_weights

    config = resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", overrides=TINY_HP))
    venv = VecNormalize(_tiny_vec_env(), norm_obs=True, norm_reward=True, clip_obs=10.0)
    venv.seed(0)
    model = PPO("MlpPolicy", venv, seed=0, device="cpu", n_steps=32, batch_size=64, n_epochs=1)
    model.learn(64)  # moves both the weights and the normalisation statistics off their initial values
    run = tmp_path / "run"
    save_weights(model, run)
    written = torch.load(run / "policy.pt", weights_only=True)  # the acting layers only: no value network
    assert "action_net.weight" in written and not any("value_net" in k for k in written)
    (run / "config.yaml").write_text(yaml.safe_dump({**config, "algo_kwargs": {}, "policy_kwargs": {}}))
    env = agri_envs.make(ENV_ID, **TINY_ENV)
    policy = load_policy(str(run), env)
    assert isinstance(policy, LearnedPolicy) and policy.multiagent
    state = model.policy.state_dict()
    for (weight, _), key in zip(policy.network.hidden, ("0", "2"), strict=True):
        saved = state[f"mlp_extractor.policy_net.{key}.weight"]
        assert torch.equal(torch.as_tensor(weight, dtype=torch.float32), saved)
    obs, _ = env.reset(seed=4)
    for _ in range(5):
        ours, _ = policy.predict(obs, deterministic=True)
        theirs = {
            a: model.predict(venv.normalize_obs(np.asarray(obs[a], np.float32)), deterministic=True)[0] for a in obs
        }
        assert set(ours) == set(env.agents)
        for agent in env.agents:
            np.testing.assert_allclose(ours[agent], theirs[agent], rtol=1e-5, atol=1e-6)
        obs, *_ = env.step(ours)
        if not env.agents:
            break


def test_the_chain_trains_only_a_shared_ppo(tmp_path):
    with pytest.raises(ValueError, match="parameter-shared PPO"):
        resolve_config(TrainRequest(ENV_ID, "sac", tmp_path))
    with pytest.raises(ValueError, match="wrappers"):
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path, overrides={"wrappers": ["FlattenObservation"]}))


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"wrappers": ["FlattenObservation"]}, "Gymnasium envs only"),
        ({"action_repeat": 4}, "Gymnasium envs only"),
        ({"train_wrappers": ["RandomStartWaypoint"]}, "'RandomStartWaypoint' is not allowed; allowed: ShortMissions"),
    ],
)
def test_gymnasium_only_training_keys_are_refused_for_the_chain(overrides, match, tmp_path):
    request = TrainRequest("robot_chain_v1", "ppo", tmp_path / "run", overrides=overrides)
    with pytest.raises(ValueError, match=match):
        resolve_config(request)


def test_short_missions_curriculum_draws_short_missions_then_fewer():
    from agri_training.learned.curricula import ShortMissions

    env = ShortMissions(agri_envs.make(ENV_ID, n_robots=3), goal_distance=(1.0, 2.0), start=1.0, end=0.0, ramp_steps=20)
    lengths = []
    for seed in range(4):
        _, infos = env.reset(seed=seed)
        lengths.append(infos["robot_0"]["astar_length"])
    # Early on every mission is short: the leader starts 1-2 m from the goal along the free floor.
    assert all(1.0 - 0.1 <= d <= 2.0 + 0.1 for d in lengths), lengths
    assert env.share == 1.0
    for _ in range(20):
        env.step({a: np.zeros(2, np.float32) for a in env.agents}) if env.agents else env.reset()
    assert env.share == 0.0
    _, infos = env.reset(seed=9)
    assert infos["robot_0"]["astar_length"] >= env.unwrapped.config.min_goal_distance - 0.1
    with pytest.raises(ValueError, match="goal_distance"):
        ShortMissions(agri_envs.make(ENV_ID), goal_distance=(3.0, 1.0))
    with pytest.raises(ValueError, match="goal_distance"):
        agri_envs.make(ENV_ID).reset(seed=0, options={"goal_distance": "near"})


def _cloning_config(tmp_path, **pretrain):
    block = {"policy": "apoorva-chain", "episodes": 2, "epochs": 2, "seed": 50_000, **pretrain}
    hp = {**TINY_HP, "train_wrappers": [], "pretrain": block}
    return resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "run", seed=2, overrides=hp))


def test_demonstrations_are_every_robots_decisions_one_trajectory_per_robot(tmp_path):
    from agri_baselines import make_policy
    from agri_training.learned.pretrain import PretrainSpec, demonstrate

    config = _cloning_config(tmp_path)
    demos = demonstrate(PretrainSpec.from_config(config["pretrain"]), config, seeds=[50_000])
    n = TINY_ENV["n_robots"]
    assert demos.episodes == 1 and len(demos.actions) % n == 0 and demos.episode_ends.sum() == n
    steps = len(demos.actions) // n
    # Robot k's decisions are rows k * steps .. (k + 1) * steps - 1, its last one ending the episode.
    assert np.flatnonzero(demos.episode_ends).tolist() == [k * steps + steps - 1 for k in range(n)]
    env = agri_envs.make(ENV_ID, **TINY_ENV)
    expert = make_policy("apoorva-chain", env)
    obs, _ = env.reset(seed=50_000)
    advice, _ = expert.predict(obs, episode_start=np.array([True]))
    for k, agent in enumerate(env.possible_agents):
        np.testing.assert_array_equal(demos.observations[k * steps], obs[agent])
        np.testing.assert_allclose(demos.actions[k * steps], np.clip(advice[agent], -1, 1), rtol=1e-6)
    # The cooperative reward: every robot is paid the same each step.
    rewards = demos.rewards.reshape(n, steps)
    np.testing.assert_array_equal(rewards, np.repeat(rewards[:1], n, axis=0))


def test_in_a_dagger_round_the_learner_drives_and_apoorva_chain_labels(tmp_path):
    from agri_training.learned.pretrain import PretrainSpec, demonstrate

    config = _cloning_config(tmp_path)
    spec = PretrainSpec.from_config(config["pretrain"])
    expert = demonstrate(spec, config, seeds=[50_000])
    standing = demonstrate(spec, config, seeds=[50_000], learner=lambda batch: np.zeros((len(batch), 2), np.float32))
    n = TINY_ENV["n_robots"]
    xy = standing.observations[:, 8:10].reshape(n, -1, 2)
    # The learner stands still (so does the chain, until the time limit), while the labels are what
    # apoorva-chain would do there: drive off. The baseline's own run moves.
    assert len(standing.actions) == n * TINY_ENV["max_cycles"] and standing.successes == 0
    np.testing.assert_allclose(xy, np.repeat(xy[:, :1], xy.shape[1], axis=1), atol=1e-9)
    assert np.abs(standing.actions).max() > 0.1
    moved = expert.observations[:, 8:10].reshape(n, -1, 2)
    assert np.abs(moved - moved[:, :1]).max() > 1e-3
    np.testing.assert_allclose(standing.actions[0], expert.actions[0])  # the same first decision


def test_pretraining_the_chain_with_dagger_rounds(tmp_path):
    hp = {
        **TINY_HP,
        "train_wrappers": [],
        "policy_kwargs": {"net_arch": {"pi": [64, 64], "vf": [16]}},
        "pretrain": {
            "policy": "apoorva-chain",
            "episodes": 2,
            "epochs": 80,
            "seed": 50_000,
            "dagger_rounds": 2,
            "dagger_episodes": 1,
            "dagger_epochs": 40,
        },
    }
    out = tmp_path / "cloned"
    train(TrainRequest(ENV_ID, "ppo", out, seed=1, timesteps=64, overrides=hp, progress=False), "test")
    meta = json.loads((out / "meta.json").read_text())["pretrain"]
    assert [r["seeds"] for r in meta["dagger_rounds"]] == [[50_002, 50_002], [50_003, 50_003]]
    # Every robot's decisions of the 2 demonstrations and the 2 rounds, each episode at most max_cycles long.
    n = TINY_ENV["n_robots"]
    assert meta["decisions"] % n == 0 and 4 * n <= meta["decisions"] <= 4 * n * TINY_ENV["max_cycles"]
    assert meta["action_mse_first_last"][1] < 0.5 * meta["action_mse_first_last"][0]
    assert (out / "checkpoints" / "step_0" / "policy.pt").is_file()
    with pytest.raises(ValueError, match="must lie below 100000"):
        late = {**hp, "pretrain": {**hp["pretrain"], "seed": 99_998}}  # its second round would run seed 100001
        resolve_config(TrainRequest(ENV_ID, "ppo", tmp_path / "x", overrides=late))


def test_a_chain_baseline_that_needs_other_env_arguments_is_refused(tmp_path, monkeypatch):
    import dataclasses

    import agri_training.learned.pretrain as pretrain

    config = _cloning_config(tmp_path)
    spec = pretrain.PretrainSpec.from_config(config["pretrain"])
    needs = dataclasses.replace(pretrain.policy_spec("apoorva-chain"), env_kwargs={"sonar_range": 5.0})
    monkeypatch.setattr(pretrain, "policy_spec", lambda name: needs)
    # The learner would see the baseline's 5 m sonars in training and 3 m ones when evaluated.
    with pytest.raises(ValueError, match=r"needs \['sonar_range'\]"):
        pretrain.demonstrate(spec, config, seeds=[50_000])
