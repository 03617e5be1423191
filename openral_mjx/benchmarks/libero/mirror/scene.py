"""`libero_mjx`: a LIBERO task on our backends (`c`, `mjx`, `warp`), seed for seed LIBERO's.

The model is the MJCF LIBERO's own task construction composes (`assets`, exported from the
``lerobot-libero`` worker environment), simulated without its visual meshes. What the scene
reproduces of LIBERO's `OffScreenRenderEnv` (robosuite 1.4):

- **Reset**: seed s starts from the task's shipped initial state ``s mod 50``, as on the
  `libero` host scene, with LIBERO's fixtures (cabinets, stoves, racks, which its reset
  places by numpy's RNG and the initial states do not hold) where its reset puts them for
  that state (per-env `body_pos`/`body_quat`, `fixture_fields`), then LIBERO's 10 settle
  steps with the arm held and the gripper opening. The controller starts as robosuite's
  `reset` leaves it (`controller`). Option ``protocol=sampled`` (the mass-seed protocol)
  starts seed s from LIBERO's own reset draw for numpy seed ``s mod sampled_states``
  instead: objects in their BDDL regions, fixtures, articulated joints, drawn in LIBERO's
  worker once per task and seed and kept in the export cache (`assets.load_sampled`), as
  the host scene's worker draws it live.
- **Action**: 7-D in [-1, 1], OSC_POSE deltas and the gripper, at 20 Hz over 25 physics steps
  of 2 ms, the torques recomputed every physics step (`controller`).
- **Observation**: lerobot's LIBERO ``state``: end-effector position, its orientation as
  axis-angle, the two finger positions (8 floats). robosuite samples its observables on a
  float timer that comes round at the 24th of the 25 physics steps (the export measures
  which), reading the data that step leaves: the end-effector pose computed before its
  integration, the fingers' positions after it.
- **Expert entry** (option ``expert``, on by default): per atom of the goal the expert plays
  (`export.expert_atoms`), the moved object's position and its target body's pose, or the
  moving body's pose and the joint's position (`export.expert_entry`), from the data the
  control step's last physics step leaves, as the host scene's workers read them; what
  `libero-expert` plays from.
- **Cameras** (option ``image_size``, backend `c` or `warp`): ``image`` (agentview) and
  ``wrist_image`` (robot0_eye_in_hand) as the host scene gives them, drawn from the model with
  LIBERO's visual geoms, textures and lights by MuJoCo's renderer (`c`) or MuJoCo-Warp's batch
  renderer (`warp`). robosuite renders them when it samples its observables (the same physics
  step as the state), from the data that step leaves, whose poses are those of the state one
  physics step earlier: the mirror draws that state, and only at that physics step of the 25.
  The observation is then the host scene's dict instead of a flat vector.
- **Success**: the task's BDDL goal, as LIBERO's predicates evaluate it (`goal`); it ends
  the episode, as on the host scene.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.benchmarks.libero.assets import TaskModel, load_sampled, load_task, physics_spec
from openral_mjx.benchmarks.libero.export import (
    EXPERT_SIZE,
    expert_entry,
    expert_ids,
    moving_body,
)
from openral_mjx.benchmarks.libero.host_scene import instruction as host_instruction
from openral_mjx.benchmarks.libero.mirror.controller import (
    ControllerState,
    Dynamics,
    OscGains,
    RobotDynamics,
    arm_torques,
    gripper_step,
    set_goal,
)
from openral_mjx.benchmarks.libero.mirror.goal import Goal
from openral_mjx.benchmarks.libero.mirror.options import LiberoMjxOptions
from openral_mjx.core.errors import ConfigError
from openral_mjx.physics import (
    PhysicsBackend,
    PhysicsSettings,
    PhysicsState,
    Quantities,
    QuantitySpec,
    make_backend,
    resolve_backend_name,
)
from openral_mjx.physics.cameras import RgbSpec, RgbStyle
from openral_mjx.scenes.base import Scene, State, obs_slices
from openral_mjx.scenes.composition import for_mjx_jax

STATE_SIZE = 8
# MJX contact slots kept per condim on `mjx` (`for_mjx_jax`): LIBERO's scenes hold 18-87
# active contacts after their settle steps (libero_10/0, libero_spatial/0).
MJX_CONTACTS_PER_CONDIM = 128
# The cameras lerobot's LIBERO env hands a policy, by its observation names.
CAMERAS = {"image": "agentview", "wrist_image": "robot0_eye_in_hand"}
# robosuite draws with MuJoCo's renderer's defaults (textures, skybox, shadows, reflections)
# but hides geom group 0, the collision geoms (`render_collision_mesh` off); 1 is the visual.
LIBERO_STYLE = RgbStyle(textures=True, shadows=True)
LIBERO_GROUPS = (1, 2)
# On `warp`, textures are drawn from their mipmap level half the image's width in texels
# (`RgbStyle.texels`), in place of MuJoCo's per-pixel mipmaps. Measured at 128 x 128 against
# LIBERO's images (docs/libero_mjx.md, "Cameras on warp"): of 32, 64, 128 and 256 texels, 64
# agreed best on `agentview`; the close-up wrist camera prefers finer levels (libero_object/0:
# 68.9% at 64, 77.6% at 256, with 2 x 2 samples), and one level serves both cameras.
TEXELS_PER_PIXEL = 0.5


def libero_style(image_size: int, samples: int = 1) -> RgbStyle:
    """How the mirror's cameras are drawn at `image_size` (see `TEXELS_PER_PIXEL`), with
    `samples` sub-pixel samples per axis on `warp`."""
    texels = max(1, round(TEXELS_PER_PIXEL * image_size))
    return dataclasses.replace(LIBERO_STYLE, texels=texels, samples=samples)


def axis_angle(quat_wxyz: jax.Array) -> jax.Array:
    """robosuite's `quat2axisangle` of a unit quaternion (w, x, y, z)."""
    w = jnp.clip(quat_wxyz[0], -1.0, 1.0)
    s = jnp.sqrt(1.0 - w * w)
    angle = 2.0 * jnp.arccos(w)
    return jnp.where(s < 1e-8, 0.0, quat_wxyz[1:] * angle / jnp.where(s < 1e-8, 1.0, s))


def fixture_fields(
    export: TaskModel, m: mujoco.MjModel, ids: np.ndarray, pos: np.ndarray, quat: np.ndarray
) -> dict[str, jax.Array]:
    """Per initial state, the model's `body_pos` and `body_quat` with LIBERO's fixtures where
    its reset for that state puts them (bodies `ids` of the export's order at `pos`, `quat`:
    (states, bodies, 3 or 4)), as per-env model fields; empty where none moves from one
    initial state to another (then the model's own poses, the export's for state 0, hold)."""
    moved = (np.ptp(pos, axis=0).max(-1) > 0) | (np.ptp(quat, axis=0).max(-1) > 0)
    if not moved.any():
        return {}
    names = [str(n) for n in export.meta["body_names"]]
    rows = np.array([m.body(names[i]).id for i in np.asarray(ids)[moved]])
    body_pos = np.repeat(m.body_pos[None], len(pos), axis=0)
    body_quat = np.repeat(m.body_quat[None], len(pos), axis=0)
    body_pos[:, rows], body_quat[:, rows] = pos[:, moved], quat[:, moved]
    return {
        "body_pos": jnp.asarray(body_pos, jnp.float32),
        "body_quat": jnp.asarray(body_quat, jnp.float32),
    }


def initial_states(
    export: TaskModel, options: LiberoMjxOptions
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The states seeds cycle through: flattened ``[time, qpos, qvel]`` states, and the ids,
    positions and quaternions of the bodies LIBERO's reset places per state: the 50 shipped
    states (`standard`; every body's pose, from `TaskExport.fixture_poses`) or the mass-seed
    protocol's draws (`sampled`; the fixtures', from `load_sampled`)."""
    if options.protocol == "sampled":
        drawn = load_sampled(export.task, options.sampled_states)
        return drawn["states"], drawn["fixture_ids"], drawn["fixture_pos"], drawn["fixture_quat"]
    a = export.arrays
    ids = np.arange(a["fixture_pos"].shape[1])
    return export.init_states, ids, a["fixture_pos"], a["fixture_quat"]


def gains(model: TaskModel, ctrlrange: np.ndarray, gripper_ids: np.ndarray) -> OscGains:
    a = model.arrays
    f32 = lambda k: np.asarray(a[k], np.float32)  # noqa: E731
    return OscGains(
        kp=f32("kp"),
        kd=f32("kd"),
        input_min=f32("input_min"),
        input_max=f32("input_max"),
        output_min=f32("output_min"),
        output_max=f32("output_max"),
        nullspace_pose=f32("nullspace_pose"),
        torque_low=f32("torque_low"),
        torque_high=f32("torque_high"),
        gripper_speed=float(model.meta["gripper_speed"]),
        gripper_low=ctrlrange[gripper_ids, 0].astype(np.float32),
        gripper_high=ctrlrange[gripper_ids, 1].astype(np.float32),
    )


def camera_images(q: Quantities) -> dict[str, jax.Array]:
    """The cameras' images as lerobot's LIBERO env hands them over: uint8, and rotated by
    180 degrees from what the camera sees (its ``[::-1, ::-1]`` of MuJoCo's bottom-up rows;
    ours come upright, so only the columns turn)."""
    return {
        k: jnp.round(jnp.clip(q.sensors[k][:, ::-1], 0.0, 1.0) * 255.0).astype(jnp.uint8)
        for k in CAMERAS
    }


def joint_bodies(goal: Goal, model: mujoco.MjModel) -> tuple[str, ...]:
    """The bodies the goal's joint atoms move (the expert watches their poses), beyond the
    bodies the goal reads already."""
    names: list[str] = []
    for atom in goal.atoms:
        for joint in atom.get("joints", ()):
            name = moving_body(model, joint)
            if name not in names and name not in goal.bodies:
                names.append(name)
    return tuple(names)


class LiberoMjx(Scene):
    """One LIBERO task on a MuJoCo backend (see the module docstring)."""

    name = "libero_mjx"
    robot_name = "panda"

    def __init__(
        self,
        options: LiberoMjxOptions | None = None,
        *,
        backend: str = "auto",
        settings: PhysicsSettings | None = None,
    ) -> None:
        self.options = o = options or LiberoMjxOptions()
        self.task = o.task
        cameras = o.image_size is not None
        if cameras and resolve_backend_name(backend) not in ("c", "warp"):
            raise ConfigError(
                f"libero_mjx option image_size renders on backend c (MuJoCo's renderer) or "
                f"warp (MuJoCo-Warp's), not {resolve_backend_name(backend)!r}"
            )
        if o.image_samples != 1 and resolve_backend_name(backend) != "warp":
            raise ConfigError(
                f"libero_mjx option image_samples={o.image_samples} sets MuJoCo-Warp's "
                f"samples: backend warp, not {resolve_backend_name(backend)!r} (c draws with "
                "MuJoCo's renderer, multisampled as LIBERO's)"
            )
        self.export = t = load_task(o.task)
        self.spec = physics_spec(t, visuals=cameras)
        self.mjx_changes: dict[str, int] = {}
        if resolve_backend_name(backend) == "mjx":
            self.mjx_changes = for_mjx_jax(self.spec, MJX_CONTACTS_PER_CONDIM)
        meta = t.meta
        # The reference pose backends park a diverged env at (and warp warms up from): the
        # first shipped initial state. The MJCF's own qpos0 piles the objects at the origin.
        self.spec.add_key(name="reference", qpos=t.init_states[0][1 : 1 + int(meta["nq"])])
        # Compiled once, here and for the backend. A copy, not the spec itself: MuJoCo keeps
        # a compiled spec's loaded meshes, and every later copy of it then takes ~20 ms per
        # element deleted (the controller's robot-only spec deletes ~160).
        compiled = self.spec.copy().compile()
        if compiled.nq != meta["nq"]:
            raise ValueError(f"LIBERO task {o.task}: nq {compiled.nq}, its export {meta['nq']}")
        self.goal = Goal.build(t.goal, compiled)
        self._joint_bodies = joint_bodies(self.goal, compiled)
        self.backend = self._make_backend(backend, settings, compiled)
        m = self.mj_model
        self.n_substeps = int(meta["n_substeps"])
        self.observed_substep = int(meta["observation_substep"])
        # The 0-based physics step whose readout draws the cameras: robosuite draws the poses
        # its observed step computed before integrating, those of the state one step earlier.
        # `warp`'s readout after a step holds those same poses (`mjx.step`'s forward pass,
        # as `mj_step`'s), so it draws the observed step itself; `c` draws the state a step
        # ends in (`c_render`), so it draws the step before.
        self.drawn_substep = self.observed_substep - (2 if self.backend.name == "c" else 1)
        if cameras and self.drawn_substep < 0:
            raise ConfigError(
                f"LIBERO task {o.task}: robosuite observes physics step {self.observed_substep}"
                " of a control step; the mirror's cameras on c draw one step before it (>= 2)"
            )
        self.dynamics = RobotDynamics(self.spec, compiled, meta["arm_joints"], meta["eef_site"])
        self._index_robot(m)
        self.gains = gains(t, m.actuator_ctrlrange, self._grip_act)
        self._load_states(m)
        self._expert = expert_ids(t.goal, m, self.backend.quantity_spec.bodies.index)
        sizes = {"state": STATE_SIZE, **({"expert": EXPERT_SIZE} if o.expert else {})}
        self._layout = {} if cameras else obs_slices(sizes)
        self._obs_sizes = sizes

    def _make_backend(
        self, backend: str, settings: PhysicsSettings | None, model: mujoco.MjModel
    ) -> PhysicsBackend:
        """The physics of the task's model (`model`: the spec compiled): the end effector and
        the goal's bodies, sites and contacts read out, LIBERO's two cameras where
        `image_size` is set."""
        meta, o = self.export.meta, self.options
        return make_backend(
            backend,
            self.spec,
            QuantitySpec(
                bodies=(meta["eef_body"], *self.goal.bodies, *self._joint_bodies),
                sites=(meta["eef_site"],),
                contacts=self.goal.contacts,
                sensors=tuple(
                    RgbSpec(
                        cam,
                        o.image_size,
                        o.image_size,
                        name=key,
                        groups=LIBERO_GROUPS,
                        style=libero_style(o.image_size, o.image_samples),
                    )
                    for key, cam in CAMERAS.items()
                    if o.image_size is not None
                ),
            ),
            1,  # the controller acts at every physics step; `step` runs them
            settings,
            model,
        )

    def _index_robot(self, m: mujoco.MjModel) -> None:
        """The robot's joints (qpos, dofs) and actuators in the model, by the export's names."""
        meta = self.export.meta
        joint = lambda n: m.joint(n)  # noqa: E731
        self._robot_qpos = np.array([joint(n).qposadr[0] for n in self.dynamics.qpos_names])
        self._robot_dofs = np.array([joint(n).dofadr[0] for n in self.dynamics.qpos_names])
        self._arm_q = np.array([joint(n).qposadr[0] for n in meta["arm_joints"]])
        self._arm_v = np.array([joint(n).dofadr[0] for n in meta["arm_joints"]])
        self._fingers = np.array([joint(n).qposadr[0] for n in meta["gripper_joints"]])
        arm_act = np.array([m.actuator(n).id for n in meta["arm_actuators"]])
        grip_act = np.array([m.actuator(n).id for n in meta["gripper_actuators"]])
        self._arm_act, self._grip_act = arm_act, grip_act

    def _load_states(self, m: mujoco.MjModel) -> None:
        """The task's initial states (shipped or drawn: `initial_states`), its settle steps,
        robosuite's stale controller state, and the fixtures' per-state poses."""
        t, o, meta = self.export, self.options, self.export.meta
        states, fixture_ids, fixture_pos, fixture_quat = initial_states(t, o)
        states = np.asarray(states, np.float64)
        self._init_qpos = jnp.asarray(states[:, 1 : 1 + m.nq], jnp.float32)
        self._init_qvel = jnp.asarray(states[:, 1 + m.nq :], jnp.float32)
        self._goal_ori = jnp.asarray(t.arrays["goal_ori_after_reset"], jnp.float32)
        self._settle = (int(meta["settle_steps"]), jnp.asarray(t.arrays["settle_action"]))
        a = t.arrays
        f32 = lambda k: jnp.asarray(a[k], jnp.float32)  # noqa: E731
        # robosuite's controller state from `reset`, which the first step after
        # `set_init_state` still reads (the bias forces excepted: read fresh every step)
        self._stale = (
            Dynamics(
                f32("stale_ee_pos"), f32("stale_ee_mat"), f32("stale_jac"), f32("stale_mass"), None
            ),
            f32("stale_q"),
            f32("stale_qd"),
        )
        self._stale_first = bool(meta["stale_pending"])
        self._fixtures = fixture_fields(t, m, fixture_ids, fixture_pos, fixture_quat)

    # ---- layout ---------------------------------------------------------------------------

    @property
    def cameras(self) -> bool:
        """Whether the observation holds camera images (the host scene's dict)."""
        return self.options.image_size is not None

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        """The flat observation's slices; none where it is a dict (cameras on)."""
        return dict(self._layout)

    @property
    def observation_size(self) -> int:
        if self.cameras:
            raise ConfigError(
                "libero_mjx with image_size observes a dict of arrays (image, wrist_image, "
                "state, expert), not one flat vector: policies and trainers that need a flat "
                "vector (mlp, finetune) do not apply"
            )
        return sum(self._obs_sizes.values())

    @property
    def instruction(self) -> str:
        return host_instruction(self.task)

    @property
    def max_steps(self) -> int:
        return self.options.episode_limit

    @property
    def control_dt(self) -> float:
        """One control step: the scene's own `n_substeps` physics steps (the backend steps
        one at a time, so its `control_dt` is a physics step's)."""
        return float(self.mj_model.opt.timestep) * self.n_substeps

    @property
    def action_size(self) -> int:
        return 7

    def action_bounds(self) -> tuple[jax.Array, jax.Array]:
        return -jnp.ones(7, jnp.float32), jnp.ones(7, jnp.float32)

    @property
    def n_init_states(self) -> int:
        return int(self._init_qpos.shape[0])

    # ---- reset ----------------------------------------------------------------------------

    def reset(self, key: jax.Array) -> State:
        return self.reset_with_seed(jnp.zeros((), jnp.int32), key)

    def reset_with_seed(self, seed: jax.Array, key: jax.Array) -> State:
        """LIBERO's initial state ``seed mod 50`` (protocol ``sampled``: its draw for seed
        ``seed mod sampled_states``), then its settle steps."""
        del key  # LIBERO's protocol draws nothing: the initial state is the seed's
        return self.reset_from(jnp.asarray(seed) % self.n_init_states)

    def model_fields(self, init: jax.Array) -> dict[str, jax.Array]:
        """The per-env model fields of initial state `init`: its fixtures' poses
        (`fixture_fields`; empty where the task's fixtures never move)."""
        return {k: table[init] for k, table in self._fixtures.items()}

    def initial_physics(self, init: jax.Array) -> PhysicsState:
        """Initial state `init`'s physics before the settle steps, its fixtures placed."""
        fields = self.model_fields(init)
        return self.backend.init(self._init_qpos[init], self._init_qvel[init], fields)

    def reset_from(self, init: jax.Array) -> State:
        return self._reset(init, record=False)[0]

    def reset_controls(self, init: jax.Array) -> tuple[State, jax.Array]:
        """`reset_from(init)` and the controls its settle steps applied, ``(settle_steps,
        n_substeps, nu)``: with `step_controls`, an episode's physics to replay alone from
        `initial_physics` (the evaluator against raw physics, `benchmarks/`)."""
        return self._reset(init, record=True)

    def _reset(self, init: jax.Array, record: bool) -> tuple[State, jax.Array | None]:
        physics = self.initial_physics(init)
        controller = ControllerState(
            goal_pos=jnp.zeros(3, jnp.float32),  # every control step sets it
            goal_ori=self._goal_ori,
            gripper=jnp.zeros(2, jnp.float32),
        )
        n, action = self._settle

        def settle(i: jax.Array, pco: tuple) -> tuple:
            stale = (i == 0) & self._stale_first
            return self._control(*pco[:2], action, stale=stale, record=record)

        carry = (physics, controller, self._zero_obs())
        ctrls = None
        if record:
            carry, ctrls = jax.lax.scan(lambda pco, i: _split(settle(i, pco)), carry, jnp.arange(n))
        else:
            carry = jax.lax.fori_loop(0, n, lambda i, pco: settle(i, pco)[:3], carry)
        physics, controller, obs = carry
        diverged = ~physics.quantities.ok
        state = State(
            physics=physics,
            obs=obs,
            reward=jnp.zeros((), jnp.float32),
            done=diverged,
            metrics={"success": jnp.zeros((), bool), "diverged": diverged},
            info={"controller": controller, "init_state": init.astype(jnp.int32)},
        )
        return state, ctrls

    def episode_info(self, state: State) -> dict[str, jax.Array]:
        return {"init_state": state.info["init_state"]}

    def describe_episode(self, info: dict[str, Any]) -> dict[str, Any]:
        return {"init_state": int(info["init_state"])}

    # ---- step -----------------------------------------------------------------------------

    def _dynamics(self, physics: PhysicsState) -> Any:
        q = physics.quantities
        return self.dynamics(q.qpos[self._robot_qpos], q.qvel[self._robot_dofs])

    def _control(
        self,
        physics: PhysicsState,
        controller: ControllerState,
        action: jax.Array,
        stale: jax.Array | bool = False,
        record: bool = False,
    ) -> tuple[PhysicsState, ControllerState, Any, jax.Array | None]:
        """One control step: the goal from `action` (set at its first physics step, from the
        state it starts in), then the physics steps under OSC; returns the new state, the
        controller, the observation (read after physics step `observed_substep`, as
        robosuite's observables are) and, with `record` (no cameras), the controls each
        physics step applied ``(n_substeps, nu)`` (else None). `stale`: the goal and the
        first physics step's torques read the controller's reset state instead."""
        g = self.gains
        old, old_q, old_qd = self._stale
        nu = self.mj_model.nu

        def substep(i: jax.Array, pco: tuple, render: bool = True) -> tuple[tuple, jax.Array]:
            p, c, obs = pco
            q = p.quantities
            dyn, qa, qda = self._dynamics(p), q.qpos[self._arm_q], q.qvel[self._arm_v]
            use_old = (i == 0) & stale
            pick = lambda a, b: jnp.where(use_old, a, b)  # noqa: E731
            dyn = Dynamics(
                pick(old.ee_pos, dyn.ee_pos),
                pick(old.ee_mat, dyn.ee_mat),
                pick(old.jac, dyn.jac),
                pick(old.mass, dyn.mass),
                dyn.bias,  # read fresh from MuJoCo's data by robosuite, always
            )
            qa, qda = pick(old_q, qa), pick(old_qd, qda)
            c = jax.lax.cond(i == 0, lambda c: set_goal(g, c, action[:6], dyn), lambda c: c, c)
            tau = arm_torques(g, c, dyn, qa, qda)
            c, fingers = gripper_step(g, c, action[6])
            ctrl = jnp.zeros(nu, jnp.float32).at[self._arm_act].set(tau)
            ctrl = ctrl.at[self._grip_act].set(fingers)
            p = self.backend.step(p, ctrl, render=render)
            obs = jnp.where(i + 1 == self.observed_substep, self._obs(p), obs)
            return (p, c, obs), ctrl

        carry = (physics, controller, jnp.zeros(STATE_SIZE, jnp.float32))
        ctrls = None
        if self.cameras:  # render at physics step `drawn_substep` only
            if record:
                raise ValueError("libero_mjx records its controls without cameras only")
            drawn = self.drawn_substep
            plain = lambda i, pco: substep(i, pco, render=False)[0]  # noqa: E731
            carry = jax.lax.fori_loop(0, drawn, plain, carry)
            carry = substep(jnp.int32(drawn), carry)[0]
            carry = jax.lax.fori_loop(drawn + 1, self.n_substeps, plain, carry)
        elif record:
            body = lambda pco, i: substep(i, pco)  # noqa: E731
            carry, ctrls = jax.lax.scan(body, carry, jnp.arange(self.n_substeps))
        else:
            carry = jax.lax.fori_loop(0, self.n_substeps, lambda i, pco: substep(i, pco)[0], carry)
        physics, controller, state = carry
        obs = {"state": state}
        if self.options.expert:
            obs["expert"] = self._expert_entry(physics.quantities)
        if not self.cameras:
            return physics, controller, jnp.concatenate(list(obs.values())), ctrls
        return physics, controller, {**camera_images(physics.quantities), **obs}, ctrls

    def step(self, state: State, action: jax.Array) -> State:
        return self._step(state, action, record=False)[0]

    def step_controls(self, state: State, action: jax.Array) -> tuple[State, jax.Array]:
        """`step(state, action)` and the controls its physics steps applied, ``(n_substeps,
        nu)`` (see `reset_controls`)."""
        return self._step(state, action, record=True)

    def _step(
        self, state: State, action: jax.Array, record: bool
    ) -> tuple[State, jax.Array | None]:
        action = action.astype(jnp.float32)
        physics, controller, obs, ctrls = self._control(
            state.physics, state.info["controller"], action, record=record
        )
        diverged = ~physics.quantities.ok
        success = self.goal(physics.quantities, body_offset=1) & ~diverged
        new = state.replace(
            physics=physics,
            obs=jax.tree.map(lambda x: jnp.where(diverged, jnp.zeros_like(x), x), obs),
            reward=success.astype(jnp.float32),
            done=success | diverged,
            metrics={"success": success, "diverged": diverged},
            info={**state.info, "controller": controller},
        )
        return new, ctrls

    # ---- observation ----------------------------------------------------------------------

    def _zero_obs(self) -> Any:
        """An observation of zeros, shaped as the scene's."""
        if not self.cameras:
            return jnp.zeros(sum(self._obs_sizes.values()), jnp.float32)
        size = int(self.options.image_size)  # type: ignore[arg-type]
        images = {k: jnp.zeros((size, size, 3), jnp.uint8) for k in CAMERAS}
        return {**images, **{k: jnp.zeros(n, jnp.float32) for k, n in self._obs_sizes.items()}}

    def _expert_entry(self, q: Quantities) -> jax.Array:
        """Per atom the expert plays, what it reads (`export.expert_entry`)."""
        return expert_entry(q.body_pos, q.body_quat, q.qpos, self._expert, jnp)

    def _obs(self, physics: PhysicsState) -> jax.Array:
        q = physics.quantities
        return jnp.concatenate(
            [q.site_pos[0], axis_angle(q.body_quat[0]), q.qpos[self._fingers]]
        ).astype(jnp.float32)


def _split(out: tuple) -> tuple[tuple, Any]:
    """A control step's ``(physics, controller, obs, controls)`` as a scan's carry and output."""
    return out[:3], out[3]
