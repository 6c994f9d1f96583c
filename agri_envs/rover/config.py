"""Arguments of ``agri_envs/GreenhouseNav-v2``: one strict, typed, frozen dataclass (each a ``gym.make`` keyword)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from agri_envs._config import StrictConfig, param
from agri_envs.rover import robot as rover
from agri_envs.rover.distribution import DISTRIBUTIONS
from agri_envs.rover.task import RewardWeights
from agri_envs.scenes.distribution import SceneDistribution
from agri_envs.scenes.greenhouse import LayoutParams
from agri_envs.scenes.office import CorridorParams
from agri_envs.scenes.rosmap import map_waypoints

LOCALIZATION_MODES = ("ground_truth", "odometry", "none")


@dataclasses.dataclass(frozen=True)
class GreenhouseNavConfig(StrictConfig):
    """Arguments of ``agri_envs/GreenhouseNav-v2`` (each one a ``gym.make`` keyword)."""

    # Scene
    scene: str = param(
        "greenhouse",
        "kind of scene",
        choices=("greenhouse", "corridor", "map"),
    )
    map_yaml: str = param("", "ROS map_server map to load (scene='map')", valid="YAML path, e.g. EXAMPLE_MAP")
    waypoints: tuple = param(
        (),
        "loop of waypoints in the map frame (scene='map'; () takes the map YAML's)",
        unit="m",
        valid=">= 2 (x, y)",
    )
    n_rows: int = param(3, "rows of plants", low=1, high=12)
    row_length: float = param(6.0, "length of each row", unit="m", low=2.0, high=40.0)
    corridor_width: float = param(
        1.2, "free width between rows (and between outer rows and walls)", unit="m", low=0.8, high=3.0
    )
    row_width: float = param(0.4, "width of a row bed", unit="m", low=0.2, high=1.5)
    headland: float = param(1.8, "free space between row ends and the end walls", unit="m", low=1.2, high=5.0)
    plant_spacing: float = param(0.4, "distance between plants along a row", unit="m", low=0.15, high=2.0)
    plant_jitter: float = param(0.03, "uniform jitter of plant positions", unit="m", low=0.0, high=0.1)
    growth: float = param(0.0, "season: plant size and leaves reaching into corridors", low=0.0, high=1.0)
    post_spacing: float = param(
        3.0, "distance between structural posts along rows and walls", unit="m", low=1.0, high=20.0
    )
    n_trees: int = param(0, "trees placed at random plant positions (Harik Fig. 10)", low=0, high=50)
    layout_seed: int = param(
        -1, "seed of the scene layout; -1 draws a new layout every episode", low=-1, high=2**31 - 1
    )
    scene_distribution: str = param(
        "off",
        "per-episode scenes (see Starting State)",
        choices=("off", *DISTRIBUTIONS),
    )
    office_length: float = param(14.0, "corridor length (scene='corridor')", unit="m", low=6.0, high=60.0)
    office_width: float = param(1.6, "corridor width (scene='corridor')", unit="m", low=1.0, high=4.0)
    office_route: str = param(
        "experiment",
        "corridor mission: Harik 3.4 or 3.5",
        choices=("experiment", "repeatability"),
    )
    n_people: int = param(2, "people walking the corridors and headlands", low=0, high=20)
    people_tease_prob: float = param(
        0.3, "chance that a person stands in the robot's way for a while", low=0.0, high=1.0
    )
    # Robot
    max_speed: float = param(0.6, "forward speed limit (reverse: half of it)", unit="m/s", low=0.1, high=2.0)
    max_turn_rate: float = param(1.2, "angular speed limit", unit="rad/s", low=0.2, high=4.0)
    max_accel: float = param(1.0, "linear acceleration limit", unit="m/s^2", low=0.1, high=10.0)
    max_angular_accel: float = param(3.0, "angular acceleration limit", unit="rad/s^2", low=0.1, high=20.0)
    control_period: float = param(1 / 15, "time between actions (the LIDAR's 15 Hz)", unit="s", low=0.01, high=0.5)
    frame_skip: int = param(1, "control periods per step (action held, observed once at the end)", low=1, high=16)
    # Sensors
    lidar_beams: int = param(90, "LIDAR beams in the observation (min-pooled from the full scan)", low=1, high=811)
    full_scan: bool = param(
        False, "add the full-resolution 811-beam scan as observation key 'scan'", adds_observation=True
    )
    lidar_noise_std: float = param(
        0.02, "LIDAR Gaussian range noise (TiM561 statistical error)", unit="m", low=0.0, high=0.5
    )
    lidar_dropout: float = param(0.01, "probability that a LIDAR beam returns no echo (max range)", low=0.0, high=0.5)
    sonar_noise_std: float = param(0.01, "sonar Gaussian range noise", unit="m", low=0.0, high=0.5)
    # Localization
    localization: str = param("ground_truth", "pose source", choices=LOCALIZATION_MODES)
    odometry_noise: float = param(0.05, "relative std of wheel-odometry speed errors", low=0.0, high=0.5)
    odometry_gyro_bias: float = param(
        0.01, "std of the per-episode turn-rate bias of odometry", unit="rad/s", low=0.0, high=0.2
    )
    # Task and reward
    waypoint_radius: float = param(
        0.3, "d_min: a waypoint is reached within this distance", unit="m", low=0.05, high=2.0
    )
    mission_cycles: int = param(1, "times the mission is driven in one episode (Harik sec. 3.5: 10)", low=1, high=100)
    terminate_on_collision: bool = param(True, "end the episode when the robot touches anything")
    safety_margin: float = param(
        0.25, "clearance below which the clearance penalty applies", unit="m", low=0.0, high=1.0
    )
    reward_progress: float = param(3.0, "weight of progress toward the waypoint (per metre)", low=0.0, high=100.0)
    reward_waypoint: float = param(1.0, "bonus per waypoint reached", low=0.0, high=100.0)
    reward_success: float = param(10.0, "bonus when the mission is complete", low=0.0, high=1000.0)
    reward_collision: float = param(20.0, "fixed part of the crash penalty (see Rewards)", low=0.0, high=1000.0)
    reward_clearance: float = param(
        6.0, "penalty per metre driven at zero clearance (linear in shortfall)", low=0.0, high=100.0
    )
    reward_time: float = param(0.01, "penalty per step", low=0.0, high=10.0)
    time_limit_speed_fraction: float = param(
        0.5, "time limit: mission at this fraction of speed limits", low=0.05, high=1.0
    )
    time_limit_wait: float = param(
        6.0, "default time limit: extra time per person per mission cycle", unit="s", low=0.0, high=120.0
    )
    render_width: int = param(800, "width of rendered frames", unit="px", low=100, high=4000)

    def map_mission(self) -> np.ndarray:
        """The waypoints of ``scene='map'``: ``waypoints``, or the map YAML's own when none are given."""
        if self.waypoints:
            return np.asarray(self.waypoints, dtype=np.float64)
        own = map_waypoints(self.map_yaml)
        return np.zeros((0, 2)) if own is None else own

    def validate(self) -> None:
        """Check the scene arguments fit together and corridors stay passable at this growth."""
        if self.scene == "map" and self.scene_distribution != "off":
            raise ValueError(
                f"GreenhouseNavConfig: scene_distribution={self.scene_distribution!r} draws greenhouse and corridor "
                "scenes; it does not apply to scene='map'."
            )
        if self.scene == "map":
            if not self.map_yaml or not Path(self.map_yaml).is_file():
                raise ValueError(
                    f"GreenhouseNavConfig: scene='map' needs map_yaml, an existing ROS map YAML file "
                    f"(got {self.map_yaml!r}); e.g. map_yaml=str(agri_envs.scenes.EXAMPLE_MAP)."
                )
            if not self.waypoints and map_waypoints(self.map_yaml) is None:
                raise ValueError(
                    f"GreenhouseNavConfig: scene='map' needs waypoints as >= 2 (x, y) pairs, or a map YAML that "
                    f"names its own under 'waypoints' (as EXAMPLE_MAP does); {self.map_yaml!r} has none."
                )
            pts = self.map_mission()
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.all(np.isfinite(pts)):
                raise ValueError(
                    f"GreenhouseNavConfig: scene='map' needs waypoints as >= 2 (x, y) pairs, got {self.waypoints!r}."
                )
            return
        if self.map_yaml or self.waypoints:
            raise ValueError("GreenhouseNavConfig: map_yaml and waypoints apply only to scene='map'.")
        if self.scene != "greenhouse":
            return
        free = self.layout_params().narrowest_free_width()
        if free < round(rover.WIDTH + 0.2, 3):
            raise ValueError(
                f"GreenhouseNavConfig: at growth={self.growth} the corridors keep only {free:.2f} m free; "
                f"the {rover.WIDTH} m wide robot needs {rover.WIDTH + 0.2:.2f} m: increase corridor_width "
                f"or row_width, or lower growth."
            )

    def distribution(self) -> SceneDistribution | None:
        """The training distribution ``scene_distribution`` names, or None when it is ``"off"``."""
        return DISTRIBUTIONS.get(self.scene_distribution)

    def layout_params(self) -> LayoutParams:
        """The scene part of the config."""
        return LayoutParams.from_config(self)

    def office_params(self) -> CorridorParams:
        """The office-corridor scene part of the config."""
        return CorridorParams(length=self.office_length, width=self.office_width, route=self.office_route)

    def reward_weights(self) -> RewardWeights:
        """The reward part of the config."""
        return RewardWeights(
            progress=self.reward_progress,
            waypoint=self.reward_waypoint,
            success=self.reward_success,
            collision=self.reward_collision,
            clearance=self.reward_clearance,
            time=self.reward_time,
        )
