"""The `So101Box` scene: wires the model, a physics backend, the task logic and the observation.

`compose` gives the MjSpec, `make_backend` a backend reporting the quantities the task reads;
`reset` places the sampled layout, `step` advances the physics, and both finish in
`_evaluate` (observation, reward, success, done). The scripted expert lives here too: it needs
the compiled model's kinematics.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.physics import PhysicsSettings, PhysicsState, Quantities, make_backend
from openral_mjx.physics.kinematics import site_kinematics
from openral_mjx.policies.base import Policy
from openral_mjx.policies.insert_expert import insert_expert
from openral_mjx.robots import ROBOTS
from openral_mjx.scenes.base import (
    RandomizationTargets,
    Scene,
    State,
    actuator_joints,
    colliding_geoms,
    servo_hold,
)
from openral_mjx.scenes.composition import yaw_quat
from openral_mjx.scenes.sensor_obs import (
    observed_cameras,
    range_slices,
    rendered_lights,
    sensor_shapes,
)
from openral_mjx.scenes.so101_box import observation
from openral_mjx.scenes.so101_box import task as logic  # `task` is the scene's task name
from openral_mjx.scenes.so101_box.model import compose
from openral_mjx.scenes.so101_box.options import So101BoxOptions


class So101Box(Scene):
    """The `so101_box` scene on a chosen physics backend."""

    name = "so101_box"
    task = "insert_tube_in_block"
    instruction = "insert the white tube into the hole of the blue block"
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
            logic.quantity_spec(self.robot.ee_site, sensors),
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
        self._layout = observation.obs_layout(len(self.robot_joint_ids), self.sensor_shapes)
        self._range_slices = range_slices(sensors)
        self._cameras = observed_cameras(sensors, self.mj_model)
        self._lights = rendered_lights(sensors, self.mj_model)

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        return dict(self._layout)

    # ---- reset ----------------------------------------------------------------------------

    def sample_layout(self, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Block and tube (x, y, yaw) for one episode (see `task.sample_layout`)."""
        return logic.sample_layout(self.options, key)

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
        return logic.episode_factors(state.physics.quantities)

    # ---- step, task logic -----------------------------------------------------------------

    def randomization_targets(self) -> RandomizationTargets:
        """Block and tube are the objects, resting on the floor; the arm is every servo."""
        m = self.mj_model
        objects = (m.body("block").id, m.body("tube").id)
        return RandomizationTargets(
            object_bodies=objects,
            contact_geoms=(*colliding_geoms(m, objects), m.geom("floor").id),
            arm_actuators=tuple(range(m.nu)),
            arm_dofs=tuple(int(d) for d in self.robot_dof_adr),
            joint_obs=("joint_pos",),
            object_obs=("tube_pos", "tube_quat", "block_pos", "block_quat"),
            range_obs=self._range_slices,
            cameras=self._cameras,
            lights=self._lights,
            hold=servo_hold(m, {}),
        )

    def step(self, state: State, action: jax.Array) -> State:
        low, high = self.action_bounds()
        physics = self.backend.step(state.physics, jnp.clip(action, low, high))
        return self._evaluate(state, physics)

    def insertion(self, q: Quantities) -> dict[str, jax.Array]:
        """The success predicate's terms on one env's `Quantities` (see `task.insertion`)."""
        return logic.insertion(self.options, q)

    def _evaluate(self, state: State, physics: PhysicsState) -> State:
        """Observation, reward, success and done from the new physics quantities."""
        o = self.options
        q = physics.quantities
        ins = self.insertion(q)
        diverged = ~q.ok
        success = ins["success"] & ~diverged
        reward = logic.reward(o, q, ins["lower"], success)
        obs = observation.observe(q, self.robot_qpos_adr, self.robot_dof_adr, self.sensor_shapes)
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

    # ---- scripted expert ------------------------------------------------------------------

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
