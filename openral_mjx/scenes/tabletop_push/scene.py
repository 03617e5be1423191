"""The `TabletopPush` scene: wires the model, a physics backend, the task logic and the observation.

`arm.prepare` checks and measures the robot (start pose, tool, reach, base placement),
`compose` gives the MjSpec, `make_backend` a backend reporting the quantities the task reads;
`reset` places the sampled cube (the goal goes in `State.info`), `step` advances the physics,
and both finish in `_evaluate` (observation, reward, success, done). The scripted expert and the
end-effector kinematics it steers by live here too: they need the compiled model.
"""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.core import fixed_order as fo
from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import PhysicsSettings, PhysicsState, make_backend
from openral_mjx.physics.kinematics import site_kinematics
from openral_mjx.policies.base import Policy
from openral_mjx.policies.push_expert import ForwardKinematics, push_expert
from openral_mjx.scenes.base import RandomizationTargets, Scene, State, servo_hold
from openral_mjx.scenes.composition import yaw_quat
from openral_mjx.scenes.sensor_obs import (
    observed_cameras,
    range_slices,
    rendered_lights,
    sensor_shapes,
)
from openral_mjx.scenes.tabletop_push import observation
from openral_mjx.scenes.tabletop_push import task as logic  # `task` is the scene's task name
from openral_mjx.scenes.tabletop_push.arm import prepare
from openral_mjx.scenes.tabletop_push.model import compose
from openral_mjx.scenes.tabletop_push.options import TabletopPushOptions


class TabletopPush(Scene):
    """The `tabletop_push` scene on a chosen physics backend."""

    name = "tabletop_push"
    task = "push_cube_to_goal"
    instruction = "push the red cube to the green goal"

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
        self.arm = prepare(o, robot)
        self.spec = compose(o, robot, self.arm)
        sensors = o.sensor_specs()
        self.backend = make_backend(
            backend,
            self.spec,
            logic.quantity_spec(robot.ee_site, sensors),
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
        for joint, value in self.arm.qpos.items():
            home[m.joint(joint).qposadr[0]] = value
        self._qpos_home = jnp.asarray(home)
        # For each actuator, the index in `robot_joint_ids` of the joint it drives (0 for one
        # that drives none: the expert holds it at `arm.held`).
        index = {int(j): i for i, j in enumerate(self.robot_joint_ids)}
        self.actuator_joint = np.array(
            [
                index[int(j)] if i not in self.arm.held else 0
                for i, j in enumerate(m.actuator_trnid[:, 0])
            ]
        )
        self._layout = observation.obs_layout(len(self.robot_joint_ids), self.sensor_shapes)
        self._range_slices = range_slices(sensors)
        self._cameras = observed_cameras(sensors, self.mj_model)
        self._lights = rendered_lights(sensors, self.mj_model)

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        return dict(self._layout)

    @property
    def cube_rest_z(self) -> float:
        """Height of the cube's centre resting on the table (world z, m)."""
        return logic.cube_rest_z(self.options)

    # ---- reset ----------------------------------------------------------------------------

    def sample_episode(self, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Cube (x, y, yaw) and goal (x, y) for one episode (see `task.sample_episode`)."""
        return logic.sample_episode(self.options, key)

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

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        """Randomised factors of the episode, from its reset state (see `task.episode_factors`)."""
        return logic.episode_factors(state.physics.quantities, state.info["goal_xy"])

    def randomization_targets(self) -> RandomizationTargets:
        """The cube (on the table) is the object; every servo that drives a joint is the arm."""
        m = self.mj_model
        return RandomizationTargets(
            object_bodies=(m.body("cube").id,),
            contact_geoms=(m.geom("cube").id, m.geom("table").id),
            arm_actuators=tuple(i for i in range(m.nu) if i not in self.arm.held),
            arm_dofs=tuple(int(d) for d in self.robot_dof_adr),
            joint_obs=("joint_pos",),
            object_obs=("cube_pos", "cube_quat"),
            range_obs=self._range_slices,
            cameras=self._cameras,
            lights=self._lights,
            hold=servo_hold(m, self.arm.held),
        )

    # ---- video ----------------------------------------------------------------------------

    video_camera = "front"

    def frame_record(self, state: State) -> dict[str, jax.Array]:
        return {**super().frame_record(state), "goal_xy": state.info["goal_xy"]}

    def pose_frame(
        self, model: mujoco.MjModel, data: mujoco.MjData, record: Mapping[str, np.ndarray]
    ) -> None:
        """Joint positions, and the goal disc moved to this episode's goal."""
        super().pose_frame(model, data, record)
        model.site_pos[self.goal_site_id, :2] = record["goal_xy"]

    # ---- step, task logic -----------------------------------------------------------------

    def step(self, state: State, action: jax.Array) -> State:
        low, high = self.action_bounds()
        physics = self.backend.step(state.physics, jnp.clip(action, low, high))
        return self._evaluate(state, physics)

    def _evaluate(self, state: State, physics: PhysicsState) -> State:
        """Observation, reward, success and done from the new physics quantities."""
        o = self.options
        q = physics.quantities
        goal_xy = state.info["goal_xy"]
        terms = logic.success(o, q, goal_xy, self.cube_dof_adr)
        diverged = ~q.ok
        success = terms["success"] & ~diverged
        reward = logic.reward(q, terms["goal_dist"], success)
        obs = observation.observe(
            q, goal_xy, self.robot_qpos_adr, self.robot_dof_adr, self.sensor_shapes
        )
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
                "goal_dist": jnp.where(diverged, jnp.inf, terms["goal_dist"]),
            },
        )

    # ---- kinematics, scripted expert ------------------------------------------------------

    def forward_kinematics(self) -> ForwardKinematics:
        """Robot joint positions -> (ee position, tool +z axis, and their Jacobians), pure JAX."""
        fk = site_kinematics(self.mj_model, self.ee_site_id, self.robot_qpos_adr)

        def ee_pose(q: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
            pos, rot, jacp, jacr = fk(q)
            axis = rot[:, 2]
            # d(axis)/dq_i = omega_i x axis for the rotational Jacobian column omega_i.
            jac_axis = jnp.stack([fo.cross(jacr[:, i], axis) for i in range(q.shape[0])], 1)
            return pos, axis, jacp, jac_axis

        return ee_pose

    def action_obs_index(self) -> tuple[int, ...] | None:
        """The joint position each actuator drives; None where one drives no joint (a
        gripper's tendon)."""
        if self.arm.held:
            return None
        start, _ = self._layout["joint_pos"]
        return tuple(start + int(i) for i in self.actuator_joint)

    def scripted_policy(self) -> Policy:
        """The scene's expert: push along the cube->goal line (see `push_expert`), with the
        tool size, push and hover heights measured on the robot (`arm.prepare`)."""
        arm, o = self.arm, self.options
        if arm.unreachable is not None:
            raise ConfigError(f"the scripted expert cannot push: {arm.unreachable}")
        low, high = self.action_bounds()
        held = None
        if arm.held:
            mask = np.zeros(self.action_size, bool)
            ctrl = np.zeros(self.action_size, np.float32)
            for i, value in arm.held.items():
                mask[i], ctrl[i] = True, value
            held = (jnp.asarray(mask), jnp.asarray(ctrl))
        # A servo's step response has time constant kv / kp; where that is longer than the
        # control period, its target leads the joint by that many IK steps.
        m = self.mj_model
        tau = -m.actuator_biasprm[:, 2] / np.maximum(m.actuator_gainprm[:, 0], 1e-9)
        factor = np.maximum(1.0, tau / self.control_dt)
        lead = None if np.all(factor == 1.0) else jnp.asarray(factor, jnp.float32)
        return push_expert(
            self.obs_layout,
            self.forward_kinematics(),
            jnp.asarray(self.actuator_joint),
            low,
            high,
            table_z=o.table_height,
            cube_half=o.cube_size / 2,
            goal_radius=o.goal_radius,
            tool_radius=arm.tool_radius,
            push_z=o.table_height + arm.push_height,
            hover_z=o.table_height + 2 * (o.cube_size / 2) + arm.hover_clearance,
            held=held,
            lead=lead,
        )
