"""A learned policy's own localization: Hector SLAM on the LIDAR, as ``harik-apf`` runs it, feeding the waypoint.

GreenhouseNav made with ``localization="none"`` gives a robot what a real one has: LIDAR, sonars, its achieved
velocity, and the mission's current waypoint in the frame it started in (``target``, a map-frame waypoint on a
robot that starts at the map's origin). :class:`SlamWaypoint` turns that into the ``waypoint`` key the
privileged policies read from the true pose, ``[d / diagonal, sin(alpha), cos(alpha)]``, with ``d`` and ``alpha``
measured from a Hector SLAM estimate (:class:`agri_baselines.hector_slam.HectorSlam`, the configuration
``harik-apf`` uses) updated on the full scan of each observation it sees. Nothing privileged is read: the scan
geometry is the robot's own, and the diagonal (the scale the env writes ``target`` in) is the scene's, which
the map gives.

``aim_inside`` (m, default 0) adds a margin to the distance it reports, as ``harik-apf`` aims its ``d_min``
``localization_margin`` inside the waypoint radius: the env counts a waypoint reached from the true position, so a
policy that learned to stop at the radius (its teacher's rule, on the true pose) would stand a few centimetres
short of it on an estimate that is that far off, and wait there. It is a deployment setting: trained with a margin,
the network would learn to stop at the radius plus the margin. ``dagger-greenhouse-nav-slam`` was trained without
one and ships with ``aim_inside: 0.1`` (its ``config.yaml`` differs from its run's in that line).

The wrapper sees one observation per decision (the policy's rate: every ``action_repeat``-th scan), in
training and in evaluation alike (:class:`~agri_training.learned.policy.ObservationReplay`), so the SLAM
the network learned with is the SLAM it drives with. With ``every_scan`` (default off) a policy that decides every
``action_repeat``-th scan still feeds every scan to its SLAM (:meth:`SlamWaypoint.see` on the steps whose action
it holds), as ``harik-apf`` updates its map on every scan.
Half the scans leave twice the motion between two matches, and in long featureless corridors Hector SLAM then
loses itself: ``dagger-greenhouse-nav-slam-shielded`` in the 12x24 m greenhouse finished 3 of 10 validation
episodes on SLAM at its decisions, 9 of 10 with every scan. Imitation (``pretrain``: demonstrations and DAgger
rounds) feeds the held steps' scans too, so a recipe can learn with it; PPO's rollouts hold actions inside the
env and cannot, so ``agri train`` refuses it with ``action_repeat`` > 1 and PPO steps.

With ``odometry`` (default off; needs ``every_scan``) the SLAM is given the robot's wheel odometry: each scan is
matched from the previous pose moved on by the motion the observation's ``velocity`` (the achieved speeds, as wheel
encoders measure them, scaled by the robot's own limits) gives over the step, hector_mapping's odometry guess,
instead of its own constant-velocity prediction. The env adds no slip or noise to that key. Among 20 people, in the
last corridor of the default greenhouse, the prediction let ``dagger-greenhouse-nav-slam-every-scan-shielded``'s
SLAM lose itself in 5 of 60 validation missions (seeds 20020-20079); with odometry, the same network finished all
60. It is a deployment setting: ``dagger-greenhouse-nav-slam-odometry-shielded`` is that network with it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from agri_baselines.hector_slam import HectorSlam, HectorSlamConfig


class SlamWaypoint(gym.ObservationWrapper[dict[str, Any], Any, dict[str, Any]]):
    """Add ``waypoint`` (from a Hector SLAM pose) to a GreenhouseNav observation made without localization.

    Needs the env made with ``localization="none"`` and ``full_scan=True`` (keys ``target`` and ``scan``). The
    SLAM map starts afresh with each episode (:meth:`clear`, which a reset calls and the replay of a learned
    policy calls when an episode starts). In a config: ``SlamWaypoint`` or ``{SlamWaypoint: {aim_inside: 0.1,
    every_scan: true, odometry: true}}`` (see the module doc; put it before ``FlattenObservation``).

    Raises:
        ValueError: For an observation without ``target`` or ``scan``, ``aim_inside`` outside [0, 1) m, an
            ``every_scan`` or ``odometry`` that is not a bool, or ``odometry`` without ``every_scan``.
    """

    def __init__(
        self, env: gym.Env[Any, Any], aim_inside: float = 0.0, every_scan: bool = False, odometry: bool = False
    ) -> None:
        if not 0.0 <= float(aim_inside) < 1.0:
            raise ValueError(f"SlamWaypoint aim_inside must be in [0, 1) m, got {aim_inside}")
        for name, value in (("every_scan", every_scan), ("odometry", odometry)):
            if not isinstance(value, bool):
                raise ValueError(f"SlamWaypoint {name} must be true or false, got {value!r}")
        if odometry and not every_scan:
            raise ValueError("SlamWaypoint odometry needs every_scan: true (one control period between two scans)")
        self.aim_inside = float(aim_inside)
        self.every_scan = every_scan
        self.odometry = odometry
        space = env.observation_space
        if not isinstance(space, gym.spaces.Dict) or not {"target", "scan"} <= set(space.spaces):
            raise ValueError(
                "SlamWaypoint needs GreenhouseNav made with localization='none' and full_scan=True (observation "
                f"keys 'target' and 'scan'), got {space}"
            )
        super().__init__(env)
        polar = gym.spaces.Box(np.array([0, -1, -1], np.float32), np.ones(3, np.float32), dtype=np.float32)
        self.observation_space = gym.spaces.Dict({**space.spaces, "waypoint": polar})
        robot: Any = env.unwrapped  # a GreenhouseNav env: its LIDAR's geometry, its scene's diagonal
        lidar = robot.lidar.spec
        self.max_range = float(lidar.max_range)
        self.slam = HectorSlam(HectorSlamConfig(), lidar.beam_angles, lidar.mount)
        self._fresh = True

    def clear(self) -> None:
        """Forget the map: the next observation starts a new one, at the origin of its start frame."""
        self._fresh = True

    def reset(self, **kwargs: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        """Reset the env and start a new map."""
        self.clear()
        return super().reset(**kwargs)

    def see(self, observation: Mapping[str, Any]) -> None:
        """With ``every_scan``, match the scan of a step whose action the policy holds (else nothing).

        ``observation`` is the env's raw one (its ``scan``). A map not yet started (no decision this episode)
        is left alone: the episode's first decision starts it.
        """
        if self.every_scan and not self._fresh:
            scan = np.asarray(observation["scan"], dtype=np.float64) * self.max_range
            self.slam.update(scan, self._odometry(observation))

    def _odometry(self, observation: Mapping[str, Any]) -> tuple[float, float, float] | None:
        """With ``odometry``, the motion of the last env step from the observation's ``velocity``.

        The robot's own limits scale the velocity; a step lasts ``frame_skip`` control periods.
        """
        if not self.odometry:
            return None
        robot: Any = self.env.unwrapped
        spec, dt = robot.robot_spec, float(robot.config.control_period) * int(robot.config.frame_skip)
        u, r = np.asarray(observation["velocity"], dtype=np.float64)
        v, w = u * spec.max_speed * dt, r * spec.max_turn_rate * dt
        return v * math.cos(0.5 * w), v * math.sin(0.5 * w), w

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The observation with ``waypoint`` measured from the SLAM pose after this scan."""
        if self._fresh:
            self.slam.reset((0.0, 0.0, 0.0))
            self._fresh = False
            x, y, yaw = self.slam.update(np.asarray(observation["scan"], dtype=np.float64) * self.max_range)
        else:
            scan = np.asarray(observation["scan"], dtype=np.float64) * self.max_range
            x, y, yaw = self.slam.update(scan, self._odometry(observation))
        unwrapped: Any = self.env.unwrapped
        diagonal = float(unwrapped.diagonal)
        tx, ty = np.asarray(observation["target"], dtype=np.float64) * diagonal
        d = math.hypot(tx - x, ty - y) + self.aim_inside
        alpha = math.atan2(ty - y, tx - x) - yaw
        waypoint = np.array([min(1.0, d / diagonal), math.sin(alpha), math.cos(alpha)], np.float32)
        return {**observation, "waypoint": waypoint}
