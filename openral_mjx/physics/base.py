"""The physics-backend contract: advance one env's state, report the quantities task logic reads.

Task logic (reset sampling, observation, reward, success) never touches backend internals; it
reads `Quantities`, which every backend produces the same way. Backends are single-env and
pure, so the runner batches them with `jax.vmap` like any other JAX function.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
import mujoco
from flax import struct

from openral_mjx.errors import ConfigError


@dataclasses.dataclass(frozen=True)
class QuantitySpec:
    """Which named bodies and sites the task logic reads (their world poses)."""

    bodies: tuple[str, ...] = ()
    sites: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class PhysicsSettings:
    """How a backend runs, as opposed to what it simulates (that is the scene's MjSpec).

    Attributes:
        threads: MuJoCo C worker threads (`c`); None: all cores.
        batch_size: envs per device the backend sizes per-batch buffers for (`warp`: contact
            and constraint capacity); the runner rejects larger per-device batches.
        contacts_per_env: `warp` contact capacity per env (a buffer overflow marks the env
            diverged, never silently wrong).
    """

    threads: int | None = None
    batch_size: int = 4096
    contacts_per_env: int = 32

    def __post_init__(self) -> None:
        if self.threads is not None and self.threads < 1:
            raise ConfigError(f"threads must be >= 1, got {self.threads}")
        for name in ("batch_size", "contacts_per_env"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)}")


@struct.dataclass
class Quantities:
    """Backend-agnostic physics readout of one env, float32, world frame (quaternions w-x-y-z)."""

    qpos: jax.Array  # (nq,)
    qvel: jax.Array  # (nv,)
    body_pos: jax.Array  # (len(spec.bodies), 3)
    body_quat: jax.Array  # (len(spec.bodies), 4)
    site_pos: jax.Array  # (len(spec.sites), 3)
    ok: jax.Array  # () bool: False once the state went non-finite or the engine reset it


@struct.dataclass
class PhysicsState:
    """One env's physics: backend-specific `data` plus the common `quantities`."""

    data: Any
    quantities: Quantities


class PhysicsBackend(abc.ABC):
    """Advances single-env physics states; `vmap` batches them.

    Args:
        spec: the composed scene (not modified; backends compile their own copy).
        quantities: the bodies and sites to report.
        n_substeps: physics steps per control step (control held constant across them).
        settings: how to run (threads, buffer sizes); each backend reads what applies to it.
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
    ) -> None:
        self.quantity_spec = quantities
        self.n_substeps = n_substeps
        self.settings = settings or PhysicsSettings()
        self.mj_model = spec.copy().compile()
        self.body_ids = tuple(self.mj_model.body(n).id for n in quantities.bodies)
        self.site_ids = tuple(self.mj_model.site(n).id for n in quantities.sites)
        self._setup(spec)

    def _setup(self, spec: mujoco.MjSpec) -> None:  # noqa: B027 - optional hook
        """Backend-specific construction, after the common fields above are set."""

    @abc.abstractmethod
    def init(self, qpos: jax.Array, qvel: jax.Array) -> PhysicsState:
        """A state at time 0 with the given joint positions and velocities (forward-evaluated)."""

    @abc.abstractmethod
    def step(self, state: PhysicsState, ctrl: jax.Array) -> PhysicsState:
        """Hold `ctrl` for `n_substeps` physics steps."""

    def warm_up(self) -> None:  # noqa: B027 - an optional hook, a no-op by default
        """Build whatever the first step would build lazily (e.g. GPU kernels), so that it is
        counted as compile time rather than in the first chunk's run time."""

    def devices(self) -> list[jax.Device]:
        """The devices the runner shards envs over (default: every device JAX sees)."""
        return list(jax.devices())

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


def all_finite(*arrays: jax.Array) -> jax.Array:
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in arrays]))
