"""Arguments of robot_chain_v1: one strict, typed, frozen dataclass (each field a keyword of ``parallel_env``)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from agri_envs._config import StrictConfig, param
from agri_envs.chain.distribution import DISTRIBUTIONS
from agri_envs.chain.task import ChainWeights, GhostParams
from agri_envs.scenes.distribution import SceneDistribution
from agri_envs.scenes.greenhouse import LayoutParams
from agri_envs.scenes.office import OfficeFloorParams


@dataclasses.dataclass(frozen=True)
class RobotChainConfig(StrictConfig):
    """Arguments of ``robot_chain_v1`` (each one a keyword of ``parallel_env`` / ``env``)."""

    n_robots: int = param(4, "robots in the chain (robot_0 leads)", low=1, high=256)
    scene: str = param("office", "kind of map", choices=("office", "greenhouse", "map"))
    map_yaml: str = param("", "ROS map_server map to load (scene='map')", valid="YAML path")
    layout_seed: int = param(-1, "seed of the generated map; -1 draws a new one every episode", low=-1, high=2**31 - 1)
    office_width: float = param(14.0, "office floor length along x (scene='office')", unit="m", low=6.0, high=100.0)
    office_height: float = param(9.0, "office floor depth along y (scene='office')", unit="m", low=5.0, high=100.0)
    office_rooms: int = param(3, "rooms on each side of the corridor (scene='office')", low=1, high=20)
    n_rows: int = param(3, "rows of plants (scene='greenhouse')", low=1, high=12)
    row_length: float = param(8.0, "length of the rows (scene='greenhouse')", unit="m", low=2.0, high=40.0)
    scene_distribution: str = param(
        "off", "per-episode floors and obstacles (see Starting State)", choices=("off", *DISTRIBUTIONS)
    )
    start: tuple = param((), "leader start (x, y); empty: sampled", unit="m", valid="() or (x, y)")
    goal: tuple = param((), "leader goal (x, y); empty: sampled", unit="m", valid="() or (x, y)")
    min_goal_distance: float = param(6.0, "shortest A* distance of a sampled goal", unit="m", low=0.0, high=500.0)
    n_dynamic_obstacles: int = param(1, "obstacles dropped into the leader's path", low=0, high=20)
    obstacle_radius: float = param(0.2, "radius of a dropped obstacle", unit="m", low=0.05, high=1.0)
    robot_radius: float = param(0.165, "robot radius (Amigobot: about 0.33 x 0.28 m)", unit="m", low=0.05, high=0.5)
    max_speed: float = param(0.4, "speed limit, both directions", unit="m/s", low=0.05, high=2.0)
    max_turn_rate: float = param(2.0, "angular speed limit", unit="rad/s", low=0.2, high=6.0)
    max_accel: float = param(1.0, "linear acceleration limit", unit="m/s^2", low=0.1, high=10.0)
    max_angular_accel: float = param(6.0, "angular acceleration limit", unit="rad/s^2", low=0.1, high=40.0)
    control_period: float = param(0.1, "time between actions", unit="s", low=0.01, high=0.5)
    sonar_range: float = param(3.0, "sonar maximum range", unit="m", low=0.5, high=10.0)
    sonar_aperture: float = param(0.9, "sonar cone opening angle", unit="rad", low=0.05, high=1.5)
    sonar_noise_std: float = param(0.005, "sonar Gaussian range noise", unit="m", low=0.0, high=0.5)
    spacing: float = param(0.55, "d_s: desired distance between neighbours", unit="m", low=0.2, high=5.0)
    max_gap: float = param(1.2, "Delta: a gap larger than this breaks the chain", unit="m", low=0.3, high=10.0)
    planning_margin: float = param(0.2, "clearance added to the robot radius for A*", unit="m", low=0.0, high=1.0)
    map_resolution: float = param(0.05, "grid cell size for planning", unit="m", low=0.01, high=0.5)
    ghost_speed: float = param(0.35, "v_F: ghost pseudo speed along the A* path", unit="m/s", low=0.01, high=5.0)
    ghost_back_speed: float = param(0.2, "v_B: ghost speed back toward a stuck leader", unit="m/s", low=0.0, high=5.0)
    ghost_leash: float = param(0.5, "eta: the ghost waits while the leader is farther", unit="m", low=0.1, high=10.0)
    ghost_patience: float = param(2.0, "T: time beyond eta before the ghost comes back", unit="s", low=0.0, high=60.0)
    goal_radius: float = param(
        0.3, "the leader has arrived within this distance of the goal", unit="m", low=0.05, high=2.0
    )
    arrival_stretch: float = param(
        1.2, "robot k has arrived within goal_radius + k * arrival_stretch * spacing of the goal", low=1.0, high=10.0
    )
    max_cycles: int = param(1500, "steps before truncation", low=1, high=1_000_000)
    terminate_on_collision: bool = param(True, "end the episode when any robot touches anything")
    terminate_on_break: bool = param(True, "end the episode when a gap between neighbours exceeds max_gap")
    reward_progress: float = param(
        1.0, "per metre the robots come nearer to arriving (mean over robots)", low=0.0, high=100.0
    )
    reward_spacing: float = param(
        1.0, "spacing-error penalty over a whole episode (paid per step)", low=0.0, high=100.0
    )
    reward_strip: float = param(0.5, "strip-distance penalty over a whole episode (paid per step)", low=0.0, high=100.0)
    reward_time: float = param(1.0, "time penalty over a whole episode (paid per step)", low=0.0, high=100.0)
    reward_collision: float = param(
        10.0, "cost of a contact (plus the rest of the episode at the worst step cost)", low=0.0, high=1000.0
    )
    reward_break: float = param(
        10.0, "cost of a gap above max_gap (plus the rest of the episode likewise)", low=0.0, high=1000.0
    )
    reward_success: float = param(
        10.0, "bonus when every robot has arrived, chain intact, no contact", low=0.0, high=1000.0
    )
    render_width: int = param(800, "width of rendered frames", unit="px", low=100, high=4000)

    def validate(self) -> None:
        """Check map, start/goal and spacing arguments fit together."""
        if self.scene == "map":
            if not self.map_yaml or not Path(self.map_yaml).is_file():
                raise ValueError(
                    "RobotChainConfig: scene='map' needs map_yaml, an existing ROS map YAML file "
                    f"(got {self.map_yaml!r})."
                )
        elif self.map_yaml:
            raise ValueError("RobotChainConfig: map_yaml applies only to scene='map'.")
        if self.scene_distribution != "off" and (
            self.scene == "map" or self.layout_seed >= 0 or self.start or self.goal
        ):
            raise ValueError(
                f"RobotChainConfig: scene_distribution={self.scene_distribution!r} draws a new floor every episode; "
                "it takes neither scene='map', a layout_seed >= 0, nor a given start or goal."
            )
        for name in ("start", "goal"):
            value = getattr(self, name)
            if value != () and (
                len(value) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value)
            ):
                raise ValueError(f"RobotChainConfig: {name} must be () or (x, y) in metres, got {value!r}.")
        if self.spacing < 2 * self.robot_radius + 0.05:
            raise ValueError(
                f"RobotChainConfig: spacing={self.spacing} m leaves no room between robots of radius "
                f"{self.robot_radius} m; use spacing >= {2 * self.robot_radius + 0.05:.2f}."
            )
        if self.max_gap <= self.spacing:
            raise ValueError(f"RobotChainConfig: max_gap ({self.max_gap}) must exceed spacing ({self.spacing}).")
        if self.arrival_stretch * self.spacing > self.max_gap:
            raise ValueError(
                f"RobotChainConfig: arrival_stretch * spacing ({self.arrival_stretch * self.spacing:.3g} m) must not "
                f"exceed max_gap ({self.max_gap} m): an arrived chain is an intact chain; use arrival_stretch <= "
                f"{self.max_gap / self.spacing:.3g}."
            )
        step_cost = self.reward_time + self.reward_spacing + self.reward_strip
        if self.reward_success <= step_cost:
            raise ValueError(
                f"RobotChainConfig: reward_success ({self.reward_success}) must exceed reward_time + reward_spacing + "
                f"reward_strip ({step_cost:.3g}), the most the per-step penalties can cost in an episode; otherwise a "
                "slow success can pay less than never arriving."
            )
        if self.terminate_on_collision and not self.reward_collision > 0:
            raise ValueError("RobotChainConfig: reward_collision must be > 0 while terminate_on_collision is set.")
        if self.terminate_on_break and not self.reward_break > 0:
            raise ValueError("RobotChainConfig: reward_break must be > 0 while terminate_on_break is set.")

    def distribution(self) -> SceneDistribution | None:
        """The distribution ``scene_distribution`` names, or None when it is ``"off"``."""
        return DISTRIBUTIONS.get(self.scene_distribution)

    def office_params(self) -> OfficeFloorParams:
        """The office floor of ``scene="office"``."""
        return OfficeFloorParams(width=self.office_width, height=self.office_height, rooms_per_side=self.office_rooms)

    def greenhouse_params(self) -> LayoutParams:
        """The greenhouse of ``scene="greenhouse"`` (every other scene parameter at its default)."""
        return LayoutParams(n_rows=self.n_rows, row_length=self.row_length)

    def ghost_params(self) -> GhostParams:
        """The ghost robot's speeds and thresholds (sec. 4.4)."""
        return GhostParams(
            v_forward=self.ghost_speed,
            v_back=self.ghost_back_speed,
            eta=self.ghost_leash,
            patience=self.ghost_patience,
            window=max(1.5, 4 * self.max_speed * self.control_period + 1.0),
        )

    def weights(self) -> ChainWeights:
        """The reward part of the config."""
        return ChainWeights(
            progress=self.reward_progress,
            spacing=self.reward_spacing,
            strip=self.reward_strip,
            collision=self.reward_collision,
            chain_break=self.reward_break,
            success=self.reward_success,
            time=self.reward_time,
        )

    def arrival_radii(self) -> tuple[float, ...]:
        """Robot k has arrived within ``goal_radius + k * arrival_stretch * spacing`` of the goal (m)."""
        step = self.arrival_stretch * self.spacing
        return tuple(self.goal_radius + k * step for k in range(self.n_robots))
