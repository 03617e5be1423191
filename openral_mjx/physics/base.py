"""The physics-backend contract: advance one env's state, report the quantities task logic reads.

Task logic (reset sampling, observation, reward, success) never touches backend internals; it
reads `Quantities`, which every backend produces the same way. Backends are single-env and
pure, so the runner batches them with `jax.vmap` like any other JAX function.
"""

from __future__ import annotations

import abc
import dataclasses
import importlib.util
import sys
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from openral_mjx import raycast
from openral_mjx.core.errors import ConfigError
from openral_mjx.physics.cameras import RgbSpec, SensorSpec, sensor_key


def warp_installed() -> bool:
    """Whether warp-lang can be imported (without importing it)."""
    return importlib.util.find_spec("warp") is not None


def release_warp_graphs() -> None:
    """Free the CUDA graphs Warp captured for the `warp` backend's calls so far, and the
    device memory they hold (a no-op where Warp was never imported).

    A Warp callable called from JAX captures a graph for each distinct set of buffer
    addresses it meets (up to 32 per callable, `warp/_src/jax/ffi.py`), and each graph keeps
    the temporaries it allocated, outside JAX's allocator: 4.6 GB for one LIBERO step at
    16,384 envs with 128 CCD slots per env. A finished run's programs are not called again,
    so a process that runs several (a suite's task process, a sweep's points) would pile
    them up; a program called after this captures its graphs again."""
    warp = sys.modules.get("warp")
    if warp is not None and hasattr(warp, "clear_jax_callable_graph_cache"):
        warp.clear_jax_callable_graph_cache()


@dataclasses.dataclass(frozen=True)
class QuantitySpec:
    """What the task logic reads: named bodies', sites' and geoms' world poses, and sensors.

    `sensors` are laser scanners (`raycast.LaserSpec`), depth cameras (`raycast.DepthSpec`)
    and RGB cameras (`RgbSpec`: MuJoCo-Warp's renderer on `warp`, MuJoCo's OpenGL renderer on
    `c`, none on `mjx`); their readings appear in `Quantities.sensors` under each spec's key.

    `contacts`: pairs of geom-name sets; each reads whether any geom of the first set touches
    any of the second (in MuJoCo's contact list as the step's collision left it, as
    ``contact`` sensors find it): robosuite's `check_contact` between two objects.

    `poses_after_step`: after a step, report the poses of the state the step ends in (as an
    `mj_forward` after `mj_step` would), not those `mj_step` leaves in MuJoCo's data (computed
    before its last integration, one physics step earlier: the default). The simulation itself
    is the same either way; only what is read from it moves.
    """

    bodies: tuple[str, ...] = ()
    sites: tuple[str, ...] = ()
    sensors: tuple[SensorSpec, ...] = ()
    geoms: tuple[str, ...] = ()
    poses_after_step: bool = False
    contacts: tuple[tuple[tuple[str, ...], tuple[str, ...]], ...] = ()


# PhysicsSettings.warp_graphs: Warp's JaxCallableGraphMode member of each
WARP_GRAPHS = {"warp": "WARP", "staged": "WARP_STAGED", "none": "NONE"}


def check_warp_graphs(value: str | None) -> None:
    """Raise `ConfigError` unless `value` is None or one of `WARP_GRAPHS`."""
    if value is not None and value not in WARP_GRAPHS:
        raise ConfigError(f"unknown warp_graphs {value!r}; valid: {', '.join(WARP_GRAPHS)}")


@dataclasses.dataclass(frozen=True)
class PhysicsSettings:
    """How a backend runs, as opposed to what it simulates (that is the scene's MjSpec).

    Attributes:
        threads: MuJoCo C worker threads (`c`); None: all cores.
        batch_size: envs per device the backend sizes per-batch buffers for (`warp`: contact
            and constraint capacity); the runner rejects larger per-device batches.
        contacts_per_env: `warp` contact capacity per env (a buffer overflow marks the env
            diverged, never silently wrong).
        ccd_contacts_per_env: of those, how many may come from convex collision detection
            (GJK/EPA: meshes, cylinders), whose working buffers are the largest per contact;
            None: all of them. Lower it to fit bigger batches of mesh-heavy scenes.
        max_devices: use at most this many of the backend's devices (the first ones); None:
            all of them.
        warp_graphs: how `warp` replays its calls as CUDA graphs (`WARP_GRAPHS`); None: MJX's
            default (``warp`` on a GPU). ``warp`` captures one graph per set of buffer
            addresses a call meets, up to 32, each holding its own copy of the call's
            temporaries (MuJoCo-Warp's EPA buffers: 4.6 GB at 16,384 envs x 128 CCD contacts);
            ``staged`` captures one per call site and copies its buffers in and out; ``none``
            launches the kernels without a graph, its temporaries freed after each call.
    """

    threads: int | None = None
    batch_size: int = 4096
    contacts_per_env: int = 32
    ccd_contacts_per_env: int | None = None
    max_devices: int | None = None
    warp_graphs: str | None = None

    def __post_init__(self) -> None:
        check_warp_graphs(self.warp_graphs)
        for name in ("threads", "max_devices", "ccd_contacts_per_env"):
            value = getattr(self, name)
            if value is not None and value < 1:
                raise ConfigError(f"{name} must be >= 1, got {value}")
        for name in ("batch_size", "contacts_per_env"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)}")
        ccd = self.ccd_contacts_per_env
        if ccd is not None and ccd > self.contacts_per_env:
            raise ConfigError(
                f"ccd_contacts_per_env must be <= contacts_per_env ({self.contacts_per_env}),"
                f" got {ccd}"
            )


@struct.dataclass
class Quantities:
    """Backend-agnostic physics readout of one env, float32, world frame (quaternions w-x-y-z)."""

    qpos: jax.Array  # (nq,)
    qvel: jax.Array  # (nv,)
    body_pos: jax.Array  # (len(spec.bodies), 3)
    body_quat: jax.Array  # (len(spec.bodies), 4)
    site_pos: jax.Array  # (len(spec.sites), 3)
    geom_pos: jax.Array  # (len(spec.geoms), 3)
    geom_quat: jax.Array  # (len(spec.geoms), 4)
    ok: jax.Array  # () bool: False once the state went non-finite or the engine reset it
    # Sensor readings by key: laser ranges (n_beams,) and depth images (H, W) in metres, RGB
    # images (H, W, 3) in [0, 1].
    sensors: dict[str, jax.Array]
    # (len(spec.contacts),) bool: whether each pair of `QuantitySpec.contacts` touches
    contacts: jax.Array | None = None
    # () bool, once set kept: an engine buffer (contacts, constraints) overflowed, which also
    # clears `ok`; a capacity to raise, not physics gone wrong. None: a backend with no such
    # buffers (`c`)
    overflowed: jax.Array | None = None


@struct.dataclass
class PhysicsState:
    """One env's physics: backend-specific `data` plus the common `quantities`.

    `fields` are this env's own values of model fields (name -> the whole field, e.g.
    ``body_pos`` (nbody, 3)), set at `init` and used by every step: per-episode geometry that
    a scene writes into the model (a MetaWorld mirror moves fixed bodies per reset) and
    per-env randomised physics. Empty: the model's own values.
    """

    data: Any
    quantities: Quantities
    fields: dict[str, jax.Array] = struct.field(default_factory=dict)


# Model fields an env may override (`PhysicsState.fields`): geometry, per-episode physics and
# rendering (`light_diffuse`: only `warp`'s renderer reads it).
PER_ENV_FIELDS = frozenset(
    {
        "body_pos",
        "body_quat",
        "body_mass",
        "body_inertia",
        "geom_friction",
        "site_pos",
        "dof_damping",
        "dof_armature",
        "dof_M0",
        "cam_pos",
        "cam_quat",
        "light_diffuse",
        "actuator_gainprm",
        "actuator_biasprm",
    }
)


def camera_local(
    fields: dict[str, jax.Array] | None, cam: int, model: mujoco.MjModel
) -> tuple[jax.Array, jax.Array] | None:
    """Camera `cam`'s pose in its body's frame from an env's `cam_pos`/`cam_quat` fields
    (the model's value for a missing one); None when the env has neither."""
    if not fields or not ({"cam_pos", "cam_quat"} & set(fields)):
        return None
    pos = fields["cam_pos"][cam] if "cam_pos" in fields else jnp.asarray(model.cam_pos[cam])
    quat = fields["cam_quat"][cam] if "cam_quat" in fields else jnp.asarray(model.cam_quat[cam])
    return pos.astype(jnp.float32), quat.astype(jnp.float32)


def check_fields(fields: dict[str, Any]) -> None:
    """A `ConfigError` for a model field no backend varies per env."""
    bad = sorted(set(fields) - PER_ENV_FIELDS)
    if bad:
        raise ConfigError(
            f"model fields {bad} cannot vary per env; valid: {', '.join(sorted(PER_ENV_FIELDS))}"
        )


class PhysicsBackend(abc.ABC):
    """Advances single-env physics states; `vmap` batches them.

    Args:
        spec: the composed scene (not modified; backends compile their own copy).
        quantities: the bodies and sites to report.
        n_substeps: physics steps per control step (control held constant across them).
        settings: how to run (threads, buffer sizes); each backend reads what applies to it.
        model: `spec` compiled already, by a caller that needed the model too (from a copy):
            taken as the backend's `mj_model` instead of compiling the spec again (a LIBERO
            task's model, with its cameras' meshes, takes seconds to compile).
    """

    name: ClassVar[str]
    # Whether an episode on this backend can be serialized with `jax.export` (no host
    # callbacks, no foreign custom calls); see `export_cache`.
    exportable: ClassVar[bool] = False
    # True where a seed's episode is bit-identical in any batch layout (size, neighbours,
    # devices), so re-running a seed alone reproduces it; else only the same layout may.
    layout_invariant: ClassVar[bool] = False

    def __init__(
        self,
        spec: mujoco.MjSpec,
        quantities: QuantitySpec,
        n_substeps: int,
        settings: PhysicsSettings | None = None,
        model: mujoco.MjModel | None = None,
    ) -> None:
        self.quantity_spec = quantities
        self.n_substeps = n_substeps
        self.settings = settings or PhysicsSettings()
        self.mj_model = spec.copy().compile() if model is None else model
        self.body_ids = tuple(self.mj_model.body(n).id for n in quantities.bodies)
        self.site_ids = tuple(self.mj_model.site(n).id for n in quantities.sites)
        self.geom_ids = tuple(self.mj_model.geom(n).id for n in quantities.geoms)
        keys = [sensor_key(s) for s in quantities.sensors]
        duplicate = sorted({k for k in keys if keys.count(k) > 1})
        if duplicate:
            raise ConfigError(f"sensor names must be unique; {duplicate} repeat")
        self.rendered = self._rendered(quantities.sensors)
        for s in quantities.sensors:
            if isinstance(s, RgbSpec) and s.key not in self.rendered:
                raise ConfigError(
                    f"rgb camera {s.key!r} needs backend warp or c (a renderer); "
                    f"backend {self.name!r} has depth cameras and lasers only"
                )
        self.ray_sensors = {
            sensor_key(s): s.build(self.mj_model)
            for s in quantities.sensors
            if sensor_key(s) not in self.rendered
        }
        rest = raycast.geoms.rest_data(self.mj_model)
        self._rest_xpos = np.asarray(rest.xpos, np.float32)
        self._rest_xquat = np.asarray(rest.xquat, np.float32)
        self._setup(spec)

    def _rendered(self, sensors: tuple[SensorSpec, ...]) -> frozenset[str]:
        """Keys of the sensors this backend renders itself rather than ray casting them (none
        by default); every `RgbSpec` must be among them."""
        del sensors
        return frozenset()

    @property
    def sensor_bodies(self) -> tuple[int, ...]:
        """Moving bodies whose poses the ray-cast sensors read."""
        return tuple(sorted({b for s in self.ray_sensors.values() for b in s.bodies}))

    def read_sensors(
        self, xpos: jax.Array, xquat: jax.Array, fields: dict[str, jax.Array] | None = None
    ) -> dict[str, jax.Array]:
        """Ray-cast sensor readings of one env from body poses indexed by body id; a depth
        camera sits where this env's `cam_pos`/`cam_quat` fields put it, if it has them."""
        out = {}
        for key, sensor in self.ray_sensors.items():
            if isinstance(sensor, raycast.Laser):
                out[key] = raycast.laser_scan(sensor, xpos, xquat)
            else:
                local = camera_local(fields, sensor.cam_id, self.mj_model)
                out[key] = raycast.depth_image(sensor, xpos, xquat, local)[0]
        return out

    def read_sensors_of(
        self, pos: jax.Array, quat: jax.Array, fields: dict[str, jax.Array] | None = None
    ) -> dict[str, jax.Array]:
        """`read_sensors` from the poses of `sensor_bodies` alone (others at rest)."""
        ids = np.asarray(self.sensor_bodies, np.int64)
        xpos, xquat = jnp.asarray(self._rest_xpos), jnp.asarray(self._rest_xquat)
        if ids.size:
            xpos, xquat = xpos.at[ids].set(pos), xquat.at[ids].set(quat)
        return self.read_sensors(xpos, xquat, fields)

    def _setup(self, spec: mujoco.MjSpec) -> None:  # noqa: B027 - optional hook
        """Backend-specific construction, after the common fields above are set."""

    @abc.abstractmethod
    def init(
        self, qpos: jax.Array, qvel: jax.Array, fields: dict[str, jax.Array] | None = None
    ) -> PhysicsState:
        """A state at time 0 with the given joint positions and velocities (forward-evaluated),
        simulating a model whose `fields` (see `PhysicsState.fields`) take these values."""

    @abc.abstractmethod
    def step(
        self,
        state: PhysicsState,
        ctrl: jax.Array,
        mocap: tuple[jax.Array, jax.Array] | None = None,
        render: bool = True,
    ) -> PhysicsState:
        """Hold `ctrl` (and, for a model with mocap bodies, `mocap` = their positions (nmocap,
        3) and unit quaternions (nmocap, 4)) for `n_substeps` physics steps. `render` False:
        the backend draws no camera this step (`c`: no RGB image; `warp`: none of the images
        MuJoCo-Warp's renderer draws, RGB or depth) and the new state keeps the previous ones,
        so a scene that observes one physics step of several draws that one only."""

    def warm_up(self) -> None:  # noqa: B027 - an optional hook, a no-op by default
        """Build whatever the first step would build lazily (e.g. GPU kernels), so that it is
        counted as compile time rather than in the first chunk's run time."""

    def devices(self) -> list[jax.Device]:
        """The devices the runner shards envs over: the backend's candidates, at most
        `settings.max_devices` of them."""
        return self._candidate_devices()[: self.settings.max_devices]

    def _candidate_devices(self) -> list[jax.Device]:
        """Every device this backend can run on (default: every device JAX sees)."""
        return list(jax.devices())

    def home_device(self) -> jax.Device:
        """Where this process keeps the model: its first device among the backend's (in a job
        of several processes, `jax.devices()[0]` belongs to process 0, which MJX would pick)."""
        here = jax.process_index()
        return next(d for d in self._candidate_devices() if d.process_index == here)

    @property
    def max_batch(self) -> int | None:
        """Largest per-device batch this backend can run (None: unbounded)."""
        return None

    @property
    def control_dt(self) -> float:
        return float(self.mj_model.opt.timestep) * self.n_substeps

    def describe(self) -> dict[str, Any]:
        """Settings recorded in reports."""
        return {"name": self.name, "n_substeps": self.n_substeps}


def reference_qpos(m: mujoco.MjModel) -> np.ndarray:
    """The model's reference pose: its first keyframe's joint positions if it has one, else
    `qpos0`. Where a backend parks a diverged env and what Warp warms its kernels up from, so
    a model whose `qpos0` piles bodies on each other (LIBERO's objects all start at the
    origin: 1,862 contacts in `libero_10/0`) names a resting pose in a keyframe."""
    return np.array(m.key_qpos[0] if m.nkey else m.qpos0)


def all_finite(*arrays: jax.Array) -> jax.Array:
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in arrays]))
