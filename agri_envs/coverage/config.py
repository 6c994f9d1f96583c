"""Arguments of ``agri_envs/GreenhouseCoverage-v2``: one strict, typed, frozen dataclass (``gym.make`` keywords)."""

from __future__ import annotations

import dataclasses
import math

from agri_envs._config import StrictConfig, param
from agri_envs.coverage import robot as fito
from agri_envs.coverage.distribution import DISTRIBUTIONS
from agri_envs.coverage.task import CoverageWeights
from agri_envs.scenes.distribution import SceneDistribution
from agri_envs.scenes.greenhouse import LayoutParams

LOCALIZATION_MODES = ("odometry", "ground_truth")


@dataclasses.dataclass(frozen=True)
class GreenhouseCoverageConfig(StrictConfig):
    """Arguments of ``agri_envs/GreenhouseCoverage-v2`` (each one a ``gym.make`` keyword)."""

    # Scene
    n_rows: int = param(4, "rows of plants (the corridors are the n_rows + 1 spaces beside them)", low=1, high=12)
    row_length: float = param(10.0, "length of each row", unit="m", low=3.0, high=50.0)
    corridor_width: float = param(1.4, "mean free width of a corridor", unit="m", low=1.0, high=3.0)
    corridor_width_jitter: float = param(
        0.1, "each corridor is corridor_width + U(-jitter, jitter) wide", unit="m", low=0.0, high=0.4
    )
    row_incline: float = param(0.01, "each row is tilted by U(-incline, incline)", unit="rad", low=0.0, high=0.05)
    row_bend: float = param(0.05, "each row bows sideways by U(-bend, bend) at mid-length", unit="m", low=0.0, high=0.3)
    row_width: float = param(0.6, "width of a row bed", unit="m", low=0.2, high=1.5)
    headland: float = param(2.6, "free space between row ends and the end walls", unit="m", low=2.2, high=6.0)
    plant_spacing: float = param(0.4, "distance between plants along a row", unit="m", low=0.15, high=2.0)
    plant_jitter: float = param(0.03, "uniform jitter of plant positions", unit="m", low=0.0, high=0.1)
    growth: float = param(0.6, "season: plant size and leaves reaching into corridors", low=0.0, high=1.0)
    post_spacing: float = param(
        4.0, "distance between structural posts along rows and walls", unit="m", low=1.0, high=20.0
    )
    layout_seed: int = param(-1, "layout seed; -1: a new greenhouse every episode", low=-1, high=2**31 - 1)
    scene_distribution: str = param(
        "off",
        "per-episode scenes (see Starting State)",
        choices=("off", *DISTRIBUTIONS),
    )
    # Robot (756 kg: low accelerations)
    max_speed: float = param(0.5, "forward speed limit (reverse: half of it)", unit="m/s", low=0.1, high=1.5)
    max_turn_rate: float = param(0.6, "angular speed limit", unit="rad/s", low=0.1, high=2.0)
    max_accel: float = param(0.3, "linear acceleration limit", unit="m/s^2", low=0.05, high=2.0)
    max_angular_accel: float = param(0.8, "angular acceleration limit", unit="rad/s^2", low=0.05, high=5.0)
    control_period: float = param(0.1, "time between actions (the paper's 100 ms)", unit="s", low=0.02, high=0.5)
    # Sensors
    sonar_noise_std: float = param(0.01, "sonar Gaussian range noise", unit="m", low=0.0, high=0.5)
    vegetation_echo_prob: float = param(
        0.15, "chance that an echo off foliage slips through (reads long)", low=0.0, high=1.0
    )
    compass_noise_std: float = param(0.01, "compass Gaussian heading noise", unit="rad", low=0.0, high=0.5)
    compass_bias: float = param(0.03, "constant compass heading bias", unit="rad", low=-0.5, high=0.5)
    encoder_noise: float = param(0.02, "relative std of each track-speed measurement", low=0.0, high=0.5)
    encoder_scale_std: float = param(
        0.01, "per-episode scale error std of each track encoder (drift)", low=0.0, high=0.1
    )
    localization: str = param("odometry", "source of the 'pose' observation", choices=LOCALIZATION_MODES)
    route_observation: bool = param(
        False,
        "PRIVILEGED: add the 'route' observation (the covering serpentine ahead, from the true pose)",
        adds_observation=True,
    )
    # Task and reward
    bin_length: float = param(0.25, "length of a coverage bin along a corridor", unit="m", low=0.05, high=2.0)
    terminate_on_contact: bool = param(True, "end the episode on touching the crop or anything else")
    time_limit: float = param(0.0, "episode time limit; 0 sizes it to the mission", unit="s", low=0.0, high=36000.0)
    reward_coverage: float = param(1.0, "reward per corridor covered (paid per bin)", low=0.0, high=100.0)
    reward_progress: float = param(
        0.3, "reward per metre along the covering serpentine (see Rewards)", low=0.0, high=100.0
    )
    reward_success: float = param(10.0, "bonus when every corridor is covered", low=0.0, high=1000.0)
    reward_contact: float = param(10.0, "penalty on contact", low=0.0, high=1000.0)
    reward_cross_track: float = param(0.0, "penalty per step per metre of cross-track error", low=0.0, high=100.0)
    reward_time: float = param(0.001, "penalty per step", low=0.0, high=10.0)
    render_width: int = param(800, "width of rendered frames", unit="px", low=100, high=4000)

    def validate(self) -> None:
        """Check that the narrowest corridor still lets the 0.7 m wide robot pass with 0.2 m to spare."""
        free = self.layout_params().narrowest_free_width()
        if free < round(fito.WIDTH + 0.2, 3):
            raise ValueError(
                f"GreenhouseCoverageConfig: the narrowest corridor keeps only {free:.2f} m free (corridor_width "
                f"minus corridor_width_jitter, row_incline and row_bend narrowing, and leaves at "
                f"growth={self.growth}); "
                f"the {fito.WIDTH} m wide Fitorobot needs {fito.WIDTH + 0.2:.2f} m: increase corridor_width or "
                f"lower the variation."
            )

    def distribution(self) -> SceneDistribution | None:
        """The training distribution ``scene_distribution`` names, or None when it is ``"off"``."""
        return DISTRIBUTIONS.get(self.scene_distribution)

    def layout_params(self) -> LayoutParams:
        """The scene part of the config."""
        return LayoutParams.from_config(self)

    def largest_size(self) -> tuple[float, float]:
        """Inner length and width (m) of the largest greenhouse these arguments generate (corridors at their widest)."""
        lp = self.layout_params()
        return lp.width, lp.height + (self.n_rows + 1) * self.corridor_width_jitter

    def mission_time(self) -> float:
        """The episode time limit (s): ``time_limit``, or three times the serpentine at full speed plus turns."""
        if self.time_limit > 0:
            return self.time_limit
        n = self.n_rows + 1
        length = n * (self.row_length + self.headland) + self.n_rows * (self.corridor_width + self.row_width)
        turns = 2 * self.n_rows * (math.pi / 2) / self.max_turn_rate
        return 3.0 * (length / self.max_speed + turns) + 30.0

    def weights(self) -> CoverageWeights:
        """The reward part of the config."""
        return CoverageWeights(
            coverage=self.reward_coverage,
            success=self.reward_success,
            contact=self.reward_contact,
            cross_track=self.reward_cross_track,
            time=self.reward_time,
            progress=self.reward_progress,
        )
