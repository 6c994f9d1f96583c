"""The Python API for training scripts: load any policy, evaluate it on a pinned suite, get an entry's document.

    from pathlib import Path

    import gymnasium as gym
    from stable_baselines3 import PPO

    import agri_envs  # registers the envs
    import agri_training

    env = gym.make("agri_envs/GreenhouseNav-v2", localization="ground_truth")
    model = PPO("MultiInputPolicy", env).learn(10_000)
    needs = {"localization": "ground_truth"}  # what the live model needs of the suite's env
    doc = agri_training.evaluate_suite(model, "greenhouse-corridor", env_kwargs=needs, episodes=5)  # a quick check
    print(doc["summary"]["success_rate"])

    model.save("model.zip")  # read without unpickling, acting the same on every CPU
    Path("model.zip.yaml").write_text("env_kwargs: {localization: ground_truth}")  # its needs, in its sidecar
    doc = agri_training.evaluate_suite("model.zip", "greenhouse-corridor")  # what `agri leaderboard submit` records

Both accept every policy format of :mod:`agri_training.evaluation.reference`; :func:`evaluate_suite` also takes a
live object (anything with SB3's ``predict``, or a callable from observation to action), which runs in this
process.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from agri_training.evaluation.batched import BATCH_SIZE
from agri_training.evaluation.policies import load_policy
from agri_training.evaluation.reference import PolicyRef, resolve_policy
from agri_training.leaderboard.entries import evaluate_entries
from agri_training.leaderboard.suites import ROOT, SUITES_DIR, Suite, find_suite

__all__ = ["evaluate_suite", "load_policy"]


def evaluate_suite(
    policy: str | Path | PolicyRef | Any,
    suite: str | Suite,
    *,
    name: str | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    episodes: int | None = None,
    workers: int | None = 1,
    progress: bool = False,
    batch: int = BATCH_SIZE,
    suites_dir: Path | str = SUITES_DIR,
) -> dict[str, Any]:
    """Evaluate a policy on a named suite and return the document a leaderboard entry holds.

    Args:
        policy: A registered name, an ``agri train`` run folder, a ``.onnx`` or SB3 ``.zip`` file,
            ``module:attribute``, a :class:`~agri_training.evaluation.reference.PolicyRef`, or a live object with
            SB3's ``predict`` (an SB3 model) or a callable from observation to action.
        suite: A suite's name (``leaderboard/suites/<name>.yaml``) or a loaded :class:`Suite`.
        name: Display name of the policy in the document.
        env_kwargs: Env arguments the policy needs beyond the suite's (a live model's ``localization``, say):
            added to the policy's own needs; one that contradicts the suite's is refused. A file's needs belong
            in its sidecar, where ``agri leaderboard verify`` finds them again.
        episodes: Fewer episodes per level than the suite pins (a quick check in a training loop; the document
            then is not comparable with the suite's entries).
        workers: Worker processes (1: this process; a live object runs in this process only).
        progress: Show a progress bar.
        batch: Most episodes stepped together in the env's batched form (see :func:`agri_training.evaluation.
            evaluate.evaluate_many`); the records are the same.
        suites_dir: Where the suites live.

    Returns:
        The entry's document: ``suite``, ``policy``, ``env_id``, ``privileged``, ``summary`` (pooled) and
        ``levels`` (each with its ``env_kwargs``, ``summary`` and ``episodes``).

    Raises:
        ValueError: For an unknown suite or policy, a policy for another env, env arguments that contradict the
            suite's, or a live object with ``workers != 1``.
    """
    chosen = suite if isinstance(suite, Suite) else find_suite(suite, suites_dir)
    if episodes is not None:
        if episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {episodes}")
        chosen = dataclasses.replace(chosen, episodes=min(episodes, chosen.episodes))
    ref = resolve_policy(policy, name, ROOT)
    if env_kwargs:
        ref = dataclasses.replace(ref, env_kwargs={**ref.env_kwargs, **env_kwargs})
    command = f"agri_training.evaluate_suite({ref.spec!r}, {chosen.name!r})"
    (entry,) = evaluate_entries([(chosen, ref)], workers, progress, command, batch=batch)
    return entry
