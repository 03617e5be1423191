"""`so101_box` options: every geometry knob, threshold and camera intrinsic, validated once.

A frozen dataclass fed from YAML (`configs/so101_box.yaml`) or the CLI; `__post_init__` rejects
inconsistent values (a tube wider than the hole, spawn ranges outside the arena or with no room
for both objects) with a `ConfigError` naming them.
"""

from __future__ import annotations

import dataclasses
import math

from openral_mjx.core.options import check
from openral_mjx.scenes.sensor_obs import SensorObsOptions

Pair = tuple[float, float]
Vec3 = tuple[float, float, float]
Size = tuple[int, int]


@dataclasses.dataclass(frozen=True)
class So101BoxOptions(SensorObsOptions):
    """Every geometry knob and threshold of `so101_box` (SI units: m, kg, rad; world frame).

    World frame: origin on the floor at the robot base, +x forward (away from the back wall),
    +z up. Camera intrinsics are pinhole parameters in pixels, (cx, cy) in image coordinates
    where pixel (u, v) covers [u, u + 1) x [v, v + 1) (a centred principal point is (W/2,
    H/2)). Sensor observations (`obs_*`, off by default), e.g. `obs_depth_cameras:
    [overhead]`: the overhead camera's depth at `obs_depth_size` (default 64 x 40, its aspect
    ratio), intrinsics scaled from the camera's.
    """

    obs_depth_size: tuple[int, int] = (64, 40)
    obs_depth_range: tuple[float, float] = (0.0, 1.0)

    robot: str = "so101"
    # Arena: inner size, the robot's base at the middle of the back wall.
    arena_width: float = 1.0  # along y
    arena_depth: float = 0.615  # along x
    arena_height: float = 0.75
    robot_back_gap: float = 0.05  # back wall to robot base origin
    robot_home: tuple[float, float, float, float, float, float] = (0.0, -1.7, 0.6, 1.6, 0.0, 0.0)
    # Slotted block: square, a round through hole at its centre, a slot from the hole to +x.
    block_size: Vec3 = (0.0445, 0.0445, 0.020)
    hole_diameter: float = 0.023
    slot_width: float = 0.005
    block_mass: float = 0.05
    block_friction: float = 0.3
    # Tube: solid cylinder (see the package docstring for its collision shapes).
    tube_diameter: float = 0.0219
    tube_length: float = 0.09
    tube_mass: float = 0.03
    tube_friction: float = 0.3
    contact_timeconst: float = 0.005  # solref time constant of the tube's contacts
    block_solimp: Vec3 = (0.9, 0.95, 0.001)  # tube-block contacts
    grip_solimp: Vec3 = (0.99, 0.99, 0.001)  # tube-finger contacts (stiff: a 60 N squeeze)
    rim_radius: float = 0.0005
    # Spawn ranges (world frame) and separations.
    block_spawn_x: Pair = (0.17, 0.24)
    block_spawn_y: Pair = (-0.09, 0.09)
    block_spawn_yaw: Pair = (-math.pi, math.pi)
    tube_spawn_x: Pair = (0.17, 0.24)
    tube_spawn_y: Pair = (-0.09, 0.09)
    tube_spawn_yaw: Pair = (-math.pi, math.pi)
    spawn_gap: float = 0.03  # free floor between the block's and the tube's footprint circles
    robot_keepout: float = 0.10  # radius around the base origin that no footprint enters
    # Success: tube vertical in the hole.
    insertion_depth: float = 0.015  # lower end below the block's top face by at least this
    tilt_tolerance: float = math.radians(5.0)  # tube axis from vertical
    # Cameras. overhead: OAK-D Pro-like (depth-aligned 640x400, HFOV 80 deg, VFOV 55 deg).
    overhead_camera_pos: Vec3 = (0.2575, 0.0, 0.74)
    overhead_camera_target: Vec3 = (0.2575, 0.0, 0.0)
    overhead_camera_resolution: Size = (640, 400)
    overhead_camera_focal: Pair = (383.0, 383.0)  # fx, fy (pixels)
    overhead_camera_principal: Pair = (320.0, 200.0)  # cx, cy (pixels)
    # wrist: on the gripper body (gripper frame), looking between the finger tips.
    wrist_camera_pos: Vec3 = (0.0, 0.04, -0.02)
    wrist_camera_target: Vec3 = (0.004, 0.0, -0.10)
    wrist_camera_resolution: Size = (640, 480)
    wrist_camera_focal: Pair = (320.0, 320.0)
    wrist_camera_principal: Pair = (320.0, 240.0)
    # Physics and episode.
    timestep: float = 0.002
    n_substeps: int = 10
    solver_iterations: int = 6
    solver_ls_iterations: int = 8
    max_steps: int = 300

    def __post_init__(self) -> None:
        super().__post_init__()
        check(self.robot == "so101", f"scene so101_box requires robot 'so101', not {self.robot!r}")
        ranges = [f.name for f in dataclasses.fields(self) if "_spawn_" in f.name]
        for name in ranges:
            lo, hi = getattr(self, name)
            check(lo <= hi, f"option {name}={[lo, hi]}: low must be <= high")
        positive = (
            "arena_width",
            "arena_depth",
            "arena_height",
            "hole_diameter",
            "slot_width",
            "block_mass",
            "tube_diameter",
            "tube_length",
            "tube_mass",
            "contact_timeconst",
            "insertion_depth",
            "tilt_tolerance",
            "timestep",
        )
        for name in positive:
            check(getattr(self, name) > 0, f"option {name}={getattr(self, name)}: must be > 0")
        for name in ("n_substeps", "max_steps", "solver_iterations", "solver_ls_iterations"):
            check(getattr(self, name) >= 1, f"option {name}={getattr(self, name)}: must be >= 1")
        for name in ("block_friction", "tube_friction", "rim_radius", "spawn_gap", "robot_keepout"):
            check(getattr(self, name) >= 0, f"option {name}={getattr(self, name)}: must be >= 0")
        check(min(self.block_size) > 0, f"option block_size={list(self.block_size)}: must be > 0")
        check(
            self.slot_width < self.hole_diameter < min(self.block_size[:2]),
            f"options slot_width={self.slot_width} < hole_diameter={self.hole_diameter} < "
            f"block side={min(self.block_size[:2])} must hold",
        )
        check(
            self.tube_diameter < self.hole_diameter,
            f"option tube_diameter={self.tube_diameter} must be < hole_diameter "
            f"({self.hole_diameter}) for the tube to fit",
        )
        check(
            self.tube_length > self.tube_diameter,
            f"option tube_length={self.tube_length} must exceed tube_diameter "
            f"({self.tube_diameter}): the tube's capsule needs a straight part",
        )
        check(
            0 < self.insertion_depth <= self.block_size[2],
            f"option insertion_depth={self.insertion_depth}: must be in (0, block height "
            f"{self.block_size[2]}]",
        )
        check(
            self.tilt_tolerance < math.pi / 2,
            f"option tilt_tolerance={self.tilt_tolerance}: must be < pi/2",
        )
        for name in ("block_solimp", "grip_solimp"):
            imp = getattr(self, name)
            check(
                min(imp[:2]) >= 0 and max(imp[:2]) < 1 and imp[2] > 0,
                f"option {name}={list(imp)}: impedances must be in [0, 1), width > 0",
            )
        for cam in ("overhead", "wrist"):
            res = getattr(self, f"{cam}_camera_resolution")
            focal = getattr(self, f"{cam}_camera_focal")
            check(min(res) >= 1, f"option {cam}_camera_resolution={list(res)}: must be >= 1")
            check(min(focal) > 0, f"option {cam}_camera_focal={list(focal)}: must be > 0")
        x_lo, x_hi = -self.robot_back_gap, self.arena_depth - self.robot_back_gap
        for obj, radius in (("block", self.block_radius), ("tube", self.tube_diameter / 2)):
            xr, yr = getattr(self, f"{obj}_spawn_x"), getattr(self, f"{obj}_spawn_y")
            inside = (
                xr[0] - radius >= x_lo
                and xr[1] + radius <= x_hi
                and max(abs(yr[0]), abs(yr[1])) + radius <= self.arena_width / 2
            )
            check(
                inside,
                f"options {obj}_spawn_x={list(xr)}, {obj}_spawn_y={list(yr)}: the {obj} must "
                f"spawn inside the arena (x in [{x_lo}, {x_hi}], |y| <= {self.arena_width / 2})",
            )
        self.fallback_layout()

    @property
    def block_radius(self) -> float:
        """Radius of the block's footprint circle (half its footprint diagonal)."""
        return math.hypot(self.block_size[0], self.block_size[1]) / 2

    def fallback_layout(self) -> tuple[Pair, Pair]:
        """Block and tube (x, y), corners of their spawn ranges, that keep every separation.

        Used when no random draw does; a `ConfigError` if even the best corners cannot.
        """
        r_block, r_tube = self.block_radius, self.tube_diameter / 2
        best, best_sep = None, -1.0
        for bx in self.block_spawn_x:
            for by in self.block_spawn_y:
                for tx in self.tube_spawn_x:
                    for ty in self.tube_spawn_y:
                        sep = math.hypot(bx - tx, by - ty) - r_block - r_tube
                        ok = (
                            math.hypot(bx, by) >= self.robot_keepout + r_block
                            and math.hypot(tx, ty) >= self.robot_keepout + r_tube
                            and sep >= self.spawn_gap
                        )
                        if ok and sep > best_sep:
                            best, best_sep = ((bx, by), (tx, ty)), sep
        check(
            best is not None,
            "spawn ranges leave no room to place the block and the tube apart (spawn_gap="
            f"{self.spawn_gap}) and clear of the robot (robot_keepout={self.robot_keepout})",
        )
        return best  # type: ignore[return-value]
