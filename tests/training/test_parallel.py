"""Episodes on worker processes and Ray tasks give the serial run's records; failures name their seed."""

import json
import sys

import pytest

import agri_envs
from agri_baselines import list_policies
from agri_training.cli import main
from agri_training.evaluation import parallel
from agri_training.evaluation.episode import run_episode
from agri_training.evaluation.evaluate import evaluate, evaluate_many
from agri_training.evaluation.parallel import EpisodeError, EpisodeJob, run_episodes, run_job
from agri_training.evaluation.policies import EvalRequest, load_policy, resolve_env_kwargs
from agri_training.evaluation.reference import PolicyRef
from agri_training.leaderboard.entries import compare_documents

NAV = "agri_envs/GreenhouseNav-v2"
GRAPE = "agri_envs/GrapeHarvest-v1"
SMALL_NAV = {"n_rows": 1, "row_length": 3}


def _requests():
    return [
        EvalRequest(NAV, "harik-apf-gt", episodes=4, seed=7, env_kwargs=SMALL_NAV, record_traces=2),
        EvalRequest(GRAPE, "luo-apf", episodes=3, seed=2, record_traces=1),
        EvalRequest(NAV, "harik-apf", episodes=3, seed=0, env_kwargs=SMALL_NAV, record_traces=3),
        EvalRequest(NAV, "harik-apf-gt", episodes=1, seed=3, scenario="plant-development"),
        EvalRequest(NAV, "harik-apf-gt", episodes=4, seed=20, env_kwargs=SMALL_NAV, campaign_runs=2),
    ]


def test_pool_documents_equal_serial():
    serial = evaluate_many(_requests(), progress=False, workers=1)
    pooled = evaluate_many(_requests(), progress=False, workers=2)
    assert [[e["seed"] for e in d["episodes"]] for d in pooled[:3]] == [[7, 8, 9, 10], [2, 3, 4], [0, 1, 2]]
    assert [lv["label"] for lv in pooled[3]["levels"]] == [lv["label"] for lv in serial[3]["levels"]]
    assert compare_documents(pooled, serial) == []
    # the traces came back too, and are the first episodes' ones
    assert [t["seed"] for t in pooled[0]["traces"]] == [7, 8] and len(pooled[2]["traces"]) == 3
    assert all(e["wall_time_s"] > 0 for d in pooled[:3] for e in d["episodes"])
    # campaigns: two worlds (layout_seed = each campaign's first seed), runs 0 and 1 in each
    campaign = pooled[4]["episodes"]
    assert [(e["seed"], e["campaign_run"], e["layout_seed"]) for e in campaign] == [
        (20, 0, 20),
        (21, 1, 20),
        (22, 0, 22),
        (23, 1, 22),
    ]
    assert pooled[4]["campaign_runs"] == 2 and pooled[4]["summary"]["later_runs_episodes"] == 2
    assert [t["seed"] for t in pooled[4]["traces"]] == [20, 21]  # every run of the first campaign


def test_a_campaign_keeps_its_policy_between_runs():
    """gonzalez-hybrid in one job of two runs: the second run plans on the first run's sensory map."""
    kw = {"localization": "odometry", "n_rows": 2, "row_length": 6.0, "layout_seed": 4}
    result = run_job(EpisodeJob("agri_envs/GreenhouseCoverage-v2", kw, "gonzalez-hybrid", 4, runs=2))
    first, second = (out["record"] for out in result["outs"])
    assert first["hybrid_deliberative"] == 0 and second["hybrid_deliberative"] == 1
    assert [first["campaign_run"], second["campaign_run"], second["seed"]] == [0, 1, 5]
    # episode by episode, every run is a fresh policy's first
    alone = run_job(EpisodeJob("agri_envs/GreenhouseCoverage-v2", kw, "gonzalez-hybrid", 5))
    assert alone["outs"][0]["record"]["hybrid_deliberative"] == 0


@pytest.mark.parametrize("spec", list_policies(), ids=lambda s: s.name)
def test_reused_env_equals_fresh_one(spec):
    """A worker reuses its env across the seeds it is handed, in any order: nothing may leak between episodes."""
    small = {GRAPE: {"max_clusters": 3}, "agri_envs/GreenhouseNav-v2": SMALL_NAV}.get(spec.env_id, {})
    small = {k: v for k, v in small.items() if k not in spec.env_kwargs}  # e.g. the one-cluster reach policy
    kwargs, _ = resolve_env_kwargs(EvalRequest(spec.env_id, spec.name, env_kwargs=small))
    seeds = [5, 1, 5]
    parallel.clear_cache()
    try:
        reused = [run_job(EpisodeJob(spec.env_id, kwargs, spec.name, s, trace=True)) for s in seeds]
    finally:
        parallel.clear_cache()
    assert all(r["ok"] for r in reused), reused
    for seed, r in zip(seeds, reused, strict=True):
        env = agri_envs.make(spec.env_id, **kwargs)
        try:
            keys = tuple(getattr(env, "unwrapped", env).metadata.get("trace_keys", ()))
            fresh = run_episode(env, load_policy(spec.name, env), seed, keys)
        finally:
            env.close()
        assert compare_documents(r["outs"][0], fresh) == []


def test_episode_error_names_seed_and_exception(monkeypatch):
    real = parallel.run_episode

    def flaky(env, policy, seed, trace_keys):
        if seed == 4:
            raise FloatingPointError("pose became NaN")
        return real(env, policy, seed, trace_keys)

    monkeypatch.setattr(parallel, "run_episode", flaky)
    kwargs, _ = resolve_env_kwargs(EvalRequest(NAV, "harik-apf-gt", env_kwargs=SMALL_NAV))
    jobs = [EpisodeJob(NAV, kwargs, "harik-apf-gt", s) for s in (3, 4, 5)]
    seen = []
    with pytest.raises(EpisodeError) as info:
        run_episodes(jobs, workers=1, on_result=lambda i, job, out: seen.append(job.seed))
    msg = str(info.value)
    assert "seed 4 of harik-apf-gt" in msg and "FloatingPointError: pose became NaN" in msg
    assert "flaky" in info.value.remote_traceback and info.value.job.seed == 4
    assert seen == [3]


def test_worker_failure_names_seed(tmp_path):
    """In a worker process: a policy file that went after it was resolved fails every job; the first one is named."""
    bad = tmp_path / "broken.onnx"
    ref = PolicyRef("onnx", "broken", str(bad), "onnx", path=str(bad), observation_only=True)
    jobs = [EpisodeJob(NAV, SMALL_NAV, ref, s) for s in (11, 12)]
    with pytest.raises(EpisodeError, match=r"episode with seed 1[12] of .*broken\.onnx on agri_envs/GreenhouseNav-v2"):
        run_episodes(jobs, workers=2)


def test_build_value_error_stays_a_user_error():
    jobs = [EpisodeJob(NAV, {"n_row": 2}, "harik-apf-gt", s) for s in (0, 1)]
    with pytest.raises(ValueError, match="n_row"):
        run_episodes(jobs, workers=2)


def test_campaign_runs_must_divide_the_episodes():
    with pytest.raises(ValueError, match="campaign_runs must be >= 1 and divide episodes"):
        EvalRequest(NAV, "harik-apf-gt", episodes=5, campaign_runs=2)
    with pytest.raises(ValueError, match="runs must be an int >= 1"):
        EpisodeJob(NAV, {}, "harik-apf-gt", 0, runs=0)


def test_bad_arguments():
    with pytest.raises(ValueError, match="workers must be an int >= 1"):
        run_episodes([EpisodeJob(NAV, {}, "harik-apf-gt", 0)], workers=0)
    with pytest.raises(ValueError, match="seed must be an int >= 0"):
        EpisodeJob(NAV, {}, "harik-apf-gt", -1)
    with pytest.raises(ValueError, match="episodes must be >= 1"):
        evaluate(EvalRequest(NAV, "harik-apf-gt", episodes=0), progress=False)
    assert run_episodes([], workers=2) == []


def test_cli_workers_argument(tmp_path, capsys):
    out = tmp_path / "ev.json"
    args = ["evaluate", "--env", NAV, "--policy", "harik-apf-gt", "--episodes", "2", "--seed", "1", "--quiet"]
    args += ["--env-kwargs", "n_rows=1", "row_length=3", "--out", str(out)]
    with pytest.raises(SystemExit):
        main([*args, "--workers", "0"])
    assert "--workers: expects an integer >= 1" in capsys.readouterr().err
    assert main([*args, "--workers", "2"]) == 0
    doc = json.loads(out.read_text())
    assert [e["seed"] for e in doc["episodes"]] == [1, 2]


def test_ray_missing_names_the_extra(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    args = ["evaluate", "--env", NAV, "--policy", "harik-apf-gt", "--episodes", "1", "--quiet"]
    rc = main([*args, "--out", str(tmp_path / "x.json"), "--ray", "local"])
    assert rc == 2 and 'pip install -e ".[ray]"' in capsys.readouterr().err


def test_ray_local_equals_serial():
    pytest.importorskip("ray")
    requests = _requests()[:2]
    serial = evaluate_many(requests, progress=False, workers=1)
    on_ray = evaluate_many(requests, progress=False, workers=2, ray="local")
    assert compare_documents(on_ray, serial) == []
    import ray

    assert not ray.is_initialized()  # the private instance was shut down
