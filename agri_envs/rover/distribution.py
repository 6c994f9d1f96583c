"""GreenhouseNav's training distribution: the scenes a learner trains on (``scene_distribution="training"``).

Two families, as the paper's experiments have two kinds of place: the greenhouse (Harik secs. 3.2-3.3:
rows of plants growing through the season, trees moved into the rows, people in the corridors) and the
office corridor (secs. 3.4-3.5: 180 deg turns between walls, both missions, one to three cycles). Every
paper suite's scene lies inside it; ``greenhouse-generalization`` lies outside (more and longer rows,
wider corridors than any training scene). ``robust`` widens it along the stress suites' axes, the robot's
speed limit included.
"""

from __future__ import annotations

from agri_envs.scenes.distribution import Choice, IntRange, SceneDistribution, SceneFamily, Uniform

#: The greenhouse scenes: 2-4 rows of 4-8 m, corridors 1.1-1.5 m, any growth, up to 8 trees, up to 3 people.
GREENHOUSE = SceneFamily(
    "greenhouse",
    weight=0.6,
    fixed={"scene": "greenhouse", "mission_cycles": 1},
    ranges={
        "n_rows": IntRange(2, 4),
        "row_length": Uniform(4.0, 8.0),
        "corridor_width": Uniform(1.1, 1.5),
        "growth": Uniform(0.0, 1.0),
        "n_trees": IntRange(0, 8),
        "n_people": IntRange(0, 3),
        "people_tease_prob": Uniform(0.0, 0.6),
    },
)
#: The office corridor: 10-18 m long, 1.3-1.8 m wide, either mission driven 1-3 times, up to one person.
CORRIDOR = SceneFamily(
    "corridor",
    weight=0.4,
    fixed={"scene": "corridor"},
    ranges={
        "office_length": Uniform(10.0, 18.0),
        "office_width": Uniform(1.3, 1.8),
        "office_route": Choice(("experiment", "repeatability")),
        "mission_cycles": IntRange(1, 3),
        "n_people": IntRange(0, 1),
        "people_tease_prob": Uniform(0.0, 0.6),
    },
)
TRAINING = SceneDistribution(
    "training",
    (GREENHOUSE, CORRIDOR),
    "greenhouses of 2-4 rows (4-8 m, corridors 1.1-1.5 m, any growth, trees, 0-3 people) and office corridors "
    "(10-18 m, 1.3-1.8 m wide, both missions, 1-3 cycles, 0-1 person)",
)

#: ``robust``: the training distribution widened along the stress suites' axes (robot speed, crowds, corridor
#: width, size), each suite keeping at least one level outside it: ``max_speed`` 2.0, 12 and 20 people, 0.8 m
#: and 2.4-3.0 m corridors, 6x12 and 12x24 m greenhouses. Narrow corridors come without people or trees (a
#: person cannot pass the robot there) and with little growth (the config refuses what the robot cannot pass).
ROBOT_SPEED = Uniform(0.6, 1.4)
ROBUST_GREENHOUSE = SceneFamily(
    "greenhouse",
    weight=0.45,
    fixed=GREENHOUSE.fixed,
    ranges={
        **GREENHOUSE.ranges,
        "n_rows": IntRange(2, 5),
        "row_length": Uniform(4.0, 10.0),
        "corridor_width": Uniform(1.1, 2.2),
        "n_people": IntRange(0, 8),
        "max_speed": ROBOT_SPEED,
    },
)
ROBUST_NARROW = SceneFamily(
    "narrow",
    weight=0.2,
    fixed={"scene": "greenhouse", "mission_cycles": 1, "n_people": 0, "n_trees": 0},
    ranges={
        "n_rows": IntRange(2, 4),
        "row_length": Uniform(4.0, 8.0),
        "corridor_width": Uniform(0.85, 1.1),
        "growth": Uniform(0.0, 0.3),
        "max_speed": ROBOT_SPEED,
    },
)
ROBUST_CORRIDOR = SceneFamily(
    "corridor",
    weight=0.35,
    fixed={"scene": "corridor"},
    ranges={**CORRIDOR.ranges, "max_speed": ROBOT_SPEED},
)
ROBUST = SceneDistribution(
    "robust",
    (ROBUST_GREENHOUSE, ROBUST_NARROW, ROBUST_CORRIDOR),
    "the training distribution widened: robots of 0.6-1.4 m/s; greenhouses of 2-5 rows (4-10 m, corridors "
    "1.1-2.2 m, any growth, trees, 0-8 people); narrow greenhouses (corridors 0.85-1.1 m, no people or trees, "
    "growth up to 0.3); office corridors as in training",
)
#: The distributions ``scene_distribution`` may name.
DISTRIBUTIONS: dict[str, SceneDistribution] = {TRAINING.name: TRAINING, ROBUST.name: ROBUST}
#: Arguments of the robot (not the scene) that a distribution may draw per episode.
ROBOT_ARGUMENTS = frozenset({"max_speed", "max_turn_rate", "max_accel", "max_angular_accel"})
