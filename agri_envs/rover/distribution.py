"""GreenhouseNav's training distribution: the scenes a learner trains on (``scene_distribution="training"``).

Two families, as the paper's experiments have two kinds of place: the greenhouse (Harik secs. 3.2-3.3:
rows of plants growing through the season, trees moved into the rows, people in the corridors) and the
office corridor (secs. 3.4-3.5: 180 deg turns between walls, both missions, one to three cycles). Every
paper suite's scene lies inside it; ``greenhouse-generalization`` lies outside (more and longer rows,
wider corridors than any training scene).
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
#: The distributions ``scene_distribution`` may name.
DISTRIBUTIONS: dict[str, SceneDistribution] = {TRAINING.name: TRAINING}
