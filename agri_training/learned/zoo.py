"""The trained policies that ship with the package, registered by name like the scripted baselines.

Each lives in ``agri_training/zoo/NAME/``: the run directory of the ``agri train`` command in its
``train_command`` (weights, observation statistics, config, curve). Importing this module registers them
in :mod:`agri_baselines`' policy registry, so ``agri evaluate --policy NAME``, the leaderboard and the
report treat them like baselines; :mod:`agri_training.evaluation` imports it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from agri_baselines import PolicySpec, register_policy
from agri_training.learned.policy import LearnedPolicy

#: Where the committed trained policies live (one folder per registered name).
ZOO_DIR = Path(__file__).resolve().parent.parent / "zoo"


def zoo_path(name: str) -> Path:
    """Folder of a committed trained policy."""
    return ZOO_DIR / name


def load_zoo_policy(env: Any, name: str) -> LearnedPolicy:
    """Entry point of the registered trained policies: the committed run folder ``zoo/NAME``."""
    return LearnedPolicy(zoo_path(name), env)


register_policy(
    PolicySpec(
        name="sac-her-grape-reach",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"min_clusters": 1, "max_clusters": 1, "n_leaves": 0, "n_canes": 0, "control": "ee"},
        description="Learned (SAC + HER, 80k steps, agri_training/zoo/sac-her-grape-reach): the single-goal preset",
        learned=True,
        algo="sac",
        train_command="agri train --env agri_envs/GrapeHarvest-v1 --scenario reach --algo sac --her --seed 0 "
        "--out runs/grape-reach-sac-her",
    )
)

register_policy(
    PolicySpec(
        name="ppo-greenhouse-nav",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        description="Learned (PPO, agri_training/zoo/ppo-greenhouse-nav): LIDAR, sonar and the next two waypoints "
        "from the ground-truth pose, its last 3 observations; acts every 4th step",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --seed 0 --out runs/nav-ppo",
    )
)

register_policy(
    PolicySpec(
        name="ppo-coverage-almeria",
        env_id="agri_envs/GreenhouseCoverage-v0",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        description="Learned (PPO on sonar, compass and odometry, agri_training/zoo/ppo-coverage-almeria): the "
        "almeria scenario",
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseCoverage-v0 --scenario almeria --algo ppo --seed 0 "
        "--out runs/cover-ppo",
    )
)
