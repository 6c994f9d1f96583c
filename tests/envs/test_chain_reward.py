"""robot_chain_v1's reward is ordered (the env's Rewards section).

1. A contact or a break that ends the episode costs more than stopping in place, whenever it happens.
2. Reaching the goal as a chain pays more than any episode without a success, whatever the moment and the
   chain length.

Checked twice: on the task alone, with adversarial inputs (the largest progress a crash step could claim,
the worst shape while standing still, potentials that wander anywhere), and on the env, branching one
episode (a deep copy) into stopping, crashing and arriving.
"""

import copy

import numpy as np
import pytest

from agri_baselines import make_policy
from agri_envs.chain import robot_chain_v1
from agri_envs.chain.task import ChainTask, ChainWeights, GhostParams
from agri_envs.sim2d.polyline import Polyline


def _task(max_cycles: int, weights: ChainWeights | None = None, potential: float = -5.0) -> ChainTask:
    path = Polyline(np.array([[0.0, 0.0], [8.0, 0.0]]))
    task = ChainTask(path, GhostParams(), weights or ChainWeights(), 0.1, 0.3, max_cycles, True, True)
    task.reset(np.zeros(2), potential)
    return task


def _step(task: ChainTask, n: int, potential: float, collided: int = 0, breaks: int = 0, arrived: int = 0) -> float:
    # Worst shape: spacing error 1, the strip 5 m off (capped), the largest gap at Delta or beyond.
    shape = [5.0, 5.0, 1.3 if breaks else 1.2, float(breaks), 1.0]
    return float(task.evaluate(np.array([0.0, 0.0]), collided, shape, potential, arrived, n)["reward"])


def _advance(task: ChainTask, steps: int, rng: np.random.Generator, n: int) -> None:
    for _ in range(steps):
        _step(task, n, float(rng.uniform(-8.0, 0.0)))


#: The defaults, and weights where a contact is nearly free next to what standing still costs.
WEIGHTS = [ChainWeights(), ChainWeights(collision=0.01, chain_break=0.01, time=5.0, spacing=5.0, strip=5.0, success=16)]


@pytest.mark.parametrize("weights", WEIGHTS)
@pytest.mark.parametrize("max_cycles", [40, 1500])
@pytest.mark.parametrize("n", [2, 16])
def test_task_a_crash_or_break_costs_more_than_stopping_whenever(weights, max_cycles, n):
    rng = np.random.default_rng(n)
    for t0 in sorted({0, 1, max_cycles // 2, max_cycles - 2, max_cycles - 1}):
        base = _task(max_cycles, weights)
        _advance(base, t0, rng, n)
        here = base.potential
        stop = copy.deepcopy(base)
        stopped = sum(_step(stop, n, here) for _ in range(max_cycles - t0))  # until the time limit
        for kind in ("collided", "breaks"):
            crash = copy.deepcopy(base)
            # The crash step even claims the whole distance to go as progress (it is not paid).
            crashed = _step(crash, n, 0.0, **{kind: 1})
            assert crashed < stopped, (t0, kind, crashed, stopped)


@pytest.mark.parametrize("weights", WEIGHTS)
@pytest.mark.parametrize("n", [1, 4, 64])
def test_task_success_pays_most_whatever_the_moment(weights, n):
    rng = np.random.default_rng(n)
    max_cycles = 60
    for t0 in (0, 17, 45):
        base = _task(max_cycles, weights, potential=-float(rng.uniform(0.5, 9.0)))
        _advance(base, t0, rng, n)
        successes, others = [], []
        for _ in range(30):
            # A success at any later step, after a potential that wanders anywhere below 0.
            arrive = int(rng.integers(t0, max_cycles))
            task = copy.deepcopy(base)
            total = sum(_step(task, n, float(rng.uniform(-9.0, 0.0))) for _ in range(arrive - t0))
            # Arrived by the straight-line rule, while the floor distances may still say otherwise.
            total += _step(task, n, float(rng.uniform(-20.0, 0.0)), arrived=n)
            assert task.success
            successes.append(total)
            # No success: the potential may even reach 0 (every robot near enough along the floor but one
            # not within its straight radius), the episode ends by the time limit, a contact or a break.
            task = copy.deepcopy(base)
            end = int(rng.integers(t0, max_cycles))
            total = 0.0
            for t in range(t0, max_cycles):
                how = rng.choice(["collided", "breaks", "none"]) if t == end else "none"
                total += _step(
                    task,
                    n,
                    0.0 if rng.random() < 0.5 else float(rng.uniform(-1.0, 0.0)),
                    **({how: 1} if how != "none" else {"arrived": n - 1}),
                )
                if how != "none":
                    break
            assert not task.success
            others.append(total)
        assert min(successes) > max(others), (t0, min(successes), max(others))


def test_task_weights_that_would_break_the_order_are_refused():
    with pytest.raises(ValueError, match="reward_success"):
        robot_chain_v1.parallel_env(reward_success=2.0)  # below time + spacing + strip = 2.5
    with pytest.raises(ValueError, match="reward_collision"):
        robot_chain_v1.parallel_env(reward_collision=0.0)
    robot_chain_v1.parallel_env(reward_collision=0.0, terminate_on_collision=False)  # a flat per-step cost then


def _run(env, policy, obs, steps=None, wait=0):
    """Return of the rest of an episode: ``wait`` steps standing still, then the policy (``steps`` at most)."""
    total, done, k = 0.0, False, 0
    while env.agents and (steps is None or k < steps):
        if k < wait:
            actions = {a: np.zeros(2, np.float32) for a in env.agents}
        else:
            actions, _ = policy.predict(obs)
        obs, rewards, terms, truncs, infos = env.step(actions)
        total += rewards["robot_0"]
        done = any(terms.values()) or any(truncs.values())
        k += 1
    return total, obs, (infos if done else None)


def _crash(env):
    """Robot 1 reverses at full speed, the rest stand still, until it hits something or breaks the chain."""
    total = 0.0
    while env.agents:
        actions = {a: np.zeros(2, np.float32) for a in env.agents}
        actions["robot_1"] = np.array([-1.0, 0.0], np.float32)
        _, rewards, _, _, infos = env.step(actions)
        total += rewards["robot_0"]
    assert infos["robot_0"]["collisions"] > 0 or not infos["robot_0"]["chain_intact"]
    return total


def _stop(env):
    total = 0.0
    while env.agents:
        _, rewards, _, _, _ = env.step({a: np.zeros(2, np.float32) for a in env.agents})
        total += rewards["robot_0"]
    return total


@pytest.mark.parametrize("n", [3, 6])
def test_env_branches_crash_stop_and_arrive(n):
    env = robot_chain_v1.parallel_env(n_robots=n, n_dynamic_obstacles=1, max_cycles=700)
    policy = make_policy("apoorva-chain", env)
    obs, _ = env.reset(seed=11)
    policy.reset()
    start = copy.deepcopy((env, policy, obs))
    arrived, _, info = _run(*copy.deepcopy(start))
    assert info["robot_0"]["is_success"]
    # Whatever the moment: arriving after standing still for a while still pays more than any failure.
    late, _, info = _run(*copy.deepcopy(start), wait=150)
    assert info["robot_0"]["is_success"] and late < arrived
    alternatives = [_stop(copy.deepcopy(env))]
    prefix = 0.0
    for t in (40, 120):  # branch the episode on the way
        e, p, o = copy.deepcopy(start)
        prefix, o, _ = _run(e, p, o, steps=t)
        stopped, crashed = _stop(copy.deepcopy(e)), _crash(copy.deepcopy(e))
        assert crashed < stopped  # from the same state, crashing costs more than stopping
        alternatives += [prefix + stopped, prefix + crashed]
    assert late > max(alternatives)
