"""GrapeHarvest-v1: a 6-DOF arm cuts grape clusters without touching their anti-collision boxes (Luo 2018)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from agri_envs._actions import checked_action
from agri_envs.arm.config import (
    BOX_FEATURES,
    OTHER_FEATURES,
    GrapeHarvestConfig,
    observation_bounds,
    observation_layout,
)
from agri_envs.arm.kinematics import JOINT_LIMITS
from agri_envs.arm.robot_model import goal_vector, tip_pose
from agri_envs.arm.scene import (
    HOME_Q,
    Scene,
    harvest_configurations,
    sample_scene_and_configurations,
)
from agri_envs.arm.sim import ArmSim
from agri_envs.arm.task import HarvestTask, goal_errors


class GrapeHarvestEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """Cut every grape cluster with a 6-DOF arm, never touching a bounding box, then return home.

    ## Description

    The harvesting arm of Luo et al. (2018), built in pybullet from the paper's modified D-H table
    (Table 1, with a_3 = 100 mm so that the worked example eq. 5 holds), stands on a platform in front
    of a vine row. Each episode hangs 2-5 grape clusters at random inside the arm's workspace (Fig. 3),
    each with a cutting point on its peduncle above the berries and an axis-aligned anti-collision box
    around them (Fig. 2); trunk, cordon, canes and leaves are further boxes. The clamp centre of the
    end-effector (clamp, pallet and scissor as one tool) must reach each cutting point coming in from the
    open side of the row with the pallet along the cluster (the orientation that fits the cluster), in
    any order, and return to its home pose; no link may touch a box. The arm is kinematic: an action sets
    the joint values directly, within the joint ranges.

    By default the clusters are placed at random as in the paper's Table 2 tests, without checking that
    every cut can be reached: some scenes cannot be solved, and that counts as failure. Training presets
    set ``feasible_scenes=True``. The registered preset ``agri_envs/GrapeHarvestReach-v1`` (see the
    Arguments) is the single-goal task a goal-conditioned learner starts with: one cluster, cut it, done.

    ## Action Space

    ``Box(-1, 1, (6,), float32)``. ``control="joint"`` (default): joint-position deltas, scaled by
    ``max_joint_step`` and clipped to the joint ranges. ``control="ee"``: clamp translation (3, base
    frame, scaled by ``max_ee_step``) and rotation vector (3, scaled by ``max_ee_rotation``), solved by
    damped least squares on the arm's Jacobian (differential IK, smooth through the wrist singularity;
    ``info["ik_failed"]`` when a joint range cuts the motion). Actions outside the box are clipped; NaN
    or inf raises ``ValueError``.

    ## Observation Space

    A goal-conditioned ``Dict`` (like panda-gym's), float32, coordinates in the arm's base frame (m):

    | key | shape | meaning |
    |---|---|---|
    | ``observation`` | (N,) | arm (15), target box (7), other clusters (16 each), obstacles (7 each) |
    | ``achieved_goal`` | (9,) | clamp position, approach axis (tool z), pallet axis (tool x) |
    | ``desired_goal`` | (9,) | the same for the designated target (1) |

    Arm: joints mapped to [-1, 1] over their ranges, clamp position, approach axis, pallet axis. Target
    box: present, box min, box max of the designated cluster (its cut is only in ``desired_goal``, so a
    goal relabelled by HER never contradicts the observation; absent while the target is home). Other
    clusters (``max_clusters - 1`` slots, unharvested ones first, by index): present, box min, box max,
    cut goal (9). Obstacles (``2 + n_canes + n_leaves`` slots: cordon, trunk, canes, leaves): present,
    box min, box max. So ``N = 22 + 16 (max_clusters - 1) + 7 (2 + n_canes + n_leaves)``: 142 by default,
    36 for the Reach preset. (1) The unharvested cluster nearest the clamp when the last target was cut;
    home once all are (``return_home``). Bounds: positions in [-2, 2] m, axes in [-1, 1], flags in [0, 1].
    Empty slots are zeros.

    ## Rewards

    ``reward = compute_reward(achieved_goal, desired_goal, info)``, batched over leading axes (HER):

    | ``reward_type`` | goal term | worst step ``w`` |
    |---|---|---|
    | ``sparse`` | ``0`` if the goal is reached, else ``-1`` | 1 |
    | ``dense`` | ``-(position error [m] + orientation_weight * axis error [rad])`` | ``2 + orientation_weight * pi`` |

    minus ``(time_limit + 1) * w`` on a step with ``info["collision"]``. Why these weights: the goal term
    is the standard one of goal-conditioned tasks (panda-gym, Fetch), so HER relabels it exactly; ``w`` is
    the largest penalty one step without a collision can earn (positions differ by less than 2 m in the
    arm's reach, axes by at most pi), so the collision penalty exceeds the worst return of any episode that
    never crashes. Crashing is therefore never the best return, discounted or not, from any state; v0's
    penalty of 1 made an early crash the best return and learners learned to crash. A goal is reached
    within ``position_tolerance`` and ``orientation_tolerance``.

    ## Starting State

    The arm at its home configuration (the clamp tucked in 0.45 m in front of the base). The scene is
    drawn from the episode seed; ``reset(options={"scene": scene})`` places a given
    :class:`~agri_envs.arm.scene.Scene` instead (of at most ``max_clusters`` clusters: another type raises
    ``TypeError``, too many clusters or another option key ``ValueError``). Resets reuse the env's
    pybullet client (the scene's boxes are one multibody; visual shapes exist only with a render mode)
    and take about 3 ms: the scene sampler tests its candidates with certified compiled kernels and
    falls back to the numpy code wherever they cannot be sure, so scenes are bit for bit those of the
    original numpy sampler (``tests/envs/test_grape_harvest_env.py`` checks both against recorded digests).

    ## Episode End

    Terminated with success when the final target is reached without a collision: home after every
    cluster is harvested (``return_home``), or the last cluster's cut otherwise. Terminated on contact
    between any link and a box when ``terminate_on_collision``. Truncated at the episode's time limit,
    ``info["time_limit"]`` steps: ``time_slack`` times the steps the straight tour home -> clusters
    (nearest first) -> home takes at full speed (joint space for ``control="joint"``, the clamp's
    translation and rotation for ``"ee"``), plus 10 steps for every approach and retreat. The same rule
    gives every scene argument a limit that a competent controller meets (``luo-apf`` uses about a
    half of it). ``gym.make(..., max_episode_steps=N)`` adds a ``TimeLimit`` on top. Like Gymnasium-
    Robotics, ``compute_terminated`` and ``compute_truncated`` decide both, batched like ``compute_reward``.

    ## Info

    ``is_success``, ``collision``, ``harvested`` (clusters cut so far), ``n_clusters``, ``target_index``
    (-1: home), ``final_target`` (the designated goal is the last one), ``distance`` (m) and
    ``angle_error`` (rad) to the designated goal, ``tip_x``, ``tip_y``, ``tip_z`` (m), ``path_length``
    (m, of the clamp centre), ``ik_failed``, ``elapsed_steps``, ``time_limit`` (steps) and
    ``time_limit_reached``.

    ## Arguments

    Every argument is a field of :class:`GrapeHarvestConfig`; unknown names and values out of range raise
    ``ValueError`` naming the argument and its valid range.

    | argument | default | unit | valid | meaning |
    |---|---|---|---|---|
    | ``min_clusters`` | 2 |  | in [1, 5] | fewest grape clusters in an episode (the count is drawn uniformly) |
    | ``max_clusters`` | 5 |  | in [1, 5] | most grape clusters in an episode |
    | ``n_leaves`` | 4 |  | in [0, 8] | leaves placed around the clusters (fewer when no free place is found) |
    | ``n_canes`` | 2 |  | in [0, 4] | vertical canes in the row plane, besides trunk and cordon |
    | ``cluster_tilt`` | 0.17 | rad | in [0.0, 0.5] | largest lean of a cluster's hanging axis |
    | ``feasible_scenes`` | False |  | True or False | only scenes whose every cut is reachable (False: as Luo) |
    | ``return_home`` | True |  | True or False | after the last cut the clamp must return home |
    | ``position_tolerance`` | 0.01 | m | in [0.001, 0.1] | a cutting point (or home) is reached within this distance |
    | ``orientation_tolerance`` | 0.2 | rad | in [0.01, 3.15] | largest angle between the clamp's and the goal's axes |
    | ``control`` | 'joint' |  | one of 'joint', 'ee' | action type: joint-position deltas or end-effector deltas |
    | ``max_joint_step`` | 0.05 | rad | in [0.001, 0.5] | joint change per step at action 1 (control='joint') |
    | ``max_ee_step`` | 0.02 | m | in [0.001, 0.1] | clamp translation per step at action 1 (control='ee') |
    | ``max_ee_rotation`` | 0.1 | rad | in [0.001, 0.5] | clamp rotation per step at action 1 (control='ee') |
    | ``time_slack`` | 4.0 |  | in [1.0, 100.0] | time limit: this many times the straight tour's steps |
    | ``reward_type`` | 'sparse' |  | one of 'sparse', 'dense' | sparse (0 / -1) or dense (minus the goal error) |
    | ``orientation_weight`` | 0.1 |  | in [0.0, 10.0] | dense reward: metres of penalty per radian of axis error |
    | ``terminate_on_collision`` | True |  | True or False | end the episode when any link touches a box |
    | ``show_boxes`` | True |  | True or False | draw the clusters' anti-collision boxes in rendered frames |
    | ``render_width`` | 480 | px | in [64, 4000] | width of rendered frames |
    | ``render_height`` | 360 | px | in [64, 4000] | height of rendered frames |

    The tolerances by default are the evaluation's (1 cm, 0.2 rad: the clamp must close on the peduncle).
    ``agri_envs/GrapeHarvestReach-v1`` (and the scenario ``reach``) is this env with the kwargs preset
    :data:`~agri_envs.arm.presets.REACH_PRESET`: one
    cluster (feasible), no leaves or canes, ``return_home=False``, ``control="ee"`` with 4 cm / 0.2 rad
    steps, and the learner's tolerances (3 cm, 0.35 rad). Example::

        env = gym.make("agri_envs/GrapeHarvest-v1", min_clusters=3, max_clusters=3, reward_type="dense")
        reach = gym.make("agri_envs/GrapeHarvestReach-v1")  # the single-goal preset

    ## Baselines

    ``luo-apf``: the paper's energy-optimal harvesting order (eq. 11) and APF sampling path points (Alg. 1,
    eqs. 12-16) with the analytic IK and the point-set collision test (eqs. 6-9). It reads the cutting
    points (``desired_goal`` and the other clusters' slots) and boxes from the observation, as the
    paper's vision system supplies them; not privileged. ``luo-apf-attract-only``: the same without the
    repulsion of eq. 15 (the ablation).

    ## Version History

    * v0: initial release.
    * v1: learnable and honest (the training issue). The designated target's cut is no longer also in
      the observation (HER relabels only ``desired_goal``); the observation is sized by the arguments
      (142 dims by default instead of 198, mostly padding); ``return_home`` (False: the last cut ends the
      episode, so a single-goal task has one goal); the time limit follows the scene (``time_slack``)
      instead of a fixed 1000 steps; the collision penalty is ``(time_limit + 1)`` worst steps instead of
      ``collision_penalty`` = 1 (removed), so crashing early is never the best return;
      ``compute_terminated`` / ``compute_truncated``; scenes drawn at random as the paper did by default
      (``feasible_scenes`` keeps v0's filtered scenes); the single-goal preset
      ``agri_envs/GrapeHarvestReach-v1``; end-effector actions by differential IK (v0's analytic IK froze
      the arm near the wrist singularity); reset works after ``close()``; ``render()`` without a render
      mode warns.

    ## References

    L. Luo, H. Wen, Q. Lu, H. Huang, W. Chen, X. Zou and C. Wang, "Collision-Free Path-Planning for
    Six-DOF Serial Harvesting Robot Based on Energy Optimal and Artificial Potential Field", Complexity
    2018, 3563846.
    """

    metadata = {
        "render_modes": ["rgb_array", "human"],
        "render_fps": 20,
        "episode_metric_keys": ("collision", "harvested", "n_clusters", "path_length", "time_limit"),
        "trace_keys": ("tip_x", "tip_y", "tip_z", "harvested"),
    }

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.config = GrapeHarvestConfig.from_kwargs(kwargs)
        self.render_mode = render_mode
        cfg = self.config
        self.action_space = spaces.Box(-1.0, 1.0, (6,), np.float32)
        low, high = observation_bounds(cfg)
        goal_low = np.array([-2.0] * 3 + [-1.0] * 6, dtype=np.float32)
        self._obs_low, self._obs_high = low, high
        self.layout = observation_layout(cfg)
        self.observation_space = spaces.Dict(  # type: ignore[assignment]
            {
                "observation": spaces.Box(low, high, dtype=np.float32),
                "achieved_goal": spaces.Box(goal_low, -goal_low, dtype=np.float32),
                "desired_goal": spaces.Box(goal_low, -goal_low, dtype=np.float32),
            }
        )
        self.task = HarvestTask(
            cfg.position_tolerance,
            cfg.orientation_tolerance,
            cfg.reward_type,
            cfg.orientation_weight,
            cfg.return_home,
            cfg.terminate_on_collision,
        )
        self.sim = self._new_sim()
        self._window: Any = None
        home = tip_pose(HOME_Q)
        self.home_goal = goal_vector(home[:3, 3], home[:3, :3]).astype(np.float32).astype(np.float64)
        self.scene: Scene | None = None
        self.q = HOME_Q.copy()
        self.time_limit = 0
        self.elapsed_steps = 0

    # ------------------------------------------------------------------------------------------- API

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Draw a new scene (or place ``options["scene"]``) and put the arm home; reopens a closed sim."""
        super().reset(seed=seed)
        scene = self._scene_option(options)
        if self.sim.closed:  # Gymnasium's and SB3's checkers reset after close()
            self.sim = self._new_sim()
        configs = None
        if scene is None:
            scene, configs = sample_scene_and_configurations(self.np_random, self.config.scene_params())
        self.scene = scene
        self.sim.load_scene(self.scene)
        self.q = HOME_Q.copy()
        self.sim.set_joints(self.q)
        achieved = self._achieved()
        self.task.reset(self.scene, self.home_goal, achieved)
        self._path_length = 0.0
        self._achieved_goal = achieved
        self.elapsed_steps = 0
        self.time_limit = self._time_limit(self.scene, configs)
        pos, ang = goal_errors(achieved, self.task.desired_goal)
        outcome = {"collision": False, "is_success": False, "distance": pos, "angle_error": ang}
        info = self._info(dict(outcome, final_target=self.task.final_target), False)
        if self.render_mode == "human":
            self.render()
        return self._observe(achieved), info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Move the arm by one action, check collisions and harvests, and score the step."""
        if self.scene is None or self.sim.closed:
            raise RuntimeError("call reset() before step()")
        a = checked_action(action, 6)
        self.task.begin_step(self._achieved_goal)
        desired = self.task.desired_goal
        ik_failed = False
        if self.config.control == "joint":
            q_new = np.clip(self.q + a * self.config.max_joint_step, JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1])
        else:
            q_new, ik_failed = self._ee_target(a)
        self.q = q_new
        self.sim.set_joints(self.q)
        collision = bool(self.sim.collisions())
        achieved = self._achieved()
        self._path_length += float(np.linalg.norm(achieved[:3] - self._achieved_goal[:3]))
        self._achieved_goal = achieved
        self.elapsed_steps += 1
        outcome = self.task.evaluate(achieved, collision, self.time_limit)
        for i in outcome["harvested_now"]:
            self.sim.remove_cluster(i)
        info = self._info(outcome, ik_failed)
        terminated = bool(self.compute_terminated(achieved, desired, info))
        truncated = bool(self.compute_truncated(achieved, desired, info))
        info["time_limit_reached"] = truncated
        if self.render_mode == "human":
            self.render()
        return self._observe(achieved), float(outcome["reward"]), terminated, truncated, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        """Reward for (batches of) goals, as in the Rewards section; what HER relabels with."""
        return self.task.compute_reward(achieved_goal, desired_goal, info)

    def compute_terminated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        """Whether (batches of) steps end the episode: the final target reached, or a collision."""
        return self.task.compute_terminated(achieved_goal, desired_goal, info)

    def compute_truncated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        """Whether (batches of) steps hit the episode's time limit (and did not terminate)."""
        return self.task.compute_truncated(achieved_goal, desired_goal, info)

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """An RGB frame from the fixed camera (``rgb_array``), or that frame in a pygame window (``human``)."""
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array' to gym.make")
            return None
        if self.sim.closed:
            raise RuntimeError("call reset() before render(): the env is closed")
        frame = self.sim.render(self.config.render_width, self.config.render_height)
        if self.render_mode == "rgb_array":
            return frame
        import pygame  # only the human mode needs a window

        if self._window is None:
            pygame.display.init()
            self._window = pygame.display.set_mode((frame.shape[1], frame.shape[0]))
        pygame.event.pump()
        self._window.blit(pygame.surfarray.make_surface(np.transpose(frame, (1, 0, 2))), (0, 0))
        pygame.display.flip()
        return None

    def close(self) -> None:
        """Disconnect this env's pybullet client and close the window (idempotent; ``reset`` reopens)."""
        self.sim.close()
        if self._window is not None:
            import pygame

            pygame.display.quit()
            self._window = None

    # ------------------------------------------------------------------------------------- pickling

    def __getstate__(self) -> dict[str, Any]:
        state = {k: v for k, v in self.__dict__.items() if k not in ("sim", "_window")}
        state["_harvested_bodies"] = self.task.harvested.copy()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        harvested = state.pop("_harvested_bodies")
        self.__dict__.update(state)
        self._window = None
        self.sim = self._new_sim()
        if self.scene is not None:
            self.sim.load_scene(self.scene)
            for i in np.flatnonzero(harvested):
                self.sim.remove_cluster(int(i))
        self.sim.set_joints(self.q)

    # -------------------------------------------------------------------------------------- helpers

    def _scene_option(self, options: Any) -> Scene | None:
        """The ``scene`` reset option, checked: a :class:`Scene` of at most ``max_clusters`` clusters, or None."""
        if options is None:
            return None
        if not isinstance(options, Mapping):
            raise TypeError(f"reset options must be a dict (or None), got {type(options).__name__}: {options!r}")
        unknown = sorted(str(k) for k in options if k != "scene")
        if unknown:
            raise ValueError(f"reset options {unknown} unknown; allowed: ['scene']")
        scene = options.get("scene")
        if scene is None:
            return None
        if not isinstance(scene, Scene):
            raise TypeError(
                f"reset option 'scene' must be an agri_envs.arm.scene.Scene (or None), got {type(scene).__name__}"
            )
        n = len(scene.clusters)
        if n > self.config.max_clusters:
            raise ValueError(
                f"reset option 'scene' has {n} clusters; this env observes at most max_clusters="
                f"{self.config.max_clusters} (make it with max_clusters >= {n})"
            )
        return scene

    def _new_sim(self) -> ArmSim:
        """A pybullet client for this env; visual shapes only when it renders (they cost time and memory)."""
        return ArmSim(show_boxes=self.config.show_boxes, visuals=self.render_mode is not None)

    def _time_limit(self, scene: Scene, configs: tuple[tuple[np.ndarray, np.ndarray], ...] | None = None) -> int:
        """Steps of the episode: ``time_slack`` x the straight tour at full speed, plus approaches.

        ``configs``: :func:`harvest_configurations` of every cluster, when the scene sampler already has them.
        """
        cfg = self.config
        joint = cfg.control == "joint"
        home = _HOME_TIP
        # Nearest-first tour through the cuts (the order the task designates targets in).
        left = list(range(len(scene.clusters)))
        here_q, here_t = HOME_Q, home
        steps = 0.0
        legs: list[tuple[np.ndarray | None, np.ndarray]] = []
        at = home[:3, 3]
        while left:
            i = min(left, key=lambda j: float(np.linalg.norm(scene.clusters[j].cut_point - at)))
            left.remove(i)
            pair = harvest_configurations(scene.clusters[i]) if configs is None else configs[i]
            # Clamp poses only count for end-effector control (they cost numpy calls on 3-vectors).
            legs.append((None if pair is None else pair[1], home if joint else scene.clusters[i].tip_pose()))
            at = scene.clusters[i].cut_point
        if cfg.return_home or not legs:
            legs.append((HOME_Q, home))
        for q, t in legs:
            if joint:
                # An unreachable cut (possible in Luo's random scenes) gets a half-turn of the slowest joint.
                dq = math.pi / 2 if q is None else float(np.max(np.abs(q - here_q)))
                steps += dq / cfg.max_joint_step
                here_q = here_q if q is None else q
            else:
                dist = float(np.linalg.norm(t[:3, 3] - here_t[:3, 3]))
                turn = float(np.arccos(np.clip((np.trace(here_t[:3, :3].T @ t[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
                steps += max(dist / cfg.max_ee_step, turn / cfg.max_ee_rotation)
            here_t = t
        approaches = 10 * (2 * len(scene.clusters) if cfg.return_home else 2 * len(scene.clusters) - 1)
        limit = cfg.time_slack * steps
        if configs is not None and joint and abs(limit - round(limit)) < 1e-4:
            # The sampler's configurations equal harvest_configurations' up to rounding (~1e-12 rad), which
            # could only move a limit this close to an integer: take numpy's own.
            return self._time_limit(scene)
        return int(math.ceil(limit)) + approaches

    def _ee_target(self, a: np.ndarray) -> tuple[np.ndarray, bool]:
        """Joint values for a clamp-pose delta (:func:`end_effector_step` from the current joints)."""
        return end_effector_step(self.q, a, self.config.max_ee_step, self.config.max_ee_rotation)

    def _achieved(self) -> np.ndarray:
        """The achieved goal, rounded to the observation's float32 so that rewards match ``compute_reward``."""
        pos, rot = self.sim.tip_pose()
        return goal_vector(pos, rot).astype(np.float32).astype(np.float64)

    def _observe(self, achieved: np.ndarray) -> dict[str, np.ndarray]:
        assert self.scene is not None
        cfg = self.config
        obs = np.zeros(cfg.obs_dim, dtype=np.float64)
        lo, hi = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
        obs[:6] = 2.0 * (self.q - lo) / (hi - lo) - 1.0
        obs[6:15] = achieved
        target = self.task.target
        if target >= 0:
            c = self.scene.clusters[target]
            k = self.layout["target_box"].start
            obs[k], obs[k + 1 : k + 4], obs[k + 4 : k + 7] = 1.0, c.box_lo, c.box_hi
        k = self.layout["others"].start
        for i, c in enumerate(self.scene.clusters):
            if i == target or self.task.harvested[i]:
                continue
            obs[k], obs[k + 1 : k + 4], obs[k + 4 : k + 7] = 1.0, c.box_lo, c.box_hi
            obs[k + 7 : k + 16] = self.task.goals[i]
            k += OTHER_FEATURES
        k = self.layout["obstacles"].start
        for o in self.scene.obstacles[: cfg.n_obstacle_slots]:
            obs[k], obs[k + 1 : k + 4], obs[k + 4 : k + 7] = 1.0, o.lo, o.hi
            k += BOX_FEATURES
        return {
            "observation": np.clip(obs, self._obs_low, self._obs_high).astype(np.float32),
            "achieved_goal": achieved.astype(np.float32),
            "desired_goal": self.task.desired_goal.astype(np.float32),
        }

    def _info(self, outcome: dict[str, Any], ik_failed: bool) -> dict[str, Any]:
        return {
            "is_success": bool(outcome["is_success"]),
            "collision": bool(outcome["collision"]),
            "harvested": int(self.task.harvested.sum()),
            "n_clusters": len(self.task.goals),
            "target_index": self.task.target,
            "final_target": bool(outcome["final_target"]),
            "distance": float(outcome["distance"]),
            "angle_error": float(outcome["angle_error"]),
            "tip_x": float(self._achieved_goal[0]),
            "tip_y": float(self._achieved_goal[1]),
            "tip_z": float(self._achieved_goal[2]),
            "path_length": self._path_length,
            "ik_failed": ik_failed,
            "elapsed_steps": self.elapsed_steps,
            "time_limit": self.time_limit,
            "time_limit_reached": False,
        }


#: The clamp's home pose.
_HOME_TIP = tip_pose(HOME_Q)
#: Largest joint change of one end-effector step (rad): the damped solution near a singularity is bounded.
_MAX_EE_JOINT_STEP = 0.3


def end_effector_step(
    q: np.ndarray, action: np.ndarray, max_ee_step: float, max_ee_rotation: float
) -> tuple[np.ndarray, bool]:
    """The joint values an end-effector action (``control="ee"``) moves the arm to from ``q``, and ``ik_failed``.

    Damped least squares on the arm's Jacobian for the clamp twist ``(action[:3] * max_ee_step, action[3:] *
    max_ee_rotation)``. Differential IK (like the controllers of panda-gym and robosuite) rather than the
    analytic IK: near the wrist singularity (theta_5 = 0) the analytic solution nearest the current joints
    jumps, and a learner would see the arm freeze there. ``ik_failed`` reports a motion the joint ranges cut.
    A controller may call it to see where an action would take the arm (the safety layer of the learned
    harvesters does).
    """
    a = np.asarray(action, dtype=np.float64)
    twist = np.concatenate([a[:3] * max_ee_step, a[3:] * max_ee_rotation])
    jac = _jacobian(q)
    damping = 0.02
    lo, hi = JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1]
    free = np.ones(6, dtype=bool)
    for _ in range(3):  # a joint that would pass its limit is locked there, the others solve the rest
        j = jac * free
        dq = j.T @ np.linalg.solve(j @ j.T + damping**2 * np.eye(6), twist)
        dq *= min(1.0, _MAX_EE_JOINT_STEP / max(float(np.max(np.abs(dq))), 1e-12))
        over = free & ((q + dq < lo) | (q + dq > hi))
        if not over.any():
            break
        free &= ~over
    q_new = q + dq
    clipped = np.clip(q_new, lo, hi)
    return clipped, bool(np.any(clipped != q_new) or not free.all())


def _jacobian(q: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Geometric Jacobian (6, 6) of the clamp centre: linear rows, then angular rows (base frame)."""
    t0 = tip_pose(q)
    qs = q[None, :] + eps * np.eye(6)
    jac = np.zeros((6, 6))
    for j in range(6):
        t = tip_pose(qs[j])
        jac[:3, j] = (t[:3, 3] - t0[:3, 3]) / eps
        r = t[:3, :3] @ t0[:3, :3].T
        jac[3:, j] = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2.0 * eps)
    return jac
