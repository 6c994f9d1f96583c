"""Training sweeps (agri train --seeds/--grid) and the Ray Tune search (agri tune)."""

import csv
import json

import numpy as np
import pytest
import yaml

from agri_training.cli import main
from agri_training.sweep import SweepRequest, parse_grid, plan_sweep, read_curve, run_sweep
from agri_training.tune import Param, TuneRequest, load_space, parse_param, run_tune

ENV_ID = "agri_envs/GreenhouseNav-v2"
TINY_HP = {
    "n_envs": 2,
    "env_kwargs": {"n_rows": 1, "row_length": 3.0, "n_people": 0, "max_episode_steps": 40},
    # the tiny fixed scene: no training distribution (the YAML draws scenes), which would override it
    "train_env_kwargs": {"scene_distribution": "off"},
    "eval_env_kwargs": {"scene_distribution": "off"},
    "algo_kwargs": {"n_steps": 32, "batch_size": 32},
    "policy_kwargs": {"net_arch": {"pi": [16], "vf": [16]}},
    "eval_freq": 64,
    "eval_episodes": 2,
    "checkpoint_freq": 0,
}
GRID = {"algo_kwargs.n_epochs": (1, 2)}
RUN_FILES = ("policy.pt", "normalize.json", "config.yaml", "meta.json", "curve.csv", "command.txt")


def _request(out, seeds=(0, 1), grid=GRID, **kwargs):
    return SweepRequest(ENV_ID, "ppo", out, seeds=seeds, grid=grid, timesteps=128, overrides=TINY_HP, **kwargs)


@pytest.fixture(scope="module")
def pool_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "pool"
    doc = run_sweep(_request(out), workers=2, progress=False, command="test")
    return out, doc


def test_sweep_writes_one_run_folder_per_point_and_seed(pool_sweep):
    out, doc = pool_sweep
    names = ["n_epochs=1-seed0", "n_epochs=1-seed1", "n_epochs=2-seed0", "n_epochs=2-seed1"]
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == names
    assert [r["run"] for r in doc["summary"]["runs"]] == names
    for name in names:
        for f in RUN_FILES:
            assert (out / name / f).is_file(), (name, f)
        config = yaml.safe_load((out / name / "config.yaml").read_text())
        assert config["algo_kwargs"]["n_epochs"] == int(name[9]) and config["seed"] == int(name[-1])
        assert config["torch_threads"] == 1 and config["n_envs"] == 2 and config["timesteps"] == 128
        command = (out / name / "command.txt").read_text()
        assert command.startswith(f"agri train --env {ENV_ID} --algo ppo --seed {name[-1]} --timesteps 128")
        assert f"n_epochs: {name[9]}" in command
    assert "2 worker processes" in doc["backend"]


def test_summary_numbers_are_the_runs_final_evaluations(pool_sweep):
    out, doc = pool_sweep
    finals = {}
    for row in doc["summary"]["runs"]:
        curve = read_curve(out / row["run"] / "curve.csv")
        assert row["status"] == "ok" and row["timesteps"] == int(curve[-1]["timesteps"]) >= 128
        assert row["final_success_rate"] == curve[-1]["success_rate"]
        assert row["final_mean_return"] == curve[-1]["mean_return"]
        assert row["best_success_rate"] == max(r["success_rate"] for r in curve)
        finals[row["run"]] = curve[-1]
    with (out / "summary.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert [r["run"] for r in table] == [r["run"] for r in doc["summary"]["runs"]]
    for r in table:
        assert float(r["final_mean_return"]) == finals[r["run"]]["mean_return"]
        assert r["algo_kwargs.n_epochs"] == r["run"][9]
    assert json.loads((out / "sweep.json").read_text())["summary"] == json.loads(json.dumps(doc["summary"]))
    for point in doc["summary"]["points"]:
        n = point["point"]["algo_kwargs.n_epochs"]
        returns = [finals[f"n_epochs={n}-seed{s}"]["mean_return"] for s in (0, 1)]
        stat = point["final_mean_return"]
        assert point["ok"] == point["runs"] == 2
        assert stat["mean"] == pytest.approx(np.mean(returns))
        lo, hi = stat["ci"]
        assert min(returns) - 1e-12 <= lo <= stat["mean"] <= hi <= max(returns) + 1e-12
    md = (out / "summary.md").read_text()
    assert "percentile bootstrap of the mean across seeds" in md and "| algo_kwargs.n_epochs=2 | 2/2 |" in md


def test_bad_grid_specs_raise_clear_errors(tmp_path):
    assert parse_grid(["algo_kwargs.learning_rate=1e-4,3e-4", "policy_kwargs.net_arch=[64,64],[32]"]) == {
        "algo_kwargs.learning_rate": (1e-4, 3e-4),
        "policy_kwargs.net_arch": ([64, 64], [32]),
    }
    with pytest.raises(ValueError, match="--grid expects KEY=V1,V2"):
        parse_grid(["algo_kwargs.learning_rate"])
    with pytest.raises(ValueError, match="unknown hyperparameter 'learning_rate'.*valid: n_timesteps"):
        parse_grid(["learning_rate=1e-4,3e-4"])
    with pytest.raises(ValueError, match="empty value"):
        parse_grid(["algo_kwargs.gamma=0.9,,0.99"])
    with pytest.raises(ValueError, match="repeats a value"):
        parse_grid(["algo_kwargs.gamma=0.9,0.90"])
    with pytest.raises(ValueError, match="given twice"):
        parse_grid(["n_envs=1", "n_envs=2"])
    with pytest.raises(ValueError, match="dotted hyperparameter path"):
        parse_grid(["algo_kwargs..gamma=0.9"])
    # A value that does not resolve fails before any run starts, naming its grid point and seed.
    with pytest.raises(ValueError, match=r"seed 3, grid point eval_episodes=200000: eval seeds must lie"):
        plan_sweep(_request(tmp_path / "a", seeds=(3,), grid={"eval_episodes": (2, 200000)}))
    with pytest.raises(ValueError, match="vec_env 'subproc'.*one CPU"):
        plan_sweep(_request(tmp_path / "b", grid={"vec_env": ("subproc",)}))
    with pytest.raises(ValueError, match="seeds must be distinct"):
        _request(tmp_path / "c", seeds=(1, 1))
    assert not (tmp_path / "a").exists()


def test_a_failing_run_is_reported_with_its_seed_and_the_others_finish(tmp_path, capsys):
    out = tmp_path / "sweep"
    hp = ["n_envs=2", "env_kwargs={n_rows: 1, row_length: 3.0, n_people: 0, max_episode_steps: 40}",
          "algo_kwargs={n_steps: 32}", "policy_kwargs={net_arch: {pi: [8], vf: [8]}}", "eval_freq=64",
          "eval_episodes=1", "checkpoint_freq=0", "train_env_kwargs={scene_distribution: 'off'}",
          "eval_env_kwargs={scene_distribution: 'off'}"]  # fmt: skip
    # PPO refuses batch_size 1 when it builds the model, i.e. inside the run, after planning succeeded.
    grid = ["--seeds", "7", "--grid", "algo_kwargs.batch_size=1,32", "--workers", "1", "--quiet"]
    code = main(["train", "--env", ENV_ID, "--algo", "ppo", "--timesteps", "64", "--out", str(out), *grid, "--hp", *hp])
    captured = capsys.readouterr()
    assert code == 1
    assert "1 of 2 runs failed" in captured.err
    assert "run batch_size=1-seed7 (seed 7, algo_kwargs.batch_size=1) failed: AssertionError" in captured.err
    doc = json.loads((out / "sweep.json").read_text())
    failed, ok = doc["summary"]["runs"]
    assert failed["status"] == "failed" and failed["seed"] == 7 and "AssertionError" in failed["error"]
    assert "batch_size" in doc["tracebacks"]["batch_size=1-seed7"]
    assert "seed 7, grid point algo_kwargs.batch_size=1" in (out / "batch_size=1-seed7" / "error.txt").read_text()
    assert ok["status"] == "ok" and (out / "batch_size=32-seed7" / "policy.pt").is_file()
    assert "- batch_size=1-seed7 (seed 7, grid point algo_kwargs.batch_size=1): AssertionError" in (
        out / "summary.md"
    ).read_text()
    assert doc["summary"]["points"][0]["failed_seeds"] == [7] and doc["summary"]["points"][1]["ok"] == 1


def test_cli_keeps_single_runs_apart_from_sweeps(tmp_path, capsys):
    base = ["train", "--env", ENV_ID, "--algo", "ppo", "--out", str(tmp_path / "x")]
    assert main([*base, "--workers", "2"]) == 2
    assert "spread the runs of a sweep" in capsys.readouterr().err
    assert main([*base, "--seed", "1", "--seeds", "1", "2"]) == 2
    assert "either --seed (one run) or --seeds" in capsys.readouterr().err
    assert main([*base, "--seeds", "0", "--grid", "lr=1,2"]) == 2
    assert "unknown hyperparameter 'lr'" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_ray_sweep_gives_the_pool_sweeps_runs(pool_sweep, tmp_path):
    out, doc = pool_sweep
    ray_out = tmp_path / "ray"
    ray_doc = run_sweep(_request(ray_out), workers=2, ray="local", progress=False, command="test")
    assert ray_doc["backend"].startswith("Ray (local)")
    for row in doc["summary"]["runs"]:
        name = row["run"]
        assert (ray_out / name / "config.yaml").read_text() == (out / name / "config.yaml").read_text()
        strip = [{k: v for k, v in r.items() if k != "wall_time_s"} for r in read_curve(out / name / "curve.csv")]
        assert strip == [
            {k: v for k, v in r.items() if k != "wall_time_s"} for r in read_curve(ray_out / name / "curve.csv")
        ]
    drop = ("wall_time_s", "cpu_time_s")
    assert [{k: v for k, v in r.items() if k not in drop} for r in ray_doc["summary"]["runs"]] == [
        {k: v for k, v in r.items() if k not in drop} for r in doc["summary"]["runs"]
    ]


def test_search_space_parsing(tmp_path):
    assert parse_param("algo_kwargs.learning_rate=loguniform:1e-5:1e-3") == (
        "algo_kwargs.learning_rate",
        Param("loguniform", (1e-5, 1e-3)),
    )
    assert parse_param("policy_kwargs.net_arch=choice:[64,64],[32]") == (
        "policy_kwargs.net_arch",
        Param("choice", ([64, 64], [32])),
    )
    space = tmp_path / "space.yaml"
    space.write_text("algo_kwargs.gamma: {uniform: [0.9, 0.99]}\nalgo_kwargs.n_epochs: [1, 2]\n")
    assert load_space(space) == {
        "algo_kwargs.gamma": Param("uniform", (0.9, 0.99)),
        "algo_kwargs.n_epochs": Param("choice", (1, 2)),
    }
    with pytest.raises(ValueError, match="needs low > 0"):
        parse_param("algo_kwargs.learning_rate=loguniform:0:1e-3")
    with pytest.raises(ValueError, match="low < high"):
        parse_param("algo_kwargs.gamma=uniform:0.99:0.9")
    with pytest.raises(ValueError, match="kind must be one of uniform"):
        parse_param("algo_kwargs.gamma=normal:0:1")
    with pytest.raises(ValueError, match="randint needs integer bounds"):
        parse_param("algo_kwargs.n_epochs=randint:1:2.5")
    with pytest.raises(ValueError, match="--param expects KEY=KIND"):
        parse_param("algo_kwargs.gamma=0.9")
    with pytest.raises(ValueError, match="unknown hyperparameter 'gamma'"):
        parse_param("gamma=uniform:0.9:0.99")
    with pytest.raises(ValueError, match="search space is empty"):
        TuneRequest(ENV_ID, "ppo", tmp_path, space={})


@pytest.mark.slow
def test_tune_search_on_local_ray_reports_and_writes_the_best(tmp_path):
    out = tmp_path / "tune"
    space = {
        "algo_kwargs.learning_rate": Param("loguniform", (1e-5, 1e-3)),
        "algo_kwargs.n_epochs": Param("choice", (1, 2)),
    }
    request = TuneRequest(ENV_ID, "ppo", out, space=space, samples=3, timesteps=128, overrides=TINY_HP)
    best = run_tune(request, ray="local", workers=2, progress=False)
    with (out / "trials.csv").open() as fh:
        trials = list(csv.DictReader(fh))
    assert len(trials) == 3 and all(t["status"] == "ok" for t in trials)
    for t in trials:
        run = out / "trials" / t["trial_id"]
        config = yaml.safe_load((run / "config.yaml").read_text())
        assert config["algo_kwargs"]["learning_rate"] == pytest.approx(float(t["algo_kwargs.learning_rate"]))
        assert 1e-5 <= config["algo_kwargs"]["learning_rate"] <= 1e-3 and config["algo_kwargs"]["n_epochs"] in (1, 2)
        assert float(t["final_mean_return"]) == read_curve(run / "curve.csv")[-1]["mean_return"]
    assert best["value"] == max(float(t["final_mean_return"]) for t in trials)
    assert yaml.safe_load((out / "best.yaml").read_text())["hyperparameters"] == best["hyperparameters"]
    assert best["command"].startswith(f"agri train --env {ENV_ID} --algo ppo --seed 0 --timesteps 128")
