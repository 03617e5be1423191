"""`tabletop_push` model: the MjSpec of the robot on a table with a cube, a goal disc, cameras.

Composition only (no task logic): the robot re-anchored on the table top where `arm.prepare`
placed it, its colliding cylinders as prisms (`cylinders_as_prisms`: MJX has no cylinder-box
pair), table, floor, the free cube, the goal site (moved per episode by the renderer, see
`TabletopPush.pose_frame`), light and cameras, with their contact bits.
"""

from __future__ import annotations

import mujoco

from openral_mjx.robots import RobotSpec
from openral_mjx.scenes.composition import cylinders_as_prisms, load_robot, look_at_quat
from openral_mjx.scenes.tabletop_push.arm import ArmSetup, place_root, prepare, root_quat
from openral_mjx.scenes.tabletop_push.options import TabletopPushOptions


def compose(
    options: TabletopPushOptions, robot: RobotSpec, arm: ArmSetup | None = None
) -> mujoco.MjSpec:
    """The scene's MjSpec: the robot re-anchored on the table, plus table, cube, goal, cameras.

    `arm`: the robot measured and placed by `arm.prepare` (done here when None).
    """
    o = options
    if arm is None:
        arm = prepare(o, robot)
    spec = load_robot(robot)
    robot_model = spec.compile()
    cylinders_as_prisms(spec)
    place_root(
        spec,
        [arm.base_x, o.robot_base_y, o.table_height],
        root_quat(robot_model, o.robot_base_yaw),
    )
    spec.modelname = "tabletop_push"
    spec.option.timestep = o.timestep
    spec.option.iterations = o.solver_iterations
    spec.option.ls_iterations = o.solver_ls_iterations
    # Euler (joint damping implicit) where the servos allow (see `arm.integrator`): MJX's
    # implicitfast disagrees with MuJoCo C's on saturated servos' velocity gain, while Euler
    # matches it to float32 precision.
    spec.option.integrator = arm.integrator

    spec.add_material(name="table_wood", rgba=[0.55, 0.42, 0.3, 1])
    spec.add_material(name="floor_grey", rgba=[0.3, 0.3, 0.32, 1])
    spec.add_material(name="cube_red", rgba=[0.85, 0.15, 0.12, 1])
    spec.add_material(name="goal_green", rgba=[0.1, 0.8, 0.2, 0.5])

    w = spec.worldbody
    box, plane = mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_PLANE
    # Contact bits: floor/table/cube contype 1; cube conaffinity 1|2|4 (floor, table, robot
    # distal geoms with contype 2 and links with contype 4); table conaffinity 2 (robot distal).
    w.add_geom(
        name="floor", type=plane, size=[3, 3, 0.1], material="floor_grey", contype=1, conaffinity=0
    )
    half_h = o.table_height / 2
    w.add_geom(
        name="table",
        type=box,
        material="table_wood",
        contype=1,
        conaffinity=2,
        size=[o.table_size[0] / 2, o.table_size[1] / 2, half_h],
        pos=[o.table_center[0], o.table_center[1], half_h],
        friction=[0.6, 0.005, 0.0001],
    )
    cube = w.add_body(name="cube", pos=[0.2, 0.0, o.table_height + o.cube_size / 2])
    cube.add_freejoint(name="cube_joint")
    h = o.cube_size / 2
    cube.add_geom(
        name="cube",
        type=box,
        size=[h, h, h],
        mass=o.cube_mass,
        material="cube_red",
        contype=1,
        conaffinity=7,
        condim=3,
        friction=[o.cube_friction, 0.005, 0.0001],
    )
    w.add_site(
        name="goal",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        material="goal_green",
        size=[o.goal_radius, 0.0005, 0],
        pos=[0.2, 0.1, o.table_height + 0.0005],
    )
    # Rendering only: a brighter headlight than MuJoCo's default, or the table and the arm
    # come out dark from the scene's cameras.
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.55, 0.55, 0.55]
    w.add_light(name="top_light", pos=[0.2, 0, 2.5], dir=[0, 0, -1], diffuse=[0.8, 0.8, 0.8])
    for name, pos in (("overhead", o.camera_overhead_pos), ("front", o.camera_front_pos)):
        w.add_camera(name=name, pos=list(pos), quat=look_at_quat(pos, o.camera_target).tolist())
    return spec
