"""GreenhouseCoverage's training distribution: the greenhouses a learner trains on (``scene_distribution="training"``).

One family, the Almería greenhouse of González 2009 (sec. 3.2): 2-5 corridors of 4-12 m that are neither
straight nor equally wide, plants from young to fully grown, sonar echoes slipping into the foliage. The
ranges are chosen so that the narrowest corridor any draw can make still keeps the 0.9 m the Fitorobot
needs (the config refuses narrower ones). ``coverage-almeria`` and ``coverage-dense-foliage`` lie inside it;
``coverage-generalization`` lies outside (more and longer corridors, wider ones than any training scene).
"""

from __future__ import annotations

from agri_envs.scenes.distribution import IntRange, SceneDistribution, SceneFamily, Uniform

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
#: The distributions ``scene_distribution`` may name.
DISTRIBUTIONS: dict[str, SceneDistribution] = {TRAINING.name: TRAINING}
