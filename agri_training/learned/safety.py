"""Safety layers: a fixed rule between a learned policy's action and the robot, which the network cannot override.

A run names its layer in its config (``safety_layer``, :data:`SAFETY_LAYERS`); wherever its weights act (the
periodic evaluation of training, ``agri validate``, ``agri evaluate``, the leaderboard) they act through it. PPO's
rollouts and DAgger's data are the network's own actions: the layer is part of the deployed policy, not of what
the network learned. Every intervention is counted, and an entry's episodes carry the counts
(:meth:`HarikPassiveSafety.episode_metrics`), so a reader sees how often the rule, not the network, drove.

``harik-passive-safety`` (GreenhouseNav) is the passive motion safety of Harik & Korsæth (2018, sec. 3.1), the
same code that ``harik-apf`` runs (:meth:`agri_baselines.harik_apf.HarikApfController.passive_safety`): with
something in the front zone closer than the stop distance the robot stops, steps back a few centimetres and
waits until the front is free; before that its speed is capped so it can still stop short. The network keeps
the steering. It reads the observation the network reads: the min-pooled LIDAR (each sector's range placed at
the sector's centre angle, within 1.5 deg of the beam that measured it at the default 90 sectors) and the
sonars, with the gains :func:`agri_baselines.harik_apf.robot_params` gives the robot and corridor of the
episode, as ``harik-apf`` has them.

``luo-box-check`` (GrapeHarvest, end-effector control) tests where each action would take the arm against the
observed boxes with Luo's point-set model (:class:`LuoBoxCheck`), and replaces an action that would touch one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from agri_baselines.luo_apf import joints_from_observation, targets_from_observation
from agri_envs.arm.collision import ArmCollisionModel
from agri_envs.arm.grape_harvest import end_effector_step


class HarikPassiveSafety:
    """Harik's passive motion safety over a learned GreenhouseNav policy's linear speed (see the module).

    Args:
        env: The GreenhouseNav env the policy drives (its robot, sensors and the episode's arguments are read
            when an episode starts, never during one).
    """

    name = "harik-passive-safety"
    env_id = "agri_envs/GreenhouseNav-v2"

    def __init__(self, env: Any) -> None:
        from agri_baselines.harik_apf import robot_geometry

        self.env = env
        #: What the layer knows of the robot: its footprint and sonars, the LIDAR as the pooled observation.
        self.geometry = dataclasses.replace(robot_geometry(env), beam_angles=env.unwrapped.lidar_sector_angles)
        self.controller: Any = None
        self.spec: Any = None
        self.interventions = 0

    def start_episode(self) -> None:
        """A fresh safety state with the gains of the episode that just started (its robot and corridor)."""
        from agri_baselines.harik_apf import HarikApfController, robot_params

        e = self.env.unwrapped
        cfg = getattr(e, "episode_config", e.config)
        self.controller = HarikApfController(robot_params(self.env, cfg.waypoint_radius, cfg), self.geometry)
        self.spec = e.robot_spec
        self.interventions = 0

    def apply(self, observation: Mapping[str, Any], action: np.ndarray, episode_start: bool) -> np.ndarray:
        """The action the robot gets: ``action`` with its speed through the passive safety (steering unchanged)."""
        if episode_start or self.controller is None:
            self.start_episode()
        g, spec = self.geometry, self.spec
        a = np.array(action, dtype=np.float32, copy=True)
        u = float(a[0]) * (spec.max_speed if a[0] >= 0 else spec.max_reverse_speed)
        ranges = np.asarray(observation["lidar"], dtype=np.float64) * g.lidar_max_range
        sonar = np.asarray(observation["sonar"], dtype=np.float64) * g.sonar_max_range
        front, _, _ = self.controller.obstacle_zones(ranges, sonar)
        safe = self.controller.passive_safety(u, front, sonar)
        if safe != u:
            self.interventions += 1
            a[0] = safe / spec.max_speed if safe >= 0 else safe / max(spec.max_reverse_speed, 1e-9)
        return a

    def episode_metrics(self) -> dict[str, float]:
        """The layer's counts in the episode so far.

        Returns:
            ``safety_interventions`` (steps whose speed the layer changed), ``safety_stops`` (stops it made) and
            ``safety_blocked_time`` (s it held the robot in front of something).
        """
        c = self.controller
        if c is None:
            return {"safety_interventions": 0.0, "safety_stops": 0.0, "safety_blocked_time": 0.0}
        return {
            "safety_interventions": float(self.interventions),
            "safety_stops": float(c.stops),
            "safety_blocked_time": c.blocked_steps * self.geometry.control_period,
        }


class LuoBoxCheck:
    """Luo's collision test (eqs. 6-9) on where each end-effector action would take a learned GrapeHarvest arm.

    Before an action reaches the arm, the joints it leads to (:func:`agri_envs.arm.grape_harvest.
    end_effector_step`, the env's own differential IK, from the joints in the observation) are tested against the
    boxes in the observation (the clusters' and the stems' and leaves', as ``luo-apf`` reads them) with the
    point set of the arm (:class:`agri_envs.arm.collision.ArmCollisionModel`, no margin). An action that would
    touch a box is replaced by the first of these whose configuration is clear: half of it, a quarter of it, a
    step back along the tool's approach axis, standing still. The network's action is kept whenever it is clear.

    Args:
        env: The GrapeHarvest env (end-effector control) the policy drives: its layout and step sizes are read
            once, never the scene.
    """

    name = "luo-box-check"
    env_id = "agri_envs/GrapeHarvest-v1"

    def __init__(self, env: Any) -> None:
        e = env.unwrapped
        if e.config.control != "ee":
            raise ValueError(f"safety_layer {self.name!r} checks end-effector actions: make the env with control='ee'")
        self.layout = dict(e.layout)
        self.steps = (float(e.config.max_ee_step), float(e.config.max_ee_rotation))
        self.interventions = 0
        self.stops = 0

    def apply(self, observation: Mapping[str, Any], action: np.ndarray, episode_start: bool) -> np.ndarray:
        """The network's action if its configuration is clear of every observed box, else the first clear fallback."""
        if episode_start:
            self.interventions = self.stops = 0
        obs = {k: np.asarray(v) for k, v in observation.items()}
        targets, lo, hi = targets_from_observation(obs, self.layout)
        model = ArmCollisionModel(
            np.concatenate([np.array([t.box_lo for t in targets]).reshape(-1, 3), lo]),
            np.concatenate([np.array([t.box_hi for t in targets]).reshape(-1, 3), hi]),
        )
        q = joints_from_observation(obs["observation"])
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        back = np.concatenate([-np.asarray(obs["achieved_goal"][3:6], dtype=np.float64), np.zeros(3)])
        for k, candidate in enumerate((a, 0.5 * a, 0.25 * a, back)):
            if not model.collides(end_effector_step(q, candidate, *self.steps)[0])[0]:
                self.interventions += int(k > 0)
                return np.asarray(candidate, dtype=np.float32)
        self.interventions += 1
        self.stops += 1
        return np.zeros(6, dtype=np.float32)

    def episode_metrics(self) -> dict[str, float]:
        """The layer's counts in the episode so far.

        Returns:
            ``safety_interventions`` (steps whose action the layer replaced) and ``safety_stops`` (steps it held
            the arm still: no fallback was clear).
        """
        return {"safety_interventions": float(self.interventions), "safety_stops": float(self.stops)}


#: The safety layers a run may name (``safety_layer`` in its config), name -> class (taking the env; its
#: ``env_id`` is the env it guards).
SAFETY_LAYERS: dict[str, Any] = {layer.name: layer for layer in (HarikPassiveSafety, LuoBoxCheck)}


def check_safety_layer(name: str | None, env_id: str) -> None:
    """Refuse an unknown layer, or one for another env (the message lists the known ones).

    Raises:
        ValueError: As above.
    """
    if name is None:
        return
    if name not in SAFETY_LAYERS:
        raise ValueError(f"safety_layer must be one of {', '.join(SAFETY_LAYERS)} or null, got {name!r}")
    guarded_env = SAFETY_LAYERS[name].env_id
    if guarded_env != env_id:
        raise ValueError(f"safety_layer {name!r} guards {guarded_env}, not {env_id}")


def make_safety_layer(name: str | None, env: Any, env_id: str) -> Any:
    """The layer ``name`` on ``env``, an ``env_id`` env (a run's: its config's ``env_id``); None: no layer.

    Raises:
        ValueError: For an unknown layer, or one that guards another env (:func:`check_safety_layer`).
    """
    if name is None:
        return None
    check_safety_layer(name, env_id)
    return SAFETY_LAYERS[name](env)
