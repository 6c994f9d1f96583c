"""Episodes stepped together in an env's batched form give the reference loop's records and traces, bit for bit."""

import shutil

import numpy as np
import pytest
import torch

import agri_baselines
from agri_baselines import PolicySpec, register_policy
from agri_training import leaderboard as lb
from agri_training.evaluation import batched, parallel
from agri_training.evaluation.batched import batchable, has_batched_form
from agri_training.evaluation.evaluate import episode_jobs, evaluate_many
from agri_training.evaluation.parallel import EpisodeError, EpisodeJob, run_episodes
from agri_training.evaluation.policies import EvalRequest, resolve_env_kwargs
from agri_training.evaluation.reference import resolve_policy
from agri_training.leaderboard.entries import compare_documents
from agri_training.learned.policy import LearnedPolicy
from agri_training.learned.zoo import ZOO_DIR

NAV = "agri_envs/GreenhouseNav-v2"


def _entry(suite: str, policy: str) -> dict:
    return next(e for e in lb.load_entries() if e["suite"]["name"] == suite and e["policy"]["name"] == policy)


@pytest.mark.parametrize(
    ("suite", "policy", "episodes"),
    [
        ("greenhouse-corridor", "ppo-greenhouse-nav", 20),  # learned; lengths 79-1323 steps: the last ones re-run
        ("greenhouse-sim-loop", "harik-apf", 3),  # Hector SLAM: the trajectory error of its own pose estimate
        ("greenhouse-sim-loop", "dagger-greenhouse-nav-slam", 3),  # learned, on its own SLAM: one map per episode
        ("greenhouse-default", "ppo-greenhouse-nav-general-shielded", 3),  # behind a safety layer, people about
        pytest.param("greenhouse-repeatability", "harik-apf-gt", 2, marks=pytest.mark.slow),  # 10 missions, TimeLimit
    ],
)
def test_batched_episodes_are_the_committed_entry(suite, policy, episodes):
    """The committed records (made one episode at a time) come out of a batch, and the same out of the loop.

    (``agri leaderboard verify``, batched by default, compares every committed entry the same way.)
    """
    entry = _entry(suite, policy)
    level = entry["levels"][0]
    s = lb.find_suite(suite)
    request = EvalRequest(
        s.env_id, lb.policy_argument(entry["policy"]), episodes, s.seed_start, env_kwargs=dict(level["env_kwargs"])
    )
    together, alone = (evaluate_many([request], progress=False, batch=b)[0] for b in (16, 1))
    assert compare_documents(together["episodes"], level["episodes"][:episodes]) == []
    assert compare_documents(together, alone) == []
    assert all(e["wall_time_s"] > 0 for e in together["episodes"])


def test_traces_and_reruns_match_the_reference_loop(monkeypatch):
    """Traces of every step (reset row included), and episodes the batch hands back to single envs."""
    kwargs = {"n_rows": 1, "row_length": 3.0, "n_people": 2}
    request = EvalRequest(NAV, "harik-apf", episodes=6, seed=40, env_kwargs=kwargs, record_traces=6)
    reference = evaluate_many([request], progress=False, batch=1)[0]
    reruns = []
    real = parallel.run_episode

    def counted(env, policy, seed, trace_keys):
        reruns.append(seed)
        return real(env, policy, seed, trace_keys)

    monkeypatch.setattr(parallel, "run_episode", counted)
    for cost, rerun in ((1e-9, True), (1e9, False)):  # hand back at once, or never
        monkeypatch.setattr(batched, "SINGLE_STEP_COST", cost)
        reruns.clear()
        doc = evaluate_many([request], progress=False, batch=6)[0]
        assert bool(reruns) == rerun
        assert compare_documents(doc, reference) == []
        assert [t["seed"] for t in doc["traces"]] == list(range(40, 46))
        first = doc["traces"][0]["data"]
        assert len(first["x"]) == doc["episodes"][0]["steps"] + 1 and "slam_x" in first


def test_which_policies_run_batched(monkeypatch):
    assert has_batched_form(NAV) and has_batched_form("agri_envs/GreenhouseCoverage-v2")
    assert not has_batched_form("robot_chain_v1") and not has_batched_form("agri_envs/GrapeHarvest-v1")
    ref = resolve_policy
    assert not batchable("agri_envs/GreenhouseCoverage-v2", ref("gonzalez-pseudo-reactive"))  # it reads the env
    assert batchable(NAV, ref("harik-apf")) and batchable(NAV, ref("ppo-greenhouse-nav"))
    assert batchable(NAV, ref(str(ZOO_DIR / "ppo-greenhouse-nav")))  # a run folder: a learned policy
    assert not batchable("agri_envs/GrapeHarvest-v1", ref("luo-apf"))
    # a registered policy stays for the whole process (the report evaluates every one): registered for this test only
    monkeypatch.setattr(agri_baselines, "_REGISTRY", dict(agri_baselines._REGISTRY))
    register_policy(PolicySpec("test-reads-the-env", NAV, "agri_baselines.harik_apf:make_harik_apf_gt"))
    assert not batchable(NAV, ref("test-reads-the-env"))  # observation_only is opt-in


def test_levels_split_into_balanced_batches_with_traced_episodes_apart():
    kwargs, _ = resolve_env_kwargs(EvalRequest(NAV, "harik-apf-gt"))
    request = EvalRequest(NAV, "harik-apf-gt", episodes=50, seed=100, record_traces=1)
    jobs = episode_jobs(request, kwargs, batch=16)
    assert [(j.seed, j.batch, j.trace) for j in jobs] == [
        (100, 1, True),
        (101, 13, False),
        (114, 12, False),
        (126, 12, False),
        (138, 12, False),
    ]
    assert [j.batch for j in episode_jobs(request, kwargs, batch=1)] == [1] * 50
    luo = EvalRequest("agri_envs/GrapeHarvest-v1", "luo-apf", episodes=5)
    assert [j.batch for j in episode_jobs(luo, resolve_env_kwargs(luo)[0], batch=16)] == [1] * 5
    with pytest.raises(ValueError, match="batch must be"):
        episode_jobs(request, kwargs, batch=0)
    with pytest.raises(ValueError, match="campaign .* or a batch"):
        EpisodeJob(NAV, kwargs, "harik-apf-gt", 0, runs=2, batch=2)


def test_a_failing_episode_of_a_batch_is_named_by_its_seed(monkeypatch):
    """The batch raises; its episodes then run one by one in the reference loop, and the one that raises is named."""
    from agri_baselines.harik_apf import HarikApfPolicy
    from agri_envs.rover.greenhouse_nav import GreenhouseNavEnv

    reset, predict, make = GreenhouseNavEnv.reset, HarikApfPolicy.predict, parallel.build_policy

    def remember_seed(self, *, seed=None, options=None):
        self.test_seed = seed
        return reset(self, seed=seed, options=options)

    def flaky(self, observation, state=None, episode_start=None, deterministic=True):
        if self.env.unwrapped.test_seed == 12:
            raise FloatingPointError("pose became NaN")
        return predict(self, observation, state, episode_start, deterministic)

    def load(name, env):
        policy = make(name, env)
        policy.env = env
        return policy

    monkeypatch.setattr(GreenhouseNavEnv, "reset", remember_seed)
    monkeypatch.setattr(HarikApfPolicy, "predict", flaky)
    monkeypatch.setattr(parallel, "build_policy", load)
    kwargs, _ = resolve_env_kwargs(EvalRequest(NAV, "harik-apf-gt", env_kwargs={"n_rows": 1, "row_length": 3.0}))
    with pytest.raises(EpisodeError, match=r"seed 12 of harik-apf-gt .*FloatingPointError: pose became NaN"):
        run_episodes([EpisodeJob(NAV, kwargs, "harik-apf-gt", 10, batch=4)], workers=1)


def test_jobs_start_longest_first_and_come_back_in_job_order():
    kwargs = {"n_rows": 1, "row_length": 3.0, "full_scan": True, "localization": "ground_truth"}
    jobs = [EpisodeJob(NAV, kwargs, "harik-apf-gt", s) for s in (1, 2, 3, 4)]
    started = []
    outs = run_episodes(jobs, workers=1, priority=[1, 5, 0, 3], on_result=lambda i, j, o: started.append(j.seed))
    assert started == [2, 4, 1, 3]
    assert [o["record"]["seed"] for o in outs] == [1, 2, 3, 4]
    with pytest.raises(ValueError, match="priority"):
        run_episodes(jobs, workers=1, priority=[1.0])


def test_learned_policies_share_their_network_until_the_weights_change(tmp_path):
    import gymnasium as gym

    folder = tmp_path / "nav"
    shutil.copytree(ZOO_DIR / "ppo-greenhouse-nav", folder)
    env = gym.make(NAV, localization="ground_truth")
    first, second = LearnedPolicy(folder, env), LearnedPolicy(folder, env)
    assert first.network is second.network and first._replay is not second._replay
    state = torch.load(folder / "policy.pt", weights_only=True)
    state["action_net.bias"] += 1.0
    torch.save(state, folder / "policy.pt")
    third = LearnedPolicy(folder, env)
    assert third.network is not first.network
    assert np.allclose(third.network.output[1], first.network.output[1] + 1.0)


def test_evaluation_runs_robust_scenes_on_single_envs():
    # The evaluator batches observation-only policies where the batched form takes the arguments; here it does not.
    from agri_training.evaluation.batched import has_batched_form

    assert has_batched_form("agri_envs/GreenhouseNav-v2", {"scene_distribution": "training"})
    assert not has_batched_form("agri_envs/GreenhouseNav-v2", {"scene_distribution": "robust"})
