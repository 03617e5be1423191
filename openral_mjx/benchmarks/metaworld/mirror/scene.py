"""`metaworld_mjx`: a MetaWorld v3 task mirrored on our backends (`mjx`, `warp`, `c`).

The model is MetaWorld's own XML (`assets`), the task logic is ours in JAX (`task`, `tasks/`);
the `metaworld` host scene runs the original, and the agreement tests and report compare the
two on the same initial states. What the scene reproduces of MetaWorld's `SawyerXYZEnv`:

- **Reset**: MetaWorld moves the hand to ``hand_init_pos`` with 50 mocap-driven control steps
  from the model's default state before placing anything; that state does not depend on the
  episode (the objects sit at their defaults, out of the hand's way), so it is simulated once
  here with MuJoCo C and every reset starts from it. The random vector is drawn uniformly from
  the task's ``_random_reset_space`` with the episode's key (the first of 32 draws that the
  task's `accept` keeps: MetaWorld redraws the same way), then the task places the objects.
  MetaWorld's numpy generator is not reproduced: seed s gives the same episode here on every
  run, and the `metaworld` host scene hands MetaWorld the same vector for seed s
  (`task.random_vector`), so seed s is one initial state on both scenes. Episode factors are
  MetaWorld's ``obj_init_pos`` and ``_target_pos`` after the reset, as the host scene reports.
- **Action**: 4-D in [-1, 1]: the mocap target moves by ``action[:3] / 100``, clipped to the
  task's mocap box, with the hand's fixed orientation; the gripper's two actuators get
  ``(a[3], -a[3])``; 5 physics steps of 2.5 ms per control step.
- **Observation**: MetaWorld's 39 floats: hand position, gripper opening, the objects' poses
  (padded to 14), the previous step's 18, and the goal (zeros when not observable), clipped to
  MetaWorld's observation box after every step (not at reset, as MetaWorld); the poses are
  those of the state the step ends in (MetaWorld calls `mj_forward` after its physics steps;
  `poses_after_step`). On `warp`, RGB images of MetaWorld's cameras may follow
  (`obs_rgb_cameras`, see `sensor_obs`), rendered by MuJoCo-Warp from those poses.
- **Contacts**: as mujoco 4 makes them from MetaWorld's XML. mujoco 4 makes several contacts
  per convex pair by default where MetaWorld's mujoco 3.3 made one; turning that off
  (`mjDSBL_MULTICCD`) brought door-open to 99.6% agreement and stick-pull to 97.4% but turned
  box-close's lean around (BENCHMARKS.md), so the model keeps mujoco 4's default.
- **Success**: the task's predicate, which ends the episode; MetaWorld's limit is 500 steps.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from openral_mjx.benchmarks.metaworld.host_scene import FACTORS, ROBOT
from openral_mjx.benchmarks.metaworld.host_scene import instruction as host_instruction
from openral_mjx.benchmarks.metaworld.mirror import task as mw
from openral_mjx.benchmarks.metaworld.mirror.assets import load_spec
from openral_mjx.benchmarks.metaworld.mirror.options import MetaWorldMjxOptions
from openral_mjx.benchmarks.metaworld.mirror.tasks import TASKS, check_reward
from openral_mjx.core.errors import unknown
from openral_mjx.core.rotations import quat_mul
from openral_mjx.physics import (
    PhysicsSettings,
    PhysicsState,
    QuantitySpec,
    make_backend,
    resolve_backend_name,
)
from openral_mjx.scenes.base import (
    RandomizationTargets,
    Scene,
    State,
    colliding_geoms,
    obs_slices,
)
from openral_mjx.scenes.composition import for_mjx_jax, geom_frame_offsets
from openral_mjx.scenes.sensor_obs import (
    observed_cameras,
    rendered_lights,
    sensor_obs,
    sensor_shapes,
)

OBS_SIZES = {"hand": 3, "gripper": 1, "objects": 14, "prev": 18, "goal": 3}
_MOCAP_QUAT = np.asarray(mw.MOCAP_QUAT) / np.linalg.norm(mw.MOCAP_QUAT)
# MJX contact slots kept per condim (its `max_contact_points`). Uncapped, MJX gives every
# candidate pair its slots and constraint rows every step (box-close: 780 slots, 2,995 rows;
# 14 s per solve on a 2-core CPU, 20 ms at 32 per condim). MetaWorld's experts, in MuJoCo C,
# have at most 46 active contacts of one condim at once (peg-insert-side; 3 seeds of every
# task); an env that may exceed the cap is counted diverged by the `mjx` backend.
MJX_CONTACTS_PER_CONDIM = 64


def for_mjx(spec: mujoco.MjSpec) -> dict[str, int]:
    """`for_mjx_jax` with MetaWorld's cap (`MJX_CONTACTS_PER_CONDIM`); the agreement table
    measures the effect (``--backend mjx``). MetaWorld's claws and pads have 1 mm margins."""
    return for_mjx_jax(spec, MJX_CONTACTS_PER_CONDIM)


def hand_reset_state(m: mujoco.MjModel, hand_init_pos: tuple[float, ...]) -> mujoco.MjData:
    """MetaWorld's ``_reset_hand`` from the model's default state, in MuJoCo C (float64),
    with the poses as its last ``mj_step`` leaves them (what MetaWorld reads as ``init_tcp``;
    no forward pass after it)."""
    d = mujoco.MjData(m)
    mujoco.mj_resetData(m, d)
    mocap = m.body_mocapid[m.body("mocap").id]
    for _ in range(mw.HAND_RESET_STEPS):
        d.mocap_pos[mocap] = hand_init_pos
        d.mocap_quat[mocap] = mw.MOCAP_QUAT
        d.ctrl[:] = (-1.0, 1.0)
        mujoco.mj_step(m, d, nstep=mw.FRAME_SKIP)
    return d


def model_facts(m: mujoco.MjModel, task: mw.MirrorTask) -> tuple[mw.ModelFacts, Any]:
    """The task's `ModelFacts` for compiled model `m`, and the hand-reset MjData they were
    read from."""
    d = hand_reset_state(m, task.hand_init_pos)
    ends = [d.site_xpos[m.site(n).id] for n in ("rightEndEffector", "leftEndEffector")]
    rest: dict[str, np.ndarray] = {"init_tcp": (ends[0] + ends[1]) / 2.0}  # before a forward
    mujoco.mj_forward(m, d)  # the other positions: the state the hand reset ends in
    for i in range(m.nbody):
        rest[f"body:{m.body(i).name}"] = d.xpos[i].copy()
    for i in range(m.nsite):
        rest[f"site:{m.site(i).name}"] = d.site_xpos[i].copy()
    for i in range(m.ngeom):
        if m.geom(i).name:
            rest[f"geom:{m.geom(i).name}"] = d.geom_xpos[i].copy()
    joints = [m.joint(i) for i in range(m.njnt)]
    facts = mw.ModelFacts(
        qpos_adr={j.name: int(j.qposadr[0]) for j in joints},
        dof_adr={j.name: int(j.dofadr[0]) for j in joints},
        site_pos={m.site(i).name: m.site_pos[i].copy() for i in range(m.nsite)},
        rest=rest,
    )
    return facts, d


class MetaWorldMjx(Scene):
    """One MetaWorld v3 task on a MuJoCo backend (see the module docstring)."""

    name = "metaworld_mjx"
    robot_name = ROBOT

    def __init__(
        self,
        options: MetaWorldMjxOptions | None = None,
        *,
        backend: str = "auto",
        settings: PhysicsSettings | None = None,
    ) -> None:
        self.options = o = options or MetaWorldMjxOptions()
        self.task = o.task
        self.logic = t = TASKS[o.task]
        self.spec = load_spec(t.xml)
        self.mjx_changes: dict[str, int] = {}
        original = None
        if resolve_backend_name(backend) == "mjx":
            original = self.spec.compile()
            self.mjx_changes = for_mjx(self.spec)
        bodies = tuple(dict.fromkeys((*mw.COMMON_BODIES, *t.bodies, *t.moved_bodies)))
        sites = tuple(dict.fromkeys((*mw.COMMON_SITES, *t.sites)))
        geoms = tuple(dict.fromkeys(t.geoms))
        cameras = [c.name for c in self.spec.cameras]
        for name in o.obs_rgb_cameras:
            if name not in cameras:
                raise unknown("MetaWorld camera", name, cameras)
        sensors = o.sensor_specs()
        self.backend = make_backend(
            backend,
            self.spec,
            # MetaWorld's step ends with `mj_forward`: it observes the state it ends in
            QuantitySpec(bodies, sites, geoms=geoms, sensors=sensors, poses_after_step=True),
            mw.FRAME_SKIP,
            settings,
        )
        self.sensor_shapes = sensor_shapes(sensors)
        m = self.mj_model  # the backend's compiled copy of the spec
        self.facts, rest = model_facts(m, t)
        # MetaWorld's orientation of a geom that `for_mjx` made a prism (see
        # `geom_frame_offsets`), or None where every observed geom keeps its frame
        self._geom_frames = None
        if original is not None:
            offsets = geom_frame_offsets(original, m, [m.geom(n).id for n in geoms])
            if not np.allclose(np.abs(offsets[:, 0]), 1.0):
                self._geom_frames = jnp.asarray(offsets, jnp.float32)
        self._names = (
            {n: i for i, n in enumerate(bodies)},
            {n: i for i, n in enumerate(sites)},
            {n: i for i, n in enumerate(geoms)},
            dict(self.facts.qpos_adr),
        )
        self._qpos = jnp.asarray(rest.qpos, jnp.float32)
        self._qvel = jnp.asarray(rest.qvel, jnp.float32)
        mocap = m.body_mocapid[m.body("mocap").id]
        self._mocap_id = int(mocap)
        self._mocap_start = jnp.asarray(rest.mocap_pos, jnp.float32)
        self._moved_ids = np.array([m.body(b).id for b in t.moved_bodies], np.int64)
        self._body_pos = jnp.asarray(m.body_pos, jnp.float32)
        # hinge and slide joints' (qpos, dof) addresses: a state's positions one physics step
        # back are qpos - dt qvel there (MuJoCo integrates positions with the new velocity)
        kinds = {int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)}
        scalar = [j for j in range(m.njnt) if int(m.jnt_type[j]) in kinds]
        self._scalar_qpos = np.array([m.jnt_qposadr[j] for j in scalar], np.int64)
        self._scalar_dof = np.array([m.jnt_dofadr[j] for j in scalar], np.int64)
        self._timestep = float(m.opt.timestep)
        low = t.mocap_low if t.mocap_low is not None else t.hand_low
        high = t.mocap_high if t.mocap_high is not None else t.hand_high
        self._mocap_box = (jnp.asarray(low, jnp.float32), jnp.asarray(high, jnp.float32))
        images = {k: int(np.prod(shape)) for k, shape in self.sensor_shapes.items()}
        self._layout = obs_slices({**OBS_SIZES, **images})
        self._cameras = observed_cameras(sensors, m)
        self._lights = rendered_lights(sensors, m)
        obs_low = np.full(39, -np.inf, np.float32)
        obs_high = np.full(39, np.inf, np.float32)
        for start in (0, 18):
            obs_low[start : start + 3], obs_high[start : start + 3] = (
                mw.HAND_SPACE_LOW,
                mw.HAND_SPACE_HIGH,
            )
            obs_low[start + 3], obs_high[start + 3] = -1.0, 1.0
        if o.goal_observable:
            obs_low[36:], obs_high[36:] = t.goal_low, t.goal_high
        else:
            obs_low[36:], obs_high[36:] = 0.0, 0.0
        self._obs_box = (jnp.asarray(obs_low), jnp.asarray(obs_high))

    # ---- layout ---------------------------------------------------------------------------

    @property
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        return dict(self._layout)

    @property
    def instruction(self) -> str:
        """The host scene's text for the task (lerobot's MetaWorld description)."""
        return host_instruction(self.task)

    @property
    def action_size(self) -> int:
        return 4

    def action_bounds(self) -> tuple[jax.Array, jax.Array]:
        return -jnp.ones(4, jnp.float32), jnp.ones(4, jnp.float32)

    def randomization_targets(self) -> RandomizationTargets:
        """The task's free objects (mass; friction with the table), the objects' observed
        poses; a delayed hand stands still with the gripper open, as MetaWorld resets it. The
        hand moves by mocap: no arm servos or joints to vary."""
        m = self.mj_model
        free = mujoco.mjtJoint.mjJNT_FREE
        objects = tuple(
            sorted({int(m.jnt_bodyid[j]) for j in range(m.njnt) if m.jnt_type[j] == free})
        )
        contact = colliding_geoms(m, (*objects, m.body("tablelink").id)) if objects else ()
        still = jnp.array([0.0, 0.0, 0.0, -1.0], jnp.float32)
        return RandomizationTargets(
            object_bodies=objects,
            contact_geoms=contact,
            object_obs=("objects",),
            cameras=self._cameras,
            lights=self._lights,
            hold=lambda state: still,
        )

    # ---- reset ----------------------------------------------------------------------------

    def draw(self, key: jax.Array) -> jax.Array:
        """The episode's random vector (`task.random_vector`, shared with the host scene)."""
        return mw.random_vector(self.logic, key)

    def reset(self, key: jax.Array) -> State:
        return self.reset_from(self.draw(key))

    def reset_from(self, vec: jax.Array) -> State:
        """The episode that MetaWorld's reset builds from random vector `vec`."""
        t = self.logic
        vec = jnp.asarray(vec, jnp.float32)
        hand_qpos, hand_qvel = self._qpos, self._qvel  # the state the hand reset leaves
        qpos, qvel, moved = t.place(self.facts, vec, hand_qpos, hand_qvel)
        fields = {}
        if t.moved_bodies:
            pos = jnp.stack([moved[b] for b in t.moved_bodies]).astype(jnp.float32)
            fields = {"body_pos": self._body_pos.at[self._moved_ids].set(pos)}
        reset_ok = jnp.ones((), bool)
        if t.hand_reset_per_episode:
            hand_qpos, hand_qvel, reset_ok, tcp = self._hand_reset(fields)
            qpos, qvel, _ = t.place(self.facts, vec, hand_qpos, hand_qvel)
        physics = self.backend.init(qpos, qvel, fields=fields)
        # an env whose simulated reset could not be trusted stays flagged (counted diverged)
        q = physics.quantities
        physics = physics.replace(quantities=q.replace(ok=q.ok & reset_ok))
        view = self._view(physics)
        episode = t.episode(self.facts, vec, view)
        # MetaWorld's `init_tcp`: where the hand reset ends, shared or this episode's
        init = tcp if t.hand_reset_per_episode else mw.init_tcp(self.facts)
        episode = {**episode, "init_tcp": init}
        curr = self._current(view)
        if t.observes_before_place:  # the hand reset's state, with the moved bodies in place
            before = self.backend.init(hand_qpos, hand_qvel, fields=fields)
            curr = self._current(self._view(before))
        obs = jnp.concatenate([curr, curr, self._goal(episode), *self._images(physics)])
        info = {
            "vec": vec,
            "episode": episode,
            "mocap_pos": self._mocap_start,
            "prev": curr,
        }
        metrics = {"success": jnp.zeros((), bool), "diverged": ~physics.quantities.ok}
        return State(
            physics=physics,
            obs=obs.astype(jnp.float32),
            reward=jnp.zeros((), jnp.float32),
            done=jnp.zeros((), bool),
            metrics=metrics,
            info=info,
        )

    def _hand_reset(
        self, fields: dict[str, jax.Array]
    ) -> tuple[jax.Array, jax.Array, jax.Array, jax.Array]:
        """MetaWorld's hand reset simulated with this episode's fixed bodies in place (from
        the model's default joint state: MetaWorld resets the data before its second, final
        `reset_model`, whose hand reset sees the bodies the first one moved). Returns the
        joint positions and velocities it ends in (after the task's `settle_steps`), whether
        its physics stayed ok, and the tcp centre its last hand-reset step leaves (MetaWorld's
        ``init_tcp``)."""
        m = self.mj_model
        physics = self.backend.init(
            jnp.asarray(m.qpos0, jnp.float32), jnp.zeros(m.nv, jnp.float32), fields=fields
        )
        mocap = self._mocap_start.at[self._mocap_id].set(jnp.asarray(self.logic.hand_init_pos))
        quat = jnp.broadcast_to(jnp.asarray(_MOCAP_QUAT, jnp.float32), (mocap.shape[0], 4))
        ctrl = jnp.array([-1.0, 1.0], jnp.float32)

        def steps(n: int, physics: PhysicsState) -> PhysicsState:
            return jax.lax.fori_loop(
                0, n, lambda _, p: self.backend.step(p, ctrl, mocap=(mocap, quat)), physics
            )

        physics = steps(mw.HAND_RESET_STEPS, physics)
        # MetaWorld reads the tcp as its last `mj_step` leaves the poses: those of the state
        # before that step's integration (the hand's own joints are hinges and slides)
        q = physics.quantities
        back = q.qvel[self._scalar_dof] * self._timestep
        before = self.backend.init(q.qpos.at[self._scalar_qpos].add(-back), q.qvel, fields=fields)
        tcp = self._view(before).tcp_center
        physics = steps(self.logic.settle_steps, physics)  # then the reset's own steps
        q = physics.quantities
        return q.qpos, q.qvel, q.ok, tcp

    def check_reward(self) -> None:
        """`ConfigError` unless this task's reward is MetaWorld's (other tasks return 0):
        `finetune ppo` asks before training."""
        check_reward(self.task)

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        """MetaWorld's ``obj_init_pos`` and ``_target_pos`` after the reset: the `metaworld`
        host scene's factors (`FACTORS`), the same quantities under the same names."""
        episode = state.info["episode"]
        values = jnp.concatenate([episode["obj_init_pos"], episode["target_pos"]])
        return {n: values[i].astype(jnp.float32) for i, n in enumerate(FACTORS)}

    # ---- step -----------------------------------------------------------------------------

    def step(self, state: State, action: jax.Array) -> State:
        a = jnp.clip(action.astype(jnp.float32), -1.0, 1.0)
        low, high = self._mocap_box
        mocap = state.info["mocap_pos"]
        target = jnp.clip(mocap[self._mocap_id] + a[:3] * mw.ACTION_SCALE, low, high)
        mocap = mocap.at[self._mocap_id].set(target)
        quat = jnp.broadcast_to(jnp.asarray(_MOCAP_QUAT, jnp.float32), (mocap.shape[0], 4))
        ctrl = jnp.stack([a[3], -a[3]])
        physics = self.backend.step(state.physics, ctrl, mocap=(mocap, quat))
        view = self._view(physics)
        episode = state.info["episode"]
        curr = self._current(view)
        obs = jnp.concatenate([curr, state.info["prev"], self._goal(episode)])
        obs = jnp.clip(obs, *self._obs_box)
        diverged = ~physics.quantities.ok
        success = self.logic.success(obs, view, episode) & ~diverged
        reward = jnp.where(diverged, 0.0, self.logic.reward(obs, view, episode, a))
        obs = jnp.concatenate([obs, *self._images(physics)])
        return state.replace(
            physics=physics,
            obs=jnp.where(diverged, 0.0, obs).astype(jnp.float32),
            reward=reward.astype(jnp.float32),
            done=success | diverged,
            metrics={"success": success, "diverged": diverged},
            info={**state.info, "mocap_pos": mocap, "prev": curr},
        )

    # ---- observation ----------------------------------------------------------------------

    def _view(self, physics: PhysicsState) -> mw.View:
        q = physics.quantities
        if self._geom_frames is not None:
            q = q.replace(geom_quat=quat_mul(q.geom_quat, self._geom_frames))
        return mw.View(q, *self._names)

    def _current(self, view: mw.View) -> jax.Array:
        """MetaWorld's ``_get_curr_obs_combined_no_goal`` (18 floats)."""
        gap = jnp.linalg.norm(view.body_pos("rightclaw") - view.body_pos("leftclaw"))
        objects = _interleave(*self.logic.objects(view))
        objects = jnp.pad(objects, (0, mw.OBS_OBJ_MAX_LEN - objects.shape[0]))
        return jnp.concatenate([view.hand, jnp.clip(gap / 0.1, 0.0, 1.0)[None], objects])

    def _images(self, physics: PhysicsState) -> list[jax.Array]:
        """The observed camera images, flattened (none unless `obs_rgb_cameras`)."""
        return sensor_obs(physics.quantities, self.sensor_shapes)

    def _goal(self, episode: dict[str, jax.Array]) -> jax.Array:
        if not self.options.goal_observable:
            return jnp.zeros(3, jnp.float32)
        return episode["target_pos"].astype(jnp.float32)


def _interleave(pos: jax.Array, quat: jax.Array) -> jax.Array:
    """(p1, q1, p2, q2, ...) from flat positions and quaternions, as MetaWorld stacks them."""
    n = pos.shape[0] // 3
    return jnp.concatenate([pos.reshape(n, 3), quat.reshape(n, 4)], axis=1).reshape(-1)
