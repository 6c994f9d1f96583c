"""robot_chain_v0: SuperSuit vectorisation, invariants, errors (its PettingZoo API tests: test_env_conformance.py)."""

import numpy as np
import pytest

from agri_envs.chain import robot_chain_v0

# The PettingZoo API, seed, max-cycles and render tests, over argument sets, are in test_env_conformance.py.


def test_seeding_is_deterministic():
    a, b = robot_chain_v0.parallel_env(n_robots=4), robot_chain_v0.parallel_env(n_robots=4)
    oa, _ = a.reset(seed=5)
    ob, _ = b.reset(seed=5)
    oc, _ = b.reset(seed=6)
    assert all(np.array_equal(oa[k], ob[k]) for k in oa)
    assert not all(np.array_equal(oa[k], oc[k]) for k in oa)


def test_supersuit_vector_env_for_parameter_sharing():
    import supersuit as ss

    env = robot_chain_v0.parallel_env(n_robots=3, max_cycles=20)
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class="stable_baselines3")
    obs = vec.reset()
    assert obs.shape == (6, robot_chain_v0.OBS_SIZE)
    for _ in range(25):  # past max_cycles: the vec env resets by itself
        obs, rewards, dones, infos = vec.step(np.random.default_rng(0).uniform(-1, 1, (6, 2)).astype(np.float32))
    assert obs.shape == (6, robot_chain_v0.OBS_SIZE) and rewards.shape == (6,)
    vec.close()


def test_spaces_state_and_infos():
    env = robot_chain_v0.parallel_env(n_robots=5, n_dynamic_obstacles=2)
    obs, infos = env.reset(seed=1)
    raw = env.unwrapped
    assert raw.robot_radius == pytest.approx(0.165)
    assert env.possible_agents == [f"robot_{k}" for k in range(5)]
    assert all(env.observation_space(a) is env.observation_space("robot_0") for a in env.agents)
    for a, o in obs.items():
        assert env.observation_space(a).contains(o)
    assert obs["robot_0"][18] == 1.0 and obs["robot_1"][18] == 0.0
    assert obs["robot_4"][16] == 0.0 and np.all(obs["robot_4"][14:16] == 0.0)
    s = env.state()
    assert s.shape == env.state_space.shape == (5 * 5 + 4 + 3 * 2,)
    for k, a in enumerate(env.agents):
        assert {"x", "y", "yaw", "collision", "is_success"} <= set(infos[a])
        np.testing.assert_allclose(s[5 * k : 5 * k + 3], [infos[a]["x"], infos[a]["y"], infos[a]["yaw"]], atol=1e-5)
    # A follower's predecessor slot is the predecessor seen in its own frame.
    i0, i1 = infos["robot_0"], infos["robot_1"]
    dx, dy = i0["x"] - i1["x"], i0["y"] - i1["y"]
    c, sn = np.cos(i1["yaw"]), np.sin(i1["yaw"])
    np.testing.assert_allclose(obs["robot_1"][12:14] * 3.0, [c * dx + sn * dy, -sn * dx + c * dy], atol=1e-5)


@pytest.mark.parametrize("n", [4, 64])
def test_robots_never_overlap_under_random_actions(n):
    kwargs = {"office_width": 24.0, "office_height": 16.0, "min_goal_distance": 2.0} if n > 16 else {}
    env = robot_chain_v0.parallel_env(n_robots=n, terminate_on_collision=False, max_cycles=10_000, **kwargs)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    r = env.unwrapped.robot_radius
    contacts = 0
    for _ in range(150 if n == 64 else 400):
        _, _, _, _, infos = env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})
        xy = np.array([[i["x"], i["y"]] for i in infos.values()])
        d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        d[np.diag_indices(n)] = np.inf
        assert d.min() >= 2 * r - 1e-9
        contacts += sum(i["collision"] for i in infos.values())
        assert np.all(env.unwrapped.world.clearance(rb) > -1e-9 for rb in env.unwrapped.robots)
    assert contacts > 0  # random driving does bump into things: the contacts were really tested


def test_bad_arguments_and_actions():
    with pytest.raises(ValueError, match="n_robots"):
        robot_chain_v0.parallel_env(n_robots=0)
    with pytest.raises(ValueError, match="did you mean 'n_robots'"):
        robot_chain_v0.parallel_env(n_robot=3)
    with pytest.raises(ValueError, match="spacing"):
        robot_chain_v0.parallel_env(spacing=0.2)
    with pytest.raises(ValueError, match="map_yaml"):
        robot_chain_v0.parallel_env(scene="map")
    with pytest.raises(ValueError, match="render_mode"):
        robot_chain_v0.parallel_env(render_mode="ascii")
    with pytest.raises(ValueError, match="free floor"):
        robot_chain_v0.parallel_env(start=(0.0, 0.0)).reset(seed=0)
    env = robot_chain_v0.parallel_env(n_robots=2)
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    env.reset(seed=0)
    ok = np.zeros(2, np.float32)
    with pytest.raises(ValueError, match="missing"):
        env.step({"robot_0": ok})
    with pytest.raises(ValueError, match="unknown"):
        env.step({"robot_0": ok, "robot_1": ok, "robot_9": ok})
    with pytest.raises(ValueError, match="robot_1: action contains NaN"):
        env.step({"robot_0": ok, "robot_1": np.array([np.nan, 0.0])})
    with pytest.raises(ValueError, match=r"robot_0: action must have shape \(2,\)"):
        env.step({"robot_0": np.zeros(3), "robot_1": ok})
    _, rewards, *_ = env.step({"robot_0": np.array([5.0, -5.0]), "robot_1": ok})  # clipped, not an error
    assert set(rewards) == {"robot_0", "robot_1"}


def test_wrong_types_are_named_and_leave_the_env_working():
    """Wrong argument types name the argument and type; a malformed action names the agent and the shape."""
    for name, bad, expected in (
        ("n_robots", "3", "an integer"),
        ("spacing", None, "a number"),
        ("terminate_on_collision", 1, "a bool"),
        ("start", ("a", 1.0), "a tuple"),
        ("scene", None, "one of"),
    ):
        with pytest.raises(ValueError, match=rf"{name}=.*{expected}"):
            robot_chain_v0.parallel_env(**{name: bad})
    env, fresh = robot_chain_v0.parallel_env(n_robots=3), robot_chain_v0.parallel_env(n_robots=3)
    env.reset(seed=0)
    fresh.reset(seed=0)
    ok = np.zeros(2, np.float32)
    for bad in ({"v": 0.0}, "ab", [0.0, 0.0, 0.0], np.zeros((2, 1)), None):
        with pytest.raises(ValueError, match=r"robot_1: action must .*\(2,\)"):
            env.step({"robot_0": ok, "robot_1": bad, "robot_2": ok})
    actions = {a: np.array([0.5, 0.1], np.float32) for a in env.agents}
    for _ in range(3):
        a, b = env.step(actions), fresh.step(actions)
        for x, y in zip(a, b, strict=True):
            assert x.keys() == y.keys()
            assert all(np.array_equal(x[k], y[k]) if isinstance(x[k], np.ndarray) else x[k] == y[k] for k in x)


def _to_goal(env):
    """Every robot's free-floor (A*) distance to the goal, leader first."""
    from agri_envs.sim2d.astar import distance_field

    raw = env.unwrapped
    cmap = raw.chain_map
    field = distance_field(cmap.blocked, cmap.cell(raw.goal)) * cmap.grid.resolution
    return np.array([field[cmap.cell(p)] for p in raw._poses[:, :2]])


def test_followers_start_behind_the_leader():
    # Starting State: the followers stand behind the leader, away from the goal. A start in a room's far
    # corner used to put eight robots' followers between the leader and the goal (7 of seeds 0-9).
    env = robot_chain_v0.parallel_env(n_robots=8)
    for seed in range(10):
        env.reset(seed=seed)
        d = _to_goal(env)
        assert np.all(d[1:] >= d[0]), (seed, d)
    # A given start is kept even when the chain cannot stand behind it.
    start = tuple(float(v) for v in env.unwrapped._poses[0, :2])
    env = robot_chain_v0.parallel_env(n_robots=8, start=start, layout_seed=5)
    env.reset(seed=0)
    np.testing.assert_allclose(env.unwrapped._poses[0, :2], start, atol=0.05)
