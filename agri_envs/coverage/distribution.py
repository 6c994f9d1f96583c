"""GreenhouseCoverage's training distributions: the greenhouses a learner trains on (``scene_distribution``).

One family, the Almería greenhouse of González 2009 (sec. 3.2): 2-5 corridors of 4-12 m that are neither
straight nor equally wide, plants from young to fully grown, sonar echoes slipping into the foliage. The
ranges are chosen so that the narrowest corridor any draw can make still keeps the 0.9 m the Fitorobot
needs (the config refuses narrower ones). ``coverage-almeria`` and ``coverage-dense-foliage`` lie inside it;
``coverage-generalization`` lies outside (more and longer corridors, wider ones than any training scene).

``scene_distribution="robust"`` (:data:`ROBUST`) widens it along the stress suites' axes: corridors 1.3-2.5 m,
1-6 rows of 4-16 m, vegetation echoes 0-0.7, and the dead reckoning's four arguments (encoder noise and scale
error, compass noise and bias) drawn per episode too. Every stress suite keeps at least one level outside it:
1.2 and 3.0 m corridors, 7 rows of 20 m and 12 of 30 m, every echo slipping (1.0), the odometry suite's last
level (0.5, 0.1, 0.5, 0.5). Corridors narrower than 1.5 m have growth up to 0.7 (family ``narrow``), or
1.4-1.5 m corridors growth up to 1 in rows of up to 12 m (family ``dense``): fully grown leaves beside 16 m
inclined rows would leave the robot too little room, and the config refuses such a greenhouse. Every training
scene, and ``coverage-generalization``'s, lies inside it.
"""

from __future__ import annotations

from agri_envs.scenes.distribution import ArgumentRange, IntRange, SceneDistribution, SceneFamily, Uniform

#: Almería greenhouses of 1-4 rows (2-5 corridors) of 4-12 m, corridors 1.4-1.6 m wide and uneven. Small ones
#: put the turns into the next corridor within reach of a learner's first drives.
ALMERIA = SceneFamily(
    "almeria",
    weight=1.0,
    ranges={
        "n_rows": IntRange(1, 4),
        "row_length": Uniform(4.0, 12.0),
        "corridor_width": Uniform(1.4, 1.6),
        "corridor_width_jitter": Uniform(0.0, 0.1),
        "row_incline": Uniform(0.0, 0.012),
        "row_bend": Uniform(0.0, 0.05),
        "growth": Uniform(0.2, 1.0),
        "vegetation_echo_prob": Uniform(0.0, 0.3),
    },
)
TRAINING = SceneDistribution(
    "training",
    (ALMERIA,),
    "Almería greenhouses of 2-5 corridors (4-12 m rows, corridors 1.4-1.6 m, uneven, inclined and bent; "
    "growth 0.2-1; vegetation echoes 0-0.3)",
)

#: The dead reckoning and the sonars' echoes, drawn per episode by ``robust`` (the stress suites' first three
#: levels; their last lies outside): the env gives its sensors each episode's values.
ROBUST_SENSORS: dict[str, ArgumentRange] = {
    "vegetation_echo_prob": Uniform(0.0, 0.7),
    "encoder_noise": Uniform(0.0, 0.2),
    "encoder_scale_std": Uniform(0.0, 0.05),
    "compass_noise_std": Uniform(0.0, 0.2),
    "compass_bias": Uniform(-0.2, 0.2),
}
#: The training family's shape of corridor (uneven, inclined, bent) in greenhouses of 1-6 rows of 4-16 m.
_ROBUST_SHAPE: dict[str, ArgumentRange] = {
    "n_rows": IntRange(1, 6),
    "row_length": Uniform(4.0, 16.0),
    "corridor_width_jitter": ALMERIA.ranges["corridor_width_jitter"],
    "row_incline": ALMERIA.ranges["row_incline"],
    "row_bend": ALMERIA.ranges["row_bend"],
}
#: Corridors 1.5-2.5 m wide at any growth of the training family.
ROBUST_ALMERIA = SceneFamily(
    "almeria",
    weight=0.65,
    ranges={**_ROBUST_SHAPE, "corridor_width": Uniform(1.5, 2.5), "growth": Uniform(0.2, 1.0), **ROBUST_SENSORS},
)
#: Corridors 1.3-1.5 m wide with the leaves short of the corridor (growth up to 0.7): at 1.3 m, 16 m rows and
#: the most jitter, incline and bend they keep 0.908 m free, the 0.9 m the Fitorobot needs.
ROBUST_NARROW = SceneFamily(
    "narrow",
    weight=0.2,
    ranges={**_ROBUST_SHAPE, "corridor_width": Uniform(1.3, 1.5), "growth": Uniform(0.2, 0.7), **ROBUST_SENSORS},
)
#: The training family's fully grown narrow greenhouses (1.4-1.5 m, growth 0.7-1), in rows of up to 12 m as
#: there: with 16 m inclined rows the leaves would leave too little room. With it every training scene is a
#: robust one.
ROBUST_DENSE = SceneFamily(
    "dense",
    weight=0.15,
    ranges={
        **_ROBUST_SHAPE,
        "row_length": ALMERIA.ranges["row_length"],
        "corridor_width": Uniform(1.4, 1.5),
        "growth": Uniform(0.7, 1.0),
        **ROBUST_SENSORS,
    },
)
ROBUST = SceneDistribution(
    "robust",
    (ROBUST_ALMERIA, ROBUST_NARROW, ROBUST_DENSE),
    "the training distribution widened: greenhouses of 2-7 corridors (4-16 m rows, corridors 1.3-2.5 m, uneven, "
    "inclined and bent; growth 0.2-1, but at most 0.7 below 1.5 m, except in rows of up to 12 m at 1.4 m and "
    "up); vegetation echoes 0-0.7; encoder noise 0-0.2 and scale error 0-0.05, compass noise 0-0.2 rad and "
    "bias -0.2..0.2 rad",
)
#: The distributions ``scene_distribution`` may name.
DISTRIBUTIONS: dict[str, SceneDistribution] = {TRAINING.name: TRAINING, ROBUST.name: ROBUST}
