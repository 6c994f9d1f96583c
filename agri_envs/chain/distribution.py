"""robot_chain_v1's robust distribution: floors and dropped obstacles drawn per episode (``scene_distribution``).

``scene_distribution="robust"`` (:data:`ROBUST`) draws each episode's floor and how many obstacles drop onto
the leader's path, along the chain's stress suites' axes: office floors of 14-24 x 9-14 m with 2-4 rooms a
side, greenhouses of 2-8 rows of 6-20 m, 0-12 dropped obstacles. The chain's length (``n_robots``) is an
argument of the env, not drawn: every agent keeps its slot through training. Each stress suite keeps levels
outside it: 20 obstacles, the 12 x 30 m greenhouse, and chains longer than the one trained (with their
28 x 14 and 40 x 20 m offices). The paper's office (14 x 9 m, 3 rooms a side, one obstacle) lies inside.
"""

from __future__ import annotations

from agri_envs.scenes.distribution import IntRange, SceneDistribution, SceneFamily, Uniform

#: Obstacles dropped onto the leader's path, for every family.
DROPPED = IntRange(0, 12)
OFFICE = SceneFamily(
    "office",
    weight=0.6,
    fixed={"scene": "office"},
    ranges={
        "office_width": Uniform(14.0, 24.0),
        "office_height": Uniform(9.0, 14.0),
        "office_rooms": IntRange(2, 4),
        "n_dynamic_obstacles": DROPPED,
    },
)
GREENHOUSE = SceneFamily(
    "greenhouse",
    weight=0.4,
    fixed={"scene": "greenhouse"},
    ranges={"n_rows": IntRange(2, 8), "row_length": Uniform(6.0, 20.0), "n_dynamic_obstacles": DROPPED},
)
ROBUST = SceneDistribution(
    "robust",
    (OFFICE, GREENHOUSE),
    "office floors of 14-24 x 9-14 m (2-4 rooms a side) and greenhouses of 2-8 rows of 6-20 m, 0-12 obstacles "
    "dropped onto the leader's path",
)
DISTRIBUTIONS = {d.name: d for d in (ROBUST,)}
