"""Run evaluation episodes on every local core (worker processes) or on a Ray cluster, identically to a serial run.

The unit of work is one :class:`EpisodeJob`: an env (id + resolved arguments), a policy and one seed, or
a campaign of ``runs`` episodes on seeds ``seed .. seed + runs - 1`` that one policy drives one after the
other, keeping what it learned (:func:`run_campaign`). :func:`run_episodes` runs a list of jobs and
returns their episodes' outputs (what :func:`agri_training.evaluate.run_episode` returns) in the order of
the jobs and of their seeds, whichever worker ran which job, so every record equals the serial one except
its ``wall_time_s``. Three backends:

- ``workers=1``: in this process, one episode after the other (the reference).
- ``workers=N > 1``: a pool of N worker processes (``forkserver`` start method, so no thread or pybullet
  client of the caller is forked). Each worker builds an env once per configuration and reuses it across
  the seeds it is handed (``reset(seed=...)`` re-seeds everything; ``tests/training/test_parallel.py`` checks
  reused envs against fresh ones). The policy is built afresh for every job, on every backend: not
  every policy forgets everything on ``episode_start`` (``luo-apf``'s sampling stream runs on across
  episodes), and an episode's record must depend on its job only, not on which jobs its worker ran
  before. Building a baseline policy costs microseconds.
- ``ray=ADDRESS``: the same jobs as Ray tasks of one CPU each. ``"local"`` starts a private Ray instance
  for this run and shuts it down at the end; ``"auto"`` joins the cluster started on this machine with
  ``ray start``; anything else is a cluster address (``HOST:PORT`` or ``ray://HOST:PORT``). Ray is the
  optional ``ray`` extra.

Worker processes (and Ray tasks) limit torch to one thread, so that N workers use N cores, not N^2. An
episode that raises stops the run with :class:`EpisodeError`, which names the seed, the policy, the env
and the exception, with the worker's traceback.
"""

from __future__ import annotations

import dataclasses
import json
import traceback
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium as gym

import agri_envs
from agri_training.core.documents import EpisodeOutput
from agri_training.core.pool import limit_torch_threads, run_items
from agri_training.evaluation.batched import run_batch
from agri_training.evaluation.episode import run_episode
from agri_training.evaluation.recording import StepRecorder
from agri_training.evaluation.reference import PolicyRef, build_policy, resolve_policy

#: Per-process cache of built envs (and their trace keys), keyed by :meth:`EpisodeJob.config_key`. A worker
#: usually sees one configuration at a time (jobs are handed out in order), so a few entries suffice.
_CACHE: OrderedDict[str, tuple[gym.Env[Any, Any], tuple[str, ...]]] = OrderedDict()
#: The same for the batched forms (:func:`_vector_env_for`), keyed by configuration and number of sub-envs.
_VECTOR_CACHE: OrderedDict[str, Any] = OrderedDict()
_CACHE_SIZE = 2


@dataclasses.dataclass(frozen=True)
class EpisodeJob:
    """One episode to run.

    Attributes:
        env_id: Registered env id.
        env_kwargs: Resolved ``gym.make`` arguments (JSON-able).
        policy: The resolved policy (anything else that :func:`~.reference.resolve_policy` takes is resolved
            when the job is made).
        seed: Seed of ``env.reset`` (of a campaign's first run).
        trace: Whether the episode (every run of the campaign) records the env's per-step ``trace_keys``.
        runs: Episodes of the campaign, on seeds ``seed .. seed + runs - 1``, driven by one policy; 1: a
            single episode.
        batch: Episodes on seeds ``seed .. seed + batch - 1``, each with a fresh policy, stepped together in
            the env's batched form (:mod:`agri_training.evaluation.batched`); their records are the
            reference loop's. Only for policies that :func:`~agri_training.evaluation.batched.batchable` allows.
        record: Keep every step for a dataset (:class:`~agri_training.evaluation.recording.StepRecorder`): the
            episode's output then also holds ``steps``, its trajectories. One episode a job (no campaign, no
            batch).
    """

    env_id: str
    env_kwargs: Mapping[str, Any]
    policy: PolicyRef | str
    seed: int
    trace: bool = False
    runs: int = 1
    batch: int = 1
    record: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.policy, PolicyRef):
            object.__setattr__(self, "policy", resolve_policy(self.policy))
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed must be an int >= 0, got {self.seed!r}")
        for name in ("runs", "batch"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name} must be an int >= 1, got {value!r}")
        if self.runs > 1 and self.batch > 1:
            raise ValueError(
                f"a job is a campaign (runs > 1) or a batch (batch > 1), got runs={self.runs}, batch={self.batch}"
            )
        if self.record and self.episodes > 1:
            raise ValueError(f"a recording job runs one episode, got runs={self.runs}, batch={self.batch}")

    @property
    def ref(self) -> PolicyRef:
        """The resolved policy."""
        assert isinstance(self.policy, PolicyRef)
        return self.policy

    @property
    def episodes(self) -> int:
        """The episodes the job runs (seeds ``seed .. seed + episodes - 1``)."""
        return max(self.runs, self.batch)

    def config_key(self) -> str:
        """Identity of the (env, policy) pair the job runs on; equal keys share a built env and policy."""
        return json.dumps([self.env_id, dict(self.env_kwargs), self.ref.key()], sort_keys=True, default=repr)

    def describe(self) -> str:
        """``seed S of POLICY on ENV_ID (args)`` (``campaign of R runs from seed S ...``), for messages."""
        args = ", ".join(f"{k}={v!r}" for k, v in sorted(self.env_kwargs.items()))
        what = f"seed {self.seed}"
        if self.runs > 1:
            what = f"campaign of {self.runs} runs from seed {self.seed}"
        elif self.batch > 1:
            what = f"seeds {self.seed}..{self.seed + self.batch - 1} (batched)"
        return f"{what} of {self.ref.spec} on {self.env_id}" + (f" ({args})" if args else "")


class EpisodeError(RuntimeError):
    """An episode raised. The message names the job (seed, policy, env) and the exception.

    Attributes:
        job: The failing job.
        remote_traceback: The traceback printed where the episode ran (a worker or a Ray task).
    """

    def __init__(self, job: EpisodeJob, error: str, remote_traceback: str) -> None:
        super().__init__(f"episode with {job.describe()} failed: {error}")
        self.job = job
        self.remote_traceback = remote_traceback


def _env_for(job: EpisodeJob) -> tuple[gym.Env[Any, Any], tuple[str, ...]]:
    key = job.config_key()
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    while len(_CACHE) >= _CACHE_SIZE:
        _CACHE.popitem(last=False)[1][0].close()
    env = agri_envs.make(job.env_id, **job.env_kwargs)
    _CACHE[key] = (env, tuple(getattr(env, "unwrapped", env).metadata.get("trace_keys", ())))
    return _CACHE[key]


def _vector_key(job: EpisodeJob) -> str:
    return f"{job.config_key()}|batch {job.batch}"


def _vector_env_for(job: EpisodeJob) -> Any:
    """The env's batched form with ``job.batch`` sub-envs, built once per configuration and size (cached)."""
    key = _vector_key(job)
    if key in _VECTOR_CACHE:
        _VECTOR_CACHE.move_to_end(key)
        return _VECTOR_CACHE[key]
    while len(_VECTOR_CACHE) >= _CACHE_SIZE:
        _VECTOR_CACHE.popitem(last=False)[1].close()
    _VECTOR_CACHE[key] = gym.make_vec(job.env_id, num_envs=job.batch, **job.env_kwargs)
    return _VECTOR_CACHE[key]


def clear_cache() -> None:
    """Close and forget the envs built in this process."""
    while _CACHE:
        _CACHE.popitem()[1][0].close()
    while _VECTOR_CACHE:
        _VECTOR_CACHE.popitem()[1].close()


def run_campaign(
    env: gym.Env[Any, Any], policy: Any, seed: int, runs: int, trace_keys: tuple[str, ...] | None
) -> list[EpisodeOutput]:
    """A campaign: ``runs`` episodes on seeds ``seed, seed + 1, ...`` driven by one policy, one after the other.

    The policy is not rebuilt between runs, so what it keeps across episodes (the hybrid's sensory map) carries
    over: run k is the k-th time it drives this world. Each record gets ``campaign_run`` (0 for the first run).
    """
    outs = []
    for k in range(runs):
        out = run_episode(env, policy, seed + k, trace_keys)
        if runs > 1:
            out["record"]["campaign_run"] = k
        outs.append(out)
    return outs


def run_job(job: EpisodeJob) -> dict[str, Any]:
    """Run one job in this process, on the env of an earlier job with the same configuration and a fresh policy.

    Returns:
        ``{"ok": True, "outs": [run_episode's output per run]}``, or ``{"ok": False, "stage": "build" |
        "episode", "user_error": ..., "error": ..., "exc_type": ..., "traceback": ...}`` when building or
        running raised (so that every backend reports failures the same way, and a failed build's
        ``ValueError``, or a :class:`agri_envs.SetupError` a reset raised, stays a user error).
    """
    stage = "build"
    try:
        if job.batch > 1:
            envs = _vector_env_for(job)
            policies = [build_policy(job.ref, sub_env) for sub_env in envs.envs]
            limit_torch_threads()
            stage = "episode"
            try:
                outs = _run_batch_job(job, envs, policies)
            except Exception:
                # Which episode raised? Run them one by one in the reference loop: the one that raises there is
                # reported with its seed, as without batching. If none does, the batch's own error stands.
                _VECTOR_CACHE.pop(_vector_key(job)).close()
                singles = [dataclasses.replace(job, seed=job.seed + i, batch=1) for i in range(job.batch)]
                for single in singles:
                    if not (result := run_job(single))["ok"]:
                        return {**result, "seed": single.seed}
                raise
        else:
            env, trace_keys = _env_for(job)
            policy = build_policy(job.ref, env)
            limit_torch_threads()  # loading an SB3 checkpoint imports torch
            stage = "episode"
            if job.record:
                recorder = StepRecorder(env)
                outs = [run_episode(recorder, policy, job.seed, trace_keys if job.trace else None)]
                outs[0]["steps"] = recorder.episodes()
            else:
                outs = run_campaign(env, policy, job.seed, job.runs, trace_keys if job.trace else None)
    except Exception as exc:  # reported to the caller with the job's seed
        if stage == "episode":  # the envs may be left mid-episode in a bad state: rebuild them next time
            if (built := _CACHE.pop(job.config_key(), None)) is not None:
                built[0].close()
            if (batched := _VECTOR_CACHE.pop(_vector_key(job), None)) is not None:
                batched.close()
        return {
            "ok": False,
            "stage": stage,
            # The user's to fix, reported as one line: a bad argument while building, or arguments that a reset
            # found cannot be set up (a chain longer than its floor holds).
            "user_error": isinstance(exc, agri_envs.SetupError) or (stage == "build" and type(exc) is ValueError),
            "exc_type": type(exc).__name__,
            "error": f"{type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
        }
    return {"ok": True, "outs": outs}


def _run_batch_job(job: EpisodeJob, envs: Any, policies: list[Any]) -> list[EpisodeOutput]:
    """The episodes of a batch job in the env's batched form; the last few, if any, on the cached single env."""
    trace_keys = tuple(envs.envs[0].unwrapped.metadata.get("trace_keys", ())) if job.trace else None
    seeds = [job.seed + i for i in range(job.batch)]

    def rerun(i: int) -> EpisodeOutput:
        env, keys = _env_for(job)
        return run_episode(env, build_policy(job.ref, env), seeds[i], keys if job.trace else None)

    return run_batch(envs, policies, seeds, trace_keys, rerun)


def _unwrap(job: EpisodeJob, result: dict[str, Any]) -> list[EpisodeOutput]:
    if result["ok"]:
        outs: list[EpisodeOutput] = result["outs"]
        return outs
    if result.get("user_error"):
        # A bad env argument or policy name, or a setup the env refused: the same clear user error as in a
        # serial run.
        raise ValueError(result["error"].split(": ", 1)[-1])
    if "seed" in result:  # the episode of a batch that raised when run alone
        job = dataclasses.replace(job, seed=result["seed"], batch=1)
    raise EpisodeError(job, result["error"], result["traceback"])




#: ``on_result(index, job, output)``: called in this process for each episode as its job finishes (in
#: completion order); ``index`` counts episodes in job and seed order.
ResultCallback = Callable[[int, EpisodeJob, EpisodeOutput], None]

#: What the worker processes import once (numba kernels loaded, envs and baselines registered).
PRELOAD = ("agri_training.evaluation.parallel", "agri_envs", "agri_baselines")
#: ... and, when a job runs a learned policy, torch (its weights are read with ``torch.load``; about 2 s of imports
#: that every worker would pay on its first learned episode).
LEARNED_PRELOAD = ("torch",)


def _runs_learned(job: EpisodeJob) -> bool:
    return job.ref.needs_torch


def _lost(index: int, message: str) -> dict[str, Any]:
    return {"ok": False, "stage": "episode", "exc_type": "BrokenProcessPool", "error": message, "traceback": ""}


def run_episodes(
    jobs: Sequence[EpisodeJob],
    workers: int | None = None,
    ray: str | None = None,
    on_result: ResultCallback | None = None,
    priority: Sequence[float] | None = None,
) -> list[EpisodeOutput]:
    """Run the jobs and return their episodes' outputs in job and seed order (each as :func:`~.episode.run_episode`'s).

    Args:
        jobs: The episodes.
        workers: Worker processes (None: one per core; 1: in this process). With ``ray``, the number of CPUs
            of a ``"local"`` Ray instance (None: all).
        ray: None (local workers), ``"local"``, ``"auto"`` or a Ray cluster address.
        on_result: Called in this process as each job finishes, e.g. for progress.
        priority: The jobs' expected costs: they start in decreasing order (ties in job order), so that the
            longest do not come last and leave one worker running alone. None: job order.

    Raises:
        ValueError: For ``workers < 1``, a missing ``ray`` extra, or an env/policy that cannot be built.
        EpisodeError: When an episode raises (the run stops; unfinished jobs are cancelled).
    """
    first = [0]
    for job in jobs:
        first.append(first[-1] + job.episodes)
    outs: list[EpisodeOutput | None] = [None] * first[-1]

    if priority is not None and len(priority) != len(jobs):
        raise ValueError(f"priority: one value per job expected ({len(jobs)}), got {len(priority)}")
    order = sorted(range(len(jobs)), key=lambda j: -priority[j]) if priority is not None else list(range(len(jobs)))

    def done(k: int, result: dict[str, Any]) -> None:
        i = order[k]
        for r, out in enumerate(_unwrap(jobs[i], result)):
            outs[first[i] + r] = out
            if on_result is not None:
                on_result(first[i] + r, jobs[i], out)

    try:
        # Jobs go out in order (or longest first), two per worker in flight: jobs of one configuration stay
        # together on a worker (its cached env is reused) and the tail of the run stays balanced.
        preload = PRELOAD + (LEARNED_PRELOAD if any(_runs_learned(job) for job in jobs) else ())
        run_items(run_job, [jobs[i] for i in order], done, workers, ray, preload, _lost, in_flight_per_worker=2)
    finally:
        clear_cache()
    return [o for o in outs if o is not None]
