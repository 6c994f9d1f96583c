"""The whole harvest from a learned reach: clusters one by one in the order of Luo's eq. 11, then home.

The skill is a goal-conditioned network (TQC + HER in the shipped recipe) that moves the clamp by end-effector
actions to a goal pose (position, approach axis, pallet axis) while keeping the tool off every box it sees
(:class:`~agri_training.learned.arm_observation.NearestBoxes`). Above it sits a task level that is scripted
and says so: :class:`HarvestOrder` takes the clusters in the order that minimises eq. 11's weighted joint
rotation over the tour home -> clusters -> home (``agri_baselines.luo_apf.harvest_order``, the same order
``luo-apf`` follows), and hands the skill the first cluster of that order still on the vine, then home. A
cluster is cut when the clamp reaches its goal, by the env's own rule, which the order applies to each
observation it is shown.

Two places use that task level, so that training sees the legs that evaluation will ask for:

* :class:`HarvestLegs`, a training-only wrapper (``train_wrappers``): it cuts each GrapeHarvest-v1 episode
  into legs, one per goal (home -> first cluster, cluster -> next cluster, last cluster -> home), each a
  short episode for the learner (and for HER), ended when its goal is reached, by a collision (the env's
  episode ends with it) or after ``max_leg_steps``; the next leg starts where the last one stopped.
* :class:`LearnedHarvester`, the evaluation policy: the skill driving every step, the order choosing its
  goal. No scripted path (IK, APF) moves the arm; the analytic IK only prices the order, as in the paper.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from agri_baselines.luo_apf import cut_configurations, harvest_order, joints_from_observation, targets_from_observation
from agri_envs.arm.task import goal_errors
from agri_training.learned.policy import LearnedPolicy
from agri_training.learned.zoo import zoo_path


class HarvestOrder:
    """The clusters of one episode in eq. 11's order, and the goal of the moment, read from the observations.

    Clusters whose cut has no inverse-kinematics solution in the arm's working branch (none in the scenes
    drawn so far) come last, in the observation's order: eq. 11 cannot price them. A cluster counts as
    harvested from the step its goal is reached, by the env's own rule (within the tolerances; any cluster,
    in any order): :meth:`see` applies it to every observation. The env keeps a just-cut designated cluster's
    box in its observation for that one step (its designated target switches on the next step), although the
    box has left the scene with the cluster; :meth:`see` hides it.

    Args:
        observation: The env's first observation of the episode (one env, not batched).
        layout: ``env.unwrapped.layout``: where each part of ``observation["observation"]`` sits.
        position_tolerance: The env's ``position_tolerance`` (m).
        orientation_tolerance: The env's ``orientation_tolerance`` (rad).
    """

    def __init__(
        self,
        observation: Mapping[str, np.ndarray],
        layout: Mapping[str, slice],
        position_tolerance: float,
        orientation_tolerance: float,
    ) -> None:
        self.layout = layout
        self.position_tolerance = position_tolerance
        self.orientation_tolerance = orientation_tolerance
        targets, _, _ = targets_from_observation(dict(observation), dict(layout))
        q0 = joints_from_observation(np.asarray(observation["observation"]))
        reachable, q_cuts, unreachable = [], [], []
        for i, target in enumerate(targets):
            q = cut_configurations(q0, [target])
            if q is None:
                unreachable.append(i)
            else:
                reachable.append(i)
                q_cuts.append(q[0])
        order, self.energy = harvest_order(q0, np.array(q_cuts).reshape(-1, 6))
        #: Cluster indices (as ``targets_from_observation`` lists them: the env's designated one first) in order.
        self.order = tuple(reachable[j] for j in order) + tuple(unreachable)
        #: Goal (cut position, approach axis, pallet axis) of each cluster.
        self.goals = np.array([np.concatenate([t.cut_point, t.approach, t.down]) for t in targets]).reshape(-1, 9)
        self._boxes = [tuple(t.box_lo.tolist()) for t in targets]
        #: Which clusters have been cut.
        self.harvested = np.zeros(len(targets), dtype=bool)
        #: Clusters passed over without a cut (training: reached at a looser tolerance than the env's).
        self.skipped = np.zeros(len(targets), dtype=bool)
        #: The clamp's pose at the episode's start: home, where the harvest ends.
        self.home = np.asarray(observation["achieved_goal"], dtype=np.float64).copy()

    def see(self, observation: Mapping[str, np.ndarray]) -> tuple[dict[str, np.ndarray], int]:
        """Take in one observation: mark what it cut, and return it aimed at the goal of the moment.

        Returns:
            ``(observation, index)``: the observation with ``desired_goal`` set to the first cluster of the
            order still on the vine (home once none is: index -1) and without the box of a cluster cut at this
            step; and that cluster's index.
        """
        achieved = np.asarray(observation["achieved_goal"], dtype=np.float64)
        if len(self.goals):
            pos, ang = goal_errors(achieved[None], self.goals)
            self.harvested |= (pos <= self.position_tolerance) & (ang <= self.orientation_tolerance)
        out = dict(observation)
        o = np.asarray(observation["observation"])
        slot = self.layout["target_box"]
        if o[slot.start] > 0.5 and self._cut(o[slot][1:4]):
            o = o.copy()
            o[slot] = 0.0
            out["observation"] = o
        index = next((i for i in self.order if not (self.harvested[i] or self.skipped[i])), -1)
        out["desired_goal"] = (self.goals[index] if index >= 0 else self.home).astype(np.float32)
        return out, index

    def _cut(self, box_lo: np.ndarray) -> bool:
        key = tuple(np.asarray(box_lo, dtype=np.float64).tolist())
        return any(self.harvested[i] for i, b in enumerate(self._boxes) if b == key)


class HarvestLegs(gym.Wrapper[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray], np.ndarray]):
    """Training only: each GrapeHarvest-v1 episode as a sequence of legs, one goal each (module docstring).

    The learner sees the leg's goal as ``desired_goal`` and this wrapper's reward for it, which
    :meth:`compute_reward` also gives HER (SB3 asks the outermost wrapper that has one), so relabelled legs
    are scored exactly like real ones:

    - the env's goal term (sparse: 0 at the goal, else -1; dense: minus the position and weighted axis
      errors), at the tolerance of the moment (below);
    - minus ``(max_leg_steps + 1)`` worst steps (the env's ``task.worst_step``) on a step with a collision:
      more than any leg without one costs, the env's own rule applied to a leg. The env sizes the cost for
      its whole episode (about 200 steps, hence 200-500 per crash); at that size every box became a cliff
      and the learner fled from the vine altogether (measured: the clamp ended farther from its goal than it
      started after 30k steps).

    Tolerance curriculum (``tolerance_start``, ``tolerance_steps``): a leg counts as reached within a
    position and orientation tolerance that shrink linearly from ``tolerance_start`` to the env's over this
    wrapper's first ``tolerance_steps`` steps. A cluster reached at a looser tolerance than the env's stays
    on the vine (the env's rule decides cuts) with its box, and the next leg goes on to the next cluster of
    the order (aiming at the same cut again would start the leg inside its tolerance: a free success); home
    reached that way ends the episode for the learner. ``info["is_success"]`` says whether the leg reached
    its goal.

    Args:
        env: A GrapeHarvest-v1 env.
        max_leg_steps: Steps after which a leg is truncated (the next one starts there, same goal), >= 1.
        tolerance_start: ``[position (m), orientation (rad)]`` tolerances at the start of training, at least
            the env's (None: the env's from the start).
        tolerance_steps: Steps over which the tolerances reach the env's, >= 1.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        max_leg_steps: int = 50,
        tolerance_start: tuple[float, float] | list[float] | None = None,
        tolerance_steps: int = 1,
    ) -> None:
        if int(max_leg_steps) < 1:
            raise ValueError(f"HarvestLegs: max_leg_steps must be >= 1, got {max_leg_steps}")
        if int(tolerance_steps) < 1:
            raise ValueError(f"HarvestLegs: tolerance_steps must be >= 1, got {tolerance_steps}")
        raw: Any = env.unwrapped
        if not hasattr(raw, "task") or not hasattr(raw, "layout"):
            raise ValueError("HarvestLegs needs a GrapeHarvest-v1 env")
        final = np.array([raw.config.position_tolerance, raw.config.orientation_tolerance])
        start = final if tolerance_start is None else np.asarray(tolerance_start, dtype=np.float64)
        if start.shape != (2,) or np.any(start < final):
            raise ValueError(
                f"HarvestLegs: tolerance_start must be [position, orientation] no tighter than the env's "
                f"{final.tolist()}, got {tolerance_start!r}"
            )
        super().__init__(env)
        self.max_leg_steps = int(max_leg_steps)
        self.tolerance_start, self.tolerance_final = start, final
        self.tolerance_steps = int(tolerance_steps)
        task = raw.task
        #: Cost of a colliding step: one more worst step than the longest leg can cost without one.
        self.collision_cost = (self.max_leg_steps + 1) * float(task.worst_step)
        self.reward_type, self.orientation_weight = task.reward_type, task.orientation_weight
        self.steps = 0
        self._order: HarvestOrder | None = None
        self._last: tuple[dict[str, np.ndarray], dict[str, Any]] | None = None
        self._episode_over = True
        self._goal = np.zeros(9)
        self._goal_index = -1
        self._leg_steps = 0

    @property
    def tolerances(self) -> np.ndarray:
        """Position (m) and orientation (rad) tolerances of the moment."""
        share = min(1.0, self.steps / self.tolerance_steps)
        return self.tolerance_start + share * (self.tolerance_final - self.tolerance_start)

    def reached(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        """Whether (batches of) goals are reached at the tolerances of the moment."""
        pos, ang = goal_errors(achieved, desired)
        tol = self.tolerances
        return (pos <= tol[0]) & (ang <= tol[1])

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> Any:
        """The leg's reward for (batches of) goals (class docstring); what HER relabels with."""
        if self.reward_type == "sparse":
            base = -(~self.reached(achieved_goal, desired_goal)).astype(np.float64)
        else:
            pos, ang = goal_errors(achieved_goal, desired_goal)
            base = -(pos + self.orientation_weight * ang)
        infos = [info] if isinstance(info, Mapping) else list(info)
        collision = np.array([bool(i.get("collision", False)) for i in infos]).reshape(np.shape(base))
        reward = base - self.collision_cost * collision
        return float(reward) if np.ndim(reward) == 0 else reward

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start the next leg: where the last one stopped, or in a new episode once the env's has ended."""
        if self._episode_over or self._last is None or seed is not None or options:
            obs, info = self.env.reset(seed=seed, options=options)
            raw: Any = self.env.unwrapped
            cfg = raw.config
            self._order = HarvestOrder(obs, raw.layout, cfg.position_tolerance, cfg.orientation_tolerance)
            self._episode_over = False
            self._last = self._order.see(obs)[0], info
        assert self._order is not None
        obs, info = self._last
        self._goal = np.asarray(obs["desired_goal"], dtype=np.float64)
        self._goal_index = self._order.see(obs)[1]
        self._leg_steps = 0
        return obs, dict(info, is_success=False)

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Step the env toward the leg's goal; the leg ends at the goal, on a collision or at its step limit."""
        assert self._order is not None, "call reset() before step()"
        obs, _, terminated, truncated, info = self.env.step(action)
        self._episode_over = bool(terminated or truncated)
        self._leg_steps += 1
        achieved = np.asarray(obs["achieved_goal"], dtype=np.float64)
        reward = float(self.compute_reward(achieved, self._goal, info))
        reached = bool(self.reached(achieved, self._goal)) and not info["collision"]
        self.steps += 1
        seen, index = self._order.see(obs)
        if reached and index == self._goal_index:  # reached within the curriculum's tolerance, not the env's
            if index >= 0:
                self._order.skipped[index] = True
                seen, _ = self._order.see(obs)
            else:
                self._episode_over = True
        self._last = seen, info
        leg_terminated = reached or bool(terminated)
        leg_truncated = not leg_terminated and (bool(truncated) or self._leg_steps >= self.max_leg_steps)
        out = {**seen, "desired_goal": self._goal.astype(np.float32)}  # the leg's own goal, to its end
        return out, reward, leg_terminated, leg_truncated, dict(info, is_success=reached)


class LearnedHarvester:
    """SB3-style policy: the learned reach drives, :class:`HarvestOrder` picks its goal (module docstring).

    Args:
        skill: The goal-conditioned reach, loaded weights-only, built for the env it will drive.
        layout: ``env.unwrapped.layout`` of that env.
        position_tolerance: The env's ``position_tolerance`` (m): when a cluster counts as cut.
        orientation_tolerance: The env's ``orientation_tolerance`` (rad).
    """

    def __init__(
        self, skill: LearnedPolicy, layout: Mapping[str, slice], position_tolerance: float, orientation_tolerance: float
    ) -> None:
        self.skill = skill
        self.layout = layout
        self.tolerances = (position_tolerance, orientation_tolerance)
        self.orders: list[HarvestOrder | None] = []

    def predict(
        self,
        observation: Mapping[str, np.ndarray],
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """End-effector actions toward each env's current goal (one observation or a batch)."""
        single = np.ndim(observation["observation"]) == 1
        n = 1 if single else len(observation["observation"])
        rows = [observation] if single else [{k: v[i] for k, v in observation.items()} for i in range(n)]
        starts = np.ones(n, bool) if episode_start is None else np.asarray(episode_start, bool).reshape(-1)
        actions = []
        for k, obs in enumerate(rows):
            while len(self.orders) <= k:
                self.orders.append(None)
            order = self.orders[k]
            if starts[k] or order is None:
                order = self.orders[k] = HarvestOrder(obs, self.layout, *self.tolerances)
            seen, _ = order.see(obs)
            action, _ = self.skill.predict(seen, episode_start=np.array([starts[k]]), deterministic=deterministic)
            actions.append(action)
        return (actions[0] if single else np.stack(actions)), state

    def episode_metrics(self, index: int) -> dict[str, Any]:
        """The harvesting order of env ``index``'s episode (clusters numbered as its first observation lists them)."""
        order = self.orders[index] if index < len(self.orders) else None
        if order is None:
            return {}
        return {"order": "->".join(str(i + 1) for i in order.order), "energy": order.energy}


def make_harvester(skill_folder: Any, env: gym.Env[Any, Any]) -> LearnedHarvester:
    """The harvester of a GrapeHarvest-v1 env made with end-effector control, from a reach skill's run folder.

    Raises:
        ValueError: When the env does not take end-effector actions (the skill's action space).
    """
    skill = LearnedPolicy(skill_folder, env)
    raw: Any = env.unwrapped
    cfg = raw.config
    for key in ("control", "max_ee_step", "max_ee_rotation"):
        trained = skill.config["env_kwargs"].get(key)
        if trained is not None and getattr(cfg, key) != trained:
            raise ValueError(
                f"the reach skill in {skill_folder} was trained with {key}={trained!r}; make the env with it "
                f"(got {getattr(cfg, key)!r})"
            )
    return LearnedHarvester(skill, raw.layout, cfg.position_tolerance, cfg.orientation_tolerance)


def load_zoo_harvester(env: gym.Env[Any, Any], name: str) -> LearnedHarvester:
    """Entry point of the registered learned harvesters: the reach skill of ``zoo/NAME`` called in eq. 11's order."""
    return make_harvester(zoo_path(name), env)
