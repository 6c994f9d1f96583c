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
#: (env id, scene_distribution) of the distributions the generic tests check.
DISTRIBUTIONS = [(NAV, "training"), (COVER, "training"), (NAV, "robust"), (COVER, "robust")]


def _distribution(env_id, name):
    return CONFIGS[env_id](scene_distribution=name).distribution()


@pytest.mark.parametrize(("env_id", "name"), DISTRIBUTIONS)
def test_draws_stay_in_range_and_follow_the_seed(env_id, name):
    distribution = _distribution(env_id, name)
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


@pytest.mark.parametrize(("env_id", "name"), DISTRIBUTIONS)
def test_every_draw_and_the_tightest_corner_are_valid_scenes(env_id, name):
    distribution = _distribution(env_id, name)
    base = CONFIGS[env_id](scene_distribution=name)
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


def test_the_coverage_robust_distribution_widens_training_and_keeps_a_level_of_each_stress_suite_outside():
    from agri_envs.coverage.distribution import ROBUST, TRAINING

    defaults = GreenhouseCoverageConfig().to_dict()
    rng = np.random.default_rng(2)
    assert not any(ROBUST.lies_outside(TRAINING.sample(rng)[1], defaults) for _ in range(300))
    inside = [{"corridor_width": w} for w in (1.4, 2.0, 2.5)] + [
        {"vegetation_echo_prob": 0.7},
        {"n_rows": 4, "row_length": 10.0},
        {"encoder_noise": 0.2, "encoder_scale_std": 0.05, "compass_noise_std": 0.2, "compass_bias": 0.2},
    ]
    outside = [{"corridor_width": w} for w in (1.2, 3.0)] + [
        {"vegetation_echo_prob": 1.0},
        {"n_rows": 7, "row_length": 20.0},
        {"encoder_noise": 0.5, "encoder_scale_std": 0.1, "compass_noise_std": 0.5, "compass_bias": 0.5},
    ]
    assert not any(ROBUST.lies_outside(kwargs, defaults) for kwargs in inside)
    assert all(ROBUST.lies_outside(kwargs, defaults) for kwargs in outside)


def test_a_robust_coverage_episode_gives_its_sensors_the_drawn_arguments():
    # Two episodes in a row, so that the second updates the sensors the first one set. The compass bias is
    # checked by what the compass reads too: standing still, its mean error is the episode's bias.
    env = gym.make(COVER, scene_distribution="robust", localization="ground_truth")
    biases = []
    for seed in (0, 6):
        env.reset(seed=seed)
        e = env.unwrapped
        cfg = e.episode_config
        assert e.sonars.spec.foliage_slip_prob == cfg.vegetation_echo_prob
        assert (e.compass.noise_std, e.compass.bias) == (cfg.compass_noise_std, cfg.compass_bias)
        assert (e.encoders.noise, e.encoders.scale_std) == (cfg.encoder_noise, cfg.encoder_scale_std)
        errors = []
        for _ in range(100):
            _, _, terminated, truncated, info = env.step(np.zeros(2, np.float32))
            assert not (terminated or truncated)
            errors.append(np.angle(np.exp(1j * (info["compass"] - info["yaw"]))))
        assert np.mean(errors) == pytest.approx(cfg.compass_bias, abs=3 * cfg.compass_noise_std / 10 + 1e-9)
        biases.append(cfg.compass_bias)
    assert abs(biases[0] - biases[1]) > 0.1 and all(abs(b - e.config.compass_bias) > 0.1 for b in biases)


def test_every_drawn_scene_fits_the_one_canvas_of_its_env():
    # The canvas is fixed at construction (frames keep one size); every episode's scene must lie inside it.
    from agri_envs.chain import robot_chain_v1
    from agri_envs.sim2d.geometry import enclosing_bounds

    assert enclosing_bounds([(0, 1, 2, 3), (-1, 2, 1, 5)]) == (-1.0, 1.0, 2.0, 5.0)
    envs = [
        (gym.make(NAV, scene_distribution="robust").unwrapped, lambda e: e.world.geometry.bounds),
        (gym.make(COVER, scene_distribution="robust").unwrapped, lambda e: e.world.geometry.bounds),
        (robot_chain_v1.parallel_env(scene_distribution="robust"), lambda e: e.chain_map.geometry.bounds),
    ]
    for env, scene_bounds in envs:
        xmin, ymin, xmax, ymax = env.view.canvas
        for seed in range(8):
            env.reset(seed=seed)
            bx0, by0, bx1, by1 = scene_bounds(env)
            assert xmin <= bx0 + 1e-9 and ymin <= by0 + 1e-9 and bx1 <= xmax + 1e-9 and by1 <= ymax + 1e-9, seed
