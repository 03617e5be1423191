"""`tabletop_push` options: every geometry knob and threshold, and which robot, validated once.

A frozen dataclass fed from YAML (`configs/tabletop_push.yaml`) or the CLI; `__post_init__`
rejects inverted ranges, non-positive sizes, and spawn ranges or goal regions off the table
with a `ConfigError` naming them, and `robot_spec` resolves the robot (registered, or a user
MJCF).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import check
from openral_mjx.robots import ROBOTS, RobotSpec, user_robot
from openral_mjx.scenes.sensor_obs import SensorObsOptions

Pair = tuple[float, float]
Vec3 = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class TabletopPushOptions(SensorObsOptions):
    """Every geometry knob and threshold of `tabletop_push` (SI units, world frame).

    The robot base sits on the table top at (`robot_base_x`, `robot_base_y`), turned by
    `robot_base_yaw` (rad) about z from its MJCF orientation; `robot_base_x` None (the default)
    places it from the arm's measured reach (0 where the arm reaches the workspace from there,
    as the SO-101 does). The arm starts at keyframe `robot_keyframe`; None: the robot's own
    home pose (so101), else its MJCF's `home` keyframe, else qpos0. Spawn ranges and the goal
    region are in the world frame and must lie on the table. Sensor
    observations (`obs_*`, off by default): depth cameras `overhead` and `front`, RGB on
    `warp`, and a laser on a robot body or site (a user robot with a mobile base).
    """

    robot: str = "so101"
    robot_mjcf: str | None = None
    ee_site: str = "ee"
    robot_keyframe: str | None = None
    robot_base_x: float | None = None
    robot_base_y: float = 0.0
    robot_base_yaw: float = 0.0
    table_size: Pair = (0.6, 0.7)
    table_center: Pair = (0.2, 0.0)
    table_height: float = 0.75
    cube_size: float = 0.03
    cube_mass: float = 0.05
    cube_friction: float = 0.6
    cube_spawn_x: Pair = (0.17, 0.25)
    cube_spawn_y: Pair = (-0.08, 0.08)
    goal_distance: Pair = (0.06, 0.10)
    goal_region_x: Pair = (0.14, 0.28)
    goal_region_y: Pair = (-0.12, 0.12)
    goal_radius: float = 0.02
    rest_height_tol: float = 0.005
    rest_speed: float = 0.05
    timestep: float = 0.002
    n_substeps: int = 10
    solver_iterations: int = 6
    solver_ls_iterations: int = 8
    max_steps: int = 200
    camera_overhead_pos: Vec3 = (0.2, 0.0, 1.45)
    camera_front_pos: Vec3 = (0.75, 0.0, 1.05)
    camera_target: Vec3 = (0.2, 0.0, 0.75)

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in (
            "cube_spawn_x",
            "cube_spawn_y",
            "goal_distance",
            "goal_region_x",
            "goal_region_y",
        ):
            lo, hi = getattr(self, name)
            check(lo <= hi, f"option {name}={[lo, hi]}: low must be <= high")
        for name in (
            "cube_size",
            "cube_mass",
            "goal_radius",
            "timestep",
            "table_height",
            "rest_height_tol",
            "rest_speed",
        ):
            check(getattr(self, name) > 0, f"option {name}={getattr(self, name)}: must be > 0")
        check(min(self.table_size) > 0, f"option table_size={list(self.table_size)}: must be > 0")
        for name in ("n_substeps", "max_steps", "solver_iterations", "solver_ls_iterations"):
            check(getattr(self, name) >= 1, f"option {name}={getattr(self, name)}: must be >= 1")
        check(self.cube_friction >= 0, f"option cube_friction={self.cube_friction}: must be >= 0")
        lo, hi = self.goal_distance
        check(lo >= 0, f"option goal_distance={[lo, hi]}: must be >= 0")
        check(
            self.cube_size < min(self.table_size),
            f"option cube_size={self.cube_size}: must be smaller than the table "
            f"(table_size={list(self.table_size)})",
        )
        # Cube centres (spawned, or resting on a goal) keep the whole cube on the table top.
        for axis, name in ((0, "x"), (1, "y")):
            margin = self.table_size[axis] / 2 - self.cube_size / 2
            low = round(self.table_center[axis] - margin, 6)
            high = round(self.table_center[axis] + margin, 6)
            for option in (f"cube_spawn_{name}", f"goal_region_{name}"):
                lo, hi = getattr(self, option)
                check(
                    low <= lo and hi <= high,
                    f"option {option}={[lo, hi]} leaves the table: cube centres must lie in "
                    f"[{low}, {high}] (table_center, table_size, cube_size)",
                )

    def robot_spec(self) -> RobotSpec:
        """The registered robot, or the user MJCF when `robot_mjcf` is set."""
        if self.robot_mjcf is not None:
            path = Path(self.robot_mjcf)
            if not path.is_file():
                raise ConfigError(f"robot MJCF {self.robot_mjcf!r} does not exist")
            return user_robot(path, self.ee_site)
        return ROBOTS.get(self.robot)
