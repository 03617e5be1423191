"""`tabletop_push`: push a cube to a goal disc on a table, with any position-controlled arm.

The robot (a registered one, or a user MJCF with position actuators and an end-effector site)
is loaded into an `MjSpec`; table, cube (freejoint), goal disc, floor, light and cameras are
appended. Reset samples the cube pose and a goal at a random bearing and distance from it.

Action: one position target per actuator, clipped to its ctrlrange.

Observation (flat, float32; named slices in `obs_layout`): robot joint positions and velocities,
end-effector position, cube position and quaternion (w, x, y, z), goal position (x, y), all in
the world frame (metres, radians).

Reward (dense, per control step): ``-|cube_xy - goal_xy| - 0.5 |ee - cube| + 1[success]``:
bring the tool to the cube, the cube to the goal.

Success: the cube centre within `goal_radius` of the goal (in the table plane) while the cube
rests on the table: centre height within `rest_height_tol` of half an edge above the top face,
and speed below `rest_speed`. The episode ends on success (or divergence, or at max steps).

Episode factors (for the report's breakdown), from the reset state: `goal_distance` (cube centre
to goal in the table plane, m), `cube_x`, `cube_y` (initial cube position, m), and
`push_face_angle` (rad, in [0, pi/4]): the angle between the cube->goal direction and the
nearest cube face normal; 0 is a push square onto a face, pi/4 onto an edge.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.errors import ConfigError
from openral_mjx.core.options import check
from openral_mjx.physics import PhysicsSettings, QuantitySpec, make_backend
from openral_mjx.physics.kinematics import site_kinematics
from openral_mjx.policies.base import Policy
from openral_mjx.policies.push_expert import push_expert
from openral_mjx.robots import ROBOTS, RobotSpec, user_robot
from openral_mjx.scenes.base import Scene, State, actuator_joints, arm_obs_layout
from openral_mjx.scenes.composition import load_robot, look_at_quat, yaw_quat
from openral_mjx.scenes.sensor_obs import SensorObsOptions, sensor_obs, sensor_shapes

Pair = tuple[float, float]
Vec3 = tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class TabletopPushOptions(SensorObsOptions):
    """Every geometry knob and threshold of `tabletop_push` (SI units, world frame).

    The robot base sits on the table top at (`robot_base_x`, `robot_base_y`), facing
    `robot_base_yaw` (rad); spawn ranges and the goal region are in the world frame. Sensor
    observations (`obs_*`, off by default): depth cameras `overhead` and `front`, RGB on
    `warp`, and a laser on a robot body or site (a user robot with a mobile base).
    """

    robot: str = "so101"
    robot_mjcf: str | None = None
    ee_site: str = "ee"
    robot_base_x: float = 0.0
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

    def robot_spec(self) -> RobotSpec:
        """The registered robot, or the user MJCF when `robot_mjcf` is set."""
        if self.robot_mjcf is not None:
            path = Path(self.robot_mjcf)
            if not path.is_file():
                raise ConfigError(f"robot MJCF {self.robot_mjcf!r} does not exist")
            return user_robot(path, self.ee_site)
        return ROBOTS.get(self.robot)


def compose(options: TabletopPushOptions, robot: RobotSpec) -> mujoco.MjSpec:
    """The scene's MjSpec: the robot re-anchored on the table, plus table, cube, goal, cameras."""
    o = options
    spec = load_robot(robot)
    spec.modelname = "tabletop_push"
    spec.option.timestep = o.timestep
    spec.option.iterations = o.solver_iterations
    spec.option.ls_iterations = o.solver_ls_iterations
    # Euler (joint damping implicit): MJX's implicitfast disagrees with MuJoCo C's on the
    # servos' velocity gain, while Euler matches it to float32 precision.
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER

    root = spec.worldbody.first_body()
    root.pos = [o.robot_base_x, o.robot_base_y, o.table_height]
    root.quat = [math.cos(o.robot_base_yaw / 2), 0.0, 0.0, math.sin(o.robot_base_yaw / 2)]

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


class TabletopPush(Scene):
    """The `tabletop_push` scene on a chosen physics backend."""

    name = "tabletop_push"
    task = "push_cube_to_goal"

    def __init__(
        self,
        options: TabletopPushOptions | None = None,
        *,
        backend: str = "auto",
        settings: PhysicsSettings | None = None,
    ) -> None:
        self.options = o = options or TabletopPushOptions()
        robot = o.robot_spec()
        self.robot_name = robot.name
        self.robot = robot
        self.spec = compose(o, robot)
        sensors = o.sensor_specs()
        self.backend = make_backend(
            backend,
            self.spec,
            QuantitySpec(bodies=("cube",), sites=(robot.ee_site,), sensors=sensors),
            o.n_substeps,
            settings,
        )
        self.sensor_shapes = sensor_shapes(sensors)
        m = self.mj_model
        cube_joint = m.joint("cube_joint")
        # Every joint but the cube's belongs to the robot (the scene adds no others).
        self.robot_joint_ids = np.array([j for j in range(m.njnt) if j != cube_joint.id])
        self.robot_qpos_adr = m.jnt_qposadr[self.robot_joint_ids]
        self.robot_dof_adr = m.jnt_dofadr[self.robot_joint_ids]
        self.cube_qpos_adr = int(cube_joint.qposadr[0])
        self.cube_dof_adr = int(cube_joint.dofadr[0])
        self.ee_site_id = m.site(robot.ee_site).id
        self.goal_site_id = m.site("goal").id
        home = np.array(m.qpos0, dtype=np.float32)
        for joint, value in robot.home_qpos.items():
            home[m.joint(joint).qposadr[0]] = value
        self._qpos_home = jnp.asarray(home)
        self._layout = arm_obs_layout(
            len(self.robot_joint_ids),
            {
                "cube_pos": 3,
                "cube_quat": 4,
                "goal_xy": 2,
            },
            self.sensor_shapes,
        )

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        return dict(self._layout)

    @property
    def cube_rest_z(self) -> float:
        return self.options.table_height + self.options.cube_size / 2

    def sample_episode(self, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Cube (x, y, yaw) and goal (x, y) for one episode."""
        o = self.options
        kx, ky, kyaw, kth, kr = jax.random.split(key, 5)
        u = jax.random.uniform
        cube_xy = jnp.stack(
            [
                u(kx, (), minval=o.cube_spawn_x[0], maxval=o.cube_spawn_x[1]),
                u(ky, (), minval=o.cube_spawn_y[0], maxval=o.cube_spawn_y[1]),
            ]
        )
        yaw = u(kyaw, (), minval=-jnp.pi, maxval=jnp.pi)
        theta = u(kth, (), minval=-jnp.pi, maxval=jnp.pi)
        dist = u(kr, (), minval=o.goal_distance[0], maxval=o.goal_distance[1])
        # Computed once: the goal feeds both `info` and the observation, and XLA recomputed
        # this product inside both fusions, rounding differently at some batch sizes (the
        # goal in the observation then differed in the last bit from one batch size to another).
        offset = jax.lax.optimization_barrier(dist * jnp.stack([jnp.cos(theta), jnp.sin(theta)]))
        lo = jnp.array([o.goal_region_x[0], o.goal_region_y[0]])
        hi = jnp.array([o.goal_region_x[1], o.goal_region_y[1]])
        inside = jnp.all((cube_xy + offset >= lo) & (cube_xy + offset <= hi))
        # Flip the bearing when it leaves the goal region, then clamp what still does.
        goal_xy = jnp.clip(jnp.where(inside, cube_xy + offset, cube_xy - offset), lo, hi)
        return jnp.concatenate([cube_xy, yaw[None]]), goal_xy

    def reset(self, key: jax.Array) -> State:
        cube, goal_xy = self.sample_episode(key)
        qpos = self._qpos_home
        a = self.cube_qpos_adr
        qpos = qpos.at[a : a + 3].set(jnp.array([cube[0], cube[1], self.cube_rest_z]))
        qpos = qpos.at[a + 3 : a + 7].set(yaw_quat(cube[2]))
        qvel = jnp.zeros(self.mj_model.nv, jnp.float32)
        physics = self.backend.init(qpos, qvel)
        info = {"goal_xy": goal_xy}
        zero = jnp.zeros((), jnp.float32)
        metrics = {
            "success": jnp.zeros((), bool),
            "diverged": jnp.zeros((), bool),
            "goal_dist": zero,
        }
        state = State(
            physics=physics,
            obs=jnp.zeros(0),
            reward=zero,
            done=jnp.zeros((), bool),
            metrics=metrics,
            info=info,
        )
        return self._evaluate(state, physics)

    video_camera = "front"

    def frame_record(self, state: State) -> dict[str, jax.Array]:
        return {**super().frame_record(state), "goal_xy": state.info["goal_xy"]}

    def pose_frame(
        self, model: mujoco.MjModel, data: mujoco.MjData, record: Mapping[str, np.ndarray]
    ) -> None:
        """Joint positions, and the goal disc moved to this episode's goal."""
        super().pose_frame(model, data, record)
        model.site_pos[self.goal_site_id, :2] = record["goal_xy"]

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        q = state.physics.quantities
        cube_xy, quat = q.body_pos[0][:2], q.body_quat[0]
        to_goal = state.info["goal_xy"] - cube_xy
        yaw = 2 * jnp.arctan2(quat[3], quat[0])  # the cube is only ever yawed at reset
        quarter = jnp.pi / 2
        offset = jnp.mod(jnp.arctan2(to_goal[1], to_goal[0]) - yaw, quarter)
        return {
            "goal_distance": jnp.hypot(to_goal[0], to_goal[1]),
            "cube_x": cube_xy[0],
            "cube_y": cube_xy[1],
            "push_face_angle": jnp.minimum(offset, quarter - offset),
        }

    def step(self, state: State, action: jax.Array) -> State:
        low, high = self.action_bounds()
        physics = self.backend.step(state.physics, jnp.clip(action, low, high))
        return self._evaluate(state, physics)

    def _evaluate(self, state: State, physics) -> State:
        """Observation, reward, success and done from the new physics quantities."""
        o = self.options
        q = physics.quantities
        cube_pos, cube_quat = q.body_pos[0], q.body_quat[0]
        ee = q.site_pos[0]
        goal_xy = state.info["goal_xy"]
        goal_dist = fo.norm(cube_pos[:2] - goal_xy)
        cube_speed = fo.norm(q.qvel[self.cube_dof_adr : self.cube_dof_adr + 3])
        resting = (jnp.abs(cube_pos[2] - self.cube_rest_z) <= o.rest_height_tol) & (
            cube_speed <= o.rest_speed
        )
        diverged = ~q.ok
        success = (goal_dist <= o.goal_radius) & resting & ~diverged
        reward = -goal_dist - 0.5 * fo.norm(ee - cube_pos) + success.astype(jnp.float32)
        obs = jnp.concatenate(
            [
                q.qpos[self.robot_qpos_adr],
                q.qvel[self.robot_dof_adr],
                ee,
                cube_pos,
                cube_quat,
                goal_xy,
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
                "goal_dist": jnp.where(diverged, jnp.inf, goal_dist),
            },
        )

    def forward_kinematics(self):
        """Robot joint positions -> (ee position, tool +z axis, and their Jacobians), pure JAX."""
        fk = site_kinematics(self.mj_model, self.ee_site_id, self.robot_qpos_adr)

        def ee_pose(q: jax.Array):
            pos, rot, jacp, jacr = fk(q)
            axis = rot[:, 2]
            # d(axis)/dq_i = omega_i x axis for the rotational Jacobian column omega_i.
            jac_axis = jnp.stack([fo.cross(jacr[:, i], axis) for i in range(q.shape[0])], 1)
            return pos, axis, jacp, jac_axis

        return ee_pose

    def action_obs_index(self) -> tuple[int, ...]:
        start, _ = self._layout["joint_pos"]
        return tuple(start + int(i) for i in actuator_joints(self.mj_model, self.robot_joint_ids))

    def scripted_policy(self) -> Policy:
        """The scene's expert: push along the cube->goal line (see `push_expert`)."""
        low, high = self.action_bounds()
        return push_expert(
            self.obs_layout,
            self.forward_kinematics(),
            actuator_joints(self.mj_model, self.robot_joint_ids),
            low,
            high,
            table_z=self.options.table_height,
            cube_half=self.options.cube_size / 2,
            goal_radius=self.options.goal_radius,
        )
