"""Training distributions: draws stay in range and follow the seed, envs draw per episode, outside is outside."""

import gymnasium as gym
import numpy as np
import pytest

import agri_envs
from agri_envs.coverage.config import GreenhouseCoverageConfig
from agri_envs.rover.config import GreenhouseNavConfig
from agri_envs.scenes.distribution import Choice, IntRange, SceneDistribution, SceneFamily, Uniform

NAV = "agri_envs/GreenhouseNav-v2"
COVER = "agri_envs/GreenhouseCoverage-v2"
CONFIGS = {NAV: GreenhouseNavConfig, COVER: GreenhouseCoverageConfig}


@pytest.mark.parametrize("env_id", [NAV, COVER])
def test_draws_stay_in_range_and_follow_the_seed(env_id):
    distribution, _ = agri_envs.training_distribution(env_id)
    draws = [distribution.sample(np.random.default_rng(seed)) for seed in range(400)]
    assert draws == [distribution.sample(np.random.default_rng(seed)) for seed in range(400)]
    seen = {f.name: 0 for f in distribution.families}
    for name, kwargs in draws:
        family = distribution.family(name)
        seen[name] += 1
        assert set(kwargs) == set(family.arguments)
        assert all(kwargs[k] == v for k, v in family.fixed.items())
        assert all(r.contains(kwargs[k]) for k, r in family.ranges.items()), kwargs
        assert not family.excludes(kwargs, {})
    total = sum(f.weight for f in distribution.families)
    for f in distribution.families:  # each family about as often as its weight says (400 draws)
        assert abs(seen[f.name] / 400 - f.weight / total) < 0.08
    # every range is explored, not pinned: its draws spread over most of it
    for f in distribution.families:
        for k, r in f.ranges.items():
            values = [kw[k] for name, kw in draws if name == f.name]
            if isinstance(r, Uniform):
                assert max(values) - min(values) > 0.8 * (r.high - r.low), k
            else:
                assert len(set(values)) == (r.high - r.low + 1 if isinstance(r, IntRange) else len(r.values)), k


@pytest.mark.parametrize("env_id", [NAV, COVER])
def test_every_draw_and_the_tightest_corner_are_valid_scenes(env_id):
    distribution, _ = agri_envs.training_distribution(env_id)
    base = CONFIGS[env_id](scene_distribution="training")
    rng = np.random.default_rng(0)
    for _ in range(300):
        base.replace(**distribution.sample(rng)[1])
    for f in distribution.families:  # narrowest corridors, most growth and bending, longest rows at once
        corner = {k: r.largest() for k, r in f.ranges.items()}
        for k in ("corridor_width", "office_width"):
            if k in f.ranges:
                corner[k] = f.ranges[k].low
        base.replace(**f.fixed, **corner)


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [(NAV, {"localization": "ground_truth"}), (COVER, {}), (COVER, {"localization": "ground_truth"})],
)
def test_env_draws_one_scene_per_episode_from_the_episode_seed(env_id, kwargs):
    env = gym.make(env_id, scene_distribution="training", render_mode="rgb_array", **kwargs)
    distribution, _ = agri_envs.training_distribution(env_id)
    space = env.observation_space
    configs, frames = [], set()
    for seed in range(6):
        obs, info = env.reset(seed=seed)
        cfg = env.unwrapped.episode_config
        configs.append(cfg)
        assert space.contains(obs)
        drawn = {k: getattr(cfg, k) for k in distribution.arguments}
        assert not all(distribution.outside(drawn, {}).values())  # some family draws exactly this scene
        frames.add(env.render().shape)
        again = gym.make(env_id, scene_distribution="training", **kwargs)
        obs2, _ = again.reset(seed=seed)
        assert again.unwrapped.episode_config == cfg and all(np.array_equal(obs[k], obs2[k]) for k in obs)
    assert len(set(configs)) == 6 and len(frames) == 1
    if env_id == COVER:
        assert env.unwrapped.n_corridors == configs[-1].n_rows + 1


@pytest.mark.parametrize(("env_id", "argument"), [(NAV, "n_rows"), (NAV, "office_route"), (COVER, "growth")])
def test_an_argument_the_distribution_draws_cannot_be_given_too(env_id, argument):
    default = getattr(CONFIGS[env_id](), argument)
    with pytest.raises(ValueError, match=f"draws \\['{argument}'\\] per episode"):
        gym.make(env_id, scene_distribution="training", **{argument: default})


def test_off_changes_nothing_and_the_map_scene_refuses_a_distribution():
    a, b = gym.make(NAV), gym.make(NAV, scene_distribution="off")
    oa, _ = a.reset(seed=5)
    ob, _ = b.reset(seed=5)
    assert all(np.array_equal(oa[k], ob[k]) for k in oa)
    with pytest.raises(ValueError, match="does not apply to scene='map'"):
        GreenhouseNavConfig(scene="map", map_yaml=str(agri_envs.scenes.EXAMPLE_MAP), waypoints=((0, 0), (1, 1)),
                            scene_distribution="training")


def test_outside_needs_every_family_to_exclude():
    d = SceneDistribution(
        "t",
        (
            SceneFamily("a", 1.0, {"scene": "a"}, {"n": IntRange(1, 3), "w": Uniform(1.0, 2.0)}),
            SceneFamily("b", 1.0, {"scene": "b"}, {"route": Choice(("x", "y"))}),
        ),
    )
    defaults = {"scene": "a", "n": 2, "w": 1.5, "route": "x"}
    assert not d.lies_outside({}, defaults)  # the defaults are family a's
    assert not d.lies_outside({"scene": "b", "n": 9}, defaults)  # family b does not draw n
    assert d.lies_outside({"n": 4}, {**defaults, "route": "z"})
    reasons = d.outside({"n": 4, "w": 2.5}, defaults)
    assert reasons["a"] == ["n=4 outside 1..3", "w=2.5 outside [1, 2]"] and reasons["b"] == [
        "scene='a' (family 'b' has 'b')"
    ]
    # The nearest family is of the same kind, even when another has fewer reasons.
    assert d.nearest({"n": 4, "w": 2.5}, defaults) == ("a", ["n=4 outside 1..3", "w=2.5 outside [1, 2]"])
    assert d.nearest({"scene": "b", "route": "z"}, defaults) == ("b", ["route='z' outside {'x', 'y'}"])
    assert d.nearest({}, defaults) == ("a", [])


@pytest.mark.parametrize(
    "make",
    [
        lambda: Uniform(2.0, 1.0),
        lambda: Uniform(0.0, float("inf")),
        lambda: IntRange(3, 2),
        lambda: Choice(()),
        lambda: SceneFamily("a", 0.0),
        lambda: SceneFamily("a", 1.0, {"n": 1}, {"n": IntRange(1, 2)}),
        lambda: SceneDistribution("t", ()),
        lambda: SceneDistribution("t", (SceneFamily("a", 1.0), SceneFamily("a", 2.0))),
    ],
)
def test_malformed_distributions_are_refused(make):
    with pytest.raises(ValueError):
        make()


def test_the_robust_distribution_draws_valid_scenes_and_robots_in_range():
    from agri_envs.rover.distribution import ROBOT_ARGUMENTS, ROBUST

    base = GreenhouseNavConfig(scene_distribution="robust")
    rng = np.random.default_rng(1)
    speeds = []
    for _ in range(300):
        name, kwargs = ROBUST.sample(rng)
        family = ROBUST.family(name)
        assert all(r.contains(kwargs[k]) for k, r in family.ranges.items()) and not family.excludes(kwargs, {})
        base.replace(**kwargs)  # a valid config, or this raises
        speeds.append(kwargs["max_speed"])
    assert min(speeds) < 0.7 and max(speeds) > 1.3 and ROBOT_ARGUMENTS & ROBUST.arguments == {"max_speed"}
    narrow = ROBUST.family("narrow")  # its tightest corner: narrowest corridor at the most growth
    base.replace(**narrow.fixed, **{**{k: r.largest() for k, r in narrow.ranges.items()}, "corridor_width": 0.85})


def test_a_robust_episode_drives_the_robot_it_drew():
    # Full speed ahead until the robot stops accelerating: it reaches the episode's drawn limit, never more,
    # and the observation's velocity is read against that limit. Two episodes in a row with different limits,
    # so that the second moves (and re-limits) the robot built for the first.
    env = gym.make(NAV, scene_distribution="robust", localization="ground_truth")
    speeds = []
    for seed in (7, 8):  # both without people: the second episode keeps the first one's world
        env.reset(seed=seed)
        e = env.unwrapped
        limit = e.episode_config.max_speed
        speeds.append(limit)
        assert e.robot.spec is e.robot_spec and e.robot_spec.max_speed == limit
        fastest = 0.0
        for _ in range(int(limit / e.robot_spec.max_accel / e.config.control_period) + 3):
            obs, _, terminated, truncated, _ = env.step(np.array([1.0, 0.0], np.float32))
            assert not (terminated or truncated)
            fastest = max(fastest, e.robot.v)
            assert obs["velocity"][0] == np.float32(e.robot.v / limit)
        assert fastest == pytest.approx(limit, abs=1e-9)
    assert abs(speeds[0] - speeds[1]) > 0.1


def test_the_batched_form_refuses_a_distribution_that_draws_the_robot():
    with pytest.raises(ValueError, match=r"draws \['max_speed'\] per episode: use single envs"):
        gym.make_vec(NAV, num_envs=2, scene_distribution="robust")
    envs = gym.make_vec(NAV, num_envs=2, vectorization_mode="sync", scene_distribution="robust")
    envs.reset(seed=0)
    envs.close()

