"""``agri dataset``: any policy on any env of the package, its episodes written as a Minari dataset.

::

    agri dataset --env agri_envs/GreenhouseNav-v2 --policy harik-apf-gt --training-distribution
                 --episodes 50 --seed 0 --dataset-id agri/GreenhouseNav-v2/harik-apf-gt-v0

Episode ``i`` is reset with seed ``S + i`` and driven exactly as ``agri evaluate`` drives it (the same jobs,
workers and episode loop, :mod:`agri_training.evaluation.parallel`), with a
:class:`~agri_training.evaluation.recording.StepRecorder` between loop and env. The env's arguments are the
scenario's (``--scenario``), the user's (``--env-kwargs``), ``scene_distribution="training"``
(``--training-distribution``) and what the policy needs (e.g. harik-apf-gt's ``full_scan`` and true pose), resolved
as evaluation resolves them; the dataset's env spec holds exactly those. What the dataset holds is described
in :mod:`agri_training.core.datasets`.

Everything that can be refused is refused before an episode runs: a policy of another env, seeds at or above
:data:`agri_training.leaderboard.HELD_OUT_SEED` (held out for evaluation), a scenario that sweeps an argument
(a dataset describes one env), arguments that JSON cannot hold, an existing id without ``overwrite``.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import agri_envs
from agri_envs.scenarios import scenario as get_scenario
from agri_training.core.datasets import DatasetEnv, DatasetWriter, EpisodeSteps, check_dataset_id, dataset_path
from agri_training.core.documents import EpisodeOutput, git_commit
from agri_training.core.progress import Progress
from agri_training.evaluation.parallel import EpisodeJob, run_episodes
from agri_training.evaluation.policies import EvalRequest, resolve_env_kwargs
from agri_training.evaluation.reference import resolve_policy
from agri_training.leaderboard import HELD_OUT_SEED


@dataclasses.dataclass(frozen=True)
class DatasetRequest:
    """What to record.

    Attributes:
        env_id: Registered env id (Gymnasium or PettingZoo).
        policy: Registered policy name or ``agri train`` run (what ``agri evaluate`` accepts).
        dataset_id: Minari id, e.g. ``agri/GreenhouseNav-v2/harik-apf-gt-v0``.
        episodes: Episodes (seeds ``seed .. seed + episodes - 1``), >= 1.
        seed: First seed, >= 0; the last must lie below ``HELD_OUT_SEED``.
        scenario: Name of an env-argument preset, or None.
        env_kwargs: Extra env arguments.
        training_distribution: Draw every episode's scene from the env's training distribution
            (``scene_distribution="training"``; only envs that declare one).
        overwrite: Replace a dataset already under the id.
    """

    env_id: str
    policy: str
    dataset_id: str
    episodes: int = 100
    seed: int = 0
    scenario: str | None = None
    env_kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    training_distribution: bool = False
    overwrite: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.episodes, bool) or not isinstance(self.episodes, int) or self.episodes < 1:
            raise ValueError(f"episodes must be an int >= 1, got {self.episodes!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be an int >= 0, got {self.seed!r}")
        last = self.seed + self.episodes - 1
        if last >= HELD_OUT_SEED:
            raise ValueError(
                f"seeds {self.seed}..{last} reach the held-out seeds ({HELD_OUT_SEED} and up, kept for evaluation): "
                f"a dataset's last seed must lie below {HELD_OUT_SEED}"
            )


def default_env(policy: str) -> str:
    """The env a policy drives (``--env`` may then be left out): a registered one's, a run's, a sidecar's.

    Raises:
        ValueError: For a policy that does not say which env it drives (then give ``--env``).
    """
    env_id = resolve_policy(policy).env_id
    if env_id is None:
        raise ValueError(f"{policy!r} does not say which env it drives: give --env")
    return env_id


def default_dataset_id(env_id: str, policy: str) -> str:
    """``agri/<env name>/<policy>-v0`` (a run: its folder name), e.g. ``agri/GreenhouseNav-v2/harik-apf-gt-v0``."""
    return f"agri/{env_id.split('/')[-1]}/{Path(policy.rstrip('/')).name}-v0"


def resolve_dataset_env(request: DatasetRequest) -> DatasetEnv:
    """The env the episodes run in: id and arguments (scenario, user's, training distribution, the policy's needs).

    The arguments are passed through JSON, as the dataset stores them, so the episodes run with exactly what
    the dataset describes.

    Raises:
        ValueError: For an unknown env, a policy of another env, a sweeping scenario, an env without a training
            distribution asked for one, or arguments JSON cannot hold.
    """
    if request.env_id not in agri_envs.env_ids():
        raise ValueError(f"unknown env id {request.env_id!r}; known: {', '.join(agri_envs.env_ids())}")
    base: dict[str, Any] | None = None
    if request.scenario:
        sc = get_scenario(request.env_id, request.scenario)
        if sc.sweep is not None:
            raise ValueError(
                f"scenario {request.scenario!r} sweeps {sc.sweep[0]} over {list(sc.sweep[1])}: a dataset describes "
                f"one env; add --env-kwargs {sc.sweep[0]}=VALUE"
            )
        base = dict(sc.env_kwargs)
    user = dict(request.env_kwargs)
    if request.training_distribution:
        if agri_envs.training_distribution(request.env_id) is None:
            raise ValueError(
                f"{request.env_id} declares no training distribution (scene_distribution); its default arguments "
                "already draw a new scene per seed: leave out --training-distribution"
            )
        if user.get("scene_distribution", "training") != "training":
            raise ValueError(f"--training-distribution contradicts scene_distribution={user['scene_distribution']!r}")
        user["scene_distribution"] = "training"
    eval_request = EvalRequest(request.env_id, request.policy, scenario=request.scenario, env_kwargs=user)
    kwargs, _ = resolve_env_kwargs(eval_request, base)
    try:
        stored = json.loads(json.dumps(kwargs, allow_nan=False))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"the env arguments {kwargs} cannot be stored in a dataset's spec (JSON): {exc}") from None
    return DatasetEnv(request.env_id, stored, agri_envs.is_parallel_id(request.env_id))


def make_dataset(
    request: DatasetRequest, workers: int | None = 1, ray: str | None = None, progress: bool = True
) -> dict[str, Any]:
    """Run the episodes and write the dataset (see the module doc).

    Args:
        request: What to record.
        workers: Worker processes (1: in this process; None: one per core), as ``agri evaluate``'s.
        ray: Run the episodes as Ray tasks (``"local"``, ``"auto"`` or an address).
        progress: A progress bar (or plain lines in a log) over the episodes.

    Returns:
        A summary: ``dataset_id``, ``path``, ``episodes``, ``trajectories`` (Minari episodes: one per agent and
        run on a PettingZoo env), ``steps``, ``successes``, ``size_mb``, ``seconds``, ``env_id``, ``env_kwargs``.

    Raises:
        ValueError: For bad input (nothing is written then).
        agri_training.evaluation.parallel.EpisodeError: When an episode raises (nothing is written then).
    """
    check_dataset_id(request.dataset_id)
    if dataset_path(request.dataset_id).exists() and not request.overwrite:
        raise ValueError(
            f"dataset {request.dataset_id} exists at {dataset_path(request.dataset_id)}; add --overwrite to replace it"
        )
    described = resolve_dataset_env(request)
    env = described.make()  # bad arguments fail here, before anything is written
    t0 = time.perf_counter()
    try:
        with DatasetWriter(request.dataset_id, env, described, request.overwrite) as writer:
            summary = _record(request, described, writer, workers, ray, progress)
            path = writer.commit(request.policy, _description(request, described), _extra(request))
    finally:
        env.close()
    size = sum(f.stat().st_size for f in Path(path).rglob("*") if f.is_file())
    return {
        "dataset_id": request.dataset_id,
        "path": str(path),
        **summary,
        "size_mb": size / 1e6,
        "seconds": time.perf_counter() - t0,
        "env_id": described.env_id,
        "env_kwargs": dict(described.env_kwargs),
    }


def _record(
    request: DatasetRequest,
    described: DatasetEnv,
    writer: DatasetWriter,
    workers: int | None,
    ray: str | None,
    progress: bool,
) -> dict[str, Any]:
    """Run the jobs; write each episode as soon as those before it are written (seed order, bounded memory)."""
    policy = resolve_policy(request.policy)  # once for every job
    jobs = [
        EpisodeJob(described.env_id, described.env_kwargs, policy, request.seed + i, record=True)
        for i in range(request.episodes)
    ]
    bar = Progress(len(jobs), 1, progress)
    bar.start_block(f"{request.policy} on {described.env_id.split('/')[-1]} -> {request.dataset_id}")
    waiting: dict[int, list[EpisodeSteps]] = {}
    written = {"next": 0, "trajectories": 0, "steps": 0, "successes": 0}

    def on_result(index: int, job: EpisodeJob, out: EpisodeOutput) -> None:
        bar.episode_done(out["record"])
        written["successes"] += bool(out["record"].get("is_success"))
        waiting[index] = out.pop("steps")
        while written["next"] in waiting:
            for trajectory in waiting.pop(written["next"]):
                writer.add(trajectory, written["next"])
                written["trajectories"] += 1
                written["steps"] += trajectory.steps
            written["next"] += 1

    try:
        run_episodes(jobs, workers=workers, ray=ray, on_result=on_result)
    finally:
        bar.close()
    return {
        "episodes": written["next"],
        "trajectories": written["trajectories"],
        "steps": written["steps"],
        "successes": written["successes"],
    }


def _description(request: DatasetRequest, described: DatasetEnv) -> str:
    where = "its training distribution" if request.training_distribution else "its given arguments"
    if request.scenario:
        where = f"scenario {request.scenario}"
    form = (
        " Every robot's trajectory is one Minari episode (metadata: agent, run, seed)."
        if described.parallel
        else " One Minari episode per run (metadata: run, seed)."
    )
    return (
        f"{request.policy} on {described.env_id} ({where}), seeds {request.seed}..{request.seed + request.episodes - 1}"
        f", written by `agri dataset`.{form} Replay: reset the env with an episode's seed and step its actions."
    )


def _extra(request: DatasetRequest) -> dict[str, Any]:
    return {
        "seeds": [request.seed, request.seed + request.episodes - 1],
        "scenario": request.scenario,
        "training_distribution": request.training_distribution,
        "package_version": agri_envs.__version__,
        "git_commit": git_commit(),
        "command": " ".join(sys.argv),
    }
