"""`so101_box` model: the MjSpec of the arena, the SO-101 (with a jaw pad), block and tube.

Composition only (no task logic): geometry, materials, contact bits and parameters, cameras
with their intrinsics, and the sites the task reads (`grasp`, `tube_end_a`, `tube_end_b`). The
collision shapes are chosen for what MJX's JAX implementation can collide; the package
docstring says why each one is what it is.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from openral_mjx.robots import ROBOTS
from openral_mjx.scenes.composition import load_robot, look_at_quat
from openral_mjx.scenes.so101_box.options import Pair, Size, So101BoxOptions, Vec3

# Contact bits (contype/conaffinity); a pair collides when one's contype meets the other's
# conaffinity. The SO-101 MJCF gives arm links contype 4 and wrist/gripper/jaw contype 2.
_SURFACE = 1  # floor and walls (contype)
_DISTAL = 2  # robot wrist, gripper body and fingers (contype, from so101.xml)
_LINK = 4  # robot upper/lower arm and shoulder (contype, from so101.xml)
_TUBE_SIDE = 8  # the tube's capsule (contype) meeting the block's wall boxes (conaffinity)
_RESTING = 16  # the tube's cylinder and the block's footprint: they meet floor and walls


def _frame_quat(x_axis: Vec3, z_axis: Vec3) -> list[float]:
    """Quaternion of the frame with these x and z axes (y = z cross x)."""
    x, z = np.asarray(x_axis, float), np.asarray(z_axis, float)
    mat = np.stack([x, np.cross(z, x), z], axis=1)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.reshape(-1))
    return quat.tolist()


def _camera(
    parent: mujoco.MjsBody,
    name: str,
    pos: Vec3,
    target: Vec3,
    resolution: Size,
    focal: Pair,
    principal: Pair,
) -> None:
    """A pinhole camera with intrinsics in pixels (sensor pitch 3 um, OV9282's)."""
    pitch = 3e-6
    cam = parent.add_camera(name=name, pos=list(pos), quat=look_at_quat(pos, target).tolist())
    cam.resolution = list(resolution)
    cam.sensor_size = [resolution[0] * pitch, resolution[1] * pitch]
    cam.focal_pixel = list(focal)
    # MuJoCo's principal point is the image centre's offset from the optical axis: the axis
    # crosses the image at (W/2 - px, H/2 - py), as its renderer draws it (checked against
    # MuJoCo's OpenGL renderer in tests/physics/test_camera_render.py).
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
