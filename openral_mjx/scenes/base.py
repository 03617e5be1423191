"""The scene contract: `reset(key) -> State`, `step(state, action) -> State`, one env, pure JAX.

Batching is `jax.vmap` outside the scene (the runner's job). Scenes compose an `MjSpec`, pick
a physics backend for it, and express reset sampling, observation, reward and success on the
backend-agnostic `Quantities`, so one scene definition runs on every backend.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import math
import types
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from openral_mjx.physics import PhysicsBackend, PhysicsState


@struct.dataclass
class State:
    """One env's state, brax/MuJoCo-Playground style.

    `metrics` holds per-step task signals (`success`, `diverged`, ...); `info` holds per-episode
    constants sampled at reset (e.g. the goal) that the task logic needs.
    """

    physics: PhysicsState
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    metrics: dict[str, jax.Array]
    info: dict[str, Any]


@dataclasses.dataclass(frozen=True)
class RandomizationTargets:
    """What `--randomize` may vary in a scene (`scenes.randomization`); an empty entry means
    the scene has nothing for the factors that need it.

    Attributes:
        object_bodies: body ids of the manipulated objects (`mass`).
        contact_geoms: ids of their colliding geoms and of the surfaces they rest on
            (`friction`: MuJoCo takes the larger friction of two touching geoms, so both sides
            are set).
        arm_actuators: ids of the arm's position servos (`kp`).
        arm_dofs: dof ids of the arm's joints (`damping`, `armature`).
        joint_obs, object_obs: observation slices of joint positions and of object poses
            (`joint_noise`, `object_noise`).
        range_obs: depth and laser observation slices with the reading of no return (their
            max range) (`depth_noise`, `depth_dropout`).
        hold: the action that holds the robot where a state has it, the command a delayed
            robot executes before the first one arrives (`delay`).
        cameras: ids of the cameras whose depth or RGB images the observation holds
            (`camera_pos`, `camera_rot`).
        lights: ids of the model lights that light the observation's RGB images (`light`);
            empty where it holds none (only `warp` renders them).
    """

    object_bodies: tuple[int, ...] = ()
    contact_geoms: tuple[int, ...] = ()
    arm_actuators: tuple[int, ...] = ()
    arm_dofs: tuple[int, ...] = ()
    joint_obs: tuple[str, ...] = ()
    object_obs: tuple[str, ...] = ()
    range_obs: tuple[tuple[str, float], ...] = ()
    hold: Callable[[State], jax.Array] | None = None
    cameras: tuple[int, ...] = ()
    lights: tuple[int, ...] = ()


@dataclasses.dataclass(frozen=True)
class TracedFns:
    """A scene's `reset_with_seed(seed, key)` and `step(state, action)` of one env, each a
    `jax.jit` (see `Scene.traced`)."""

    reset_with_seed: Callable[..., State]
    step: Callable[..., State]


class Scene(abc.ABC):
    """A registered task. Subclasses set `name`, build `spec`/`backend`, implement the logic."""

    name: str
    task: str
    backend: PhysicsBackend
    spec: mujoco.MjSpec
    options: Any
    robot_name: str

    @property
    def instruction(self) -> str:
        """The task in natural language: what language-conditioned (VLA) policies are told and
        reports record. Registered scenes write their own (benchmarks: the benchmark's text);
        this fallback spells out the task name, so a scene without one still reads sensibly."""
        return self.task.replace("_", " ").replace("-", " ")

    # Array shapes of the sensor slices of the observation (see `obs_shapes`); none by default.
    sensor_shapes: Mapping[str, tuple[int, ...]] = types.MappingProxyType({})

    @abc.abstractmethod
    def reset(self, key: jax.Array) -> State:
        """Randomise one episode from `key` (seed s -> `jax.random.PRNGKey(s)`)."""

    @abc.abstractmethod
    def step(self, state: State, action: jax.Array) -> State:
        """Apply one control action for one control period."""

    def reset_with_seed(self, seed: jax.Array, key: jax.Array) -> State:
        """What the runner calls: `reset(key)`, with the episode's seed for scenes that pick
        from a fixed list of initial states by seed (e.g. LIBERO's). Default: ignore it."""
        del seed
        return self.reset(key)

    def episode_info(self, state: State) -> dict[str, jax.Array]:
        """Per-episode scalars read from the final state, for the episode's metadata (decoded by
        `describe_episode`). Pure JAX, one env. Default: none."""
        del state
        return {}

    def describe_episode(self, info: dict[str, Any]) -> dict[str, Any]:
        """Metadata entries for one episode from its `episode_info` values (host side)."""
        return dict(info)

    def prepare(self, n_envs: int) -> None:  # noqa: B027 - an optional hook
        """Host-side setup before the run is timed (e.g. start simulator workers)."""

    def close(self) -> None:  # noqa: B027 - an optional hook
        """Release host resources (worker processes); the scene may be prepared again."""

    def episode_factors(self, state: State) -> dict[str, jax.Array]:
        """The episode's randomised factors, read from its reset state: name -> scalar.

        Reports break the success rate down by these (e.g. initial cube-to-goal distance), so
        a user sees where a policy fails. Evaluated once per env inside the jitted episode;
        pure JAX, one env. Default: none.
        """
        del state
        return {}

    def randomization_targets(self) -> RandomizationTargets | None:
        """What `--randomize` may vary here (see `RandomizationTargets`); None: nothing (a host
        scene's simulators are out of reach)."""
        return None

    def cache_parts(self) -> dict[str, Any]:
        """What, beyond its class, name, options and model, determines this scene's compiled
        code (the export cache keys on it). Default: nothing."""
        return {}

    # The camera videos show unless told otherwise (None: the model's first camera).
    video_camera: str | None = None

    def frame_record(self, state: State) -> dict[str, jax.Array]:
        """What drawing this env's frame needs, read from its state (pure JAX, one env).

        Recorded per step only for the few episodes a video shows; `pose_frame` puts it back
        into MuJoCo on the host. Default: the joint positions. A scene that draws per-episode
        markers (a goal) or moves mocap bodies adds them.
        """
        return {"qpos": state.physics.quantities.qpos}

    def pose_frame(
        self, model: mujoco.MjModel, data: mujoco.MjData, record: Mapping[str, np.ndarray]
    ) -> None:
        """Host side: load one step of `frame_record` into `data` (and per-episode markers into
        `model`, a copy private to the renderer) before `mj_forward`."""
        del model
        data.qpos[:] = record["qpos"]

    @property
    def max_steps(self) -> int:
        """Default episode length in control steps (the options' `max_steps`)."""
        return int(self.options.max_steps)

    @property
    def action_size(self) -> int:
        """One position target per actuator."""
        return int(self.mj_model.nu)

    @property
    @abc.abstractmethod
    def obs_layout(self) -> dict[str, tuple[int, int]]:
        """Named slices of the flat observation: name -> (start, size)."""

    @property
    def obs_shapes(self) -> dict[str, tuple[int, ...]]:
        """Array shape of each named observation slice: (size,) for a vector, (H, W) for a
        depth image, (H, W, 3) for RGB; `obs[start:start + size].reshape(shape)`."""
        shapes = {k: (size,) for k, (_, size) in self.obs_layout.items()}
        shapes.update(self.sensor_shapes)
        return shapes

    def sensor_frames(self, state: State) -> dict[str, jax.Array]:
        """This env's sensor readings by key (depth (H, W) and laser (n,) in metres, RGB
        (H, W, 3) in [0, 1]): what reports record as an episode's frames. Pure JAX."""
        return dict(state.physics.quantities.sensors)

    def policy_images(self, state: State) -> dict[str, jax.Array]:
        """Images the policy observes (name -> (H, W) depth in metres or (H, W, 3) RGB in
        [0, 1]), shown beside the scene in videos: the images among the sensor readings
        (none for vector observations)."""
        return {k: v for k, v in self.sensor_frames(state).items() if v.ndim >= 2}

    @functools.cached_property
    def traced(self) -> TracedFns:
        """`reset_with_seed` and `step`, each through one `jax.jit` made once per scene.

        The runner's programs call them in several places: the episode (or refill's `start`
        and `advance`), the factors' reset, and shape probes such as `observation_spec`.
        Called bare, every one of those traces the scene's Python again; through one `jit`,
        JAX traces each once per input shapes and later programs reuse that jaxpr (XLA inlines
        the nested call, so the compiled program does the same work). A large scene spends
        seconds in a trace (LIBERO's mirror on `warp`: ~4 s a reset, ~2 s a step on 2 cores).
        """
        return TracedFns(jax.jit(self.reset_with_seed), jax.jit(self.step))

    @functools.cached_property
    def observation_size(self) -> int:
        """Derived from `reset_with_seed` by shape evaluation, never hand-counted."""
        return int(self.observation_spec.shape[-1])

    @functools.cached_property
    def state_spec(self) -> State:
        """Shapes and dtypes of one env's reset state (`traced.reset_with_seed` evaluated for
        shape, so the runner's later traces reuse it)."""
        seed = jax.ShapeDtypeStruct((), jnp.int32)
        key = jax.ShapeDtypeStruct((2,), jnp.uint32)
        return jax.eval_shape(self.traced.reset_with_seed, seed, key)

    @functools.cached_property
    def observation_spec(self) -> Any:
        """Shapes and dtypes of one env's observation (an array, or a dict of arrays)."""
        return self.state_spec.obs

    @property
    def control_dt(self) -> float:
        return self.backend.control_dt

    @property
    def mj_model(self) -> mujoco.MjModel:
        """The compiled scene (as the physics backend sees it, minus backend-private additions)."""
        return self.backend.mj_model

    def action_obs_index(self) -> tuple[int, ...] | None:
        """For each actuator, the index in `obs` of the joint position it drives, or None.

        Lets a learned policy act relative to the current joint positions (position servos:
        an action is a target near where the joint is); None where no such reading exists.
        """
        return None

    def action_bounds(self) -> tuple[jax.Array, jax.Array]:
        """Per-actuator (low, high) control limits."""
        r = jnp.asarray(self.mj_model.actuator_ctrlrange, dtype=jnp.float32)
        return r[:, 0], r[:, 1]


def servo_hold(model: mujoco.MjModel, held: Mapping[int, float]) -> Callable[[State], jax.Array]:
    """The action that holds a robot of position servos where a state has it: each joint
    servo's target at its joint's position (times its gear), the others (`held`: actuator ->
    control) at their fixed control."""
    joint = model.actuator_trntype == mujoco.mjtTrn.mjTRN_JOINT
    missing = [i for i in np.flatnonzero(~joint) if int(i) not in held]
    if missing:
        raise ValueError(f"actuators {missing} drive no joint and have no held control")
    adr = np.where(joint, model.jnt_qposadr[model.actuator_trnid[:, 0]], 0)
    gear = np.where(joint, model.actuator_gear[:, 0], 0.0).astype(np.float32)
    fixed = np.array([held.get(i, 0.0) for i in range(model.nu)], np.float32)
    is_joint = jnp.asarray(joint)

    def hold(state: State) -> jax.Array:
        q = state.physics.quantities.qpos[adr]
        return jnp.where(is_joint, gear * q, fixed)

    return hold


def colliding_geoms(model: mujoco.MjModel, bodies: tuple[int, ...]) -> tuple[int, ...]:
    """Ids of the colliding geoms of `bodies`."""
    collides = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    return tuple(int(g) for g in np.flatnonzero(np.isin(model.geom_bodyid, bodies) & collides))


def obs_slices(sizes: Mapping[str, int]) -> dict[str, tuple[int, int]]:
    """Named slices (start, size) of a flat observation made of `sizes`, in order."""
    starts = np.cumsum([0, *sizes.values()])
    return {k: (int(s), int(v)) for (k, v), s in zip(sizes.items(), starts, strict=False)}


def arm_obs_layout(
    n_joints: int, task: Mapping[str, int], sensors: Mapping[str, tuple[int, ...]]
) -> dict[str, tuple[int, int]]:
    """The observation layout of an arm scene: joint positions and velocities, the
    end-effector position, the task's own slices (`task`: name -> size), then each observed
    sensor flattened row-major."""
    sizes = {"joint_pos": n_joints, "joint_vel": n_joints, "ee_pos": 3, **task}
    sizes.update({k: math.prod(shape) for k, shape in sensors.items()})
    return obs_slices(sizes)


def actuator_joints(model: mujoco.MjModel, joint_ids: np.ndarray) -> jax.Array:
    """For each actuator, the index in `joint_ids` of the joint it drives."""
    index = {int(j): i for i, j in enumerate(joint_ids)}
    return jnp.array([index[int(j)] for j in model.actuator_trnid[:, 0]])
