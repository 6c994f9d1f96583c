"""The trained policies that ship with the package, registered by name like the scripted baselines.

Each lives in ``agri_training/zoo/NAME/``: the run directory of the ``agri train`` command in its
``train_command`` (weights, observation statistics, config, curve). Importing this module registers them
in :mod:`agri_baselines`' policy registry, so ``agri evaluate --policy NAME``, the leaderboard and the
report treat them like baselines; :mod:`agri_training.evaluation` imports it.

Only the acting layers are ever read (:data:`agri_training.learned.inference.ACTOR_LAYERS`), so a folder may keep
just those, as every run now writes (:func:`agri_training.train.save_weights`); older folders may hold the whole
``state_dict``, and both act alike. Folders trimmed after their entries were made had those entries and their
validation documents re-made on the smaller files (every episode record as before), since entries record the
weights' sha256.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from agri_baselines import PolicySpec, policy_spec, register_policy
from agri_envs.arm.presets import REACH_PRESET
from agri_training.learned.goal_zoom import GoalZoom
from agri_training.learned.policy import LearnedPolicy, read_config

#: Where the committed trained policies live (one folder per registered name).
ZOO_DIR = Path(__file__).resolve().parent.parent / "zoo"


#: Registered names whose weights live in another policy's folder: one network, used two ways.
SHARED_FOLDERS = {
    "sac-her-grape-vine-eq11": "sac-her-grape-vine",
    "sac-her-grape-vine-shielded-zoom": "sac-her-grape-vine-shielded",
    "sac-her-grape-vine-shielded-zoom-homing": "sac-her-grape-vine-shielded",
    "dagger-greenhouse-nav-slam-odometry-shielded": "dagger-greenhouse-nav-slam-every-scan-shielded",
}

#: Deployment settings of a registered name on its shared folder: the arguments of the folder's observation
#: wrappers that it changes (:func:`agri_training.learned.policy.with_wrapper_settings`); the network is the folder's.
WRAPPER_SETTINGS: dict[str, dict[str, dict[str, Any]]] = {
    "dagger-greenhouse-nav-slam-odometry-shielded": {"SlamWaypoint": {"odometry": True}},
}


def zoo_path(name: str) -> Path:
    """Folder of a committed trained policy (its own, or the one it shares: :data:`SHARED_FOLDERS`)."""
    return ZOO_DIR / SHARED_FOLDERS.get(name, name)


def how_trained(config: Mapping[str, Any]) -> str:
    """How a run was trained, in a few words, from its resolved ``config.yaml``.

    ``imitation of harik-apf-gt, 8 DAgger rounds`` for a run of ``timesteps: 0`` with a ``pretrain`` block;
    ``imitation of apoorva-chain, 4 DAgger rounds, then PPO`` when the clone was fine-tuned; ``SAC + HER`` or
    ``PPO`` for a run that learned from its reward alone; a run with a ``safety_layer`` says so.
    """
    algo = str(config.get("algo", "?")).upper() + (" + HER" if config.get("her") else "")
    layer = f"; acts behind the safety layer {config['safety_layer']}" if config.get("safety_layer") else ""
    pretrain = config.get("pretrain")
    if not isinstance(pretrain, Mapping):
        return algo + layer
    teacher = pretrain.get("policy") or pretrain.get("dataset", "a baseline")
    parts = [f"imitation of {teacher}" + (" (a training teacher, no paper's)" if _is_teacher(teacher) else "")]
    rounds = int(pretrain.get("dagger_rounds") or 0)
    if rounds:
        parts.append(f"{rounds} DAgger rounds")
    text = ", ".join(parts)
    return (text if not config.get("timesteps") else f"{text}, then {algo}") + layer


def _is_teacher(name: str) -> bool:
    try:
        return policy_spec(name).teacher
    except ValueError:  # a dataset's id, or a policy registered elsewhere
        return False


def training_teacher(name: str) -> str | None:
    """The training teacher (``PolicySpec.teacher``) a committed trained policy was cloned from, or None."""
    if not (zoo_path(name) / "config.yaml").is_file():
        return None
    pretrain = read_config(zoo_path(name)).get("pretrain")
    teacher = pretrain.get("policy") if isinstance(pretrain, Mapping) else None
    return str(teacher) if teacher and _is_teacher(str(teacher)) else None


def zoo_training(name: str) -> str:
    """How a registered trained policy was trained: :func:`how_trained` of its zoo folder's config.

    A learned policy registered without a folder here says its registered algorithm (``PPO``).
    """
    if not (zoo_path(name) / "config.yaml").is_file():
        return str(policy_spec(name).algo).upper()
    return how_trained(read_config(zoo_path(name)))


def load_zoo_policy(env: Any, name: str) -> LearnedPolicy:
    """Entry point of the registered trained policies: the run folder ``zoo/NAME``, or the one it shares.

    A name with :data:`WRAPPER_SETTINGS` acts with them on its shared folder.
    """
    return LearnedPolicy(zoo_path(name), env, wrapper_settings=WRAPPER_SETTINGS.get(name))


def load_zoo_zoomed(env: Any, name: str) -> LearnedPolicy:
    """Entry point of a registered arm policy behind a goal zoom (the default :class:`GoalZoom`), on its folder."""
    return LearnedPolicy(zoo_path(name), env, goal_zoom=GoalZoom())


def load_zoo_zoomed_homing(env: Any, name: str) -> LearnedPolicy:
    """Entry point of a registered arm policy behind a goal zoom that drives its last stretch home in joint space."""
    return LearnedPolicy(zoo_path(name), env, goal_zoom=GoalZoom(), homing=True)


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
        name="ppo-greenhouse-nav-general",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        description="Learned (agri_training/zoo/ppo-greenhouse-nav-general): the inputs of ppo-greenhouse-nav, "
        "trained on the env's training distribution of greenhouses and office corridors: harik-apf-gt cloned "
        "with 4 DAgger rounds, then 2M decisions of PPO",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/ppo_generalization.yml --seed 1 --out runs/nav-dagger-s1",
    )
)

register_policy(
    PolicySpec(
        name="ppo-greenhouse-nav-general-shielded",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        description="ppo-greenhouse-nav-general's network (the same weights, retrained bit for bit) behind a safety "
        "layer: harik-apf's passive motion safety (stop, step back, wait while something is in front; slow down "
        "to stop short of it) on the pooled LIDAR and sonars, which only changes its speed, never its steering; "
        "its interventions are counted per episode (agri_training/learned/safety.py)",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/ppo_generalization.yml --seed 1 --hp safety_layer=harik-passive-safety "
        "--out runs/nav-shielded-s1",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-nav): the inputs of "
        "ppo-greenhouse-nav, its ranges also read as proximity; harik-apf-gt cloned on the env's training "
        "distribution with 8 DAgger rounds, no PPO steps",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_generalization.yml --seed 1 --out runs/nav-imitation-s1",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav-robust",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-nav-robust): dagger-greenhouse-nav's "
        "inputs plus the robot's own limits, deciding every 2nd scan; harik-apf-gt cloned with 8 DAgger rounds on the "
        "env's robust distribution (robots of 0.6-1.4 m/s, corridors 0.85-2.2 m, up to 8 people), no PPO steps",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_robust.yml --seed 0 --out runs/nav-robust-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav-robust-shielded",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth"},
        description="dagger-greenhouse-nav-robust's recipe (seed 1) behind the safety layer harik-passive-safety "
        "(harik-apf's passive motion safety over its speed; agri_training/learned/safety.py)",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_robust.yml --seed 1 --hp safety_layer=harik-passive-safety "
        "--out runs/nav-robust-shielded-s1",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav-slam-every-scan-shielded",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "none", "full_scan": True},
        description="The SLAM recipe with its Hector SLAM fed every LIDAR scan, not only the scans it decides on "
        "(dagger_slam_every_scan.yml, seed 0), behind the safety layer harik-passive-safety; nothing privileged. "
        "The line 'safety_layer: harik-passive-safety' was added to the run's config after training (the layer "
        "does not act in imitation; agri_training/learned/safety.py)",
        privileged=False,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_slam_every_scan.yml --seed 0 --out runs/nav-slam-every-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav-slam-odometry-shielded",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "none", "full_scan": True},
        description="dagger-greenhouse-nav-slam-every-scan-shielded (the same network and safety layer) whose Hector "
        "SLAM starts each scan match from the motion the robot's wheel odometry measured since the last scan (the "
        "observation's velocity) instead of its own constant-velocity prediction; no training, nothing privileged "
        "(agri_training/learned/slam_pose.py)",
        privileged=False,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_slam_every_scan.yml --seed 0 --out runs/nav-slam-every-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav-slam-shielded",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "none", "full_scan": True},
        description="dagger-greenhouse-nav-slam's recipe (seed 2) behind the safety layer harik-passive-safety, "
        "nothing privileged: the layer reads the pooled LIDAR and sonars and the robot's own limits, as harik-apf "
        "does (agri_training/learned/safety.py)",
        privileged=False,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_slam.yml --seed 2 --hp safety_layer=harik-passive-safety "
        "--out runs/nav-slam-shielded-s2",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-nav-slam",
        env_id="agri_envs/GreenhouseNav-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "none", "full_scan": True},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-nav-slam), nothing privileged: LIDAR, "
        "sonars, velocity and its own limits, the waypoint from its own Hector SLAM (harik-apf's) on the LIDAR; "
        "harik-apf-gt on the true pose labels it in lockstep, 8 DAgger rounds on the robust distribution, no PPO "
        "steps; deployed aiming 10 cm inside the waypoint radius, as harik-apf does",
        privileged=False,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseNav-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_slam.yml --seed 1 --out runs/nav-slam-s1",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-coverage",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-coverage): sonars read as left-right "
        "differences and ramps, compass, encoders and its own memory, no map; gonzalez-deliberative cloned on the "
        "env's training distribution with 8 DAgger rounds, no PPO steps",
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseCoverage-v2 --algo ppo --seed 2 --out runs/cov-dagger-s2",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-coverage-robust",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-coverage-robust): "
        "dagger-greenhouse-coverage's inputs and recipe on the env's robust distribution (corridors 1.3-2.5 m, 1-6 "
        "rows of 4-16 m, echoes up to 0.7, dead-reckoning errors up to the odometry suite's third level), no PPO "
        "steps",
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseCoverage-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_coverage_robust.yml --seed 0 --out runs/cov-robust-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-coverage-route",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth", "route_observation": True},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-coverage-route): the env's privileged "
        "route (the covering serpentine ahead of the true pose, and the true velocity) and the sonars read as "
        "dagger-greenhouse-coverage reads them; gonzalez-deliberative cloned on the env's robust distribution with 8 "
        "DAgger rounds, no PPO steps",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseCoverage-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_coverage_route_sonar.yml --seed 0 --out runs/cov-routes-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-greenhouse-coverage-half-circle",
        env_id="agri_envs/GreenhouseCoverage-v2",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={"localization": "ground_truth", "route_observation": True},
        description="Learned by imitation (agri_training/zoo/dagger-greenhouse-coverage-half-circle): the inputs of "
        "dagger-greenhouse-coverage-route (the privileged route and the sonars); cloned from the training teacher "
        "coverage-half-circle (no paper's controller: half-circle turns at the row ends) on the env's robust "
        "distribution with 8 DAgger rounds, the fit free past the speed limit, no PPO steps",
        privileged=True,
        learned=True,
        algo="ppo",
        train_command="agri train --env agri_envs/GreenhouseCoverage-v2 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_coverage_half_circle.yml --seed 2 --out runs/cov-half-s2",
    )
)

register_policy(
    PolicySpec(
        name="ppo-chain",
        env_id="robot_chain_v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={},
        description="Learned (agri_training/zoo/ppo-chain): one network shared by every robot, from its own 29 "
        "observations (sonars, pose, neighbours, slot, ghost, goal); cloned from apoorva-chain with 4 DAgger "
        "rounds, then 1M robot-steps of PPO on the env's reward; trained with 4 robots",
        learned=True,
        algo="ppo",
        train_command="agri train --env robot_chain_v1 --algo ppo --seed 0 --out runs/chain-dagger-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-chain-robust",
        env_id="robot_chain_v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={},
        description="Learned by imitation (agri_training/zoo/dagger-chain-robust): ppo-chain's network and inputs, "
        "apoorva-chain cloned with 6 noisy DAgger rounds on the env's robust distribution (offices of 14-24 x 9-14 m, "
        "greenhouses of 2-8 rows of 6-20 m, 0-12 dropped obstacles) with chains of 16 robots, no PPO steps",
        learned=True,
        algo="ppo",
        train_command="agri train --env robot_chain_v1 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_chain_robust.yml --seed 0 --out runs/chain-robust-s0",
    )
)

register_policy(
    PolicySpec(
        name="dagger-chain-long",
        env_id="robot_chain_v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={},
        description="Learned by imitation (agri_training/zoo/dagger-chain-long): dagger-chain-robust's network, "
        "inputs and recipe with chains of 32 robots instead of 16 (the robust distribution's floors drawn again "
        "until the chain fits, half the episodes), no PPO steps",
        learned=True,
        algo="ppo",
        train_command="agri train --env robot_chain_v1 --algo ppo --hyperparams "
        "agri_training/hyperparams/dagger_chain_long.yml --seed 2 --out runs/chain-long-s2",
    )
)

register_policy(
    PolicySpec(
        name="sac-her-grape-reach-strict",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs={**REACH_PRESET, "position_tolerance": 0.01, "orientation_tolerance": 0.2},
        description="Learned (SAC + HER, 100k steps, agri_training/zoo/sac-her-grape-reach-strict): one cluster "
        "anywhere in reach cut at 1 cm / 0.2 rad, the tolerance tightened from 3 cm / 0.35 rad in training",
        learned=True,
        algo="sac",
        train_command="agri train --env agri_envs/GrapeHarvest-v1 --scenario reach-strict --algo sac --her --seed 2 "
        "--out runs/reach-strict-s2",
    )
)

#: What the arm's whole-vine reach needs of the env: end-effector actions of the size it was trained with.
_GRAPE_EE = {"control": "ee", "max_ee_step": 0.04, "max_ee_rotation": 0.2}


def _grape_vine_command(seed: int) -> str:
    """How the whole-vine reach's seed ``seed`` was trained (its zoo folder's command.txt has the run's exact line)."""
    return (
        f"agri train --env agri_envs/GrapeHarvest-v1 --scenario table2 --algo sac --her --seed {seed} "
        f"--out runs/vine-s{seed}"
    )


register_policy(
    PolicySpec(
        name="sac-her-grape-vine",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs=dict(_GRAPE_EE),
        description="Learned (SAC + HER, agri_training/zoo/sac-her-grape-vine): one goal-conditioned reach, trained "
        "leg by leg over whole vines at the evaluation tolerances, drives every step; scripted: the env's target "
        "order (the unharvested cluster nearest the clamp, then home)",
        learned=True,
        algo="sac",
        train_command=_grape_vine_command(0),
    )
)

register_policy(
    PolicySpec(
        name="sac-her-grape-vine-shielded",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs=dict(_GRAPE_EE),
        description="sac-her-grape-vine's recipe (seed 2, its 110k-step checkpoint) behind the safety layer "
        "luo-box-check: the joints each action leads to are tested against the observed boxes with Luo's point set, "
        "and an action that would touch one is replaced (a shorter step, a step back, standing still); the line "
        "'safety_layer: luo-box-check' was added to the run's config after training (agri_training/learned/safety.py)",
        learned=True,
        algo="sac",
        train_command=_grape_vine_command(2),
    )
)

register_policy(
    PolicySpec(
        name="sac-her-grape-vine-shielded-zoom",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_zoomed",
        env_kwargs=dict(_GRAPE_EE),
        description="sac-her-grape-vine-shielded (the same weights and safety layer) behind a goal zoom: within 2 cm "
        "and 0.2 rad of its goal the network is shown the error magnified to that size (up to 20x) and its step is "
        "shrunk by the same factor, so that it cuts finer than it was trained to (agri_training/learned/goal_zoom.py)",
        learned=True,
        algo="sac",
        train_command=_grape_vine_command(2),
    )
)

register_policy(
    PolicySpec(
        name="sac-her-grape-vine-shielded-zoom-homing",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_zoomed_homing",
        env_kwargs=dict(_GRAPE_EE),
        description="sac-her-grape-vine-shielded-zoom (the same weights, safety layer and goal zoom) that drives its "
        "last 2 cm home along the straight joint line to the home configuration, where the clamp's straight line "
        "would push joint 2 past its limit and stall (agri_training/learned/homing.py)",
        learned=True,
        algo="sac",
        train_command=_grape_vine_command(2),
    )
)

register_policy(
    PolicySpec(
        name="sac-her-grape-vine-robust-shielded",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.zoo:load_zoo_policy",
        env_kwargs=dict(_GRAPE_EE),
        description="The whole-vine reach trained on a robust distribution of vines (sac_grape_robust.yml, seed 2, "
        "its final 120k-step weights): each training vine's largest cluster lean drawn from 0.17-0.4 rad and its "
        "fewest clusters from 2-5 (RobustVines), behind the safety layer luo-box-check from the start of training",
        learned=True,
        algo="sac",
        train_command="agri train --env agri_envs/GrapeHarvest-v1 --scenario table2 --algo sac --her --hyperparams "
        "agri_training/hyperparams/sac_grape_robust.yml --seed 2 --out runs/grape-robust-tf2-s2",
    )
)

register_policy(
    PolicySpec(
        name="sac-her-grape-vine-eq11",
        env_id="agri_envs/GrapeHarvest-v1",
        entry_point="agri_training.learned.harvest:load_zoo_harvester",
        env_kwargs=dict(_GRAPE_EE),
        description="The learned reach of sac-her-grape-vine drives every step; scripted: the cluster order of Luo "
        "eq. 11 (as luo-apf), then home",
        learned=True,
        algo="sac",
        train_command=_grape_vine_command(0),
    )
)
