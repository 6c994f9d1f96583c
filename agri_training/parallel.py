"""Run evaluation episodes on every local core (worker processes) or on a Ray cluster, identically to a serial run.

The unit of work is one :class:`EpisodeJob`: an env (id + resolved arguments), a policy and one seed.
:func:`run_episodes` runs a list of jobs and returns their outputs (what
:func:`agri_training.evaluate.run_episode` returns) in the order of the jobs, whichever worker ran which
job, so every record equals the serial one except its ``wall_time_s``. Three backends:

- ``workers=1``: in this process, one episode after the other (the reference).
- ``workers=N > 1``: a pool of N worker processes (``forkserver`` start method, so no thread or pybullet
  client of the caller is forked). Each worker builds an env once per configuration and reuses it across
  the seeds it is handed (``reset(seed=...)`` re-seeds everything; ``tests/test_parallel.py`` checks
  reused envs against fresh ones). The policy is built afresh for every episode, on every backend: not
  every policy forgets everything on ``episode_start`` (``luo-apf``'s sampling stream runs on across
  episodes), and an episode's record must depend on its seed only, not on which episodes its worker ran
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
import multiprocessing
import os
import sys
import traceback
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

import gymnasium as gym

RAY_EXTRA_HINT = 'pip install -e ".[ray]"'

#: Per-process cache of built envs (and their trace keys), keyed by :meth:`EpisodeJob.config_key`. A worker
#: usually sees one configuration at a time (jobs are handed out in order), so a few entries suffice.
_CACHE: OrderedDict[str, tuple[gym.Env[Any, Any], tuple[str, ...]]] = OrderedDict()
_CACHE_SIZE = 2


@dataclasses.dataclass(frozen=True)
class EpisodeJob:
    """One episode to run.

    Attributes:
        env_id: Registered env id.
        env_kwargs: Resolved ``gym.make`` arguments (JSON-able).
        policy: Baseline name or checkpoint path (what :func:`agri_training.evaluate.load_policy` accepts).
        seed: Seed of ``env.reset``.
        trace: Whether the episode records the env's per-step ``trace_keys``.
    """

    env_id: str
    env_kwargs: Mapping[str, Any]
    policy: str
    seed: int
    trace: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed must be an int >= 0, got {self.seed!r}")

    def config_key(self) -> str:
        """Identity of the (env, policy) pair the job runs on; equal keys share a built env and policy."""
        return json.dumps([self.env_id, dict(self.env_kwargs), self.policy], sort_keys=True, default=repr)

    def describe(self) -> str:
        """``seed S of POLICY on ENV_ID (args)``, for messages."""
        args = ", ".join(f"{k}={v!r}" for k, v in sorted(self.env_kwargs.items()))
        return f"seed {self.seed} of {self.policy} on {self.env_id}" + (f" ({args})" if args else "")


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


def default_workers() -> int:
    """The number of cores this process may use (the ``--workers`` default)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def limit_torch_threads() -> None:
    """One intra-op thread for torch, when torch is loaded, so that parallel workers do not oversubscribe."""
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def _env_for(job: EpisodeJob) -> tuple[gym.Env[Any, Any], tuple[str, ...]]:
    key = job.config_key()
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    while len(_CACHE) >= _CACHE_SIZE:
        _CACHE.popitem(last=False)[1][0].close()
    from agri_training.multiagent import is_multiagent, make_env

    multi = is_multiagent(job.env_id)  # PettingZoo envs (the robot chain) are not Gymnasium ids
    env: Any = make_env(job.env_id, job.env_kwargs) if multi else gym.make(job.env_id, **job.env_kwargs)
    _CACHE[key] = (env, tuple(getattr(env, "unwrapped", env).metadata.get("trace_keys", ())))
    return _CACHE[key]


def clear_cache() -> None:
    """Close and forget the envs built in this process."""
    while _CACHE:
        _CACHE.popitem()[1][0].close()


def run_job(job: EpisodeJob) -> dict[str, Any]:
    """Run one job in this process, on the env of an earlier job with the same configuration and a fresh policy.

    Returns:
        ``{"ok": True, "out": run_episode's output}``, or ``{"ok": False, "stage": "build" | "episode",
        "error": ..., "exc_type": ..., "traceback": ...}`` when building or running raised (so that every
        backend reports failures the same way, and a failed build's ``ValueError`` stays a user error).
    """
    from agri_training.evaluate import load_policy, run_episode

    stage = "build"
    try:
        env, trace_keys = _env_for(job)
        policy = load_policy(job.policy, env)
        limit_torch_threads()  # loading an SB3 checkpoint imports torch
        stage = "episode"
        out = run_episode(env, policy, job.seed, trace_keys if job.trace else None)
    except Exception as exc:  # reported to the caller with the job's seed
        if stage == "episode":  # the env may be left mid-episode in a bad state: rebuild it next time
            _CACHE.pop(job.config_key())[0].close()
        return {
            "ok": False,
            "stage": stage,
            "exc_type": type(exc).__name__,
            "error": f"{type(exc).__name__}: {exc}",
            "traceback": traceback.format_exc(),
        }
    return {"ok": True, "out": out}


def _unwrap(job: EpisodeJob, result: dict[str, Any]) -> dict[str, Any]:
    if result["ok"]:
        out: dict[str, Any] = result["out"]
        return out
    if result["stage"] == "build" and result["exc_type"] == "ValueError":
        # A bad env argument or policy name: the same clear user error as in a serial run.
        raise ValueError(result["error"].removeprefix("ValueError: "))
    raise EpisodeError(job, result["error"], result["traceback"])


def _worker_init() -> None:
    limit_torch_threads()


#: ``on_result(index, job, output)``: called in this process as each job finishes (in completion order).
ResultCallback = Callable[[int, EpisodeJob, dict[str, Any]], None]


def run_episodes(
    jobs: Sequence[EpisodeJob],
    workers: int | None = None,
    ray: str | None = None,
    on_result: ResultCallback | None = None,
) -> list[dict[str, Any]]:
    """Run the jobs and return their outputs in job order (each as :func:`~agri_training.evaluate.run_episode`).

    Args:
        jobs: The episodes.
        workers: Worker processes (None: :func:`default_workers`; 1: in this process). With ``ray``, the
            number of CPUs of a ``"local"`` Ray instance (None: all).
        ray: None (local workers), ``"local"``, ``"auto"`` or a Ray cluster address.
        on_result: Called in this process as each job finishes, e.g. for progress.

    Raises:
        ValueError: For ``workers < 1``, a missing ``ray`` extra, or an env/policy that cannot be built.
        EpisodeError: When an episode raises (the run stops; unfinished jobs are cancelled).
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be an int >= 1, got {workers!r}")
    if not jobs:
        return []
    if ray is not None:
        return _run_ray(jobs, ray, workers, on_result)
    n = min(workers if workers is not None else default_workers(), len(jobs))
    if n == 1:
        return _run_serial(jobs, on_result)
    return _run_pool(jobs, n, on_result)


def _run_serial(jobs: Sequence[EpisodeJob], on_result: ResultCallback | None) -> list[dict[str, Any]]:
    outs = []
    try:
        for i, job in enumerate(jobs):
            out = _unwrap(job, run_job(job))
            outs.append(out)
            if on_result is not None:
                on_result(i, job, out)
    finally:
        clear_cache()
    return outs


def _pool_context() -> Any:
    methods = multiprocessing.get_all_start_methods()
    if "forkserver" not in methods:
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    # Workers fork from a server that has imported the envs and baselines once (numba kernels loaded).
    ctx.set_forkserver_preload(["agri_training.parallel", "agri_training.evaluate", "agri_envs", "agri_baselines"])
    return ctx


def _run_pool(jobs: Sequence[EpisodeJob], n: int, on_result: ResultCallback | None) -> list[dict[str, Any]]:
    outs: list[dict[str, Any] | None] = [None] * len(jobs)
    with ProcessPoolExecutor(max_workers=n, mp_context=_pool_context(), initializer=_worker_init) as pool:
        # Hand jobs out one at a time, in order, at most 2 per worker in flight: jobs of one configuration
        # stay together on a worker (its cached env is reused) and the tail of the run stays balanced.
        pending: dict[Future[dict[str, Any]], int] = {}
        next_job = 0
        try:
            while next_job < len(jobs) or pending:
                while next_job < len(jobs) and len(pending) < 2 * n:
                    pending[pool.submit(run_job, jobs[next_job])] = next_job
                    next_job += 1
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in sorted(done, key=pending.__getitem__):
                    i = pending.pop(fut)
                    out = _unwrap(jobs[i], fut.result())
                    outs[i] = out
                    if on_result is not None:
                        on_result(i, jobs[i], out)
        except BaseException:
            for fut in pending:
                fut.cancel()
            raise
    return [o for o in outs if o is not None]


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ValueError(f"--ray needs Ray, the optional 'ray' extra: {RAY_EXTRA_HINT}") from None
    return ray


def _ray_job(job: EpisodeJob) -> dict[str, Any]:
    limit_torch_threads()
    return run_job(job)


def init_ray(address: str, workers: int | None = None) -> bool:
    """Connect to Ray: ``"local"`` starts a private instance, else join ``address`` (``"auto"`` or a cluster).

    Returns:
        Whether this call started Ray here (the caller then shuts it down with ``ray.shutdown()``).

    Raises:
        ValueError: Without the ``ray`` extra, or for an empty address.
    """
    ray = _import_ray()
    if not address:
        raise ValueError("--ray expects 'local', 'auto' or a cluster address HOST:PORT, got an empty string")
    if ray.is_initialized():
        return False
    if address == "local":
        ray.init(
            num_cpus=workers if workers is not None else default_workers(),
            include_dashboard=False,
            logging_level="ERROR",
            log_to_driver=False,
        )
    else:
        ray.init(address=address, logging_level="ERROR")
    return True


def _run_ray(
    jobs: Sequence[EpisodeJob], address: str, workers: int | None, on_result: ResultCallback | None
) -> list[dict[str, Any]]:
    ray = _import_ray()
    started = init_ray(address, workers)
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(_ray_job)
        refs = [task.remote(job) for job in jobs]
        index = {ref: i for i, ref in enumerate(refs)}
        outs: list[dict[str, Any] | None] = [None] * len(jobs)
        remaining = list(refs)
        try:
            while remaining:
                done, remaining = ray.wait(remaining, num_returns=1)
                for ref in done:
                    i = index[ref]
                    out = _unwrap(jobs[i], ray.get(ref))
                    outs[i] = out
                    if on_result is not None:
                        on_result(i, jobs[i], out)
        except BaseException:
            for ref in remaining:
                ray.cancel(ref, force=True)
            raise
        return [o for o in outs if o is not None]
    finally:
        if started:
            ray.shutdown()
