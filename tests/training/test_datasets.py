"""agri dataset: Minari datasets of any policy on any env, replayed exactly; pretrain clones from them; bad input."""

import dataclasses
import json
import re

import numpy as np
import pytest

pytest.importorskip("minari")
pytest.importorskip("h5py")

import minari  # noqa: E402
from tiny_runs import TINY_ENV, TINY_HP  # noqa: E402

import agri_envs  # noqa: E402
from agri_baselines import list_policies  # noqa: E402
from agri_training.cli import main  # noqa: E402
from agri_training.core import datasets  # noqa: E402
from agri_training.datasets import DatasetRequest, make_dataset, resolve_dataset_env  # noqa: E402

#: Short episodes per env family: a small scene where the env has one, and a time limit (gym.make's, kept in the spec).
SHORT = {
    "GreenhouseNav": {"n_rows": 1, "row_length": 3.0, "n_people": 0, "max_episode_steps": 150},
    "GreenhouseCoverage": {"max_episode_steps": 150},
    "GrapeHarvest": {"max_episode_steps": 150},
}


def family(env_id):
    """``GreenhouseCoverage`` for ``agri_envs/GreenhouseCoverage-v1`` (whatever its version)."""
    return env_id.split("/")[-1].rsplit("-", 1)[0]


COVERAGE = next(i for i in agri_envs.env_ids() if family(i) == "GreenhouseCoverage")


@pytest.fixture(autouse=True)
def datasets_path(tmp_path, monkeypatch):
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def paper_policy(env_id):
    """The env's first registered scripted baseline (the paper's controller)."""
    return next(p.name for p in list_policies() if p.env_id == env_id and not p.learned)


def assert_replays_exactly(dataset):
    """Reset the recovered env with each episode's seed, step its actions: every observation and reward equal."""
    env = dataset.recover_environment()
    for meta, episode in datasets.episodes(dataset):
        obs, _ = env.reset(seed=int(meta["seed"]))
        for t in range(len(episode.actions) + 1):
            for k in obs:
                np.testing.assert_array_equal(obs[k], episode.observations[k][t], err_msg=f"{meta} step {t} {k}")
            if t == len(episode.actions):
                break
            obs, reward, terminated, truncated, _ = env.step(episode.actions[t])
            assert reward == episode.rewards[t]
            assert (terminated, truncated) == (episode.terminations[t], episode.truncations[t])
    env.close()


GYM_FAMILIES = [i for i in agri_envs.env_ids() if not agri_envs.is_parallel_id(i) and family(i) in SHORT]


def test_every_gymnasium_family_is_covered():
    families = {family(i) for i in agri_envs.env_ids() if not agri_envs.is_parallel_id(i)}
    assert families - {family(i) for i in GYM_FAMILIES} <= {"GrapeHarvestReach"}  # a preset, no baseline of its own


@pytest.mark.parametrize("env_id", GYM_FAMILIES)
def test_a_dataset_replays_bit_for_bit_from_its_seeds(env_id):
    policy = paper_policy(env_id)
    dataset_id = f"agri/{env_id.split('/')[-1]}/{policy}-v0"
    kwargs = [f"{k}={v}" for k, v in SHORT[family(env_id)].items()]
    argv = ["dataset", "--env", env_id, "--policy", policy, "--episodes", "2", "--seed", "11"]
    assert main([*argv, "--dataset-id", dataset_id, "--env-kwargs", *kwargs, "--workers", "1", "--quiet"]) == 0
    dataset = minari.load_dataset(dataset_id)
    assert dataset.total_episodes == 2
    metas = [m for m, _ in datasets.episodes(dataset)]
    assert [int(m["seed"]) for m in metas] == [11, 12] and [int(m["run"]) for m in metas] == [0, 1]
    # The spec holds the arguments the episodes ran with: the user's and what the policy needs.
    spec = dataset.spec.env_spec
    needs = {p.name: p for p in list_policies()}[policy].env_kwargs
    assert {**spec.kwargs, "max_episode_steps": spec.max_episode_steps} == {**SHORT[family(env_id)], **needs}
    episode = dataset[0]
    assert episode.actions.dtype == np.float64 and {"is_success", "collision"} <= set(episode.infos)
    assert len(episode.infos["is_success"]) == len(episode.actions) + 1
    assert_replays_exactly(dataset)


def test_the_chain_is_one_dataset_with_every_robots_trajectory(datasets_path):
    request = DatasetRequest(
        "robot_chain_v1", "apoorva-chain", "agri/robot_chain_v1/apoorva-chain-v0", 2, seed=5, env_kwargs={"n_robots": 3}
    )
    done = make_dataset(request, progress=False)
    assert done["episodes"] == 2 and done["trajectories"] == 6
    dataset = minari.load_dataset(request.dataset_id)
    rows = list(datasets.episodes(dataset))
    assert [(m["agent"], int(m["run"]), int(m["seed"])) for m, _ in rows] == [
        (a, r, 5 + r) for r in range(2) for a in agri_envs.make("robot_chain_v1", n_robots=3).possible_agents
    ]
    described = datasets.describe(dataset)
    assert described.parallel and described.env_kwargs == {"n_robots": 3}
    env = datasets.recover_env(dataset)
    for run in range(2):
        mine = {m["agent"]: e for m, e in rows if int(m["run"]) == run}
        obs, _ = env.reset(seed=5 + run)
        for t in range(len(next(iter(mine.values())).actions)):
            for a, e in mine.items():
                np.testing.assert_array_equal(obs[a], e.observations[t])
            obs, rewards, *_ = env.step({a: e.actions[t] for a, e in mine.items()})
            assert all(rewards[a] == e.rewards[t] for a, e in mine.items())
    env.close()


def test_bad_input_is_refused_before_anything_is_written(datasets_path, capsys):
    grape = {"max_episode_steps": 30}
    ok = DatasetRequest("agri_envs/GrapeHarvest-v1", "luo-apf", "agri/GrapeHarvest-v1/luo-apf-v0", 1, env_kwargs=grape)
    make_dataset(ok, progress=False)
    with pytest.raises(ValueError, match="exists.*--overwrite"):
        make_dataset(ok, progress=False)
    make_dataset(dataclasses.replace(ok, overwrite=True, seed=3), progress=False)
    assert [int(m["seed"]) for m, _ in datasets.episodes(minari.load_dataset(ok.dataset_id))] == [3]
    cases = {
        "drives agri_envs/GreenhouseNav-v2, not": dict(policy="harik-apf-gt", dataset_id="t0/b-v0"),
        "held-out seeds": dict(seed=99_999, episodes=2, dataset_id="t0/c-v0"),
        "sweeps": dict(
            env_id="agri_envs/GreenhouseNav-v2", policy="harik-apf-gt", scenario="plant-development",
            dataset_id="t0/d-v0", env_kwargs={},
        ),
        "declares no training distribution": dict(training_distribution=True, dataset_id="t0/e-v0"),
        "Minari's form": dict(dataset_id="no version"),
        "cannot be stored": dict(dataset_id="t0/f-v0", env_kwargs={**grape, "bad": {1, 2}}),
    }  # fmt: skip
    for message, changes in cases.items():
        with pytest.raises(ValueError, match=message):
            make_dataset(dataclasses.replace(ok, **changes), progress=False)
    assert sorted(p.name for p in datasets_path.iterdir()) == ["agri"]  # nothing else, no partial folder
    # The command line: one line, exit status 2.
    argv = ["dataset", "--env", ok.env_id, "--policy", "luo-apf", "--seed", "100000", "--dataset-id", "t0/g-v0"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "held-out" in err[0]


def test_an_interrupted_run_leaves_no_dataset(datasets_path, monkeypatch):
    request = DatasetRequest(
        "agri_envs/GrapeHarvest-v1", "luo-apf", "agri/GrapeHarvest-v1/cut-v0", 2, env_kwargs={"max_episode_steps": 20}
    )
    calls = []

    def interrupted(self, episode, run):
        calls.append(run)
        if len(calls) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr(datasets.DatasetWriter, "add", interrupted)
    with pytest.raises(KeyboardInterrupt):
        make_dataset(request, progress=False)
    assert not datasets.dataset_path(request.dataset_id).exists()
    assert [p.name for p in datasets_path.iterdir() if p.name.startswith(".")] == []
    with pytest.raises(ValueError, match="no dataset"):
        datasets.load(request.dataset_id)


def test_the_spec_records_a_policys_own_arguments():
    request = DatasetRequest(
        "agri_envs/GreenhouseNav-v2", "harik-apf-gt", "agri/GreenhouseNav-v2/x-v0", 1, training_distribution=True
    )
    described = resolve_dataset_env(request)
    assert described.env_kwargs == {"scene_distribution": "training", "full_scan": True, "localization": "ground_truth"}
    json.dumps(described.env_kwargs)


def test_a_clone_from_a_dataset_equals_the_clone_from_the_same_baseline_driven_live(tmp_path):
    import torch

    from agri_training.learned.pretrain import PretrainSpec, demonstrate, demonstrate_dataset
    from agri_training.train import TrainRequest, resolve_config, train

    env_id = "agri_envs/GreenhouseNav-v2"
    hp = {**TINY_HP, "n_envs": 1, "env_kwargs": {**TINY_ENV, "max_episode_steps": 60}}
    live = {**hp, "pretrain": {"policy": "harik-apf-gt", "episodes": 2, "epochs": 3, "seed": 50000}}
    config = resolve_config(TrainRequest(env_id, "ppo", tmp_path / "live", seed=4, overrides=live))
    # The dataset: the same baseline, seeds and training env (the baseline adds its own arguments).
    learner_kwargs = {**config["env_kwargs"], **config["train_env_kwargs"]}
    dataset_id = "agri/GreenhouseNav-v2/harik-apf-gt-v0"
    request = DatasetRequest(env_id, "harik-apf-gt", dataset_id, 2, 50000, env_kwargs=learner_kwargs)
    make_dataset(request, progress=False)
    cloned = {**hp, "pretrain": {"dataset": dataset_id, "episodes": 2, "epochs": 3, "seed": 50000}}
    config_d = resolve_config(TrainRequest(env_id, "ppo", tmp_path / "data", seed=4, overrides=cloned))
    # The dataset's env adds only the full scan to the learner's: its recorded observations are shown.
    spec, from_data = demonstrate_dataset(PretrainSpec.from_config(config_d["pretrain"]), config_d)
    shown = demonstrate(PretrainSpec.from_config(config["pretrain"]), config)
    assert spec.policy == "harik-apf-gt"
    for name in ("observations", "actions", "rewards", "episode_ends", "successes", "episodes"):
        np.testing.assert_array_equal(getattr(from_data, name), getattr(shown, name))
    # So the cloned weights are equal bit for bit.
    runs = {}
    for name, overrides in (("live", live), ("data", cloned)):
        out = tmp_path / f"run-{name}"
        train(TrainRequest(env_id, "ppo", out, seed=4, timesteps=0, overrides=overrides, progress=False), "test")
        runs[name] = torch.load(out / "checkpoints" / "step_0" / "policy.pt", weights_only=True)
    assert runs["live"].keys() == runs["data"].keys()
    assert all(torch.equal(runs["live"][k], runs["data"][k]) for k in runs["live"])
    with pytest.raises(ValueError, match=r"holds no episode of seeds 50002 \(it holds seeds 50000..50001\)"):
        demonstrate_dataset(PretrainSpec(dataset=dataset_id, episodes=3, seed=50000), config_d)
    with pytest.raises(ValueError, match="policy .* or dataset"):
        PretrainSpec.from_config({"epochs": 3})
    with pytest.raises(ValueError, match="was driven by harik-apf-gt, not harik-apf"):
        demonstrate_dataset(PretrainSpec(policy="harik-apf", dataset=dataset_id, episodes=2, seed=50000), config_d)


def test_a_privileged_dataset_is_replayed_in_the_learners_own_env(tmp_path):
    from agri_training.learned.pretrain import PretrainSpec, demonstrate, demonstrate_dataset
    from agri_training.train import TrainRequest, resolve_config

    coverage = COVERAGE
    hp = {"env_kwargs": {"max_episode_steps": 60}, "pretrain": {"policy": "gonzalez-deliberative", "episodes": 1}}
    config = resolve_config(TrainRequest(coverage, "ppo", tmp_path / "run", seed=0, overrides=hp))
    scene = {**config["env_kwargs"], **config["train_env_kwargs"]}  # the training distribution, odometry
    seed = config["pretrain"].get("seed", 50000)
    dataset_id = f"agri/{family(coverage)}/gonzalez-deliberative-v0"
    request = DatasetRequest(coverage, "gonzalez-deliberative", dataset_id, 1, seed, env_kwargs=scene)
    make_dataset(request, progress=False)
    # gonzalez-deliberative drove on the true pose; the learner (odometry) sees its own env, stepped in lockstep.
    shown = demonstrate(PretrainSpec.from_config(config["pretrain"]), config)
    data_hp = {**hp, "pretrain": {**hp["pretrain"], "dataset": dataset_id}}
    data_config = resolve_config(TrainRequest(coverage, "ppo", tmp_path / "data", seed=0, overrides=data_hp))
    _, from_data = demonstrate_dataset(PretrainSpec.from_config(data_config["pretrain"]), data_config)
    for key in shown.observations:
        np.testing.assert_array_equal(from_data.observations[key], shown.observations[key])
    np.testing.assert_array_equal(from_data.actions, shown.actions)
    np.testing.assert_array_equal(from_data.rewards, shown.rewards)
    # A dataset whose arguments change the rewards is refused, naming the dynamics.
    other = f"agri/{family(coverage)}/slow-v0"
    slower = DatasetRequest(coverage, "gonzalez-deliberative", other, 1, seed, env_kwargs={**scene, "reward_time": 0.5})
    make_dataset(slower, progress=False)
    with pytest.raises(ValueError, match=re.escape(f"change {coverage}'s dynamics")):
        demonstrate_dataset(PretrainSpec(dataset=other, episodes=1, seed=seed), data_config)
    with pytest.raises(ValueError, match=re.escape(f"ran {coverage}, not")):
        demonstrate_dataset(
            PretrainSpec(dataset=other, episodes=1, seed=seed), {**data_config, "env_id": "agri_envs/GreenhouseNav-v2"}
        )


def test_the_chain_clones_from_its_dataset_robot_by_robot_as_live(tmp_path):
    from agri_training.learned.pretrain import PretrainSpec, demonstrate, demonstrate_dataset
    from agri_training.train import TrainRequest, resolve_config

    pretrain = {"policy": "apoorva-chain", "episodes": 1, "seed": 50000, "dagger_rounds": 0}
    hp = {"env_kwargs": {"n_robots": 3}, "pretrain": pretrain}
    config = resolve_config(TrainRequest("robot_chain_v1", "ppo", tmp_path / "run", seed=0, overrides=hp))
    dataset_id = "agri/robot_chain_v1/apoorva-chain-v0"
    kwargs = {**config["env_kwargs"], **config.get("train_env_kwargs", {})}
    make_dataset(
        DatasetRequest("robot_chain_v1", "apoorva-chain", dataset_id, 1, 50000, env_kwargs=kwargs), progress=False
    )
    shown = demonstrate(PretrainSpec.from_config(config["pretrain"]), config)
    _, from_data = demonstrate_dataset(PretrainSpec.from_config({**pretrain, "dataset": dataset_id}), config)
    for name in ("observations", "actions", "rewards", "episode_ends", "successes", "episodes"):
        np.testing.assert_array_equal(getattr(from_data, name), getattr(shown, name))
    four = {**config, "env_kwargs": {"n_robots": 4}}
    with pytest.raises(ValueError, match="differs from the training env in"):
        demonstrate_dataset(PretrainSpec.from_config({**pretrain, "dataset": dataset_id}), four)
