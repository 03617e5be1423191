"""`so101_box`: insert a tube into a slotted block's hole with the SO-101, in a box arena.

World frame: origin on the floor at the robot's base, +x forward, +z up. The arena (default
100 cm wide along y, 61.5 cm deep along x, 75 cm high) has a floor, four walls (planes facing
in) and a ceiling light; the SO-101 stands at the middle of the back wall. Cameras: `overhead`
(OAK-D Pro-like, looking straight down from the ceiling: 640 x 400 px, fx = fy = 383 px, cx, cy
at the image centre, i.e. HFOV 80 deg x VFOV 55 deg like its depth stream) and `wrist` (on the
gripper, looking between the finger tips: 640 x 480 px, fx = fy = 320 px); the intrinsics are
options and are written into the MJCF cameras (resolution, focal and principal point in
pixels, sensor pitch 3 um).

Objects. The block (44.5 x 44.5 x 20 mm, free, on the floor) has a 23 mm through hole at its
centre and a 5 mm slot from the hole to its +x face. The tube (21.9 x 90 mm, free) stands on
the floor. Reset draws block and tube (x, y, yaw) independently in their spawn ranges until
their footprint circles are `spawn_gap` apart and clear of the robot (`sample_layout`).

Collision shapes, chosen for what MJX's JAX implementation can collide (it has no
cylinder-box or cylinder-mesh pair, and box-box is its most expensive one):

* block: nine boxes, four walls (the +x one split by the slot) around a square hole and four
  45-degree corner boxes that make the hole an octagon whose inscribed circle is the 23 mm
  hole (a square would let the tube off-axis by 0.78 mm diagonally; the octagon by 0.60 mm),
  plus nine thin capsules (`rim_radius` 0.5 mm) along the hole's top edges. The capsules' inner
  surfaces are tangent to the hole's walls, so the clearance is unchanged; they make the
  tube's rounded end meet the rim as an exact capsule-capsule contact: MJX's capsule-box
  collider picks the box face of least penetration, so a tube pressed onto a bare box edge
  slides along the hole's wall instead of resting on the rim. A thin footprint box is the only
  block geom touching the floor and walls.
* tube: a capsule of the tube's radius and full length (what the block and the robot touch)
  and a cylinder (what the floor and walls touch, so it stands on a flat end). The capsule's
  lower end is a hemisphere, a lead-in the real tube does not have: held 1 mm off the hole's
  axis it rests on the rim with its tip ~8 mm into the hole, short of `insertion_depth`.
* robot: the SO-101's primitives, plus a flat pad on the moving jaw that is parallel to the
  fixed finger when the jaws are one tube diameter apart (the pivoting jaw's own finger meets
  the tube at ~15 degrees and tilts it in the grasp); the pad replaces that finger's collisions.
  The arm does not collide with the block (its nine boxes against the three gripper boxes
  would add 27 box-box pairs to every MJX step); it does collide with the tube and the floor.

Contact model: the tube's contacts use `contact_timeconst` (5 ms); with the block, impedance
`block_solimp` (MuJoCo's default); with the fingers, the stiffer `grip_solimp` (the 2.94 N m jaw
servo squeezes the 30 g tube hard: each finger sinks 1.3 mm into it at the default impedance,
0.24 mm at 0.99). 87 contact slots for MJX, all between
primitives (planes, capsules, boxes, cylinders). Tested fit (tests/test_so101_box_fit.py):
dropped at rest onto the hole with its axis vertical, the tube falls through with its axis
0.4 mm off centre and stays on the rim at 0.7 mm and 1 mm, on MuJoCo C and on MJX alike
(same resting heights within 0.1 mm): the effective radial clearance is in (0.4, 0.7) mm,
against 0.55 mm specified. Pushed down with 2 N instead of its weight, soft contacts let a
tube up to 0.75 mm off the axis squeeze in; at 1 mm it holds even at 10 N.

Physics: 2 ms steps, 10 per 20 ms control step, Newton solver 6 iterations / 8 line-search,
Euler integration (MJX's implicitfast disagrees with MuJoCo C on the servos' damping).

Action: one position target per actuator (5 arm joints and the jaw), clipped to ctrlrange.

Observation (flat, float32; slices in `obs_layout`): joint positions and velocities, the
end-effector site's position, tube position and quaternion (w, x, y, z), block position and
quaternion, world frame.

Reward (dense, per control step): ``-0.5 |grasp site - tube centre| - |tube's lower end -
(hole axis at insertion depth)| + 1[success]``.

Success: the tube inserted vertically into the hole: its axis within `tilt_tolerance` of
vertical (either end down), its lower end at least `insertion_depth` below the block's top
face and within the hole's radius of the hole's axis (both measured in the block's frame).
The episode ends on success or divergence.

Episode factors (for success breakdowns), from the reset state: `tube_block_distance`,
`tube_reach` and `block_reach` (from the robot base, m) and `block_yaw` (rad).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.options import check
from openral_mjx.physics import PhysicsSettings, QuantitySpec, make_backend
from openral_mjx.physics.kinematics import site_kinematics
from openral_mjx.policies.base import Policy
from openral_mjx.policies.insert_expert import insert_expert
from openral_mjx.robots import ROBOTS
from openral_mjx.scenes.base import Scene, State, actuator_joints, arm_obs_layout
from openral_mjx.scenes.composition import load_robot, look_at_quat, yaw_quat
from openral_mjx.scenes.sensor_obs import SensorObsOptions, sensor_obs, sensor_shapes

Pair = tuple[float, float]
Vec3 = tuple[float, float, float]
Size = tuple[int, int]

# Contact bits (contype/conaffinity); a pair collides when one's contype meets the other's
# conaffinity. The SO-101 MJCF gives arm links contype 4 and wrist/gripper/jaw contype 2.
_SURFACE = 1  # floor and walls (contype)
_DISTAL = 2  # robot wrist, gripper body and fingers (contype, from so101.xml)
_LINK = 4  # robot upper/lower arm and shoulder (contype, from so101.xml)
_TUBE_SIDE = 8  # the tube's capsule (contype) meeting the block's wall boxes (conaffinity)
_RESTING = 16  # the tube's cylinder and the block's footprint: they meet floor and walls

_CANDIDATES = 32  # (block, tube) layouts drawn per reset; the first valid one is used


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
    # Tube: solid cylinder (see module docstring for its collision shapes).
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


def _frame_quat(x_axis: Vec3, z_axis: Vec3) -> list[float]:
    """Quaternion of the frame with these x and z axes (y = z cross x)."""
    x, z = np.asarray(x_axis, float), np.asarray(z_axis, float)
    mat = np.stack([x, np.cross(z, x), z], axis=1)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.reshape(-1))
    return quat.tolist()


def _camera(parent, name: str, pos, target, resolution, focal, principal) -> None:
    """A pinhole camera with intrinsics in pixels (sensor pitch 3 um, OV9282's)."""
    pitch = 3e-6
    cam = parent.add_camera(name=name, pos=list(pos), quat=look_at_quat(pos, target).tolist())
    cam.resolution = list(resolution)
    cam.sensor_size = [resolution[0] * pitch, resolution[1] * pitch]
    cam.focal_pixel = list(focal)
    # MuJoCo's principal point is the image centre's offset from the optical axis: the axis
    # crosses the image at (W/2 - px, H/2 - py), as its renderer draws it (checked against
    # MuJoCo's OpenGL renderer in tests/test_depth_camera.py).
    cam.principal_pixel = [resolution[0] / 2 - principal[0], resolution[1] / 2 - principal[1]]


def add_block(spec: mujoco.MjSpec, o: So101BoxOptions) -> mujoco.MjsBody:
    """The slotted block (free body, frame at its centre): a box decomposition of a square
    block with an octagonal through hole (inscribed circle = the hole) and a slot to +x."""
    sx, sy, sz = (v / 2 for v in o.block_size)
    a, w = o.hole_diameter / 2, o.slot_width / 2
    body = spec.worldbody.add_body(name="block", pos=[0.2, 0.1, sz])
    body.add_freejoint(name="block_joint")
    body.explicitinertial = True
    body.mass = o.block_mass
    body.ipos = [0.0, 0.0, 0.0]
    body.iquat = [1.0, 0.0, 0.0, 0.0]
    body.inertia = [
        o.block_mass * (o.block_size[1] ** 2 + o.block_size[2] ** 2) / 12,
        o.block_mass * (o.block_size[0] ** 2 + o.block_size[2] ** 2) / 12,
        o.block_mass * (o.block_size[0] ** 2 + o.block_size[1] ** 2) / 12,
    ]
    box = mujoco.mjtGeom.mjGEOM_BOX
    common = dict(
        type=box,
        material="block_blue",
        contype=0,
        conaffinity=_TUBE_SIDE,
        friction=[o.block_friction, 0.005, 0.0001],
        solref=[o.contact_timeconst, 1.0],
        solimp=[*o.block_solimp, 0.5, 2.0],
        solmix=1e9,  # tube-block contacts use the block's parameters, not the tube's
        density=0,
    )
    # (x_lo, x_hi, y_lo, y_hi) of the four frame walls; the +x wall is split by the slot.
    walls = {
        "block_wall_xm": (-sx, -a, -sy, sy),
        "block_wall_ym": (-a, a, -sy, -a),
        "block_wall_yp": (-a, a, a, sy),
        "block_wall_xp_l": (a, sx, -sy, -w),
        "block_wall_xp_r": (a, sx, w, sy),
    }
    for name, (x0, x1, y0, y1) in walls.items():
        body.add_geom(
            name=name,
            size=[(x1 - x0) / 2, (y1 - y0) / 2, sz],
            pos=[(x0 + x1) / 2, (y0 + y1) / 2, 0.0],
            **common,
        )
    # Octagon corners: a box per diagonal whose inner face is tangent to the hole.
    half_face = a * math.tan(math.pi / 8)
    depth = (math.sqrt(2) - 1) * a / 2 + 0.0005
    for i, angle in enumerate((45, 135, 225, 315)):
        th = math.radians(angle)
        r = a + depth
        body.add_geom(
            name=f"block_chamfer_{i}",
            size=[depth, half_face, sz],
            pos=[r * math.cos(th), r * math.sin(th), 0.0],
            quat=[math.cos(th / 2), 0.0, 0.0, math.sin(th / 2)],
            **common,
        )
    # Rim: a thin capsule along each top edge of the hole (inner surface tangent to the hole's
    # wall, so the clearance is unchanged), so that a tube's rounded end meets the rim as a
    # capsule-capsule contact (exact in MJX) rather than as a box edge.
    rho = o.rim_radius
    if rho > 0:
        r_c = a + rho
        half = r_c * math.tan(math.pi / 8)
        k = 0
        for i in range(8):
            th = i * math.pi / 4
            c, s_ = math.cos(th), math.sin(th)
            segments = [(-half, half)]
            if i == 0:  # the slot interrupts the +x edge
                segments = [(-half, -w), (w, half)]
            for t0, t1 in segments:
                p0 = (r_c * c - t0 * s_, r_c * s_ + t0 * c, sz)
                p1 = (r_c * c - t1 * s_, r_c * s_ + t1 * c, sz)
                body.add_geom(
                    name=f"block_rim_{k}",
                    size=[rho, 0, 0],
                    fromto=[*p0, *p1],
                    **{**common, "type": mujoco.mjtGeom.mjGEOM_CAPSULE},
                )
                k += 1
    # Footprint: meets floor and walls only (the wall boxes meet only the tube).
    body.add_geom(
        name="block_footprint",
        type=box,
        size=[sx, sy, 0.001],
        pos=[0.0, 0.0, -sz + 0.001],
        contype=_RESTING,
        conaffinity=_SURFACE,
        friction=[o.block_friction, 0.005, 0.0001],
        density=0,
        group=3,
    )
    return body


def add_tube(spec: mujoco.MjSpec, o: So101BoxOptions) -> mujoco.MjsBody:
    """The tube (free body, frame at its centre, axis +z) with end sites `tube_end_a/b`."""
    r, h = o.tube_diameter / 2, o.tube_length / 2
    body = spec.worldbody.add_body(name="tube", pos=[0.2, -0.1, h])
    body.add_freejoint(name="tube_joint")
    # Cylinder: the visual shape and the mass; collides with floor and walls (flat ends).
    body.add_geom(
        name="tube_body",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[r, h, 0],
        mass=o.tube_mass,
        material="tube_white",
        contype=_RESTING,
        conaffinity=_SURFACE,
        friction=[o.tube_friction, 0.005, 0.0001],
        solref=[o.contact_timeconst, 1.0],
    )
    # Capsule of the same radius and overall length: what the block and the robot touch.
    body.add_geom(
        name="tube_side",
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        size=[r, h - r, 0],
        density=0,
        contype=_TUBE_SIDE,
        conaffinity=_DISTAL | _LINK,
        friction=[o.tube_friction, 0.005, 0.0001],
        solref=[o.contact_timeconst, 1.0],
        solimp=[*o.grip_solimp, 0.5, 2.0],
        solmix=1e6,  # its contacts with the fingers use these parameters, not the robot's
        group=3,
    )
    body.add_site(name="tube_end_a", pos=[0.0, 0.0, -h], size=[0.002, 0, 0])
    body.add_site(name="tube_end_b", pos=[0.0, 0.0, h], size=[0.002, 0, 0])
    return body


def _add_jaw_pad(spec: mujoco.MjSpec, o: So101BoxOptions) -> None:
    """Fit the moving jaw with a flat pad, parallel to the fixed finger's face when the jaws
    are `o.tube_diameter` apart, and let it replace the jaw's own collision box.

    The SO-101's moving jaw pivots, so its finger meets a 22 mm tube at ~15 degrees and
    squeezes it like a wedge, tilting it in the grasp; the pad makes the grasp a parallel one.
    Kinematics are untouched: the pad is collision geometry rigidly attached to the jaw.
    """
    robot = spec.copy().compile()
    data = mujoco.MjData(robot)
    pad_angle = 0.35  # jaw angle (rad) at which the pad is parallel to the fixed finger
    data.qpos[robot.joint("gripper").qposadr[0]] = pad_angle
    mujoco.mj_kinematics(robot, data)
    g, j = robot.body("gripper").id, robot.body("moving_jaw").id
    rot_g = data.xmat[g].reshape(3, 3)
    rot_j = rot_g.T @ data.xmat[j].reshape(3, 3)  # jaw axes in the gripper frame
    origin_j = rot_g.T @ (data.xpos[j] - data.xpos[g])
    fixed = robot.geom("fixed_finger")
    face_x = float(fixed.pos[0] + fixed.size[0])  # the fixed finger's inner face (gripper x)
    bottom = float(fixed.pos[2] - fixed.size[2])
    half = np.array([0.002, 0.009, 0.021])
    centre = np.array([face_x + o.tube_diameter + half[0], 0.0, bottom + half[2]])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot_j.T.reshape(-1))
    jaw = spec.body("moving_jaw")
    jaw.add_geom(
        name="jaw_pad",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=half.tolist(),
        pos=(rot_j.T @ (centre - origin_j)).tolist(),
        quat=quat.tolist(),
        contype=_DISTAL,
        conaffinity=0,
        friction=[1.0, 0.005, 0.0001],
        material="so101_dark",
        mass=0.0,
    )
    finger = spec.geom("moving_finger")
    finger.contype, finger.conaffinity = 0, 0


def compose(o: So101BoxOptions) -> mujoco.MjSpec:
    """The scene's MjSpec: SO-101 on the arena floor, walls, light, cameras, block and tube."""
    spec = load_robot(ROBOTS.get("so101"))
    spec.modelname = "so101_box"
    spec.option.timestep = o.timestep
    spec.option.iterations = o.solver_iterations
    spec.option.ls_iterations = o.solver_ls_iterations
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER

    root = spec.worldbody.first_body()
    root.pos = [0.0, 0.0, 0.0]
    _add_jaw_pad(spec, o)
    gripper = spec.body("gripper")
    # Between the fingers, where a grasped tube's axis sits against the fixed finger.
    fixed = spec.geom("fixed_finger")
    face_x = float(fixed.pos[0] + fixed.size[0])
    gripper.add_site(
        name="grasp",
        pos=[face_x + o.tube_diameter / 2 + 0.002, 0.0, float(fixed.pos[2]) - 0.003],
        size=[0.003, 0, 0],
        group=3,
    )
    _camera(
        gripper,
        "wrist",
        o.wrist_camera_pos,
        o.wrist_camera_target,
        o.wrist_camera_resolution,
        o.wrist_camera_focal,
        o.wrist_camera_principal,
    )

    spec.add_material(name="floor_grey", rgba=[0.35, 0.35, 0.37, 1])
    spec.add_material(name="wall_white", rgba=[0.85, 0.85, 0.85, 1])
    spec.add_material(name="block_blue", rgba=[0.15, 0.35, 0.8, 1])
    spec.add_material(name="tube_white", rgba=[0.95, 0.95, 0.9, 1])

    w = spec.worldbody
    plane = mujoco.mjtGeom.mjGEOM_PLANE
    x0, x1 = -o.robot_back_gap, o.arena_depth - o.robot_back_gap
    xc, half_w = (x0 + x1) / 2, o.arena_width / 2
    w.add_geom(
        name="floor",
        type=plane,
        size=[o.arena_depth / 2, half_w, 0.05],
        pos=[xc, 0.0, 0.0],
        material="floor_grey",
        contype=_SURFACE,
        conaffinity=_DISTAL,
        friction=[0.6, 0.005, 0.0001],
    )
    zc = o.arena_height / 2
    # Walls: planes (a plane's normal is its local +z) facing into the arena.
    for name, pos, x_axis, normal, size in (
        ("wall_back", [x0, 0.0, zc], (0, 1, 0), (1, 0, 0), [half_w, zc, 0.05]),
        ("wall_front", [x1, 0.0, zc], (0, -1, 0), (-1, 0, 0), [half_w, zc, 0.05]),
        ("wall_right", [xc, -half_w, zc], (-1, 0, 0), (0, 1, 0), [o.arena_depth / 2, zc, 0.05]),
        ("wall_left", [xc, half_w, zc], (1, 0, 0), (0, -1, 0), [o.arena_depth / 2, zc, 0.05]),
    ):
        w.add_geom(
            name=name,
            type=plane,
            size=size,
            pos=pos,
            quat=_frame_quat(x_axis, normal),
            material="wall_white",
            contype=_SURFACE,
            conaffinity=0,
        )
    w.add_light(
        name="ceiling_light",
        pos=[xc, 0.0, o.arena_height - 0.01],
        dir=[0, 0, -1],
        diffuse=[0.8, 0.8, 0.8],
    )
    _camera(
        w,
        "overhead",
        o.overhead_camera_pos,
        o.overhead_camera_target,
        o.overhead_camera_resolution,
        o.overhead_camera_focal,
        o.overhead_camera_principal,
    )
    add_block(spec, o)
    add_tube(spec, o)
    return spec


def _axis_z(quat: jax.Array) -> jax.Array:
    """The body's local +z axis in the world frame, from its quaternion (w, x, y, z)."""
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    return jnp.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def _rotate_inverse(quat: jax.Array, v: jax.Array) -> jax.Array:
    """`v` (world) in the frame of the body with quaternion `quat`: R^T v, fixed order."""
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    rows = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]
    # R^T v: column j of R dotted with v.
    return jnp.stack([rows[0][j] * v[0] + rows[1][j] * v[1] + rows[2][j] * v[2] for j in range(3)])


class So101Box(Scene):
    """The `so101_box` scene on a chosen physics backend."""

    name = "so101_box"
    task = "insert_tube_in_block"
    robot_name = "so101"

    def __init__(
        self,
        options: So101BoxOptions | None = None,
        *,
        backend: str = "auto",
        settings: PhysicsSettings | None = None,
    ) -> None:
        self.options = o = options or So101BoxOptions()
        self.robot = ROBOTS.get("so101")
        self.spec = compose(o)
        sensors = o.sensor_specs()
        self.backend = make_backend(
            backend,
            self.spec,
            QuantitySpec(
                bodies=("tube", "block"),
                sites=(self.robot.ee_site, "grasp", "tube_end_a", "tube_end_b"),
                sensors=sensors,
            ),
            o.n_substeps,
            settings,
        )
        self.sensor_shapes = sensor_shapes(sensors)
        m = self.mj_model
        free = {m.joint("tube_joint").id, m.joint("block_joint").id}
        self.robot_joint_ids = np.array([j for j in range(m.njnt) if j not in free])
        self.robot_qpos_adr = m.jnt_qposadr[self.robot_joint_ids]
        self.robot_dof_adr = m.jnt_dofadr[self.robot_joint_ids]
        self.tube_qpos_adr = int(m.joint("tube_joint").qposadr[0])
        self.block_qpos_adr = int(m.joint("block_joint").qposadr[0])
        self.tube_dof_adr = int(m.joint("tube_joint").dofadr[0])
        home = np.array(m.qpos0, dtype=np.float32)
        home[self.robot_qpos_adr] = o.robot_home
        self._qpos_home = jnp.asarray(home)
        self._layout = arm_obs_layout(
            len(self.robot_joint_ids),
            {
                "tube_pos": 3,
                "tube_quat": 4,
                "block_pos": 3,
                "block_quat": 4,
            },
            self.sensor_shapes,
        )

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        return dict(self._layout)

    # ---- reset ----------------------------------------------------------------------------

    def sample_layout(self, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Block and tube (x, y, yaw) for one episode, never overlapping each other or the robot.

        Draws `_CANDIDATES` independent (block, tube) pairs and keeps the first that satisfies
        the separations; if none does (vanishingly rare with the default ranges), the options'
        `fallback_layout` positions with the first draw's yaws.
        """
        o = self.options
        k_block, k_tube = jax.random.split(key)

        def draw(k, xr: Pair, yr: Pair, yawr: Pair) -> jax.Array:
            kx, ky, kyaw = jax.random.split(k, 3)
            u, n = jax.random.uniform, _CANDIDATES
            return jnp.stack(
                [
                    u(kx, (n,), minval=xr[0], maxval=xr[1]),
                    u(ky, (n,), minval=yr[0], maxval=yr[1]),
                    u(kyaw, (n,), minval=yawr[0], maxval=yawr[1]),
                ],
                axis=1,
            )

        blocks = draw(k_block, o.block_spawn_x, o.block_spawn_y, o.block_spawn_yaw)
        tubes = draw(k_tube, o.tube_spawn_x, o.tube_spawn_y, o.tube_spawn_yaw)
        r_block, r_tube = o.block_radius, o.tube_diameter / 2
        ok = (
            (fo.norm(blocks[:, :2]) >= o.robot_keepout + r_block)
            & (fo.norm(tubes[:, :2]) >= o.robot_keepout + r_tube)
            & (fo.norm(blocks[:, :2] - tubes[:, :2]) >= r_block + r_tube + o.spawn_gap)
        )
        i = jnp.argmax(ok)
        fallback_block, fallback_tube = o.fallback_layout()
        block = jnp.where(ok[i], blocks[i], jnp.append(jnp.array(fallback_block), blocks[0, 2]))
        tube = jnp.where(ok[i], tubes[i], jnp.append(jnp.array(fallback_tube), tubes[0, 2]))
        return block, tube

    def reset(self, key: jax.Array) -> State:
        o = self.options
        block, tube = self.sample_layout(key)
        qpos = self._qpos_home
        a, b = self.block_qpos_adr, self.tube_qpos_adr
        qpos = qpos.at[a : a + 3].set(jnp.array([block[0], block[1], o.block_size[2] / 2]))
        qpos = qpos.at[a + 3 : a + 7].set(yaw_quat(block[2]))
        qpos = qpos.at[b : b + 3].set(jnp.array([tube[0], tube[1], o.tube_length / 2]))
        qpos = qpos.at[b + 3 : b + 7].set(yaw_quat(tube[2]))
        physics = self.backend.init(qpos, jnp.zeros(self.mj_model.nv, jnp.float32))
        zero = jnp.zeros((), jnp.float32)
        state = State(
            physics=physics,
            obs=jnp.zeros(0),
            reward=zero,
            done=jnp.zeros((), bool),
            metrics={
                "success": jnp.zeros((), bool),
                "diverged": jnp.zeros((), bool),
                "insertion_depth": zero,
                "hole_offset": zero,
            },
            info={},
        )
        return self._evaluate(state, physics)

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        """Randomised factors of the episode, from its reset state (for success breakdowns)."""
        q = state.physics.quantities
        tube, block = q.body_pos[0][:2], q.body_pos[1][:2]
        quat = q.body_quat[1]
        return {
            "tube_block_distance": fo.norm(tube - block),
            "tube_reach": fo.norm(tube),
            "block_reach": fo.norm(block),
            "block_yaw": 2 * jnp.arctan2(quat[3], quat[0]),  # the block is only yawed at reset
        }

    # ---- step, task logic -----------------------------------------------------------------

    def step(self, state: State, action: jax.Array) -> State:
        low, high = self.action_bounds()
        physics = self.backend.step(state.physics, jnp.clip(action, low, high))
        return self._evaluate(state, physics)

    def insertion(self, q) -> dict[str, jax.Array]:
        """The success predicate's terms on one env's `Quantities`.

        `depth`: how far the tube's lower end is below the block's top face, along the block's
        axis (m); `hole_offset`: that end's distance from the hole's axis (m); `cos_tilt`: cosine
        of the tube axis' angle from vertical (either end down).
        """
        o = self.options
        end_a, end_b = q.site_pos[2], q.site_pos[3]
        lower = jnp.where(end_a[2] <= end_b[2], end_a, end_b)
        axis = end_b - end_a
        cos_tilt = jnp.abs(axis[2]) / jnp.maximum(fo.norm(axis), 1e-9)
        local = _rotate_inverse(q.body_quat[1], lower - q.body_pos[1])
        depth = o.block_size[2] / 2 - local[2]
        hole_offset = fo.norm(local[:2])
        success = (
            (depth >= o.insertion_depth)
            & (hole_offset <= o.hole_diameter / 2)
            & (cos_tilt >= math.cos(o.tilt_tolerance))
        )
        return {
            "depth": depth,
            "hole_offset": hole_offset,
            "cos_tilt": cos_tilt,
            "lower": lower,
            "success": success,
        }

    def _evaluate(self, state: State, physics) -> State:
        """Observation, reward, success and done from the new physics quantities."""
        o = self.options
        q = physics.quantities
        ins = self.insertion(q)
        diverged = ~q.ok
        success = ins["success"] & ~diverged
        tube_pos, block_pos, block_quat = q.body_pos[0], q.body_pos[1], q.body_quat[1]
        target = block_pos + _axis_z(block_quat) * (o.block_size[2] / 2 - o.insertion_depth)
        reward = (
            -0.5 * fo.norm(q.site_pos[1] - tube_pos)
            - fo.norm(ins["lower"] - target)
            + success.astype(jnp.float32)
        )
        obs = jnp.concatenate(
            [
                q.qpos[self.robot_qpos_adr],
                q.qvel[self.robot_dof_adr],
                q.site_pos[0],
                tube_pos,
                q.body_quat[0],
                block_pos,
                block_quat,
                *sensor_obs(q, self.sensor_shapes),
            ]
        ).astype(jnp.float32)
        obs = jnp.where(diverged, 0.0, obs)
        reward = jnp.where(diverged, 0.0, reward)
        return state.replace(
            physics=physics,
            obs=obs,
            reward=reward,
            done=success | diverged,
            metrics={
                "success": success,
                "diverged": diverged,
                "insertion_depth": jnp.where(diverged, 0.0, ins["depth"]),
                "hole_offset": jnp.where(diverged, jnp.inf, ins["hole_offset"]),
            },
        )

    def _pan_xy(self) -> tuple[float, float]:
        """Where the shoulder-pan axis meets the floor (world x, y)."""
        m = self.mj_model
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        anchor = d.xanchor[m.joint("shoulder_pan").id]
        return float(anchor[0]), float(anchor[1])

    def scripted_policy(self) -> Policy:
        """The scene's expert: grasp the tube, carry it over the hole, lower it in."""
        m = self.mj_model
        actuator_joint = actuator_joints(m, self.robot_joint_ids)
        low, high = self.action_bounds()
        fk = site_kinematics(m, m.site("grasp").id, self.robot_qpos_adr)
        return insert_expert(
            self.obs_layout,
            fk,
            actuator_joint,
            low,
            high,
            gripper_actuator=m.actuator("gripper").id,
            gripper_joint=int(actuator_joint[m.actuator("gripper").id]),
            pan_xy=self._pan_xy(),
            tube_length=self.options.tube_length,
            block_height=self.options.block_size[2],
        )
